"""The robot layer's fast paths: the two numpy steps of the controller's 1 kHz loop around
Pinocchio's inverse dynamics, compiled so that each is one call instead of several (at 1 kHz
the cost is the calls, not the arithmetic). Each gives the values of the numpy it replaces bit
for bit (test_robot_controller steps both and compares every state and torque):

- acceleration_into: the control law's acceleration in ComputedTorqueController._fast and
  _compute_checked, qdd_ref + kp * (q_ref - q) + kd * (qd_ref - qd);
- clip_into: the finiteness check (the sum of squares tau.dot(tau)) and the clip
  (tau.clip(-effort_limit, effort_limit)) of ComputedTorqueController._fast.
"""

import numba
import numpy as np


@numba.njit(cache=True)
def acceleration_into(refs, k, q, qd, kp, kd, a, errors):
    """The control law's acceleration for the reference refs[k] = (q_ref, qd_ref, qdd_ref):
    a = qdd_ref + Kp (q_ref - q) + Kd (qd_ref - qd), and errors[k] = q_ref - q. The operations
    of the numpy expression in compute, in its order (no fused multiply-add): the same values
    bit for bit, in one call instead of six."""
    for j in range(a.shape[0]):
        e = refs[k, 0, j] - q[j]
        errors[k, j] = e
        a[j] = refs[k, 2, j] + kp[j] * e + kd[j] * (refs[k, 1, j] - qd[j])


@numba.njit(cache=True)
def clip_into(tau, low, high, out):
    """out = tau clipped to [low, high] and True; False (out untouched) when tau's sum of
    squares is not finite (the check of compute's fast path)."""
    ss = 0.0
    for j in range(tau.shape[0]):
        ss += tau[j] * tau[j]
    if not np.isfinite(ss):
        return False
    for j in range(tau.shape[0]):
        out[j] = min(max(tau[j], low[j]), high[j])
    return True
