"""Probabilistic Movement Primitives: weights by regression (eq. 14, with a ridge or with a
curvature penalty whose strength empirical Bayes chooses) and by EM from partially observed
demonstrations (eqs. 21-33, appendix A).

Weight layout, used everywhere in the package: the weight vector of D DOFs is
[w_dof0 (N), w_dof1 (N), ...], so the position of DOF j at phase z is psi(z) . w[jN:(j+1)N].
"""

from dataclasses import dataclass

import numpy as np
from scipy import linalg

from .basis import GaussianBasis
from .numerics import first_best

LOG_2PI = np.log(2.0 * np.pi)


@dataclass
class ObservationStats:
    """Sufficient statistics of one partially observed trajectory under a basis.

    Per DOF j: G[j] = A_j^T A_j (N x N), b[j] = A_j^T y_j, yy[j] = y_j^T y_j, m[j] = number of
    observed samples, where A_j holds psi(z) at the samples where DOF j is observed (eq. 22).
    Everything EM and the evidence need, so the (m x D*N) design matrix is never formed.
    """

    G: np.ndarray
    b: np.ndarray
    yy: np.ndarray
    m: np.ndarray

    def take(self, idx) -> 'ObservationStats':
        """The statistics of trajectories ``idx`` of stacked ones (:func:`stack_stats`)."""
        return ObservationStats(self.G[idx], self.b[idx], self.yy[idx], self.m[idx])


def observation_stats(basis: GaussianBasis, z, Y) -> ObservationStats:
    """Statistics of samples Y (T, D) at phases z (T,); NaN entries are missing."""
    z = np.asarray(z, dtype=float)
    Y = np.asarray(Y, dtype=float)
    if Y.ndim != 2 or Y.shape[0] != z.shape[0]:
        raise ValueError(f'Y must have shape (len(z), dofs) = ({z.shape[0]}, D), got {Y.shape}')
    return feature_stats(basis(z), Y)


def feature_stats(psi, Y) -> ObservationStats:
    """:func:`observation_stats` from the features psi(z) (T, n_basis) already evaluated (a
    caller that needs psi for more, e.g. a gradient through z, evaluates the basis once)."""
    D, N = Y.shape[1], psi.shape[1]
    observed = ~np.isnan(Y)
    Y0 = np.where(observed, Y, 0.0)
    # DOFs observed at the same samples share A_j^T A_j (a demonstration misses whole rows of
    # an agent): one Gram matrix per distinct pattern of missing samples.
    G = np.empty((D, N, N))
    done = np.zeros(D, dtype=bool)
    for j in range(D):
        if not done[j]:
            same = ~done & (observed == observed[:, [j]]).all(axis=0)
            A = psi[observed[:, j]]
            G[same] = A.T @ A
            done |= same
    return ObservationStats(G, (Y0.T @ psi), np.einsum('tj,tj->j', Y0, Y0),
                            observed.sum(axis=0).astype(float))


# EM only starts from the regression weights, so it takes at least this ridge: a demonstration
# with few samples of a DOF then starts near zero instead of at a wild least-squares fit.
EM_START_RIDGE = 1e-2


def start_ridge(ridge: float, method: str) -> float:
    """The ridge of the per-demonstration weights a fit starts from (``method`` 'regression'
    keeps them; 'em' only starts there)."""
    return ridge if method == 'regression' else max(ridge, EM_START_RIDGE)


def ridge_weights_from_stats(st: ObservationStats, ridge: float) -> np.ndarray:
    """Eq. 14 per DOF from a demonstration's statistics, stacked (D N,):
    w_j = (A_j^T A_j + ridge I)^-1 A_j^T y_j; a DOF with no observed sample gets 0 (the ridge's
    answer)."""
    N = st.G.shape[1]
    eye = ridge * np.eye(N)
    return np.concatenate([np.linalg.solve(st.G[j] + eye, st.b[j]) for j in range(len(st.m))])


# Smoothing strengths empirical_bayes_smoothing chooses among (:func:`penalised_weights`), in
# units of the basis Gram matrix of the samples: wide enough for dense 30 Hz recordings
# (about 1e-4) and sparse ones with gaps (about 1).
SMOOTHING = tuple(float(f'{10.0 ** e:.3g}') for e in np.arange(-6.0, 4.01, 0.5))


