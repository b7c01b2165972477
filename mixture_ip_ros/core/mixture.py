"""Mixture of Interaction ProMPs (thesis 3.3): a Gaussian mixture over stacked human-robot
weights learned by EM (eqs. 6-10) from k-means initialisation; component posterior (eqs.
11-12) and conditioning of the most probable component (eq. 13); K by leave-one-out.

``method='em'`` learns the mixture from partially observed demonstrations (chapter 5 future
work): the weights of every demonstration are latent as in 4.2.1, so E-step responsibilities
use each demonstration's marginal likelihood p(D_i | k) and the M step adds the weight
posterior covariances (eqs. 27-30 per component).
"""

import inspect
from typing import NamedTuple

import numpy as np
from scipy import linalg
from scipy.special import logsumexp

from .basis import GaussianBasis
from .demonstration import Demonstration
from .interaction import condition_on_observed, trajectory_distribution
from .phase import (alpha_log_density, alpha_m_step, alpha_penalty, alpha_prior_std,
                    timing_variance)
from .promp import (LOG_2PI, ObservationStats, _regularised_cov, covariance_penalty,
                    expected_sq_residual, log_evidence, observation_stats, stack_stats,
                    weight_posterior)


def kmeans(X, n_clusters: int, random_state=0, n_init: int = 10, max_iter: int = 100):
    """k-means++ seeded Lloyd iterations; the best of ``n_init`` runs (the first of equals).
    Returns labels (n,).

    Every random draw is in the seeding, so the runs are seeded first, one after another, and
    their Lloyd iterations then run side by side, each stopping on its own: when its labels
    repeat (its means are its centres again) or its centres move less than np.allclose's
    tolerance."""
    X = np.asarray(X, dtype=float)
    n, dim = X.shape
    K = int(n_clusters)
    if K == 1:
        return np.zeros(n, dtype=int)                    # what every run ends with
    rng = np.random.default_rng(random_state)
    C = np.empty((n_init, K, dim))
    for r in range(n_init):
        C[r, 0] = X[rng.integers(n)]
        d2 = np.sum((X - C[r, 0]) ** 2, axis=1)          # squared distance to the nearest centre
        for k in range(1, K):
            total = d2.sum()
            C[r, k] = X[rng.choice(n, p=d2 / total if total > 0 else np.full(n, 1 / n))]
            d2 = np.minimum(d2, np.sum((X - C[r, k]) ** 2, axis=1))
    labels = np.full((n_init, n), -1)
    active = np.arange(n_init)
    x2 = np.einsum('ij,ij->i', X, X)
    for _ in range(max_iter):
        if not active.size:
            break
        new = _nearest_centres(X, x2, C[active])
        moved = ~(new == labels[active]).all(axis=1)
        active, new = active[moved], new[moved]
        labels[active] = new
        newC = _cluster_means(X, new, C[active])
        still = ~np.all(np.abs(newC - C[active]) <= 1e-8 + 1e-5 * np.abs(C[active]), axis=(1, 2))
        C[active[still]] = newC[still]
        active = active[still]
    inertia = [np.sum((X - C[r][labels[r]]) ** 2) for r in range(n_init)]
    return labels[int(np.argmin(inertia))]


def _nearest_centres(X, x2, C):
    """argmin_k ((x_i - c_rk) ** 2).sum() for every run r and row i (C (runs, K, dim)), the
    index exactly that sum picks. The distances are first expanded as |x|^2 + |c|^2 - 2 x.c
    (one matrix product); a row whose nearest two are closer than 1e-9 (|x|^2 + |c|^2), far
    above what rounding can move either form (~d eps of it), is decided by the direct sum."""
    c2 = np.einsum('rkd,rkd->rk', C, C)
    dist = x2[None, :, None] + c2[:, None, :] - 2 * (X @ C.transpose(0, 2, 1))   # (runs, n, K)
    labels = np.argmin(dist, axis=2)
    if C.shape[1] > 1:
        two = np.partition(dist, 1, axis=2)
        scale = x2[None, :] + c2.max(axis=1)[:, None]
        for r, i in zip(*np.nonzero(two[..., 1] - two[..., 0] <= 1e-9 * scale)):
            labels[r, i] = np.argmin(((X[i] - C[r]) ** 2).sum(-1))
    return labels


def _cluster_means(X, labels, C):
    """Every run's cluster means (labels (runs, n), centres C (runs, K, dim)), the rows of a
    cluster summed in order as X[labels == k].mean(0) sums them; an empty cluster keeps its
    centre."""
    runs, K, dim = C.shape
    keys = (np.arange(runs)[:, None] * K + labels).ravel()
    order = np.argsort(keys, kind='stable')
    counts = np.bincount(keys, minlength=runs * K)
    present = np.flatnonzero(counts)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])[present]
    out = C.reshape(runs * K, dim).copy()
    out[present] = (np.add.reduceat(X[order % len(X)], starts, axis=0)
                    / counts[present, None])
    return out.reshape(runs, K, dim)


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


def _logsumexp_rows(lp):
    """log sum_k exp(lp_ik) per row i, shifted by the row's maximum (finite rows)."""
    top = lp.max(axis=1)
    return top + np.log(np.exp(lp - top[:, None]).sum(axis=1))


def gmm_responsibilities(W, weights, means, covs):
    """Eq. 7: r_ik = p(k | w_i); also returns the log-likelihood of eq. 6 summed over i."""
    lp = gmm_log_prob(W, weights, means, covs)
    norm = logsumexp(lp, axis=1)
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


class _Prepared(NamedTuple):
    """What a fit needs of each demonstration on its own, whatever the other demonstrations it
    is fitted with: the observation statistics (stacked, promp.stack_stats), the eq. 14
    weights W (n, d), the squared residuals at them (n, D), alpha = 1/T and the timing variance
    (n,). Cross-validation computes them once and every fold and K indexes them."""

    stats: ObservationStats
    W: np.ndarray
    sq: np.ndarray
    alphas: np.ndarray
    timing: np.ndarray
    n_observed: int

    def take(self, idx) -> '_Prepared':
        return _Prepared(_take_stats(self.stats, idx), self.W[idx], self.sq[idx],
                         self.alphas[idx], self.timing[idx], self.n_observed)


def _take_stats(st: ObservationStats, idx) -> ObservationStats:
    """The stacked statistics (promp.stack_stats) of the trajectories ``idx``."""
    return ObservationStats(st.G[idx], st.b[idx], st.yy[idx], st.m[idx])


