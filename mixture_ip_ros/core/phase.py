"""Phase estimation for movements of different speeds (thesis 4.1, eqs. 15-20).

The phase is z(t) = alpha (t - t0) in [0, 1], alpha = 1/T with T the movement duration in
seconds and t0 the onset. Hypotheses are a deterministic grid of alpha values shared by all
mixture components; each component k has its own prior p(alpha | k) (the joint estimation of
component and phase proposed as future work in chapter 5).
"""

import numpy as np
from scipy.special import logsumexp

from .basis import GaussianBasis
from .numerics import logsumexp_rows


def timing_variance(durations, periods):
    """Variance of alpha = 1/T that the sampling alone leaves: onset and end are each known to
    one sample period dt, so T has variance 2 dt^2 / 12 and alpha, to first order,
    alpha^4 dt^2 / 6. (n,)"""
    alphas = 1.0 / np.asarray(durations, dtype=float)
    return alphas ** 4 * np.asarray(periods, dtype=float) ** 2 / 6.0


def alpha_log_density(alphas, mean, var):
    """log N(alpha_i; m_k, v_k) for every demonstration and component: (n, K)."""
    a = np.asarray(alphas, dtype=float)[:, None]
    return -0.5 * (np.log(2 * np.pi * var)[None, :] + (a - mean[None, :]) ** 2 / var[None, :])


def alpha_m_step(alphas, resp, prior_var: float, strength: float):
    """M step of p(alpha | k) = N(m_k, v_k), the phase-speed factor of a component's joint
    p(w, alpha | k) = p(w | k) p(alpha | k) (thesis 4.1: weights and alpha independent, eq. 17).

    m_k = sum_i r_ik alpha_i / n_k; v_k = (sum_i r_ik (alpha_i - m_k)^2 + s v0) / (n_k + s),
    the MAP variance under a conjugate prior of ``strength`` s pseudo-demonstrations of variance
    ``prior_var`` v0 (as the weight covariances are regularised). A component without members
    gets the mean of all and v0. Returns (m (K,), v (K,), n_k (K,)).
    """
    a = np.asarray(alphas, dtype=float)
    nk = resp.sum(axis=0)
    empty = nk < 1e-12
    mean = np.where(empty, a.mean(), resp.T @ a / np.where(empty, 1.0, nk))
    S = np.einsum('ik,ik->k', resp, (a[:, None] - mean[None, :]) ** 2)
    return mean, (S + strength * prior_var) / (nk + strength), nk


def alpha_penalty(var, prior_var: float, strength: float) -> float:
    """log of the conjugate prior of :func:`alpha_m_step` (up to a constant), summed over k."""
    return float(-0.5 * strength * np.sum(prior_var / var + np.log(var)))


def alpha_prior_std(var, nk, timing_var):
    """Spread of the online prior p(alpha | k): the component's variance times (1 + 1/n_k), the
    predictive spread of a new demonstration's alpha when the mean itself is estimated from n_k
    demonstrations, plus the sampling's timing variance; from the data and the sensor, never a
    fixed floor."""
    return np.sqrt(var * (1.0 + 1.0 / np.maximum(nk, 1.0)) + timing_var)


def alpha_grid(alpha_mean, alpha_std, n_alpha: int = 50, n_std: float = 3.0):
    """M alpha hypotheses covering every component's prior to +-n_std standard deviations."""
    alpha_mean = np.atleast_1d(alpha_mean)
    alpha_std = np.atleast_1d(alpha_std)
    lo = np.min(alpha_mean - n_std * alpha_std)
    hi = np.max(alpha_mean + n_std * alpha_std)
    lo = max(lo, 0.2 * np.min(alpha_mean))
    return np.linspace(lo, hi, int(n_alpha))


def alpha_log_prior(grid, alpha_mean, alpha_std):
    """log p(alpha_m | k) on the grid, normalised over the grid for each k: shape (K, M)."""
    grid = np.asarray(grid)
    mu = np.atleast_1d(alpha_mean)[:, None]
    sd = np.atleast_1d(alpha_std)[:, None]
    lp = -0.5 * ((grid[None, :] - mu) / sd) ** 2
    return lp - logsumexp(lp, axis=1, keepdims=True)