def second_difference_penalty(n_basis: int) -> np.ndarray:
    """K = D2^T D2 with D2 the second differences of neighbouring weights: w^T K w is the
    path's squared curvature over the phase, up to scale (Eilers and Marx's P-splines)."""
    D2 = np.diff(np.eye(n_basis), 2, axis=0)
    return D2.T @ D2


def penalised_weights(stats: ObservationStats, smoothing, ridge: float = 0.0) -> np.ndarray:
    """Eq. 14 with a curvature penalty, per demonstration and DOF j: w_j = (A_j^T A_j +
    lambda_j K + ridge I)^-1 A_j^T y_j, K the :func:`second_difference_penalty`, ``smoothing``
    lambda per DOF (D,) or one for all. Stacked statistics (n trajectories) give (n, D N),
    one trajectory's (D N,); a DOF with no sample gets 0."""
    G, b = stats.G, stats.b
    N = G.shape[-1]
    lam = np.broadcast_to(np.asarray(smoothing, dtype=float), G.shape[-3:-2])
    A = G + lam[:, None, None] * second_difference_penalty(N) + (ridge + _JITTER) * np.eye(N)
    W = np.linalg.solve(A, b[..., None])[..., 0]
    return W.reshape(*W.shape[:-2], -1)


# Keeps the solve of a DOF without samples defined (its weights are then 0).
_JITTER = 1e-12


def empirical_bayes_smoothing(stats: ObservationStats, grid=SMOOTHING) -> np.ndarray:
    """How smooth the demonstrations' paths are, per DOF j: lambda_j of
    :func:`penalised_weights`, the one of ``grid`` with the highest :func:`smoothing_evidence`
    (a tie, :func:`core.numerics.first_best`, goes to the smoother).

    Eq. 14's weights with a vanishing ridge follow every sample and, where the samples leave a
    gap (dropped frames, a sparse recording), whatever the least-squares solution puts there:
    metres-sized swings between a few samples of NuiSI v1 (9 Hz) once a tenth of the frames
    are dropped, which a component's covariance then learns as variability (recognition from
    30 % of the movement 59 % instead of 95 %). The smoothness the recordings show where they
    are observed decides how their gaps are bridged and how much of a tracker's noise the
    weights keep; one lambda per DOF for the set, as it is a property of the recordings (their
    rate and noise), not of one of them. ``stats``: stacked statistics (:func:`stack_stats`).
    Returns (D,)."""
    evidence = smoothing_evidence(stats, grid)
    grid = np.asarray(grid, dtype=float)
    return np.array([grid[len(grid) - 1 - first_best(e[::-1])] for e in evidence.T])


def smoothing_evidence(stats: ObservationStats, grid=SMOOTHING) -> np.ndarray:
    """Per lambda of ``grid`` and DOF j, the restricted marginal log-likelihood (up to a
    constant) of every demonstration's samples of DOF j under the prior w ~ N(0, (lambda K /
    sigma_j^2)^-) of :func:`penalised_weights`: flat along the penalty's null space (a line over
    the phase), sigma_j^2 profiled out and shared by the demonstrations (empirical Bayes for
    penalised splines: Wahba 1985; Reiss and Ogden 2009). (len(grid), D)"""
    G, b, yy, m = stats.G, stats.b, stats.yy, stats.m         # (n, D, N, N), (n, D, N), (n, D)
    N = b.shape[-1]
    K = second_difference_penalty(N)
    eig = np.linalg.eigvalsh(K)
    positive = eig > 1e-9 * eig.max()
    rank, logdet_K = int(positive.sum()), float(np.sum(np.log(eig[positive])))
    # A trajectory scores a DOF once it has more samples than the null space's two dimensions.
    scored = m > N - rank
    dof = np.maximum(np.where(scored, m - (N - rank), 0).sum(axis=0), 1)
    out = np.empty((len(grid), b.shape[-2]))
    for a, g in enumerate(grid):
        A = G + g * K + _JITTER * np.eye(N)
        W = np.linalg.solve(A, b[..., None])[..., 0]
        q = np.maximum(yy - np.einsum('ijn,ijn->ij', W, b), 0.0)     # y^T (y - A w)
        s2 = np.maximum(np.where(scored, q, 0).sum(axis=0), 1e-300) / dof
        logdet = np.linalg.slogdet(A)[1] - rank * np.log(g) - logdet_K
        out[a] = -0.5 * (dof * np.log(2 * np.pi * s2) + dof
                         + np.where(scored, logdet, 0).sum(axis=0))
    return out