def _beginning_stats(basis, demos, fractions):
    """Per fraction f, the stacked statistics of every demonstration's beginning: its samples
    (every DOF of both agents) at phases z <= f."""
    out = []
    for f in fractions:
        out.append(stack_stats([observation_stats(basis, d.phase[d.phase <= f],
                                                  np.hstack([d.observed, d.controlled])[
                                                      d.phase <= f]) for d in demos]))
    return out


def _checked_fractions(fractions):
    f = np.atleast_1d(np.asarray(fractions, dtype=float))
    if f.ndim != 1 or f.size == 0 or not np.all((f > 0) & (f < 1)):
        raise ValueError(f'fractions must be numbers in (0, 1), got {fractions!r}')
    return tuple(float(x) for x in f)


class MixtureIProMP:
    """Mixture of Interaction ProMPs learned from unlabeled demonstrations.

    Any layout: the observed agent has P >= 1 DOFs, the controlled agent Q >= 0 (Q = 0 is a
    single-agent mixture: it recognises a movement and predicts its rest from a partial
    observation). Parameters are configuration only; ``fit`` sets the fitted attributes
    (trailing underscore): ``basis_``, ``n_observed_``, ``n_controlled_``, ``weights_`` (K,),
    ``means_`` (K, d), ``covariances_`` (K, d, d), ``noise_var_`` the observation noise
    variance of eq. 15 per DOF in the DOF's own unit squared, (P+Q,) tied across components or
    (K, P+Q) with ``noise='per_component'``, ``alpha_mean_``/``alpha_std_`` (K,) the
    per-component prior over the phase speed alpha = 1/T, ``log_likelihood_`` per EM iteration
    (penalised, monotone), ``resp_`` (n, K), ``classes_`` (the labels of a supervised fit, else
    None).

    ``prior_strength`` pseudo-samples of a shared covariance ``prior_cov_`` regularise every
    component covariance (conjugate prior, so EM stays monotone in the penalised likelihood):
    the within-component covariance pooled over the initial clusters (k-means, or the labels of
    a supervised fit; ``method='regression'``) plus a diagonal floor of ``prior_scale`` times
    each weight's variance within those clusters. Every component shrinks towards the same
    target with the same strength, so their likelihoods stay comparable; this keeps every
    component positive definite with fewer members than weights. How much floor a data set
    needs is calibrated on held-out folds (:func:`calibrated_heldout_curves`, which training
    uses when it chooses K).

    Noise: ``noise='tied'`` (default) learns one variance per DOF shared by all components
    (pooled residuals), so components are compared on the same noise floor; 'per_component'
    learns one per component and DOF. ``noise_var`` (per DOF, or a scalar) fixes the noise
    instead of learning it: separately fitted models (one per class) given the same
    ``noise_var`` share the noise model. ``observation_noise`` (per observed DOF or a scalar, in
    the DOF's unit) is extra sensor noise of the online stream, added to the learned variance
    when conditioning on new observations (none by default).
    """

    def __init__(self, n_components: int = 3, n_basis: int = 15, method: str = 'regression',
                 ridge: float = 1e-6, prior_strength: float = 10.0, prior_scale: float = 0.02,
                 max_iter: int = 200, tol: float = 1e-7, n_init: int = 10, random_state=0,
                 observation_noise=0.0, noise: str = 'tied', noise_var=None):
        self.n_components = n_components
        self.n_basis = n_basis
        self.method = method
        self.ridge = ridge
        self.prior_strength = prior_strength
        self.prior_scale = prior_scale
        self.max_iter = max_iter
        self.tol = tol
        self.n_init = n_init
        self.random_state = random_state
        self.observation_noise = observation_noise
        self.noise = noise
        self.noise_var = noise_var

    # ------------------------------------------------------------------ learning
    def fit(self, demonstrations, labels=None):
        """Learn the mixture from ``demonstrations`` (unlabeled: k-means then EM, eqs. 7-10).

        ``labels`` (n,), optional: a supervised fit with one component per distinct label
        (sorted; ``n_components`` must equal their number) and the responsibilities fixed to
        the labels, i.e. one Interaction ProMP per class sharing the noise model and the
        covariance prior. ``classes_`` then names the components.
        """
        demos = _validate_demonstrations(demonstrations, self.n_components)
        self._check_params()
        return self._fit_prepared(self._prepare(demos), labels)

    def _prepare(self, demos) -> '_Prepared':
        """What a fit needs of each demonstration on its own (see _Prepared)."""
        basis = GaussianBasis(self.n_basis)
        stats = [observation_stats(basis, demo.phase, np.hstack([demo.observed, demo.controlled]))
                 for demo in demos]
        if self.method == 'regression':
            for demo, st in zip(demos, stats):
                if np.any(st.m < 1):
                    raise ValueError(f'demonstration {demo.name!r} has a DOF never observed; '
                                     "use method='em' for missing data")
        W = np.array([self._ridge_weights(st) for st in stats])
        zero = np.zeros((W.shape[1], W.shape[1]))
        sq = np.array([expected_sq_residual(st, w, zero) for st, w in zip(stats, W)])  # (n, D)
        return _Prepared(stack_stats(stats), W, sq,
                         np.array([1.0 / demo.duration for demo in demos]),
                         timing_variance([demo.duration for demo in demos],
                                         [float(np.median(np.diff(demo.t))) for demo in demos]),
                         demos[0].n_observed_dofs)

    def _initial_clusters(self, data: '_Prepared'):
        """k-means of the standardised weights and phase speeds: EM's start (eq. 7's r_ik)."""
        W, alphas = data.W, data.alphas
        w_var = np.maximum(W.var(axis=0), 1e-12)
        a_scale = np.sqrt(max(alphas.var(), data.timing.mean(), 1e-24))
        return kmeans(np.column_stack([W / np.sqrt(w_var), alphas / a_scale]), self.n_components,
                      random_state=self.random_state, n_init=self.n_init)

    def _fit_prepared(self, data: '_Prepared', labels=None, init=None):
        """:meth:`fit` from prepared demonstrations; ``init``: the k-means start
        (:meth:`_initial_clusters` of ``data``) if the caller has it already."""
        self._check_params()
        n, d = data.W.shape
        K = self.n_components
        if n < K:
            raise ValueError(f'{n} demonstrations are fewer than n_components={K}')
        self.basis_ = GaussianBasis(self.n_basis)
        self.n_observed_ = data.n_observed
        D = data.sq.shape[1]
        self.n_controlled_ = D - data.n_observed
        fixed_noise = None
        if self.noise_var is not None:
            fixed_noise = np.broadcast_to(np.asarray(self.noise_var, dtype=float), (D,)).copy()
            if not np.all(np.isfinite(fixed_noise) & (fixed_noise > 0)):
                raise ValueError(f'noise_var must be positive and finite, got {self.noise_var!r}')
        W, alphas, timing, sq = data.W, data.alphas, data.timing, data.sq
        m = data.stats.m                                                              # (n, D)
        # A component is a joint p(w, alpha | k) = p(w | k) p(alpha | k) over shape and phase
        # speed alpha = 1/T (eq. 17's independence of w and alpha within a pattern): patterns
        # that differ in speed are told apart by it, and p(alpha | k) is the online prior.
        w_var = np.maximum(W.var(axis=0), 1e-12)
        if labels is None:
            self.classes_ = None
            init = self._initial_clusters(data) if init is None else np.asarray(init)
        else:
            self.classes_, init = _label_indices(labels, n, K)
        resp = np.eye(K)[init]
        # Shrinkage target: the within-component covariance pooled over the initial clusters
        # (shape variability shared by all patterns) plus a diagonal floor. A component with a
        # dozen members then borrows the pooled structure instead of trusting spurious
        # correlations of its own sample covariance. The floor is ``prior_scale`` times each
        # weight's variance within the clusters, not over all demonstrations: the spread between
        # patterns is no part of any one component's variability, and a floor that contains it
        # blurs every component by the distance between them (with K = 1 both are the same).
        # With missing data ('em') the starting weights are unreliable where a demonstration
        # has gaps, so the target is the diagonal floor alone.
        E = W - np.array([W[init == k].mean(axis=0) if np.any(init == k) else W.mean(axis=0)
                          for k in range(K)])[init]
        floor = self.prior_scale * np.maximum((E ** 2).mean(axis=0), 1e-12 * w_var.max())
        self.prior_cov_ = np.diag(floor)
        if self.method == 'regression':
            self.prior_cov_ += E.T @ E / n
        # The same for alpha: the within-cluster variance pooled over the initial clusters, at
        # least what the sampling leaves (timing).
        a_within = alphas - np.array([alphas[init == k].mean() if np.any(init == k)
                                      else alphas.mean() for k in range(K)])[init]
        self.alpha_prior_var_ = float(max(np.mean(a_within ** 2), timing.mean(),
                                          (1e-6 * alphas.mean()) ** 2))
        weights, means, covs = gmm_maximization(W, resp, self.prior_cov_, self.prior_strength)
        a_mean, a_var, nk = alpha_m_step(alphas, resp, self.alpha_prior_var_, self.prior_strength)
        noise = fixed_noise if fixed_noise is not None else self._noise_m_step(sq, m, resp)
        stats = None
        if self.method == 'em':
            st = data.stats
            stats = [ObservationStats(st.G[i], st.b[i], st.yy[i], st.m[i]) for i in range(n)]
        self.log_likelihood_ = []
        prev = -np.inf
        self.converged_ = False
        for it in range(self.max_iter):
            lp_alpha = alpha_log_density(alphas, a_mean, a_var)
            chols = [linalg.cho_factor(c, lower=True, check_finite=False) for c in covs]
            new_resp = resp
            if self.method == 'regression':
                lp, maha = _gmm_log_prob(W, weights, means, chols)
                lp += lp_alpha                                                         # eq. 7
                if labels is None:
                    norm = _logsumexp_rows(lp)
                    new_resp, ll = np.exp(lp - norm[:, None]), float(norm.sum())
                else:
                    ll = float(np.sum(resp * lp))
                post_means, post_covs = W, None
                ll += self._covariance_penalty_of_m_step(chols, resp, maha, d)
            else:
                new_resp, ll, post_means, post_covs = self._latent_e_step(
                    stats, weights, means, covs, noise, lp_alpha,
                    resp if labels is not None else None)
                ll += sum(covariance_penalty(c, self.prior_cov_, self.prior_strength)
                          for c in chols)
            ll += alpha_penalty(a_var, self.alpha_prior_var_, self.prior_strength)
            self.log_likelihood_.append(ll)
            if ll - prev < self.tol * max(1.0, abs(ll)):
                self.converged_ = True
                resp = new_resp
                break
            prev = ll
            if (self.method == 'regression' and self.tol > 0 and it + 1 < self.max_iter
                    and np.array_equal(new_resp, resp)):
                # The parameters are the M step of these very responsibilities, so the next
                # iteration would repeat this one (same log-likelihood: converged) unchanged.
                self.log_likelihood_.append(ll)
                self.converged_ = True
                break
            resp = new_resp
            weights, means, covs = gmm_maximization(post_means, resp, self.prior_cov_,
                                                    self.prior_strength, post_covs)
            a_mean, a_var, nk = alpha_m_step(alphas, resp, self.alpha_prior_var_,
                                             self.prior_strength)
            if self.method == 'em' and fixed_noise is None:
                sq_k = np.einsum('ik,ikj->ij' if self.noise == 'tied' else 'ik,ikj->ikj', resp,
                                 np.array([[expected_sq_residual(stats[i], post_means[i, k],
                                                                 post_covs[i, k])
                                            for k in range(K)] for i in range(n)]))
                noise = self._noise_m_step(sq_k, m, resp)
        if self.method == 'regression' and fixed_noise is None:
            noise = self._noise_m_step(sq, m, resp)
        self.n_iter_ = len(self.log_likelihood_)
        self.weights_, self.means_, self.covariances_ = weights, means, covs
        self.resp_ = resp
        self.noise_var_ = noise
        self.alpha_mean_ = a_mean
        self.alpha_var_ = a_var
        timing_k = np.where(nk > 1e-12, resp.T @ timing / np.maximum(nk, 1e-12), timing.mean())
        self.alpha_std_ = alpha_prior_std(a_var, nk, timing_k)
        return self

    def _check_params(self):
        if self.method not in ('regression', 'em'):
            raise ValueError(f"method must be 'regression' or 'em', got {self.method!r}")
        if self.noise not in ('tied', 'per_component'):
            raise ValueError(f"noise must be 'tied' or 'per_component', got {self.noise!r}")
        on = np.asarray(self.observation_noise, dtype=float)
        if on.ndim > 1 or not np.all(np.isfinite(on) & (on >= 0)):
            raise ValueError('observation_noise must be a number or one number per observed DOF, '
                             f'each >= 0 (in the DOF\'s unit), got {self.observation_noise!r}')

    def _covariance_penalty_of_m_step(self, chols, resp, maha, d):
        """The covariance priors' log density (promp.covariance_penalty summed over k) at
        covariances that the M step (eq. 10) made from ``resp``, without inverting them:
        Sigma_k = (S_k + s Omega) / (n_k + s) with S_k = sum_i r_ik e_ik e_ik^T gives
        tr(Omega Sigma_k^-1) = ((n_k + s) d - sum_i r_ik e_ik^T Sigma_k^-1 e_ik) / s, and the
        E step has just computed those squared Mahalanobis distances (``maha``)."""
        s = self.prior_strength
        if s == 0:
            return 0.0
        nk = resp.sum(axis=0) + 10 * np.finfo(float).eps                 # as gmm_maximization
        trace = ((nk + s) * d - np.einsum('ik,ik->k', resp, maha)) / s
        logdet = np.array([2 * np.sum(np.log(np.diag(c[0]))) for c in chols])
        return float(-0.5 * s * np.sum(trace + logdet))

    def _ridge_weights(self, st):
        """Eq. 14 per DOF (ridge); for EM only a starting point (more ridge where data is thin)."""
        N = self.n_basis
        ridge = self.ridge if self.method == 'regression' else max(self.ridge, 1e-2)
        return np.concatenate([np.linalg.solve(st.G[j] + ridge * np.eye(N), st.b[j])
                               for j in range(len(st.m))])

    def _noise_m_step(self, sq, m, resp):
        """sigma^2 of eq. 15 per DOF: expected squared residuals over observed samples.

        Tied: sum_i E||y_ij - A w_i||^2 / sum_i m_ij (``sq`` (n, D)). Per component: each
        demonstration's residual weighted by its responsibility r_ik (``sq`` (n, D) for
        regression fits, (n, K, D) for EM)."""
        if self.noise == 'tied':
            if sq.ndim == 3:
                sq = sq.sum(axis=1)
            return np.maximum(sq.sum(axis=0) / np.maximum(m.sum(axis=0), 1), 1e-10)
        num = (np.einsum('ik,ij->kj', resp, sq) if sq.ndim == 2 else sq.sum(axis=0))
        den = np.einsum('ik,ij->kj', resp, m)
        # A component without members takes the tied estimate.
        tied = (sq if sq.ndim == 2 else sq.sum(axis=1)).sum(axis=0) / np.maximum(m.sum(axis=0), 1)
        out = np.where(den > 1e-9, num / np.maximum(den, 1e-9), tied)
        return np.maximum(out, 1e-10)

    def _latent_e_step(self, stats, weights, means, covs, noise, lp_alpha, fixed_resp=None):
        """E step with latent weights: eqs. 27-28 per (demonstration, component) and eq. 7 with
        each demonstration's marginal likelihood (eq. 21); ``fixed_resp`` keeps the
        responsibilities of a supervised fit (the returned log-likelihood is then the
        complete-data one given the labels)."""
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
        if fixed_resp is not None:
            return fixed_resp, float(np.sum(fixed_resp * lp)), post_means, post_covs
        norm = logsumexp(lp, axis=1)
        return np.exp(lp - norm[:, None]), float(norm.sum()), post_means, post_covs

    # ------------------------------------------------------------------ inference
    @property
    def observed_noise_var_(self):
        """Sigma_D of eq. 4 per observed DOF: the learned noise variance of eq. 15 plus the
        online sensor noise; (P,) when tied, (K, P) per component."""
        return self.noise_var_[..., :self.n_observed_] + np.square(self.observation_noise)

    def _observed_noise(self, k):
        nv = self.observed_noise_var_
        return nv if nv.ndim == 1 else nv[k]

    def component_log_evidence(self, z, Y_obs):
        """log p(D | k) for every component (the integral under eq. 11, eq. 21 with the observed
        agent's block), observed agent only."""
        self._check_fitted()
        z, Y_obs = _validate_observation(z, Y_obs, self.n_observed_)
        do = self.n_observed_ * self.n_basis
        st = observation_stats(self.basis_, z, Y_obs)
        out = np.empty(self.n_components)
        for k in range(self.n_components):
            chol = linalg.cho_factor(self.covariances_[k][:do, :do], lower=True)
            out[k] = weight_posterior(st, self.means_[k][:do], chol, self._observed_noise(k))[2]
        return out

    def component_posterior(self, z, Y_obs, alpha=None):
        """Eq. 11: p(k | D) for observations Y_obs (m, P) of the observed agent at phases z.
        With ``alpha`` (1/T, known with the phase) also its evidence p(alpha | k)."""
        self._check_fitted()
        lp = np.log(self.weights_) + self.component_log_evidence(z, Y_obs)
        if alpha is not None:
            lp += alpha_log_density([alpha], self.alpha_mean_, self.alpha_std_ ** 2)[0]
        return np.exp(lp - logsumexp(lp))

    def score_demonstrations(self, demonstrations):
        """log p(D_i, alpha_i) of each demonstration, every DOF of both agents, phase known
        (z = t / T): eq. 6 over components with the marginal likelihood of eq. 21 in the space
        the mixture lives in (the stacked weights of both agents, under the learned noise of
        eq. 15) and the component's p(alpha | k). The held-out criterion for K.

        Both agents, because a pattern is a joint movement: where the patterns differ mostly in
        the controlled agent (the robot's posture for the same reach), the observed agent alone
        cannot tell a mixture from one broad Gaussian. Missing samples (NaN) are skipped."""
        self._check_fitted()
        demos = list(demonstrations)
        if not demos:
            return np.empty(0)
        D = self.n_observed_ + self.n_controlled_
        stats = []
        for demo in demos:
            Y = np.hstack([demo.observed, demo.controlled])
            if Y.shape[1] != D:
                raise ValueError(f'demonstration {demo.name!r} has {demo.n_observed_dofs} + '
                                 f'{demo.n_controlled_dofs} DOFs; the model has '
                                 f'{self.n_observed_} + {self.n_controlled_}')
            stats.append(observation_stats(self.basis_, demo.phase, Y))
        return self._score_stats(stack_stats(stats),
                                 np.array([1.0 / demo.duration for demo in demos]))

    def _score_stats(self, stats: ObservationStats, alphas):
        """:meth:`score_demonstrations` of stacked statistics and their alpha = 1/T."""
        noise = np.broadcast_to(self.noise_var_, (self.n_components, self.noise_var_.shape[-1]))
        lp = np.log(self.weights_) + alpha_log_density(alphas, self.alpha_mean_,
                                                       self.alpha_std_ ** 2)
        for k in range(self.n_components):
            lp[:, k] += log_evidence(stats, self.means_[k], self.covariances_[k], noise[k])
        return _logsumexp_rows(lp)

    def score_completion(self, demonstrations, fractions=None):
        """How well the model predicts the rest of each demonstration from its beginning, the
        phase known (z = t / T, so alpha = 1/T too), for every ``fraction`` f (default
        COMPLETION_FRACTIONS): the beginning B is the samples at z <= f, the rest R those at
        z > f, every DOF of both agents. Returns (log_density, rms), each (n, len(fractions)):

        - log p(R | B, alpha) = log p(R, B, alpha) - log p(B, alpha) under the mixture (eq. 6
          with eq. 21 and p(alpha | k)): the predictive density of the rest, each component
          weighted by its posterior given the beginning (eq. 11);
        - the RMS error of the rest predicted as the thesis predicts (eqs. 12-13): the most
          probable component given B and alpha, conditioned on B, its mean at the rest's
          phases; over every DOF of the rest in the DOF's own unit (comparable across K, not
          across data sets).
        """
        self._check_fitted()
        fractions = _checked_fractions(COMPLETION_FRACTIONS if fractions is None else fractions)
        demos = list(demonstrations)
        D = self.n_observed_ + self.n_controlled_
        for demo in demos:
            if demo.n_observed_dofs + demo.n_controlled_dofs != D:
                raise ValueError(f'demonstration {demo.name!r} has {demo.n_observed_dofs} + '
                                 f'{demo.n_controlled_dofs} DOFs; the model has '
                                 f'{self.n_observed_} + {self.n_controlled_}')
        full = stack_stats([observation_stats(self.basis_, d.phase,
                                              np.hstack([d.observed, d.controlled]))
                            for d in demos])
        return self._completion_stats(full, _beginning_stats(self.basis_, demos, fractions),
                                      np.array([1.0 / d.duration for d in demos]))

    def _completion_stats(self, full: ObservationStats, beginnings, alphas):
        """:meth:`score_completion` from stacked statistics of the whole demonstrations, of
        their beginnings (one stack per fraction) and their alpha = 1/T."""
        K, D = self.n_components, self.n_observed_ + self.n_controlled_
        N = self.n_basis
        n = len(alphas)
        noise = np.broadcast_to(self.noise_var_, (K, D))
        prior = np.log(self.weights_) + alpha_log_density(alphas, self.alpha_mean_,
                                                          self.alpha_std_ ** 2)
        whole = prior + np.column_stack([log_evidence(full, self.means_[k], self.covariances_[k],
                                                      noise[k]) for k in range(K)])
        log_whole = _logsumexp_rows(whole)
        density = np.empty((n, len(beginnings)))
        rms = np.empty((n, len(beginnings)))
        for c, begin in enumerate(beginnings):
            lp = prior.copy()
            post = np.empty((K, n, D * N))
            for k in range(K):
                ll, post[k] = log_evidence(begin, self.means_[k], self.covariances_[k], noise[k],
                                           posterior_means=True)
                lp[:, k] += ll                                                  # eq. 11
            density[:, c] = log_whole - _logsumexp_rows(lp)
            w = post[np.argmax(lp, axis=1), np.arange(n)].reshape(n, D, N)     # eqs. 12-13
            # The rest's statistics are the whole's minus the beginning's (sums over samples).
            G, b = full.G - begin.G, full.b - begin.b
            sq = (full.yy - begin.yy - 2 * np.einsum('ijn,ijn->ij', w, b)
                  + np.einsum('ijn,ijnk,ijk->ij', w, G, w))
            m = (full.m - begin.m).sum(axis=1)
            rms[:, c] = np.sqrt(np.maximum(sq.sum(axis=1), 0.0) / np.maximum(m, 1.0))
        return density, rms

    # --------------------------------------------------------- weight vectors (eqs. 6-7)
    def demonstration_weights(self, demonstrations):
        """The weight vectors that ``fit`` clusters: eq. 14 per demonstration and DOF (ridge),
        stacked [observed, controlled]; shape (n, (P+Q) N). Needs every DOF observed."""
        self._check_fitted()
        W = []
        for demo in demonstrations:
            st = observation_stats(self.basis_, demo.phase,
                                   np.hstack([demo.observed, demo.controlled]))
            if np.any(st.m < 1):
                raise ValueError(f'demonstration {demo.name!r} has a DOF never observed')
            W.append(self._ridge_weights(st))
        return np.array(W)

    def score_samples(self, W):
        """log p(w_i) = log sum_k alpha_k N(w_i; mu_k, Sigma_k) (eq. 6) for weight vectors W (n, d)."""
        return logsumexp(gmm_log_prob(self._checked_weights(W), self.weights_, self.means_,
                                      self.covariances_), axis=1)

    def score(self, W):
        """Mean log-likelihood per weight vector (scikit-learn's ``score``)."""
        return float(np.mean(self.score_samples(W)))

    def predict_proba(self, W):
        """Eq. 7: p(k | w_i) for weight vectors W (n, d); shape (n, K)."""
        return gmm_responsibilities(self._checked_weights(W), self.weights_, self.means_,
                                    self.covariances_)[0]

    def predict(self, W):
        """The most probable component of each weight vector (eq. 12 on weights)."""
        return np.argmax(self.predict_proba(W), axis=1)

    def _checked_weights(self, W):
        self._check_fitted()
        W = np.asarray(W, dtype=float)
        d = self.means_.shape[1]
        if W.ndim == 1:
            W = W[None]
        if W.ndim != 2 or W.shape[1] != d:
            raise ValueError(f'weight vectors must have shape (n, {d}), got {W.shape}')
        if not np.all(np.isfinite(W)):
            raise ValueError('weight vectors contain NaN or Inf')
        return W

    def condition(self, z, Y_obs, component=None):
        """Eqs. 12-13: the most probable component (or ``component``) conditioned on D.

        Returns (k, mean, cov) of the stacked weights."""
        if component is None:
            component = int(np.argmax(self.component_posterior(z, Y_obs)))
        z, Y_obs = _validate_observation(z, Y_obs, self.n_observed_)
        mean, cov = condition_on_observed(self.means_[component], self.covariances_[component],
                                          self.basis_, self.n_observed_, z, Y_obs,
                                          self._observed_noise(component))
        return component, mean, cov

    def predict_controlled(self, z, Y_obs, z_grid, alpha=1.0, component=None):
        """Controlled agent's trajectory distribution over ``z_grid`` given D (eq. 13)."""
        k, mean, cov = self.condition(z, Y_obs, component)
        dofs = range(self.n_observed_, self.n_observed_ + self.n_controlled_)
        out = trajectory_distribution(mean, cov, self.basis_, z_grid, alpha, dofs)
        out['component'] = k
        return out

    def _check_fitted(self):
        if not hasattr(self, 'means_'):
            raise RuntimeError('this MixtureIProMP is not fitted yet; call fit() first')


