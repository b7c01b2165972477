"""Mixture of Interaction ProMPs (thesis 3.3): a Gaussian mixture over stacked human-robot
weights learned by EM (eqs. 6-10) from k-means initialisation; component posterior (eqs.
11-12) and conditioning of the most probable component (eq. 13); K by leave-one-out.

``method='em'`` learns the mixture from partially observed demonstrations (chapter 5 future
work): the weights of every demonstration are latent as in 4.2.1, so E-step responsibilities
use each demonstration's marginal likelihood p(D_i | k) and the M step adds the weight
posterior covariances (eqs. 27-30 per component).
"""

import numpy as np
from scipy import linalg
from scipy.special import logsumexp

from .basis import GaussianBasis
from .demonstration import Demonstration
from .interaction import condition_on_observed, trajectory_distribution
from .promp import (LOG_2PI, _regularised_cov, covariance_penalty, expected_sq_residual,
                    observation_stats, weight_posterior)


def kmeans(X, n_clusters: int, random_state=0, n_init: int = 10, max_iter: int = 100):
    """k-means++ seeded Lloyd iterations; the best of ``n_init`` runs. Returns labels (n,)."""
    rng = np.random.default_rng(random_state)
    best, best_inertia = None, np.inf
    for _ in range(n_init):
        centers = [X[rng.integers(len(X))]]
        for _ in range(1, n_clusters):
            d2 = np.min([np.sum((X - c) ** 2, axis=1) for c in centers], axis=0)
            p = d2 / d2.sum() if d2.sum() > 0 else np.full(len(X), 1 / len(X))
            centers.append(X[rng.choice(len(X), p=p)])
        C = np.array(centers)
        for _ in range(max_iter):
            labels = np.argmin(((X[:, None, :] - C[None]) ** 2).sum(-1), axis=1)
            newC = np.array([X[labels == k].mean(0) if np.any(labels == k) else C[k]
                             for k in range(n_clusters)])
            if np.allclose(newC, C):
                break
            C = newC
        inertia = np.sum((X - C[labels]) ** 2)
        if inertia < best_inertia:
            best, best_inertia = labels, inertia
    return best


def gmm_log_prob(W, weights, means, covs):
    """log(alpha_k N(w_i; mu_k, Sigma_k)) for every i, k: the terms of eqs. 6-7."""
    n, d = W.shape
    out = np.empty((n, len(weights)))
    for k in range(len(weights)):
        L = np.linalg.cholesky(covs[k])
        sol = linalg.solve_triangular(L, (W - means[k]).T, lower=True)
        out[:, k] = (np.log(weights[k]) - 0.5 * (d * LOG_2PI + 2 * np.sum(np.log(np.diag(L)))
                                                 + np.sum(sol ** 2, axis=0)))
    return out


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
    Wk = W if W.ndim == 3 else np.broadcast_to(W[:, None, :], (n, K, W.shape[-1]))
    means = np.einsum('ik,ikd->kd', resp, Wk) / nk[:, None]                # eq. 9
    covs = np.empty((K, means.shape[1], means.shape[1]))
    for k in range(K):
        E = Wk[:, k] - means[k]
        S = (resp[:, k, None] * E).T @ E                                    # eq. 10
        if extra_cov is not None:
            S += np.einsum('i,ide->de', resp[:, k], extra_cov[:, k])
        covs[k] = _regularised_cov(S, nk[k], np.asarray(prior_cov), prior_strength)
    return weights, means, covs


