"""Computed-torque joint control of an arm with Pinocchio inverse dynamics."""

from __future__ import annotations

import logging
import math

import numpy as np
import pinocchio as pin

from mixture_ip_ros.robot._fast import acceleration_into, clip_into
from mixture_ip_ros.robot.kinematics import RobotKinematics


def default_gains(natural_frequency, damping_ratio, dof: int):
    """Per-joint gains Kp = w^2, Kd = 2 zeta w for error dynamics e'' + Kd e' + Kp e = 0.

    damping_ratio 1 is critical damping. Scalars apply to every joint.
    """
    try:
        w = np.broadcast_to(np.asarray(natural_frequency, dtype=float), (dof,)).copy()
        z = np.broadcast_to(np.asarray(damping_ratio, dtype=float), (dof,)).copy()
    except ValueError:
        raise ValueError(f'natural_frequency and damping_ratio must be one or {dof} numbers, '
                         f'got {natural_frequency!r} and {damping_ratio!r}') from None
    if not np.all(np.isfinite(w)) or np.any(w <= 0):
        raise ValueError(f'natural_frequency must be positive, got {natural_frequency!r}')
    if not np.all(np.isfinite(z)) or np.any(z <= 0):
        raise ValueError(f'damping_ratio must be positive, got {damping_ratio!r}')
    return w**2, 2.0 * z * w