def loo_rms_by_components(demonstrations, candidates, observe: str = 'final', progress=None,
                          **params):
    """Leave-one-out RMS error of the controlled agent's predicted mean trajectory (thesis Figs.
    8 and 10) for every K in ``candidates``. The held-out demonstration is observed at its final
    observed position (``observe='final'``, as in the thesis) or along its whole path ('full').
    ``progress(done, total, K)`` is called after each fit. Needs a controlled agent (for a
    single-agent set use :func:`heldout_loglik_by_components`).

    Every fold's model is the one ``MixtureIProMP(K, **params).fit`` learns from the other
    demonstrations; what each demonstration contributes on its own (statistics, eq. 14
    weights) is computed once for all folds.

    Returns an array (len(candidates), n) of per-demonstration RMS errors.
    """
    demos = list(demonstrations)
    if demos and demos[0].n_controlled_dofs == 0:
        raise ValueError('leave-one-out RMS of the controlled agent needs a controlled agent; '
                         'these demonstrations have none (use the held-out log-likelihood)')
    data = _prepare_for_cv(demos, params)
    final = (_final_views(GaussianBasis(params.get('n_basis', _DEFAULT_N_BASIS)), demos)
             if observe == 'final' else None)
    out = np.empty((len(candidates), len(demos)))
    everyone = np.arange(len(demos))
    for a, K in enumerate(candidates):
        for i, test in enumerate(demos):
            model = MixtureIProMP(n_components=K, **params)._fit_prepared(
                data.take(everyone != i))
            out[a, i] = (_final_rms(model, final, [i])[0] if final is not None
                         else controlled_rms(model, test, observe))
            if progress:
                progress(a * len(demos) + i + 1, out.size, K)
    return out