class MixtureIProMP:
    """Mixture of Interaction ProMPs learned from unlabeled demonstrations.

    Parameters are configuration only; ``fit`` sets the fitted attributes (trailing underscore):
    ``basis_``, ``n_observed_``, ``n_controlled_``, ``weights_`` (K,), ``means_`` (K, d),
    ``covariances_`` (K, d, d), ``noise_var_`` (P+Q,), ``alpha_mean_``/``alpha_std_`` (K,) the
    per-component prior over the phase speed alpha = 1/T, ``log_likelihood_`` per EM iteration
    (penalised, monotone), ``resp_`` (n, K).

    ``prior_strength`` pseudo-samples of a shared covariance ``prior_cov_`` regularise every
    component covariance (conjugate prior, so EM stays monotone in the penalised likelihood):
    the within-component covariance pooled over the k-means clusters (``method='regression'``)
    plus a diagonal floor of ``prior_scale`` times each weight's variance over all
    demonstrations. This keeps every
    component positive definite with fewer members than weights and its posterior calibrated.
    ``observation_noise`` (metres) is the sensor noise added to the learned residual variance
    of the observed agent when conditioning on new observations.
    """

    def __init__(self, n_components: int = 3, n_basis: int = 15, method: str = 'regression',
                 ridge: float = 1e-6, prior_strength: float = 10.0, prior_scale: float = 0.02,
                 max_iter: int = 200, tol: float = 1e-7, n_init: int = 10, random_state=0,
                 observation_noise: float = 0.01, min_alpha_rel_std: float = 0.05):
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
        self.min_alpha_rel_std = min_alpha_rel_std

    # ------------------------------------------------------------------ learning
    def fit(self, demonstrations):
        demos = _validate_demonstrations(demonstrations, self.n_components)
        if self.method not in ('regression', 'em'):
            raise ValueError(f"method must be 'regression' or 'em', got {self.method!r}")
        self.basis_ = GaussianBasis(self.n_basis)
        self.n_observed_ = demos[0].n_observed_dofs
        self.n_controlled_ = demos[0].n_controlled_dofs
        N = self.n_basis
        stats, W = [], []
        for demo in demos:
            z = demo.t / demo.duration
            Y = np.hstack([demo.observed, demo.controlled])
            st = observation_stats(self.basis_, z, Y)
            if self.method == 'regression' and np.any(st.m < 1):
                raise ValueError(f'demonstration {demo.name!r} has a DOF never observed; '
                                 "use method='em' for missing data")
            stats.append(st)
            ridge = self.ridge if self.method == 'regression' else max(self.ridge, 1e-2)
            W.append(np.concatenate([np.linalg.solve(st.G[j] + ridge * np.eye(N), st.b[j])
                                     for j in range(len(st.m))]))
        W = np.array(W)
        n, d = W.shape
        floor = self.prior_scale * np.maximum(W.var(axis=0), 1e-12)
        labels = kmeans(W / np.sqrt(floor), self.n_components,
                        random_state=self.random_state, n_init=self.n_init)
        resp = np.eye(self.n_components)[labels]
        # Shrinkage target: the within-component covariance pooled over the k-means clusters
        # (shape variability shared by all patterns) plus a small diagonal floor. A component
        # with a dozen members then borrows the pooled structure instead of trusting spurious
        # correlations of its own sample covariance.
        # With missing data ('em') the starting weights are unreliable where a demonstration
        # has gaps, so the target is the diagonal floor alone.
        self.prior_cov_ = np.diag(floor)
        if self.method == 'regression':
            E = W - np.array([W[labels == k].mean(axis=0)
                              for k in range(self.n_components)])[labels]
            self.prior_cov_ += E.T @ E / n
        weights, means, covs = gmm_maximization(W, resp, self.prior_cov_, self.prior_strength)
        resid = sum(expected_sq_residual(st, w, np.zeros((d, d))) for st, w in zip(stats, W))
        noise = np.maximum(resid / np.maximum(sum(st.m for st in stats), 1), 1e-10)
        self.log_likelihood_ = []
        prev = -np.inf
        self.converged_ = False
        for it in range(self.max_iter):
            if self.method == 'regression':
                resp, ll = gmm_responsibilities(W, weights, means, covs)
                post_means, post_covs = W, None
            else:
                resp, ll, post_means, post_covs = self._latent_e_step(stats, weights, means, covs,
                                                                      noise)
            ll += sum(covariance_penalty(linalg.cho_factor(c, lower=True), self.prior_cov_,
                                         self.prior_strength) for c in covs)
            self.log_likelihood_.append(ll)
            if ll - prev < self.tol * max(1.0, abs(ll)):
                self.converged_ = True
                break
            prev = ll
            weights, means, covs = gmm_maximization(post_means, resp, self.prior_cov_,
                                                    self.prior_strength, post_covs)
            if self.method == 'em':
                num = sum(resp[i, k] * expected_sq_residual(stats[i], post_means[i, k],
                                                             post_covs[i, k])
                          for i in range(n) for k in range(self.n_components))
                noise = np.maximum(num / np.maximum(sum(st.m for st in stats), 1), 1e-10)
        self.n_iter_ = len(self.log_likelihood_)
        self.weights_, self.means_, self.covariances_ = weights, means, covs
        self.resp_ = resp
        self.noise_var_ = noise
        alphas = np.array([1.0 / demo.duration for demo in demos])
        nk = resp.sum(axis=0)
        # A component EM left without members keeps the pooled phase prior (not 0 / 0).
        empty = nk < 1e-12
        nk = np.where(empty, 1.0, nk)
        mean = np.where(empty, alphas.mean(), resp.T @ alphas / nk)
        var = np.where(empty, alphas.var(),
                       np.einsum('ik,ik->k', resp, (alphas[:, None] - mean) ** 2) / nk)
        self.alpha_mean_ = mean
        self.alpha_std_ = np.maximum(np.sqrt(var), self.min_alpha_rel_std * mean)
        return self

    def _latent_e_step(self, stats, weights, means, covs, noise):
        n, K, d = len(stats), len(weights), means.shape[1]
        post_means = np.empty((n, K, d))
        post_covs = np.empty((n, K, d, d))
        lp = np.empty((n, K))
        for k in range(K):
            chol = linalg.cho_factor(covs[k], lower=True)
            for i, st in enumerate(stats):
                post_means[i, k], post_covs[i, k], ll = weight_posterior(st, means[k], chol, noise)
                lp[i, k] = np.log(weights[k]) + ll
        norm = logsumexp(lp, axis=1)
        return np.exp(lp - norm[:, None]), float(norm.sum()), post_means, post_covs

    # ------------------------------------------------------------------ inference
    @property
    def observed_noise_var_(self):
        """Sigma_D of eq. 4: learned residual variance of the observed agent + sensor noise."""
        return self.noise_var_[:self.n_observed_] + self.observation_noise ** 2

    def component_log_evidence(self, z, Y_obs):
        """log p(D | k) for every component (the integral under eq. 11), observed agent only."""
        self._check_fitted()
        z, Y_obs = _validate_observation(z, Y_obs, self.n_observed_)
        do = self.n_observed_ * self.n_basis
        st = observation_stats(self.basis_, z, Y_obs)
        out = np.empty(self.n_components)
        for k in range(self.n_components):
            chol = linalg.cho_factor(self.covariances_[k][:do, :do], lower=True)
            out[k] = weight_posterior(st, self.means_[k][:do], chol, self.observed_noise_var_)[2]
        return out

    def component_posterior(self, z, Y_obs):
        """Eq. 11: p(k | D) for observations Y_obs (m, P) of the observed agent at phases z."""
        self._check_fitted()
        lp = np.log(self.weights_) + self.component_log_evidence(z, Y_obs)
        return np.exp(lp - logsumexp(lp))

    def condition(self, z, Y_obs, component=None):
        """Eqs. 12-13: the most probable component (or ``component``) conditioned on D.

        Returns (k, mean, cov) of the stacked weights."""
        if component is None:
            component = int(np.argmax(self.component_posterior(z, Y_obs)))
        z, Y_obs = _validate_observation(z, Y_obs, self.n_observed_)
        mean, cov = condition_on_observed(self.means_[component], self.covariances_[component],
                                          self.basis_, self.n_observed_, z, Y_obs,
                                          self.observed_noise_var_)
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
    wrist position (``observe='final'``, as in the thesis) or along its whole path ('full').
    ``progress(done, total, K)`` is called after each fit.

    Returns an array (len(candidates), n) of per-demonstration RMS errors.
    """
    demos = list(demonstrations)
    out = np.empty((len(candidates), len(demos)))
    for a, K in enumerate(candidates):
        for i, test in enumerate(demos):
            model = MixtureIProMP(n_components=K, **params).fit(demos[:i] + demos[i + 1:])
            out[a, i] = controlled_rms(model, test, observe)
            if progress:
                progress(a * len(demos) + i + 1, out.size, K)
    return out


def controlled_rms(model, demo: Demonstration, observe: str = 'final'):
    """RMS error of the predicted controlled trajectory of ``demo`` over its own samples."""
    z = demo.t / demo.duration
    rows = np.flatnonzero(~np.isnan(demo.observed).any(axis=1))
    if observe == 'final':
        rows = rows[-1:]
    elif observe != 'full':
        raise ValueError(f"observe must be 'final' or 'full', got {observe!r}")
    pred = model.predict_controlled(z[rows], demo.observed[rows], z)['position']
    ok = ~np.isnan(demo.controlled).any(axis=1)
    return float(np.sqrt(np.mean((pred[ok] - demo.controlled[ok]) ** 2)))


def select_n_components(rms):
    """Smallest K (index into the candidates) whose mean LOO RMS is within one standard error
    of the best: where the RMS-vs-K curve reaches its plateau."""
    mean = rms.mean(axis=1)
    se = rms.std(axis=1, ddof=1) / np.sqrt(rms.shape[1])
    best = int(np.argmin(mean))
    return int(np.flatnonzero(mean <= mean[best] + se[best])[0])


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
