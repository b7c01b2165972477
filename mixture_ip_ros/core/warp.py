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
MAX_ITER = 200                               # L-BFGS-B iterations of a MAP warp
FLAT = 0.01                                  # nats: a MAP warp's gradient times the prior's sd
_BUMPS = np.exp(-0.5 * ((GRID[:, None] - CENTERS) / WIDTH) ** 2)
_ONE_BUMPS = np.hstack([np.ones((len(GRID), 1)), _BUMPS])        # r and dr / db over r
_STEP = GRID[1] - GRID[0]


def _rate(b):
    """The relative phase rate on GRID up to a constant factor, which g does not depend on:
    scaled so that its largest value is 1, finite for any finite b (an optimiser's line search
    tries large ones)."""
    log_rate = _BUMPS @ np.asarray(b, dtype=float)
    return np.exp(log_rate - log_rate.max())


def _cumulative(f):
    """int_0^u f over GRID by trapezoids, for each column of ``f`` (len(GRID), m): a running
    sum of nonnegative steps for nonnegative f, so monotone in floating point too."""
    out = np.empty_like(f)
    out[0] = 0.0
    np.cumsum((0.5 * _STEP) * (f[1:] + f[:-1]), axis=0, out=out[1:])
    return out


def warp(u, b):
    """z = g(u; b) at relative times ``u``; u outside [0, 1] is kept (before the onset, after
    the end, where the linear phase's own extrapolation is what a ProMP clamps)."""
    u = np.asarray(u, dtype=float)
    return WarpAt(u.ravel())(b)[0].reshape(u.shape)


class WarpAt:
    """:func:`warp_jacobian` at fixed relative times ``u`` (1-D) for many b (an optimiser's):
    where each u falls on GRID is found once."""

    def __init__(self, u):
        u = np.asarray(u, dtype=float)
        if u.ndim != 1 or np.isnan(u).any():
            raise ValueError(f'relative times must be a 1-D array without NaN, got shape '
                             f'{u.shape}')
        self.u, self.inside = u, (u >= 0) & (u <= 1)
        at = np.clip(u, 0.0, 1.0) * (len(GRID) - 1)
        self.lo = at.astype(int)                     # u = 1: the padded point past GRID's last
        self.frac = (at - self.lo)[:, None]

    def __call__(self, b):
        """(z, dz/db): g(u; b) and its derivative with respect to b, (len(u), N_WARP), exact for
        the trapezoids and the linear interpolation between GRID's points (0 outside [0, 1]);
        g(0) = 0 and g(1) = 1 exactly, and g is monotone in floating point too."""
        cum = _cumulative(_rate(b)[:, None] * _ONE_BUMPS)          # int r, int dr / db
        both = np.empty((len(GRID) + 1, N_WARP + 1))                # g, dg / db; then padded
        both[:-1, :1] = cum[:, :1] / cum[-1, 0]
        both[:-1, 1:] = (cum[:, 1:] - both[:-1, :1] * cum[-1, 1:]) / cum[-1, 0]
        both[-1] = both[-2]
        lo, hi = both[self.lo], both[self.lo + 1]
        at = lo + self.frac * (hi - lo)
        z = np.minimum(at[:, 0], hi[:, 0])           # rounding never steps past the next point
        return np.where(self.inside, z, self.u), np.where(self.inside[:, None], at[:, 1:], 0.0)


def warp_jacobian(u, b):
    """(z, dz/db): :func:`warp` at ``u`` and its derivative with respect to b, (len(u), N_WARP),
    exact for the trapezoids and the interpolation ``warp`` computes (0 outside [0, 1])."""
    return WarpAt(u)(b)


def registered(demo: Demonstration, b) -> Demonstration:
    """``demo`` at its warped phase: each sample restamped to T g(t / T; b) (onset and end
    kept). Samples keep their values, so a learner that reads phase t / T reads g."""
    return Demonstration(demo.duration * warp(demo.phase, b), demo.observed, demo.controlled,
                         demo.label, demo.name)


def _checked_prior(prior_mean, prior_sd):
    mean = np.asarray(prior_mean, dtype=float)
    sd = np.broadcast_to(np.asarray(prior_sd, dtype=float), mean.shape)
    if mean.shape != (N_WARP,) or not (np.all(np.isfinite(mean)) and np.all(sd > 0)):
        raise ValueError(f'the prior over the warp needs a finite mean of shape ({N_WARP},) and '
                         f'positive sds, got {mean!r}, {sd!r}')
    return mean, sd


def map_warp(log_evidence, prior_mean, prior_sd, start=None, gradient: bool = False):
    """The MAP warp: b maximising log_evidence(b) + log N(b; prior_mean, diag(prior_sd^2)), by
    L-BFGS-B from ``start`` (None: the prior's mean); with ``gradient``, log_evidence returns
    (value, d value / db) (else the optimiser differences it, N_WARP + 1 calls per step); a b
    where it raises ValueError or LinAlgError, or is not finite, is taken as impossible.
    Returns (b, converged): the optimiser's last b (never worse than its start) unless that is
    not finite, then the prior's mean (the linear phase under a centred prior), so a bad fit
    never leaves a NaN in a phase; ``converged`` whether the optimiser says it converged or
    stopped where the log posterior is flat (each gradient component times the prior's sd at
    most ``FLAT`` nats)."""
    mean, sd = _checked_prior(prior_mean, prior_sd)

    def cost(b):
        try:
            value, grad = log_evidence(b) if gradient else (log_evidence(b), None)
        except (ValueError, np.linalg.LinAlgError):
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
    usable = bool(np.isfinite(res.fun) and np.all(np.isfinite(res.x)))
    # L-BFGS-B's line search can stop where rounding, not the objective, blocks progress (g
    # interpolates GRID linearly, so the evidence has kinks): a b where a step of one prior sd
    # changes the log posterior by less than FLAT nats to first order is a mode all the same.
    flat = bool(np.all(np.isfinite(res.jac)) and np.max(np.abs(res.jac) * sd) <= FLAT)
    return (res.x if usable else mean.copy()), bool((res.success or flat) and usable)