def _prepare_for_cv(demos, params) -> _Prepared:
    """Every demonstration prepared once (checked as ``fit`` checks them) for fits with
    MixtureIProMP configuration ``params``."""
    model = MixtureIProMP(**{**params, 'n_components': 1})
    model._check_params()
    return model._prepare(_validate_demonstrations(demos, 1))


def controlled_rms(model, demo: Demonstration, observe: str = 'final'):
    """RMS error of the predicted controlled trajectory of ``demo`` over its own samples."""
    z = demo.phase
    rows = np.flatnonzero(~np.isnan(demo.observed).any(axis=1))
    if observe == 'final':
        rows = rows[-1:]
    elif observe != 'full':
        raise ValueError(f"observe must be 'final' or 'full', got {observe!r}")
    k, mean, _ = model.condition(z[rows], demo.observed[rows])
    dofs = range(model.n_observed_, model.n_observed_ + model.n_controlled_)
    pred = trajectory_distribution(mean, None, model.basis_, z, dofs=dofs)['position']
    ok = ~np.isnan(demo.controlled).any(axis=1)
    return float(np.sqrt(np.mean((pred[ok] - demo.controlled[ok]) ** 2)))


class _FinalView(NamedTuple):
    """What :func:`controlled_rms` (observe='final') needs of each demonstration, whatever model
    it is scored under: the basis at its final observed sample ``phi`` (n, N) and that sample
    ``y`` (n, P); per demonstration the basis at its samples with the controlled agent observed
    ``psi`` and those samples ``yc``. Cross-validation computes it once for every fold."""

    phi: np.ndarray
    y: np.ndarray
    psi: list
    yc: list


