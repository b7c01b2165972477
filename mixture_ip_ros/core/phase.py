"""Phase estimation for movements of different speeds (thesis 4.1, eqs. 15-20).

The phase is z(t) = alpha (t - t0) in [0, 1], alpha = 1/T with T the movement duration in
seconds and t0 the onset. Hypotheses are a deterministic grid of alpha values shared by all
mixture components; each component k has its own prior p(alpha | k) (the joint estimation of
component and phase proposed as future work in chapter 5).
"""

import numpy as np
from scipy.special import logsumexp

from .basis import GaussianBasis


def alpha_prior(durations, periods=None, resp=None, prior_count: float = 1.0):
    """Per-component Gaussian prior p(alpha | k) over alpha = 1/T (thesis 4.1, below eq. 16),
    its spread from the data and the sensor rather than a fixed floor. Returns (mean, std) (K,).

    ``durations`` (n,) seconds, ``periods`` (n,) each demonstration's sample period (None: no
    timing term), ``resp`` (n, K) responsibilities (None: one component).

    - data: the responsibility-weighted variance of alpha in component k, shrunk towards the
      variance pooled over components with ``prior_count`` pseudo-demonstrations (a component
      of one demonstration still has a spread), times (1 + 1/n_k): the predictive spread of a
      new demonstration's alpha when the mean is itself estimated from n_k of them;
    - sensor: onset and end are each known to one sample period dt, so T has variance
      2 dt^2 / 12 and alpha = 1/T the variance alpha^4 dt^2 / 6 (first order).
    A component without members gets the pooled prior.
    """
    alphas = 1.0 / np.asarray(durations, dtype=float)
    n = alphas.size
    resp = np.ones((n, 1)) if resp is None else np.asarray(resp, dtype=float)
    timing = (np.zeros(n) if periods is None
              else alphas ** 4 * np.asarray(periods, dtype=float) ** 2 / 6.0)
    nk = resp.sum(axis=0)
    empty = nk < 1e-12
    nk_safe = np.where(empty, 1.0, nk)
    mean = np.where(empty, alphas.mean(), resp.T @ alphas / nk_safe)
    s2 = np.where(empty, alphas.var(), np.einsum('ik,ik->k', resp, (alphas[:, None] - mean) ** 2)
                  / nk_safe)
    pooled = float(np.sum(nk * s2) / max(nk.sum(), 1e-12)) if n > 1 else 0.0
    shrunk = (nk * s2 + prior_count * pooled) / (nk + prior_count)
    var = shrunk * (1.0 + 1.0 / np.maximum(nk, 1.0))
    var = var + np.where(empty, timing.mean(), resp.T @ timing / nk_safe)
    var = np.where(empty, alphas.var() + timing.mean(), var)
    # Identical durations and no period: a spread of one part in 10^6 keeps the prior proper.
    return mean, np.sqrt(np.maximum(var, (1e-6 * mean) ** 2))


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
                                           model.basis_, t, Y, a, model.observed_noise_var_)
    return lp - logsumexp(lp)
