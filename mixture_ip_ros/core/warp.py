"""A phase that bends (the thesis's future work, section 4.2.2, eq. 34): each movement's phase
z = g(t / T; b), a monotone time warp with a Gaussian over its parameters b.

The family: g(u) = int_0^u r / int_0^1 r, the relative phase rate r(s) = exp(sum_j b_j phi_j(s))
with ``N_WARP`` Gaussian bumps phi_j evenly over [0, 1] (Ramsay & Li 1998's monotone family):
monotone by construction, g(0) = 0 and g(1) = 1 exactly, and b = 0 is the linear phase
z = t / T. A positive rate and fixed endpoints are what eq. 34's positive sigmoid weights
secure; writing the log rate in bumps makes every b a valid warp, so the MAP of b is an
unconstrained optimisation.
"""

import numpy as np
from scipy import optimize

from .demonstration import Demonstration

N_WARP = 5                                   # bumps of the log phase rate
CENTERS = np.linspace(0.0, 1.0, N_WARP)
WIDTH = 1.0 / (N_WARP - 1)
GRID = np.linspace(0.0, 1.0, 513)            # where g is integrated (trapezoids)
_BUMPS = np.exp(-0.5 * ((GRID[:, None] - CENTERS) / WIDTH) ** 2)


def warp(u, b):
    """z = g(u; b) at relative times ``u``; u outside [0, 1] is kept (before the onset, after
    the end, where the linear phase's own extrapolation is what a ProMP clamps)."""
    rate = np.exp(_BUMPS @ np.asarray(b, dtype=float))
    cum = np.r_[0.0, np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(GRID))]
    u = np.asarray(u, dtype=float)
    return np.where((u >= 0) & (u <= 1), np.interp(u, GRID, cum / cum[-1]), u)


def registered(demo: Demonstration, b) -> Demonstration:
    """``demo`` at its warped phase: each sample restamped to T g(t / T; b) (onset and end
    kept). Samples keep their values, so a learner that reads phase t / T reads g."""
    return Demonstration(demo.duration * warp(demo.phase, b), demo.observed, demo.controlled,
                         demo.label, demo.name)


def map_warp(log_evidence, prior_mean, prior_sd):
    """The MAP warp: b maximising log_evidence(b) + log N(b; prior_mean, diag(prior_sd^2)), by
    L-BFGS-B from the prior's mean. Returns (b, converged); where the optimiser does not
    converge or the evidence is not finite, the prior's mean (b = 0 under a centred prior: the
    linear phase), so a bad fit never leaves a NaN in a phase."""
    mean = np.asarray(prior_mean, dtype=float)
    sd = np.broadcast_to(np.asarray(prior_sd, dtype=float), mean.shape)
    if mean.shape != (N_WARP,) or not (np.all(np.isfinite(mean)) and np.all(sd > 0)):
        raise ValueError(f'the prior over the warp needs a finite mean of shape ({N_WARP},) and '
                         f'positive sds, got {mean!r}, {sd!r}')

    def cost(b):
        value = -(log_evidence(b) - 0.5 * np.sum(((b - mean) / sd) ** 2))
        return value if np.isfinite(value) else np.inf

    with np.errstate(all='ignore'):
        res = optimize.minimize(cost, mean, method='L-BFGS-B')
    good = bool(res.success and np.isfinite(res.fun) and np.all(np.isfinite(res.x)))
    return (res.x if good else mean.copy()), good


def warp_prior(b, weights=None, sd_floor: float = 0.05):
    """The Gaussian over the warp of a component's members (the M step of eq. 34's prior): the
    (weighted) mean and sd of each parameter of the MAP warps ``b`` (n, N_WARP), the sd kept
    above ``sd_floor`` (a few members do not make every warp but theirs impossible)."""
    b = np.asarray(b, dtype=float)
    w = np.ones(len(b)) if weights is None else np.asarray(weights, dtype=float)
    if b.ndim != 2 or b.shape[1] != N_WARP or len(w) != len(b) or not w.sum() > 0:
        raise ValueError(f'warps must be (n, {N_WARP}) with n positive weights, got {b.shape} '
                         f'and {w.shape}')
    mean = w @ b / w.sum()
    var = w @ (b - mean) ** 2 / w.sum()
    return mean, np.sqrt(var + sd_floor ** 2)