def _final_views(basis, demos) -> _FinalView:
    rows = [np.flatnonzero(~np.isnan(d.observed).any(axis=1))[-1] for d in demos]
    ok = [~np.isnan(d.controlled).any(axis=1) for d in demos]
    return _FinalView(basis(np.array([d.phase[r] for d, r in zip(demos, rows)])),
                      np.array([d.observed[r] for d, r in zip(demos, rows)]),
                      [basis(d.phase[m]) for d, m in zip(demos, ok)],
                      [d.controlled[m] for d, m in zip(demos, ok)])


def _final_rms(model, view: _FinalView, idx) -> np.ndarray:
    """:func:`controlled_rms` (observe='final') of the demonstrations ``idx`` of ``view`` at
    once: one observation, so the Kalman form of eq. 4 (a P x P innovation per component)
    gives the evidence of eq. 11 and the conditional mean of eq. 13 directly."""
    idx = np.asarray(idx)
    P, N = model.n_observed_, model.n_basis
    do, K = P * N, model.n_components
    phi, y = view.phi[idx], view.y[idx]                                    # (m, N), (m, P)
    mu, cov = model.means_, model.covariances_
    hm = np.einsum('kpn,in->ikp', mu[:, :do].reshape(K, P, N), phi)        # H mu, (m, K, P)
    SH = np.einsum('kdpn,in->ikdp', cov[:, :, :do].reshape(K, -1, P, N), phi)  # Sigma H^T
    S = np.einsum('ikpnq,in->ikpq', SH[:, :, :do].reshape(len(idx), K, P, N, P), phi)
    nv = model.observed_noise_var_
    S = S + (np.eye(P) * nv[..., None, :])                       # (P,) tied or (K, P) each
    r = y[:, None, :] - hm
    chol = np.linalg.cholesky(S)
    u = np.linalg.solve(chol, r[..., None])[..., 0]
    logdet = 2 * np.log(np.diagonal(chol, axis1=-2, axis2=-1)).sum(axis=-1)
    lp = np.log(model.weights_) - 0.5 * ((u ** 2).sum(axis=-1) + logdet)
    k = np.argmax(lp, axis=1)
    m = np.arange(len(idx))
    gain = np.linalg.solve(S[m, k], r[m, k][..., None])[..., 0]            # S^-1 (y - H mu)
    mean = mu[k] + np.einsum('idp,ip->id', SH[m, k], gain)
    out = np.empty(len(idx))
    for j, i in enumerate(idx):
        pred = view.psi[i] @ mean[j, do:].reshape(-1, N).T
        out[j] = np.sqrt(np.mean((pred - view.yc[i]) ** 2)) if len(pred) else np.nan
    return out


