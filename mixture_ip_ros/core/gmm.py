"""The EM steps of a Gaussian mixture over weight vectors (thesis eqs. 6-10), as pure functions:
the components' log densities, the responsibilities (eq. 7), the M step with the conjugate
covariance prior (eqs. 8-10), that prior's shrinkage target and its log density, the noise M
step (eq. 15), and the E step with latent weights for demonstrations with missing data
(eqs. 21, 27-28)."""

import numpy as np
from scipy import linalg

from .numerics import logsumexp_rows
from .promp import LOG_2PI, _regularised_cov, weight_posterior


def gmm_log_prob(W, weights, means, covs):
    """log(alpha_k N(w_i; mu_k, Sigma_k)) for every i, k: the terms of eqs. 6-7."""
    return _gmm_log_prob(W, weights, means, [linalg.cho_factor(c, lower=True) for c in covs])[0]


def _gmm_log_prob(W, weights, means, chols):
    """:func:`gmm_log_prob` with the covariances' lower Cholesky factors (cho_factor), and the
    squared Mahalanobis distances (w_i - mu_k)^T Sigma_k^-1 (w_i - mu_k) it adds up (n, K)."""
    n, d = W.shape
    out = np.empty((n, len(weights)))
    maha = np.empty((n, len(weights)))
    for k in range(len(weights)):
        L = chols[k][0]
        sol = linalg.solve_triangular(L, (W - means[k]).T, lower=True, check_finite=False)
        maha[:, k] = np.sum(sol ** 2, axis=0)
        out[:, k] = (np.log(weights[k]) - 0.5 * (d * LOG_2PI + 2 * np.sum(np.log(np.diag(L)))
                                                 + maha[:, k]))
    return out, maha


def gmm_responsibilities(W, weights, means, covs):
    """Eq. 7: r_ik = p(k | w_i); also returns the log-likelihood of eq. 6 summed over i."""
    lp = gmm_log_prob(W, weights, means, covs)
    norm = logsumexp_rows(lp)
    return np.exp(lp - norm[:, None]), float(norm.sum())


def gmm_maximization(W, resp, prior_cov, prior_strength, extra_cov=None):
    """Eqs. 8-10 with the conjugate covariance prior (see ProMP). ``extra_cov`` (n, K, d, d)
    adds E[(w - mu_ik)(w - mu_ik)^T] when the weights are latent (missing-data EM)."""
    n = len(resp)
    nk = resp.sum(axis=0) + 10 * np.finfo(float).eps                     # eq. 8
    weights = nk / n
    K = resp.shape[1]
    if W.ndim == 2:
        means = resp.T @ W / nk[:, None]                                    # eq. 9
        Wk = np.broadcast_to(W[:, None, :], (n, K, W.shape[-1]))
    else:
        means = np.einsum('ik,ikd->kd', resp, W) / nk[:, None]
        Wk = W
    covs = np.empty((K, means.shape[1], means.shape[1]))
    for k in range(K):
        E = Wk[:, k] - means[k]
        S = (resp[:, k, None] * E).T @ E                                    # eq. 10
        if extra_cov is not None:
            S += np.einsum('i,ide->de', resp[:, k], extra_cov[:, k])
        covs[k] = _regularised_cov(S, nk[k], np.asarray(prior_cov), prior_strength)
    return weights, means, covs


def covariance_prior(W, clusters, n_components: int, floor_scale: float, pooled: bool = True):
    """The shrinkage target Omega (d, d) of every component covariance (the conjugate prior of
    eqs. 8-10) from the weights W (n, d) and the initial clusters (n,) in 0..n_components-1:
    the within-cluster covariance pooled over the clusters (``pooled``; the shape variability
    shared by all patterns) plus a diagonal floor. A component with a dozen members then
    borrows the pooled structure instead of trusting spurious correlations of its own sample
    covariance. The floor is ``floor_scale`` times each weight's variance within the clusters,
    not over all demonstrations: the spread between patterns is no part of any one component's
    variability, and a floor that contains it blurs every component by the distance between
    them (with one cluster both are the same)."""
    n = len(W)
    w_var = np.maximum(W.var(axis=0), 1e-12)
    E = W - np.array([W[clusters == k].mean(axis=0) if np.any(clusters == k)
                      else W.mean(axis=0) for k in range(n_components)])[clusters]
    floor = floor_scale * np.maximum((E ** 2).mean(axis=0), 1e-12 * w_var.max())
    prior = np.diag(floor)
    if pooled:
        prior += E.T @ E / n
    return prior