def ridge_weights(basis: GaussianBasis, z, Y, ridge: float = 1e-6) -> np.ndarray:
    """Eq. 14 solved per DOF with a ridge for samples Y (T, D) at phases z (T,), stacked."""
    st = observation_stats(basis, z, Y)
    if np.any(st.m == 0):
        raise ValueError('ridge regression needs at least one observed sample of every DOF')
    return ridge_weights_from_stats(st, ridge)


def cho_inverse(cov_chol) -> np.ndarray:
    """Sigma^-1 from the lower Cholesky factor of Sigma (scipy cho_factor, lower=True): LAPACK
    potri, a third of the work of solving against the identity; symmetric."""
    inv, info = linalg.lapack.dpotri(cov_chol[0], lower=1)
    if info != 0:
        raise np.linalg.LinAlgError(f'potri failed (info {info}): the factor is singular')
    low = np.tril(inv)
    full = low + low.T
    full.flat[::len(full) + 1] *= 0.5                               # the diagonal counted twice
    return full


def block_diag_info(stats: ObservationStats, noise_var: np.ndarray):
    """A^T R^-1 A (block diagonal, full matrix) and A^T R^-1 y for per-DOF noise variances."""
    D, N = stats.b.shape
    info = np.zeros((D * N, D * N))
    for j in range(D):
        info[j * N:(j + 1) * N, j * N:(j + 1) * N] = stats.G[j] / noise_var[j]
    return info, (stats.b / noise_var[:, None]).ravel()


def weight_posterior(stats: ObservationStats, mean, cov_chol, noise_var, prior_prec=None):
    """Eqs. 27-28 and the marginal likelihood of eq. 21 for one trajectory.

    ``cov_chol`` is the lower Cholesky factor of the prior covariance (from scipy cho_factor
    with lower=True, i.e. a tuple); ``prior_prec`` its inverse where the caller keeps it for
    many trajectories (None: from the factor). Returns (posterior mean, posterior covariance,
    log p(D)).
    """
    d = mean.shape[0]
    info, eta = block_diag_info(stats, noise_var)
    if prior_prec is None:
        prior_prec = cho_inverse(cov_chol)
    prec = prior_prec + info
    prec_chol = linalg.cho_factor(prec, lower=True)
    post_cov = linalg.cho_solve(prec_chol, np.eye(d))
    post_cov = 0.5 * (post_cov + post_cov.T)
    innov = eta - info @ mean                       # A^T R^-1 (y - A mu)
    post_mean = mean + post_cov @ innov
    D, N = stats.b.shape
    mu = mean.reshape(D, N)
    rr = np.sum((stats.yy - 2 * np.einsum('jn,jn->j', mu, stats.b)
                 + np.einsum('jn,jnk,jk->j', mu, stats.G, mu)) / noise_var)
    logdet_prior = 2 * np.sum(np.log(np.diag(cov_chol[0])))
    logdet_prec = 2 * np.sum(np.log(np.diag(prec_chol[0])))
    m_total = stats.m.sum()
    loglik = -0.5 * (m_total * LOG_2PI + np.sum(stats.m * np.log(noise_var))
                     + logdet_prior + logdet_prec + rr - innov @ post_cov @ innov)
    return post_mean, post_cov, loglik


def stack_stats(stats) -> ObservationStats:
    """The statistics of many trajectories stacked along a leading axis: G (n, D, N, N), b (n,
    D, N), yy (n, D), m (n, D), what :func:`log_evidence` takes."""
    return ObservationStats(*(np.stack([getattr(st, f) for st in stats])
                              for f in ('G', 'b', 'yy', 'm')))