class ComputedTorqueController:
    """tau = RNEA(q, qd, qdd_ref + Kp (q_ref - q) + Kd (qd_ref - qd)), clipped to effort limits.

    Without a reference, or when the state or the reference is not finite, the controller holds:
    the same law with a constant reference at the hold position (gravity and dynamics compensated,
    zero velocity). The hold position is the measured position when holding starts. The returned
    torque is always finite.
    """

    def __init__(self, kinematics: RobotKinematics, kp=None, kd=None,
                 natural_frequency=None, damping_ratio=None, effort_limit=None, logger=None):
        """Gains: explicit kp/kd (dof,) win; otherwise from natural_frequency and damping_ratio
        (None: the robot description's controller gains).

        With kp given and kd not, kd is the critically damped 2 sqrt(kp).
        """
        self.kinematics = kinematics
        self._model = kinematics.model
        self._data = self._model.createData()
        n = self.dof = kinematics.dof
        w0, z0 = kinematics.description.gains()
        kp0, kd0 = default_gains(w0 if natural_frequency is None else natural_frequency,
                                 z0 if damping_ratio is None else damping_ratio, n)
        self.kp = kp0 if kp is None else self._gain(kp, 'kp')
        if kd is not None:
            self.kd = self._gain(kd, 'kd')
        else:
            self.kd = kd0 if kp is None else 2.0 * np.sqrt(self.kp)
        limit = kinematics.effort_limit if effort_limit is None else effort_limit
        self.effort_limit = np.asarray(limit, dtype=float).copy()
        if self.effort_limit.shape != (n,) or np.any(~(self.effort_limit > 0)):
            raise ValueError(f'effort_limit must be {n} positive numbers')
        self._log = logger if logger is not None else logging.getLogger(__name__).warning
        self.hold_position: np.ndarray | None = None
        self.holding = True
        self._neg_limit = -self.effort_limit
        self._zero = np.zeros(n)
        self._last_raw = np.zeros(n)
        self.fault_count = 0
        self.last_fault: str | None = None
        self._active_fault: str | None = None
        self._last_safe = np.zeros(n)
        # Load robot._fast's compiled kernels now (from the disk cache), not in the first control
        # step.
        acceleration_into(np.zeros((1, 3, n)), 0, self._zero, self._zero, self.kp, self.kd,
                          np.empty(n), np.empty((1, n)))
        clip_into(self._zero, self._neg_limit, self.effort_limit, np.empty(n))

    def _gain(self, value, name):
        try:
            g = np.broadcast_to(np.asarray(value, dtype=float), (self.dof,)).copy()
        except ValueError:
            raise ValueError(f'{name} must be one or {self.dof} numbers, got {value!r}') from None
        if not np.all(np.isfinite(g)) or np.any(g < 0):
            raise ValueError(f'{name} must be {self.dof} non-negative numbers, got {value!r}')
        return g

    def _fault(self, reason: str):
        self.fault_count += 1
        # Log once per episode (and per change of reason), not at 1 kHz.
        if reason != self._active_fault:
            self._log(f'controller holding: {reason}')
        self._active_fault = reason
        self.last_fault = reason

    def reset_hold(self, q=None):
        """Hold at q from now on (None: at the next measured position)."""
        self.hold_position = None if q is None else np.asarray(q, dtype=float).copy()
        self.holding = True

    @property
    def saturated(self) -> bool:
        """Whether the last torque was clipped at an effort limit."""
        return bool(np.any(np.abs(self._last_raw) > self.effort_limit))

    def compute(self, q, qd, q_ref=None, qd_ref=None, qdd_ref=None) -> np.ndarray:
        """Joint torques (dof,) for the measured state and the reference (None: hold)."""
        # Fast path for the 1 kHz loop: a NaN or Inf anywhere in the inputs propagates into tau
        # (0 * NaN is NaN), so one check of the result covers them all; anything odd goes
        # through the careful path, which finds the culprit and holds.
        if q_ref is None:
            if self.holding and self.hold_position is not None:
                tau = self._fast(q, qd, self.hold_position, self._zero, self._zero, True)
                if tau is not None:
                    return tau
        elif qd_ref is not None and qdd_ref is not None:
            tau = self._fast(q, qd, q_ref, qd_ref, qdd_ref, False)
            if tau is not None:
                return tau
        return self._compute_checked(q, qd, q_ref, qd_ref, qdd_ref)

    def follow(self, q, qd, refs, ctrl, advance, errors) -> None:
        """Closed-loop control steps on a reference: per row refs[k] = (q_ref, qd_ref, qdd_ref)
        the torque compute(q, qd, *refs[k]) gives for the state of that moment is written into
        ``ctrl``, then ``advance()`` moves the plant one step (updating q and qd in place), and
        errors[k] = q_ref - q. The same torques, bit for bit, as calling compute per step."""
        self._steps(q, qd, refs, len(refs), False, ctrl, advance, errors)

    def hold(self, q, qd, n: int, ctrl, advance) -> None:
        """``n`` closed-loop control steps without a reference (compute(q, qd) each), as
        :meth:`follow`."""
        i, n = 0, int(n)
        while i < n and not (self.holding and self.hold_position is not None):
            ctrl[:] = self.compute(q, qd)      # starts holding
            advance()
            i += 1
        if i < n:
            # The hold position stays the same while holding (compute keeps it, also when it
            # holds through a fault), so the reference is constant.
            refs = np.zeros((1, 3, self.dof))
            refs[0, 0] = self.hold_position
            self._steps(q, qd, refs, n - i, True, ctrl, advance, np.empty((1, self.dof)))

    def _steps(self, q, qd, refs, n, holding, ctrl, advance, errors):
        # At 1 kHz the cost is numpy's and Python's call overhead, not the arithmetic: four calls
        # per step (two compiled ones from robot._fast, Pinocchio's RNEA, the plant's step),
        # everything in locals.
        # compute's fast path in those calls; a torque that is not finite goes through compute
        # itself (the careful path finds the culprit, holds and logs).
        model, data = self._model, self._data
        kp, kd, low, high = self.kp, self.kd, self._neg_limit, self.effort_limit
        rnea, accelerate, clip = pin.rnea, acceleration_into, clip_into
        a = np.empty(self.dof)
        fast = None     # the last unclipped torque of the fast path, its state not yet recorded
        for i in range(n):
            k = 0 if holding else i
            accelerate(refs, k, q, qd, kp, kd, a, errors)
            try:
                tau = rnea(model, data, q, qd, a)
                ok = clip(tau, low, high, ctrl)
            except (TypeError, ValueError, RuntimeError):
                ok = False
            if ok:
                fast = tau
            else:
                if fast is not None:
                    self._record_fast(fast, ctrl.copy(), holding)
                    fast = None
                ctrl[:] = self.compute(q, qd) if holding else self.compute(q, qd, *refs[k])
            advance()
        if fast is not None:
            self._record_fast(fast, ctrl.copy(), holding)

    def _record_fast(self, tau, clipped, holding):
        """The state the fast path leaves after the torque ``tau``, applied as ``clipped`` (kept,
        not copied); off a reference (``holding`` false) the hold ends."""
        self._active_fault = None
        self._last_raw = tau
        self._last_safe = clipped
        if not holding:
            self.holding = False
            self.hold_position = None

    def _fast(self, q, qd, q_ref, qd_ref, qdd_ref, holding):
        try:
            a = qdd_ref + self.kp * (q_ref - q) + self.kd * (qd_ref - qd)
            tau = pin.rnea(self._model, self._data, q, qd, a)
        except (TypeError, ValueError, RuntimeError):
            return None
        if tau.shape != (self.dof,) or not math.isfinite(tau.dot(tau)):
            return None
        clipped = tau.clip(self._neg_limit, self.effort_limit)
        self._record_fast(tau, clipped, holding)
        return clipped.copy()

    def _compute_checked(self, q, qd, q_ref, qd_ref, qdd_ref) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        qd = np.asarray(qd, dtype=float)
        # Finiteness by one dot product per vector: any NaN/Inf (or absurd magnitude) shows up
        # in the sum of squares, at a fraction of the cost of np.isfinite on this 1 kHz path.
        if q.shape != (self.dof,) or not math.isfinite(q.dot(q)):
            # Nothing to linearise about: repeat the last finite torque.
            self._fault('non-finite joint positions')
            return self._last_safe.copy()
        if qd.shape != (self.dof,) or not math.isfinite(qd.dot(qd)):
            self._fault('non-finite joint velocities')
            qd = self._zero
            q_ref = None
        if q_ref is not None:
            q_ref = np.asarray(q_ref, dtype=float)
            qd_ref = self._zero if qd_ref is None else np.asarray(qd_ref, dtype=float)
            qdd_ref = self._zero if qdd_ref is None else np.asarray(qdd_ref, dtype=float)
            if not (q_ref.shape == qd_ref.shape == qdd_ref.shape == (self.dof,)
                    and math.isfinite(q_ref.dot(q_ref) + qd_ref.dot(qd_ref)
                                      + qdd_ref.dot(qdd_ref))):
                self._fault('non-finite or malformed reference')
                q_ref = None
        if q_ref is None:
            if not self.holding or self.hold_position is None:
                self.hold_position = q.copy()
            self.holding = True
            a = self.kp * (self.hold_position - q) - self.kd * qd
        else:
            self.holding = False
            self.hold_position = None
            a = qdd_ref + self.kp * (q_ref - q) + self.kd * (qd_ref - qd)
        tau = pin.rnea(self._model, self._data, q, qd, a)
        if not math.isfinite(tau.dot(tau)):
            self._fault('non-finite torque from dynamics')
            tau = pin.computeGeneralizedGravity(self._model, self._data, q)
            if not math.isfinite(tau.dot(tau)):
                return self._last_safe.copy()
        self._last_raw = tau
        clipped = np.minimum(np.maximum(tau, self._neg_limit), self.effort_limit)
        self._last_safe = clipped
        return clipped.copy()