def covariance_penalty_of_m_step(chols, resp, maha, d, prior_strength):
    """The covariance priors' log density (promp.covariance_penalty summed over k) at
    covariances that the M step (eq. 10) made from ``resp``, without inverting them:
    Sigma_k = (S_k + s Omega) / (n_k + s) with S_k = sum_i r_ik e_ik e_ik^T gives
    tr(Omega Sigma_k^-1) = ((n_k + s) d - sum_i r_ik e_ik^T Sigma_k^-1 e_ik) / s, and the
    E step has just computed those squared Mahalanobis distances (``maha``)."""
    s = prior_strength
    if s == 0:
        return 0.0
    nk = resp.sum(axis=0) + 10 * np.finfo(float).eps                 # as gmm_maximization
    trace = ((nk + s) * d - np.einsum('ik,ik->k', resp, maha)) / s
    logdet = np.array([2 * np.sum(np.log(np.diag(c[0]))) for c in chols])
    return float(-0.5 * s * np.sum(trace + logdet))


def noise_m_step(sq, m, resp, tied: bool = True):
    """sigma^2 of eq. 15 per DOF: expected squared residuals over observed samples.

    Tied: sum_i E||y_ij - A w_i||^2 / sum_i m_ij (``sq`` (n, D)). Per component: each
    demonstration's residual weighted by its responsibility r_ik (``sq`` (n, D) for
    regression fits, (n, K, D) for EM)."""
    if tied:
        if sq.ndim == 3:
            sq = sq.sum(axis=1)
        return np.maximum(sq.sum(axis=0) / np.maximum(m.sum(axis=0), 1), 1e-10)
    num = (np.einsum('ik,ij->kj', resp, sq) if sq.ndim == 2 else sq.sum(axis=0))
    den = np.einsum('ik,ij->kj', resp, m)
    # A component without members takes the tied estimate.
    tied = (sq if sq.ndim == 2 else sq.sum(axis=1)).sum(axis=0) / np.maximum(m.sum(axis=0), 1)
    out = np.where(den > 1e-9, num / np.maximum(den, 1e-9), tied)
    return np.maximum(out, 1e-10)

def latent_e_step(stats, weights, means, covs, noise, lp_alpha, fixed=None):
    """E step with latent weights: eqs. 27-28 per (demonstration, component) and eq. 7 with
    each demonstration's marginal likelihood (eq. 21). ``fixed`` (responsibilities (n, K),
    rows (n,) bool) keeps those rows' responsibilities (named demonstrations'); the returned
    log-likelihood is then the complete-data one for them, the marginal one for the others."""
    n, K, d = len(stats), len(weights), means.shape[1]
    post_means = np.empty((n, K, d))
    post_covs = np.empty((n, K, d, d))
    lp = np.empty((n, K))
    for k in range(K):
        chol = linalg.cho_factor(covs[k], lower=True)
        nk = noise if noise.ndim == 1 else noise[k]
        for i, st in enumerate(stats):
            post_means[i, k], post_covs[i, k], ll = weight_posterior(st, means[k], chol, nk)
            lp[i, k] = np.log(weights[k]) + ll + lp_alpha[i, k]
    if fixed is not None:
        fixed_resp, rows = fixed
        free = ~rows
        norm = logsumexp_rows(lp[free])
        resp = fixed_resp.copy()
        resp[free] = np.exp(lp[free] - norm[:, None])
        return (resp, float(np.sum(fixed_resp[rows] * lp[rows]) + norm.sum()), post_means,
                post_covs)
    norm = logsumexp_rows(lp)
    return np.exp(lp - norm[:, None]), float(norm.sum()), post_means, post_covs