def log_evidence(stats: ObservationStats, mean, cov, noise_var, posterior_means: bool = False):
    """Eq. 21, log p(D_i) = log N(y_i; A_i mu, R + A_i Sigma A_i^T), of every trajectory in
    ``stats`` (stacked, :func:`stack_stats`) under one weight Gaussian N(mean, Sigma = ``cov``)
    and per-DOF noise variances: the marginal likelihood of :func:`weight_posterior` for many
    trajectories at once, in weight space, log|Sigma| + log|P_i| and the quadratic form
    eta_i^T P_i^-1 eta_i of the information eta_i = A^T R^-1 (y_i - A mu), where
    P_i = Sigma^-1 + A^T R^-1 A. One batched Cholesky factorisation gives both: of P_i bordered
    by eta_i, [[P_i, eta_i], [eta_i^T, c_i]], whose last row is (L_i^-1 eta_i)^T; c_i only keeps
    the last pivot positive (c_i > eta_i^T P_i^-1 eta_i, which is below eta_i^T Sigma eta_i as
    P_i >= Sigma^-1). Returns (n,); with ``posterior_means`` also the posterior means of
    eq. 27, mean + P_i^-1 eta_i = mean + L_i^-T (L_i^-1 eta_i), from the same factor (n, d)."""
    G, b, yy, m = stats.G, stats.b, stats.yy, stats.m
    n, D, N = b.shape
    d = D * N
    cov = np.asarray(cov, dtype=float)
    noise_var = np.broadcast_to(np.asarray(noise_var, dtype=float), (D,))
    chol = linalg.cho_factor(cov, lower=True, check_finite=False)
    mu = np.asarray(mean, dtype=float).reshape(D, N)
    Gmu = (G @ mu[:, :, None])[..., 0]                             # A_j^T A_j mu_j
    eta = ((b - Gmu) / noise_var[:, None]).reshape(n, d)           # A^T R^-1 (y - A mu)
    rr = ((yy - 2 * np.einsum('jn,ijn->ij', mu, b) + np.einsum('jn,ijn->ij', mu, Gmu))
          / noise_var).sum(axis=1)                                 # (y - A mu)^T R^-1 (y - A mu)
    P = np.empty((n, d + 1, d + 1))
    P[:, :d, :d] = cho_inverse(chol)
    for j in range(D):
        P[:, j * N:(j + 1) * N, j * N:(j + 1) * N] += G[:, j] / noise_var[j]
    P[:, d, :d] = eta
    P[:, :d, d] = eta
    P[:, d, d] = 2 * np.sum((eta @ cov) * eta, axis=1) + 1.0
    for Pi in P:
        # LAPACK factors P_i in place: P_i^T is P_i in Fortran order, whose lower factor L_i
        # is then the upper triangle of P_i (row-major): L_i[d, :d] is the column P_i[:d, d].
        info = linalg.lapack.dpotrf(Pi.T, lower=1, overwrite_a=1, clean=0)[1]
        if info != 0:
            raise np.linalg.LinAlgError('the posterior precision is not positive definite')
    u = P[:, :d, d]                                                # L_i^-1 eta_i
    logdet_prec = 2 * np.log(np.diagonal(P[:, :d, :d], axis1=1, axis2=2)).sum(axis=1)
    logdet_prior = 2 * np.sum(np.log(np.diag(chol[0])))
    ll = -0.5 * (m.sum(axis=1) * LOG_2PI + (m * np.log(noise_var)).sum(axis=1)
                 + logdet_prior + logdet_prec + rr - np.einsum('ij,ij->i', u, u))
    if not posterior_means:
        return ll
    # L_i^T is the upper triangle of P_i[:d, :d] (row-major); its lower triangle still holds
    # P_i, which the solve does not read.
    post = np.array([linalg.solve_triangular(Pi[:d, :d], ui, lower=False, check_finite=False)
                     for Pi, ui in zip(P, u)]).reshape(n, d)
    return ll, post + np.asarray(mean, dtype=float).ravel()


