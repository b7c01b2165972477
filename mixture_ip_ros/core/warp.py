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
MAX_ITER = 200                               # L-BFGS-B iterations of a MAP warp (a fit takes 10-40)
_BUMPS = np.exp(-0.5 * ((GRID[:, None] - CENTERS) / WIDTH) ** 2)


def _rate(b):
    """The relative phase rate on GRID up to a constant factor, which g does not depend on:
    scaled so that its largest value is 1, finite for any finite b (an optimiser's line search
    tries large ones)."""
    log_rate = _BUMPS @ np.asarray(b, dtype=float)
    return np.exp(log_rate - log_rate.max())


def warp(u, b):
    """z = g(u; b) at relative times ``u``; u outside [0, 1] is kept (before the onset, after
    the end, where the linear phase's own extrapolation is what a ProMP clamps)."""
    rate = _rate(b)
    cum = np.r_[0.0, np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(GRID))]
    u = np.asarray(u, dtype=float)
    return np.where((u >= 0) & (u <= 1), np.interp(u, GRID, cum / cum[-1]), u)


def warp_jacobian(u, b):
    """(z, dz/db): :func:`warp` at ``u`` and its derivative with respect to b, (len(u), N_WARP),
    exact for the trapezoids and the interpolation ``warp`` computes (0 outside [0, 1])."""
    rate = _rate(b)
    du = np.diff(GRID)[:, None]
    both = np.hstack([rate[:, None], rate[:, None] * _BUMPS])      # r and its derivatives
    cum = np.vstack([np.zeros((1, N_WARP + 1)),
                     np.cumsum(0.5 * (both[1:] + both[:-1]) * du, axis=0)])
    g = cum[:, 0] / cum[-1, 0]
    dg = (cum[:, 1:] - g[:, None] * cum[-1, 1:]) / cum[-1, 0]
    u = np.asarray(u, dtype=float)
    inside = (u >= 0) & (u <= 1)
    z = np.where(inside, np.interp(u, GRID, g), u)
    J = np.stack([np.interp(u, GRID, dg[:, j]) for j in range(N_WARP)], axis=1)
    return z, np.where(inside[:, None], J, 0.0)


def registered(demo: Demonstration, b) -> Demonstration:
    """``demo`` at its warped phase: each sample restamped to T g(t / T; b) (onset and end
    kept). Samples keep their values, so a learner that reads phase t / T reads g."""
    return Demonstration(demo.duration * warp(demo.phase, b), demo.observed, demo.controlled,
                         demo.label, demo.name)


def map_warp(log_evidence, prior_mean, prior_sd, start=None, gradient: bool = False):
    """The MAP warp: b maximising log_evidence(b) + log N(b; prior_mean, diag(prior_sd^2)), by
    L-BFGS-B from ``start`` (None: the prior's mean); with ``gradient``, log_evidence returns
    (value, d value / db) (else the optimiser differences it, N_WARP + 1 calls per step).
    Returns (b, converged); where the optimiser does not converge or the evidence is not
    finite, the prior's mean (b = 0 under a centred prior: the linear phase), so a bad fit
    never leaves a NaN in a phase."""
    mean = np.asarray(prior_mean, dtype=float)
    sd = np.broadcast_to(np.asarray(prior_sd, dtype=float), mean.shape)
    if mean.shape != (N_WARP,) or not (np.all(np.isfinite(mean)) and np.all(sd > 0)):
        raise ValueError(f'the prior over the warp needs a finite mean of shape ({N_WARP},) and '
                         f'positive sds, got {mean!r}, {sd!r}')

    def cost(b):
        try:
            value, grad = log_evidence(b) if gradient else (log_evidence(b), None)
        except (ValueError, np.linalg.LinAlgError):     # a warp the evidence cannot take
            return (np.inf, np.zeros(N_WARP)) if gradient else np.inf
        value = -(value - 0.5 * np.sum(((b - mean) / sd) ** 2))
        if not gradient:
            return value if np.isfinite(value) else np.inf
        grad = -(np.asarray(grad, dtype=float) - (b - mean) / sd ** 2)
        ok = np.isfinite(value) and np.all(np.isfinite(grad))
        return (value, grad) if ok else (np.inf, np.zeros(N_WARP))

    with np.errstate(all='ignore'):
        res = optimize.minimize(cost, mean if start is None else np.asarray(start, dtype=float),
                                jac=gradient, method='L-BFGS-B', options={'maxiter': MAX_ITER})
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


# Learning each component's Gaussian over b (eq. 34's prior): EM from N(0, START_SD^2 I), a log
# phase rate that departs from the linear phase by about 30 % at a bump, LEARN_STEPS rounds of
# every member's MAP warp and the Gaussian of the warps.
START_SD, LEARN_STEPS, SD_FLOOR = 0.3, 3, 0.05


def learn_warp_priors(log_evidences, component, n_components: int):
    """Each component's Gaussian over the warp from its members: ``log_evidences`` one function
    of b per demonstration (log p(D_i | k_i, b) under its component and its gradient, as
    :func:`map_warp` with ``gradient`` takes them), ``component`` (n,) the
    component k_i of each. EM over the Gaussian (:func:`map_warp`, :func:`warp_prior`), the
    demonstrations whose fit does not converge left out of it. Returns (means (K, N_WARP),
    sds (K, N_WARP), converged (n,) bool); a component with no converged member keeps
    N(0, START_SD^2 I)."""
    component = np.asarray(component, dtype=int)
    means = np.zeros((n_components, N_WARP))
    sds = np.full((n_components, N_WARP), START_SD)
    good = np.zeros(len(component), dtype=bool)
    b = np.zeros((len(component), N_WARP))
    for _ in range(LEARN_STEPS):
        # Each fit from the last step's warp: the prior moved little, so did its MAP.
        fits = [map_warp(f, means[k], sds[k], start, gradient=True) for f, k, start in
                zip(log_evidences, component, b)]
        b = np.array([x for x, _ in fits]).reshape(-1, N_WARP)
        good = np.array([ok for _, ok in fits], dtype=bool)
        for k in range(n_components):
            mine = good & (component == k)
            if mine.any():
                means[k], sds[k] = warp_prior(b[mine], sd_floor=SD_FLOOR)
    return means, sds, good


def warp_log_density(b, mean, sd) -> float:
    """log N(b; mean, diag(sd^2))."""
    return float(-0.5 * np.sum(((b - mean) / sd) ** 2) - np.sum(np.log(sd))
                 - 0.5 * len(mean) * np.log(2.0 * np.pi))