def tempered_speed_weights(log_evidence, log_prior, weight: float):
    """eta log p(D | k, alpha_m) + log p(alpha_m | k) (eta = ``weight``): the tempered posterior
    of :func:`tempered_speed_posterior` before normalising; -inf where the evidence is."""
    le = np.asarray(log_evidence, dtype=float)
    gone = np.isneginf(le)
    return np.where(gone, -np.inf, weight * np.where(gone, 0.0, le) + np.asarray(log_prior))


def tempered_speed_posterior(log_evidence, log_prior, weight: float):
    """log p_eta(alpha_m | D, k), normalised over the grid (last axis): eta log p(D | k, alpha_m)
    + log p(alpha_m | k) (eta = ``weight``; eta = 1 is eq. 16 for one component, eta = 0 the
    prior alone). A tempered likelihood is the generalised-Bayes update for a model the data
    do not quite follow (Gruenwald's learning rate; Holmes & Walker 2017): here one constant
    speed per movement, where people's speed drifts within one. -inf evidence (a pruned
    hypothesis) stays -inf, and so does a row with nothing left."""
    lp = tempered_speed_weights(log_evidence, log_prior, weight)
    rows = lp.reshape(-1, lp.shape[-1])
    norm = logsumexp_rows(rows)
    out = np.full_like(rows, -np.inf)
    alive = np.isfinite(norm)
    out[alive] = rows[alive] - norm[alive, None]
    return out.reshape(lp.shape)


def log_density_on_grid(log_posterior, grid, alpha) -> float:
    """log of the density a grid posterior (log probabilities on the evenly spaced ``grid``)
    puts at ``alpha``: the probabilities interpolated, over the grid step. Beyond the grid the
    density is 0, floored at 1e-12 per unit alpha (every posterior on that grid gets the same
    floor there, so comparisons between them are unaffected)."""
    grid = np.asarray(grid, dtype=float)
    p = np.interp(alpha, grid, np.exp(log_posterior), left=0.0, right=0.0)
    return float(np.log(max(p / (grid[1] - grid[0]), 1e-12)))


def design_matrix(basis: GaussianBasis, t, alpha: float, n_dofs: int):
    """A of eq. 19 for ``n_dofs`` DOFs sharing the basis: kron(I, psi(alpha t)), rows DOF-major."""
    psi = basis(alpha * np.asarray(t, dtype=float))
    return np.kron(np.eye(n_dofs), psi)


def log_evidence_batch(mean, cov, basis: GaussianBasis, t, Y, alpha: float, noise_var):
    """Eq. 18 evaluated directly: log N(D; A mu, Sigma_D + A Sigma A^T), D stacked DOF-major.

    This is the O(m^3) textbook form: the test oracle of the recursive estimator and the
    naive baseline of the benchmark.
    """
    Y = np.asarray(Y, dtype=float)
    m, P = Y.shape
    A = design_matrix(basis, t, alpha, P)
    D = Y.T.ravel()
    S = np.diag(np.repeat(np.broadcast_to(noise_var, (P,)), m)) + A @ cov @ A.T
    L = np.linalg.cholesky(S)
    r = np.linalg.solve(L, D - A @ mean)
    return float(-0.5 * (D.size * np.log(2 * np.pi) + 2 * np.sum(np.log(np.diag(L))) + r @ r))


def phase_posterior_batch(model, t, Y, grid, observed_only: bool = True):
    """Eq. 16 with the mixture: log p(k, alpha_m | D) for every component and grid value,
    each term from eq. 18 directly (naive; the online estimator does this recursively)."""
    do = model.n_observed_ * model.n_basis
    lp = np.log(model.weights_)[:, None] + alpha_log_prior(grid, model.alpha_mean_,
                                                           model.alpha_std_)
    for k in range(model.n_components):
        for m, a in enumerate(grid):
            lp[k, m] += log_evidence_batch(model.means_[k][:do], model.covariances_[k][:do, :do],
                                           model.basis_, t, Y, a, model.observed_noise(k))
    return lp - logsumexp(lp)