def expected_sq_residual(stats: ObservationStats, post_mean, post_cov):
    """Per DOF E[||y_j - A_j w_j||^2] under the weight posterior (M step for the noise)."""
    D, N = stats.b.shape
    out = np.empty(D)
    for j in range(D):
        s = slice(j * N, (j + 1) * N)
        w = post_mean[s]
        out[j] = (stats.yy[j] - 2 * w @ stats.b[j] + w @ stats.G[j] @ w
                  + np.sum(stats.G[j] * post_cov[s, s]))
    return out


def covariance_penalty(cov_chol, prior_cov, strength):
    """log of the conjugate covariance prior used to regularise: -s/2 (tr(Omega Sigma^-1) +
    log|Sigma|); ``prior_cov`` Omega is a matrix or the diagonal of one."""
    if strength == 0:
        return 0.0
    inv = cho_inverse(cov_chol)
    trace = np.sum(prior_cov * np.diag(inv)) if prior_cov.ndim == 1 else np.sum(prior_cov * inv)
    logdet = 2 * np.sum(np.log(np.diag(cov_chol[0])))
    return -0.5 * strength * (trace + logdet)


class ProMP:
    """A ProMP over D DOFs: Gaussian over stacked weights, learned from demonstrations.

    ``method='regression'`` fits every trajectory alone (eq. 14) and takes the sample mean and
    covariance (the thesis's baseline; needs every DOF observed in every trajectory).
    ``method='em'`` maximises eq. 21 over mean, covariance and per-DOF noise with EM
    (eqs. 27-30), using every partial observation of every trajectory together.

    The covariance is regularised by a conjugate prior (``prior_strength`` pseudo-samples of a
    diagonal covariance ``prior_scale`` times the per-weight variance of the data), so it stays
    positive definite with fewer trajectories than weights. EM then increases the penalised
    log-likelihood monotonically; ``log_likelihood_`` records it per iteration.
    """

    def __init__(self, n_basis: int = 15, method: str = 'em', ridge: float = 1e-6,
                 prior_strength: float = 1.0, prior_scale: float = 0.01, max_iter: int = 200,
                 tol: float = 1e-6, min_noise_var: float = 1e-8):
        if method not in ('em', 'regression'):
            raise ValueError(f"method must be 'em' or 'regression', got {method!r}")
        self.n_basis = n_basis
        self.method = method
        self.ridge = ridge
        self.prior_strength = prior_strength
        self.prior_scale = prior_scale
        self.max_iter = max_iter
        self.tol = tol
        self.min_noise_var = min_noise_var

    def fit(self, trajectories):
        """``trajectories``: list of (z, Y) with z (T,) phases in [0, 1] and Y (T, D), NaN = missing."""
        trajectories = _validate_trajectories(trajectories)
        self.basis_ = GaussianBasis(self.n_basis)
        self.n_dofs_ = trajectories[0][1].shape[1]
        stats = [observation_stats(self.basis_, z, Y) for z, Y in trajectories]
        W = self._regression_init(stats)
        d = W.shape[1]
        var = W.var(axis=0) if len(W) > 1 else np.ones(d)
        self.prior_cov_diag_ = self.prior_scale * np.maximum(var, 1e-12 * max(var.max(), 1e-12))
        self.mean_ = W.mean(axis=0)
        S = (W - self.mean_).T @ (W - self.mean_)
        n = len(W)
        self.cov_ = _regularised_cov(S, n, self.prior_cov_diag_, self.prior_strength)
        self.noise_var_ = self._residual_var(stats, W)
        self.log_likelihood_ = []
        self.n_iter_ = 0
        if self.method == 'em':
            self._em(stats)
        return self

    def _regression_init(self, stats):
        """Per-trajectory eq. 14 weights; for EM only a starting point (a DOF never observed in a
        trajectory starts at the mean of the others)."""
        N = self.basis_.n_basis
        ridge = start_ridge(self.ridge, self.method)
        W = np.empty((len(stats), self.n_dofs_ * N))
        for i, st in enumerate(stats):
            if self.method == 'regression' and np.any(st.m == 0):
                raise ValueError("method='regression' needs every DOF observed in every "
                                 "trajectory; use method='em' for missing data")
            W[i] = ridge_weights_from_stats(st, ridge)
            W[i].reshape(self.n_dofs_, N)[st.m == 0] = np.nan
        col_mean = np.nanmean(W, axis=0)
        if np.any(np.isnan(col_mean)):
            raise ValueError('some DOF is not observed in any trajectory')
        return np.where(np.isnan(W), col_mean, W)

    def _residual_var(self, stats, W):
        num = np.zeros(self.n_dofs_)
        den = np.zeros(self.n_dofs_)
        zero = np.zeros((W.shape[1], W.shape[1]))
        for st, w in zip(stats, W):
            num += expected_sq_residual(st, w, zero)
            den += st.m
        return np.maximum(num / np.maximum(den, 1), self.min_noise_var)

    def _em(self, stats):
        prev = -np.inf
        for it in range(self.max_iter):
            chol = linalg.cho_factor(self.cov_, lower=True)
            results = [weight_posterior(st, self.mean_, chol, self.noise_var_) for st in stats]
            ll = sum(r[2] for r in results) + covariance_penalty(
                chol, self.prior_cov_diag_, self.prior_strength)
            self.log_likelihood_.append(float(ll))
            self.n_iter_ = it + 1
            if ll - prev < self.tol * max(1.0, abs(ll)):
                break
            prev = ll
            means = np.array([r[0] for r in results])
            mean = means.mean(axis=0)                                        # eq. 29
            E = means - mean
            S = E.T @ E + sum(r[1] for r in results)                         # eq. 30
            self.mean_ = mean
            self.cov_ = _regularised_cov(S, len(stats), self.prior_cov_diag_, self.prior_strength)
            num = sum(expected_sq_residual(st, r[0], r[1]) for st, r in zip(stats, results))
            den = sum(st.m for st in stats)
            self.noise_var_ = np.maximum(num / np.maximum(den, 1), self.min_noise_var)
        return self

    def trajectory(self, z):
        """Mean (T, D) and per-DOF standard deviation (T, D) of positions at phases z (eq. 2)."""
        psi = self.basis_(z)
        N = self.basis_.n_basis
        mean = np.stack([psi @ self.mean_[j * N:(j + 1) * N] for j in range(self.n_dofs_)], axis=1)
        std = np.stack([np.sqrt(np.einsum('tn,nk,tk->t', psi,
                                          self.cov_[j * N:(j + 1) * N, j * N:(j + 1) * N], psi))
                        for j in range(self.n_dofs_)], axis=1)
        return mean, std