def laplace(log_evidence, b, prior_mean, prior_sd, step: float = 1e-5):
    """Laplace's method at the mode ``b`` (:func:`map_warp`) of log_evidence(b) (returning
    (value, gradient)) + log N(b; prior_mean, diag(prior_sd^2)): (log of its integral over b,
    the log marginal likelihood with the warp integrated out; the posterior covariance of b,
    H^-1). H, the negative log posterior's Hessian, from differences of the exact gradient;
    where it is not positive definite (a mode not reached), the prior's curvature alone.
    Exact for a Gaussian evidence."""
    mean, sd = _checked_prior(prior_mean, prior_sd)
    value, grad = log_evidence(b)
    H = np.empty((N_WARP, N_WARP))
    for j, e in enumerate(np.eye(N_WARP)):
        H[:, j] = -(np.asarray(log_evidence(b + step * e)[1]) - grad) / step
    H = 0.5 * (H + H.T) + np.diag(sd ** -2.0)
    try:
        chol = np.linalg.cholesky(H)
    except np.linalg.LinAlgError:
        H = np.diag(sd ** -2.0)
        chol = np.diag(1.0 / sd)
    log_prior = (-0.5 * np.sum(((b - mean) / sd) ** 2) - np.sum(np.log(sd))
                 - 0.5 * N_WARP * np.log(2.0 * np.pi))
    log_marginal = (value + log_prior + 0.5 * N_WARP * np.log(2.0 * np.pi)
                    - np.sum(np.log(np.diag(chol))))
    return float(log_marginal), np.linalg.inv(H)


def warp_prior(b, posterior_var=None, sd_floor: float = 0.05):
    """The Gaussian over the warp of a component's members (the M step of eq. 34's prior): the
    mean of their MAP warps ``b`` (n, N_WARP) and the sd of each parameter,
    sd^2 = mean (b_i - m)^2 + mean of the posterior variances ``posterior_var`` (n, N_WARP;
    None: 0) (the expected squared deviation, so that the prior does not shrink round by round
    with the modes it shrinks), kept above ``sd_floor`` (a few members do not make every warp
    but theirs impossible)."""
    b = np.asarray(b, dtype=float)
    if b.ndim != 2 or b.shape[1] != N_WARP or not len(b):
        raise ValueError(f'warps must be (n, {N_WARP}) with n >= 1, got {b.shape}')
    extra = 0.0 if posterior_var is None else np.mean(posterior_var, axis=0)
    mean = b.mean(axis=0)
    return mean, np.sqrt(((b - mean) ** 2).mean(axis=0) + extra + sd_floor ** 2)


# Learning each component's Gaussian over b (eq. 34's prior): EM from N(0, START_SD^2 I), a log
# phase rate that departs from the linear phase by about 30 % at a bump, LEARN_STEPS rounds of
# every member's MAP warp and its Laplace posterior, then the Gaussian.
START_SD, LEARN_STEPS, SD_FLOOR = 0.3, 3, 0.05


def learn_warp_priors(log_evidences, component, n_components: int):
    """Each component's Gaussian over the warp from its members: ``log_evidences`` one function
    of b per demonstration, log p(D_i | k_i, b) under its component and its gradient (as
    :func:`map_warp` with ``gradient`` takes them), ``component`` (n,) the component k_i of
    each. EM over the Gaussian: each member's MAP warp and posterior variance (:func:`laplace`)
    under the current Gaussian, then :func:`warp_prior` of the members whose fit converged.
    Returns (means (K, N_WARP), sds (K, N_WARP), converged (n,) bool of the last round); a
    component none of whose fits converged keeps its last Gaussian (at first N(0, START_SD^2 I))."""
    component = np.asarray(component, dtype=int)
    if len(log_evidences) != len(component):
        raise ValueError(f'{len(log_evidences)} evidences for {len(component)} components')
    means = np.zeros((n_components, N_WARP))
    sds = np.full((n_components, N_WARP), START_SD)
    b = np.zeros((len(component), N_WARP))
    var = np.zeros((len(component), N_WARP))
    good = np.zeros(len(component), dtype=bool)
    for _ in range(LEARN_STEPS):
        for i, (f, k) in enumerate(zip(log_evidences, component)):
            # From the last round's warp: the prior moved little, so did its MAP.
            b[i], good[i] = map_warp(f, means[k], sds[k], b[i], gradient=True)
            if good[i]:
                var[i] = np.diag(laplace(f, b[i], means[k], sds[k])[1])
        for k in range(n_components):
            mine = good & (component == k)
            if mine.any():
                means[k], sds[k] = warp_prior(b[mine], var[mine], SD_FLOOR)
    return means, sds, good