def cv_folds(n: int, n_folds: int, random_state=0):
    """Fold index (n,) of each demonstration: a seeded permutation cut into ``n_folds`` parts."""
    n_folds = int(min(n_folds, n))
    if n_folds < 2:
        raise ValueError(f'cross-validation needs at least 2 demonstrations, got {n}')
    order = np.random.default_rng(random_state).permutation(n)
    fold = np.empty(n, dtype=int)
    fold[order] = np.arange(n) % n_folds
    return fold


def heldout_loglik_by_components(demonstrations, candidates, n_folds: int = 5, progress=None,
                                 fold_seed=0, **params):
    """Cross-validated log-likelihood of held-out demonstrations, log p(D_i, alpha_i) of both
    agents with the phase known (:meth:`MixtureIProMP.score_demonstrations`), for every K in
    ``candidates``: works with or without a controlled agent. The same folds for every K, so
    the curves are paired. Returns (len(candidates), n); higher is better.
    """
    scale = params.pop('prior_scale', _DEFAULT_PRIOR_SCALE)
    return _heldout_scores(demonstrations, candidates, [scale], n_folds, progress, fold_seed,
                           params)['loglik'][0]


def _heldout_scores(demonstrations, candidates, scales, n_folds, progress, fold_seed, params,
                    fractions=(), controlled=False):
    """Held-out scores, each (len(scales), len(candidates), n): every fold's model is the one
    ``MixtureIProMP(K, prior_scale=scale, **params).fit`` learns from the other folds, scored
    on the fold. 'loglik': :meth:`MixtureIProMP.score_demonstrations`; with ``fractions`` also
    'completion' and 'completion_rms', :meth:`MixtureIProMP.score_completion`'s two scores
    averaged over the fractions. What each demonstration contributes on its own is computed
    once, and each fold's k-means start of each K once for every scale (it does not depend on
    the floor). With ``controlled`` and a controlled agent, also 'controlled_rms':
    :func:`controlled_rms` of the held-out demonstration given its final observed position (NaN
    for one whose controlled agent is never observed). ``progress(done, total, K)`` after each
    fit."""
    demos = list(demonstrations)
    fold = cv_folds(len(demos), n_folds, fold_seed)
    data = _prepare_for_cv(demos, params)
    shape = (len(scales), len(candidates), len(demos))
    out = {'loglik': np.empty(shape)}
    basis = GaussianBasis(params.get('n_basis', _DEFAULT_N_BASIS))
    if controlled and demos[0].n_controlled_dofs:
        out['controlled_rms'] = np.empty(shape)
        final = _final_views(basis, demos)
    if fractions:
        out['completion'], out['completion_rms'] = np.empty(shape), np.empty(shape)
        beginnings = _beginning_stats(basis, demos, _checked_fractions(fractions))
    done, total = 0, len(scales) * len(candidates) * (fold.max() + 1)
    for f in range(fold.max() + 1):
        train = data.take(fold != f)
        test = np.flatnonzero(fold == f)
        test_stats = data.take(test).stats
        for a, K in enumerate(candidates):
            init = None
            for b, scale in enumerate(scales):
                model = MixtureIProMP(n_components=K, **{**params, 'prior_scale': scale})
                if init is None and len(train.W) >= K:
                    init = model._initial_clusters(train)
                model._fit_prepared(train, init=init)
                out['loglik'][b, a, test] = model._score_stats(test_stats, data.alphas[test])
                if 'controlled_rms' in out:
                    out['controlled_rms'][b, a, test] = _final_rms(model, final, test)
                if fractions:
                    density, rms = model._completion_stats(
                        test_stats, [_take_stats(st, test) for st in beginnings],
                        data.alphas[test])
                    out['completion'][b, a, test] = density.mean(axis=1)
                    out['completion_rms'][b, a, test] = rms.mean(axis=1)
                done += 1
                if progress:
                    progress(done, total, K)
    return out