def _regularised_cov(S, n, prior_cov, strength):
    """MAP covariance under the conjugate prior: (S + s Omega) / (n + s); symmetric by
    construction. ``prior_cov`` Omega is a matrix or its diagonal."""
    omega = np.diag(prior_cov) if prior_cov.ndim == 1 else prior_cov
    cov = (S + strength * omega) / (n + strength)
    return 0.5 * (cov + cov.T)


def _validate_trajectories(trajectories):
    if len(trajectories) == 0:
        raise ValueError('no trajectories given')
    out = []
    D = None
    for i, item in enumerate(trajectories):
        z, Y = item
        z = np.asarray(z, dtype=float)
        Y = np.asarray(Y, dtype=float)
        if z.ndim != 1 or Y.ndim != 2 or Y.shape[0] != z.shape[0]:
            raise ValueError(f'trajectory {i}: need shapes z (T,) and Y (T, D), got {z.shape} and {Y.shape}')
        if not np.all(np.isfinite(z)) or np.any(np.isinf(Y)):
            raise ValueError(f'trajectory {i}: NaN/Inf in phases or Inf in values')
        if np.any(np.diff(z) <= 0):
            raise ValueError(f'trajectory {i}: phases must be strictly increasing')
        if D is None:
            D = Y.shape[1]
        elif Y.shape[1] != D:
            raise ValueError(f'trajectory {i}: has {Y.shape[1]} DOFs, expected {D}')
        if np.isnan(Y).all():
            raise ValueError(f'trajectory {i}: has no observed sample')
        out.append((z, Y))
    return out