# Covariance floors tried by :func:`calibrated_heldout_loglik`, as fractions of the within-
# component variance per weight: half decades wide enough for every scenario evaluated (their
# optima range from 3e-4, smooth generated reaches, to 1, letters and sampled covariances).
PRIOR_SCALES = tuple(float(f'{10.0 ** e:.3g}') for e in np.arange(0.5, -4.01, -0.5))
_DEFAULT_PRIOR_SCALE = inspect.signature(MixtureIProMP).parameters['prior_scale'].default
_DEFAULT_N_BASIS = inspect.signature(MixtureIProMP).parameters['n_basis'].default


def calibrated_heldout_loglik(demonstrations, candidates, prior_scales=PRIOR_SCALES,
                              n_folds: int = 5, progress=None, fold_seed=0, **params):
    """:func:`heldout_loglik_by_components` with the covariance floor (``prior_scale``)
    calibrated by the same criterion, for every K its own.

    The floor is the variance a component gets in the directions its few members do not span
    (fewer demonstrations than weights). Too small, and a held-out demonstration of the same
    pattern falls outside the component; too large, and the components blur into each other.
    The right amount depends on the data (smooth generated reaches want 1e-3 of the within-
    pattern variance, sampled covariances and letters 0.3 to 3), so no fixed value is right
    for every data set, and each K is compared at the floor its held-out likelihood prefers.
    The same folds for every scale and K; the maximum over a few scales makes every K's
    curve equally optimistic, so the paired comparison between K stays fair.

    Returns a dict: 'scores' (len(candidates), n), each K's per-demonstration held-out
    log-likelihood at its best scale; 'prior_scale' (per candidate); 'prior_scales' and
    'mean_by_scale' (len(prior_scales), len(candidates)), the mean of every curve tried.
    """
    return calibrated_heldout_curves(demonstrations, candidates, (), prior_scales, n_folds,
                                     progress, fold_seed, controlled=False, **params)['loglik']


# Where the completion criterion cuts a held-out demonstration into the beginning it observes
# and the rest it predicts: the fractions recognition is reported at (app.evaluation), spread
# over the movement so that no single cut decides.
COMPLETION_FRACTIONS = (0.3, 0.5, 0.7)


def calibrated_heldout_curves(demonstrations, candidates, fractions=COMPLETION_FRACTIONS,
                              prior_scales=PRIOR_SCALES, n_folds: int = 5, progress=None,
                              fold_seed=0, controlled: bool = True, **params):
    """Every held-out criterion for K from the same cross-validated fits, each K at the
    covariance floor the criterion itself prefers (see :func:`calibrated_heldout_loglik`):

    - 'loglik': log p(D_i, alpha_i) of the held-out demonstration (higher is better);
    - with ``controlled`` (default) and a controlled agent, 'controlled_rms': the thesis's
      leave-one-out criterion (:func:`controlled_rms`, the controlled agent predicted from the
      final observed position) on the held-out folds, lower is better. Its floor is the one
      with the lowest RMS among the floors whose held-out likelihood is not significantly
      below the likelihood's own choice (paired differences within two standard errors): a
      floor that predicts the robot best without misdescribing the observed agent, which the
      online component posterior and the novelty test read. The RMS alone barely moves below
      some floor, so its minimum there is noise at the grid's edge; the likelihood alone can
      prefer a floor that predicts the robot's posture worse than a floor it cannot tell
      apart (the Panda's box assembly at K = 4: 1.0 against 0.316).
    - with ``fractions``, the single-agent analogue of the thesis's leave-one-out of the
      controlled agent, what a model of one agent's movements is used for (recognise a
      movement and predict its rest from its beginning): 'completion', the predictive log
      density of the rest given the beginning, log p(D_i[z > f] | D_i[z <= f], alpha_i),
      and 'completion_rms', the RMS error of the rest predicted from the beginning (lower is
      better), each averaged over the fractions f (:meth:`MixtureIProMP.score_completion`).

    Returns {criterion: dict as calibrated_heldout_loglik returns}.
    """
    demos = list(demonstrations)
    scales = [float(s) for s in prior_scales]
    if not scales or not all(np.isfinite(s) and s > 0 for s in scales):
        raise ValueError(f'prior_scales must be positive numbers, got {prior_scales!r}')
    params = {k: v for k, v in params.items() if k != 'prior_scale'}
    scores = _heldout_scores(demos, candidates, scales, n_folds, progress, fold_seed, params,
                             tuple(fractions), controlled)
    out = {}
    for name, S in scores.items():
        if name == 'controlled_rms':
            mean = np.nanmean(S, axis=2)
            allowed = np.column_stack([_not_significantly_worse(scores['loglik'][:, a])
                                       for a in range(len(candidates))])
            best = np.argmin(np.where(allowed, mean, np.inf), axis=0)
        else:
            mean = S.mean(axis=2)
            best = (np.argmin(mean, axis=0) if name.endswith('_rms')
                    else np.argmax(mean, axis=0))
        out[name] = {'scores': S[best, np.arange(len(candidates))],
                     'prior_scale': [scales[b] for b in best], 'prior_scales': scales,
                     'mean_by_scale': mean}
    return out


def _not_significantly_worse(g):
    """Mask of the rows of ``g`` (options, n; per-demonstration scores, higher is better) whose
    paired difference to the best row is within two standard errors: the options the data
    cannot tell from the best."""
    d = g[np.argmax(g.mean(axis=1))] - g
    n = g.shape[1]
    se = d.std(axis=1, ddof=1) / np.sqrt(n) if n > 1 else np.zeros(len(g))
    return d.mean(axis=1) <= 2 * se


def select_n_components(scores, higher_is_better: bool = False, paired: bool = False):
    """Smallest K (index into the candidates) whose mean score is within one standard error of
    the best: where the curve reaches its plateau (LOO RMS, lower is better; or held-out
    log-likelihood, ``higher_is_better``). See :func:`selection_curve` for ``paired``."""
    return selection_curve(scores, higher_is_better, paired)['index']


def selection_curve(scores, higher_is_better: bool = False, paired: bool = False):
    """The K choice and its evidence from per-demonstration scores (candidates, n).

    Plateau rule: the smallest K within one standard error of the best K's scores (the
    thesis's RMS curves) or, ``paired``, the smallest K not significantly worse than the best:
    its per-demonstration difference to the best K within two standard errors. Held-out
    log-likelihoods need the paired form: each demonstration's own level (its number of
    samples, its noise) varies far more between demonstrations than between K, while the
    paired differences are so consistent that one standard error would call a negligible
    gain of a superfluous component significant.

    Whether the curve has a clear optimum (paired differences, two standard errors): the chosen
    K beats the first candidate, or the first candidate is chosen and beats every other.
    Otherwise the curve is flat within its noise and the note says so.
    Returns a dict: index, mean, se (per candidate), clear (bool), note (str).
    """
    s = np.asarray(scores, dtype=float)
    g = s if higher_is_better else -s               # higher is better from here on
    n = s.shape[1]

    def se_of(x):
        return float(x.std(ddof=1) / np.sqrt(n)) if n > 1 else 0.0
    mean = s.mean(axis=1)
    se = np.array([se_of(r) for r in s])
    best = int(np.argmax(g.mean(axis=1)))
    if paired:
        within = _not_significantly_worse(g)
    else:
        within = g.mean(axis=1) >= g[best].mean() - se[best]
    index = int(np.flatnonzero(within)[0])

    def beats(a, b):
        d = g[a] - g[b]
        return d.mean() > 2 * se_of(d)
    if len(s) == 1:
        clear, note = False, 'a single candidate: nothing was compared'
    elif index > 0:
        clear = beats(index, 0)
        note = ('clear: better than the first candidate by more than two paired standard errors'
                if clear else 'no clear optimum: the curve is flat within two paired standard '
                              'errors of the first candidate')
    else:
        clear = all(beats(0, b) for b in range(1, len(s)))
        note = ('clear: the first candidate beats every other by more than two paired standard '
                'errors' if clear else 'no clear optimum: the curve is flat (no candidate is '
                'better than the first by two paired standard errors); the first is kept by '
                'parsimony')
    return {'index': index, 'mean': mean.tolist(), 'se': se.tolist(), 'clear': bool(clear),
            'note': note}


def _label_indices(labels, n, n_components):
    """(sorted distinct labels, index of each demonstration's label) for a supervised fit."""
    labels = np.asarray(labels)
    if labels.shape != (n,):
        raise ValueError(f'labels must have one entry per demonstration ({n}), got shape '
                         f'{labels.shape}')
    classes, index = np.unique(labels, return_inverse=True)
    if len(classes) != n_components:
        raise ValueError(f'a supervised fit has one component per class: n_components='
                         f'{n_components} but the labels name {len(classes)} classes')
    return [c.item() if hasattr(c, 'item') else c for c in classes], index


def _validate_demonstrations(demonstrations, n_components):
    demos = list(demonstrations)
    if not all(isinstance(d, Demonstration) for d in demos):
        raise ValueError('demonstrations must be a list of Demonstration objects')
    if int(n_components) != n_components or n_components < 1:
        raise ValueError(f'n_components must be a positive integer, got {n_components!r}')
    if len(demos) < n_components:
        raise ValueError(f'{len(demos)} demonstrations are fewer than n_components={n_components}')
    shapes = {(d.n_observed_dofs, d.n_controlled_dofs) for d in demos}
    if len(shapes) != 1:
        raise ValueError(f'demonstrations disagree on (observed, controlled) DOFs: {sorted(shapes)}')
    return demos


def _validate_observation(z, Y, n_observed):
    z = np.atleast_1d(np.asarray(z, dtype=float))
    Y = np.asarray(Y, dtype=float)
    if Y.ndim == 1:
        Y = Y[None, :]
    if Y.shape != (z.shape[0], n_observed):
        raise ValueError(f'observation must have shape (len(z), {n_observed}) = '
                         f'({z.shape[0]}, {n_observed}), got {Y.shape}')
    if z.size == 0 or np.isnan(Y).all():
        raise ValueError('empty observation: nothing to condition on')
    if not np.all(np.isfinite(z)):
        raise ValueError('observation phases contain NaN or Inf')
    if np.any(np.isinf(Y)):
        raise ValueError('observation contains Inf')
    return z, Y
