"""Mixture of Interaction ProMPs (thesis 3.3): a Gaussian mixture over stacked human-robot
weights learned by EM (eqs. 6-10) from the patterns found in the metric of paths
(core.patterns); component posterior (eqs. 11-12) and conditioning of the most probable
component (eq. 13). The estimator in scikit-learn's shape: ``fit`` is a short loop of named
steps (``_initialize``, ``_e_step``, ``_m_step``) whose maths are core.gmm's pure functions;
how many components and how much covariance floor is core.selection's.

``method='em'`` learns the mixture from partially observed demonstrations (chapter 5 future
work): the weights of every demonstration are latent as in 4.2.1, so E-step responsibilities
use each demonstration's marginal likelihood p(D_i | k) and the M step adds the weight
posterior covariances (eqs. 27-30 per component).
"""

from typing import NamedTuple

import numpy as np
from scipy import linalg
from scipy.special import logsumexp

from .basis import GaussianBasis
from .demonstration import Demonstration
from .gmm import (_gmm_log_prob, covariance_penalty_of_m_step, gmm_log_prob,
                  gmm_maximization, gmm_responsibilities, latent_e_step, noise_m_step)
from .numerics import logsumexp_rows
from .noise import (MAX_LAG_S, correlation_time, decimated_rows, noise_factor,
                    residual_autocovariance)
from .patterns import PatternMixture, PatternSpace, offset_operators, translation_groups
from .interaction import condition_on_observed, trajectory_distribution
from .phase import (alpha_log_density, alpha_m_step, alpha_penalty, alpha_prior_std,
                    timing_variance)
from .promp import (ObservationStats, cho_inverse, covariance_penalty, expected_sq_residual,
                    log_evidence, empirical_bayes_smoothing, feature_stats, observation_stats,
                    penalised_weights, stack_stats, start_ridge, weight_posterior)
from .warp import N_WARP, START_SD, WarpAt, laplace, learn_warp_priors, map_warp


class Prepared(NamedTuple):
    """What a fit needs of each demonstration on its own, whatever the other demonstrations it
    is fitted with (:meth:`MixtureIProMP.prepare`): the observation statistics (stacked,
    promp.stack_stats), the weights W (n, d) (:meth:`MixtureIProMP._weights`: eq. 14 smoothed as
    the set's recordings are, the smoothing chosen on every demonstration prepared, held-out
    folds included: one unsupervised number per DOF that the folds share), the squared residuals at them (n, D),
    alpha = 1/T and the timing variance (n,), the residuals' autocovariances and sample
    periods (core.noise). Cross-validation computes them once, and every fold and K takes its
    demonstrations from them (:meth:`take`)."""

    stats: ObservationStats
    W: np.ndarray
    sq: np.ndarray
    alphas: np.ndarray
    timing: np.ndarray
    n_observed: int
    acov: np.ndarray        # (n, 2, D, L + 1): residual autocovariance sums and pair counts
    periods: np.ndarray     # (n,) sample period of each demonstration (s)
    smoothing: object       # (D,) the weights' curvature penalty (None: EM's start weights)

    def take(self, idx) -> 'Prepared':
        return Prepared(self.stats.take(idx), self.W[idx], self.sq[idx], self.alphas[idx],
                        self.timing[idx], self.n_observed, self.acov[idx], self.periods[idx],
                        self.smoothing)


class MixtureIProMP:
    """Mixture of Interaction ProMPs learned from unlabeled demonstrations.

    Any layout: the observed agent has P >= 1 DOFs, the controlled agent Q >= 0 (Q = 0 is a
    single-agent mixture: it recognises a movement and predicts its rest from a partial
    observation). Parameters are configuration only; ``fit`` sets the fitted attributes
    (trailing underscore): ``basis_``, ``n_observed_``, ``n_controlled_``, ``weights_`` (K,),
    ``means_`` (K, d), ``covariances_`` (K, d, d), ``noise_var_`` the observation noise
    variance of eq. 15 per DOF in the DOF's own unit squared, (P+Q,) tied across components or
    (K, P+Q) with ``noise='per_component'``, ``alpha_mean_``/``alpha_std_`` (K,) the
    per-component prior over the phase speed alpha = 1/T, ``noise_time_`` (P+Q,) how long each
    DOF's residuals stay correlated (s, core.noise) and ``sample_period_`` the recordings'
    sample period (s), which together say what one observation is worth online
    (:meth:`observed_noise_var_at`), ``log_likelihood_`` per EM iteration
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

    ``speed_weight`` (eta in [0, 1]) is how much the online phase-speed posterior trusts the
    observations: p(alpha | D, k) proportional to p(D | k, alpha)^eta p(alpha | k) (eta = 1:
    eqs. 16-18; core.phase.tempered_speed_posterior). The model says a movement keeps one
    speed from onset to end; people speed up and slow down within one (a handshake's shaking
    lasts as long as it lasts), so the speed that explains a prefix says less about the rest
    than eq. 16 claims. Fitting does not use it; training calibrates it on held-out
    demonstrations (core.online.speed_log_scores).

    ``smoothing`` (None: chosen from the demonstrations) is each DOF's curvature penalty of the
    per-demonstration weights (eq. 14 with core.promp.penalised_weights; ``method='regression'``):
    None picks it by empirical Bayes over the demonstrations given to :meth:`prepare`
    (core.promp.empirical_bayes_smoothing), so that gaps in a recording and a tracker's noise
    are bridged and filtered as smoothly as the recordings are where they are observed.
    Fitted: ``smoothing_`` (D,).

    ``translation``: groups of DOF indices (into the stacked [observed, controlled] DOFs) that
    move together when a demonstration happens elsewhere (core.patterns.translation_for: e.g.
    both hands' x, y and z). Where it is not part of the pattern: the patterns are found and
    the mixture fitted on the demonstrations with their offsets removed, and the offset is a
    variable of its own, shared by every component (:meth:`_add_offsets`). Fitted:
    ``offset_mean_`` (g,), ``offset_cov_`` (g, g).
    """

    def __init__(self, n_components: int = 3, n_basis: int = 15, method: str = 'regression',
                 ridge: float = 1e-6, prior_strength: float = 10.0, prior_scale: float = 0.02,
                 max_iter: int = 200, tol: float = 1e-7, n_init: int = 10, random_state=0,
                 observation_noise=0.0, noise: str = 'tied', noise_var=None,
                 speed_weight: float = 1.0, translation=(), smoothing=None):
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
        self.speed_weight = speed_weight
        self.translation = translation
        self.smoothing = smoothing

    # ------------------------------------------------------------------ learning
    def fit(self, demonstrations, labels=None, init=None):
        """Learn the mixture from ``demonstrations`` (a list of Demonstrations, or what
        :meth:`prepare` made of them): unlabeled, EM (eqs. 7-10) from the patterns found in
        the metric of their paths (:meth:`initial_clusters`, or ``init``, one component index
        per demonstration).

        ``labels`` (n,), optional: a supervised fit with one component per distinct label
        (sorted; ``n_components`` must equal their number) and the responsibilities fixed to
        the labels, i.e. one Interaction ProMP per class sharing the noise model and the
        covariance prior. ``classes_`` then names the components.
        """
        self._check_params()
        data = (demonstrations if isinstance(demonstrations, Prepared)
                else self.prepare(demonstrations))
        if len(data.W) < self.n_components:
            raise ValueError(f'{len(data.W)} demonstrations are fewer than '
                             f'n_components={self.n_components}')
        offsets = None
        if translation_groups(self.translation, data.sq.shape[1]):
            T, B = offset_operators(self.n_basis, data.sq.shape[1], self.translation)
            offsets = data.W @ T.T
            data = data._replace(W=data.W - offsets @ B.T)
        resp, fixed_noise = self._initialize(data, labels, init)
        params = self._m_step(data, resp, data.W, None, fixed_noise)
        self.log_likelihood_ = []
        self.converged_ = False
        previous = -np.inf
        for it in range(self.max_iter):
            new_resp, ll, post_means, post_covs = self._e_step(data, params, resp, labels)
            self.log_likelihood_.append(ll)
            if ll - previous < self.tol * max(1.0, abs(ll)):
                self.converged_ = True
                resp = new_resp
                break
            previous = ll
            if (self.method == 'regression' and self.tol > 0 and it + 1 < self.max_iter
                    and np.array_equal(new_resp, resp)):
                # The parameters are the M step of these very responsibilities, so the next
                # iteration would repeat this one (same log-likelihood: converged) unchanged.
                self.log_likelihood_.append(ll)
                self.converged_ = True
                break
            resp = new_resp
            params = self._m_step(data, resp, post_means, post_covs, fixed_noise, params)
        self._finish(data, resp, params, fixed_noise)
        if offsets is not None:
            self._add_offsets(offsets, B)
        return self

    def _add_offsets(self, offsets, B):
        """Where the interaction happened, back into every component (``translation``): the
        mixture was fitted to the demonstrations with their offsets o_i removed (w_i - B o_i,
        core.patterns.offset_operators), and the offset is a variable of its own, o ~ N(m, S)
        over all demonstrations, independent of the pattern and of its shape. So each component
        is N(mu_k + B m, Sigma_k + B S B^T): the same for a demonstration wherever it
        happened, up to the shared density of its offset, and conditioning on the observed
        agent infers the offset and moves the controlled agent by it. S is the offsets' sample
        covariance plus a floor of 1e-6 of its largest variance, for the rare set with fewer
        demonstrations than offset axes."""
        n, g = offsets.shape
        m = offsets.mean(axis=0)
        E = offsets - m
        S = E.T @ E / max(n - 1, 1)
        S += np.eye(g) * max(1e-6 * float(np.max(np.diag(S), initial=0.0)), 1e-12)
        self.offset_mean_, self.offset_cov_ = m, S
        self.means_ = self.means_ + B @ m
        self.covariances_ = self.covariances_ + (B @ S @ B.T)[None]

    def prepare(self, demonstrations) -> Prepared:
        """What a fit needs of each demonstration on its own (see :class:`Prepared`),
        checked as :meth:`fit` checks them."""
        self._check_params()
        demos = _validate_demonstrations(demonstrations, 1)
        basis = GaussianBasis(self.n_basis)
        periods = np.array([float(np.median(np.diff(demo.t))) for demo in demos])
        stats = [observation_stats(basis, demo.phase, np.hstack([demo.observed, demo.controlled]))
                 for demo in demos]
        if self.method == 'regression':
            for demo, st in zip(demos, stats):
                if np.any(st.m < 1):
                    raise ValueError(f'demonstration {demo.name!r} has a DOF never observed; '
                                     "use method='em' for missing data")
        stacked = stack_stats(stats)
        smoothing = None
        if self.method == 'regression':
            if self.smoothing is None:
                smoothing = empirical_bayes_smoothing(stacked)
            else:
                smoothing = np.asarray(self.smoothing, dtype=float)
                if smoothing.size not in (1, stacked.m.shape[1]):
                    raise ValueError(f'smoothing has {smoothing.size} values for '
                                     f'{stacked.m.shape[1]} DOFs (give one, or one per DOF)')
                smoothing = np.broadcast_to(smoothing, stacked.m.shape[1:]).copy()
        W = self._weights(stacked, smoothing)
        zero = np.zeros((W.shape[1], W.shape[1]))
        sq = np.array([expected_sq_residual(st, w, zero) for st, w in zip(stats, W)])  # (n, D)
        max_lag = int(np.ceil(MAX_LAG_S / np.median(periods)))
        acov = np.array([residual_autocovariance(
            np.hstack([demo.observed, demo.controlled])
            - basis(demo.phase) @ w.reshape(-1, self.n_basis).T, max_lag)
            for demo, w in zip(demos, W)])
        return Prepared(stacked, W, sq,
                        np.array([1.0 / demo.duration for demo in demos]),
                        timing_variance([demo.duration for demo in demos], periods),
                        demos[0].n_observed_dofs, acov, periods, smoothing)

    def initial_clusters(self, data: Prepared):
        """EM's start (eq. 7's r_ik): the demonstrations' patterns, found in the metric of their
        paths (core.patterns: a mixture in a few principal components of the path
        coordinates), each demonstration in its most probable one."""
        space = PatternSpace(self.n_basis, data.n_observed, min_components=self.n_components - 1,
                             translation=self.translation)
        X = space.fit(data.W).transform(data.W)
        mixture = PatternMixture(self.n_components, self.prior_strength, n_init=self.n_init,
                                 random_state=self.random_state).fit(X)
        return np.argmax(mixture.resp_, axis=1)

    def _initialize(self, data: Prepared, labels, init):
        """The fitted attributes known before EM, the starting responsibilities (labels, the
        given ``init`` or :meth:`initial_clusters`) and the covariance priors they define;
        returns (responsibilities (n, K), the fixed noise variances or None)."""
        n, d = data.W.shape
        K = self.n_components
        self.basis_ = GaussianBasis(self.n_basis)
        self.n_observed_ = data.n_observed
        D = data.sq.shape[1]
        self.n_controlled_ = D - data.n_observed
        fixed_noise = None
        if self.noise_var is not None:
            fixed_noise = np.broadcast_to(np.asarray(self.noise_var, dtype=float), (D,)).copy()
            if not np.all(np.isfinite(fixed_noise) & (fixed_noise > 0)):
                raise ValueError(f'noise_var must be positive and finite, got {self.noise_var!r}')
        W, alphas = data.W, data.alphas
        if labels is None:
            self.classes_ = None
            init = self.initial_clusters(data) if init is None else np.asarray(init)
        else:
            self.classes_, init = _label_indices(labels, n, K)
        # A component is a joint p(w, alpha | k) = p(w | k) p(alpha | k) over shape and phase
        # speed alpha = 1/T (eq. 17's independence of w and alpha within a pattern): patterns
        # that differ in speed are told apart by it, and p(alpha | k) is the online prior.
        # Shrinkage target: the within-component covariance pooled over the initial clusters
        # (shape variability shared by all patterns) plus a diagonal floor. A component with a
        # dozen members then borrows the pooled structure instead of trusting spurious
        # correlations of its own sample covariance. The floor is ``prior_scale`` times each
        # weight's variance within the clusters, not over all demonstrations: the spread between
        # patterns is no part of any one component's variability, and a floor that contains it
        # blurs every component by the distance between them (with K = 1 both are the same).
        # With missing data ('em') the starting weights are unreliable where a demonstration
        # has gaps, so the target is the diagonal floor alone.
        w_var = np.maximum(W.var(axis=0), 1e-12)
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
        self.alpha_prior_var_ = float(max(np.mean(a_within ** 2), data.timing.mean(),
                                          (1e-6 * alphas.mean()) ** 2))
        self._stats = None
        if self.method == 'em':
            st = data.stats
            self._stats = [ObservationStats(st.G[i], st.b[i], st.yy[i], st.m[i])
                           for i in range(n)]
        return np.eye(K)[init], fixed_noise

    def _m_step(self, data: Prepared, resp, post_means, post_covs, fixed_noise, previous=None):
        """Eqs. 8-10 (with the latent weights' posterior covariances under 'em', eqs. 27-30),
        the phase-speed priors and the noise: the parameters (weights, means, covariances,
        alpha means, alpha variances, n_k, noise variances) of these responsibilities."""
        weights, means, covs = gmm_maximization(post_means, resp, self.prior_cov_,
                                                self.prior_strength, post_covs)
        a_mean, a_var, nk = alpha_m_step(data.alphas, resp, self.alpha_prior_var_,
                                         self.prior_strength)
        if fixed_noise is not None:
            noise = fixed_noise
        elif previous is None or self.method == 'regression':
            # Regression fits keep the first noise until the end (:meth:`_finish`).
            noise = (noise_m_step(data.sq, data.stats.m, resp, self.noise == 'tied') if previous is None
                     else previous[6])
        else:
            stats = self._stats
            sq_k = np.einsum('ik,ikj->ij' if self.noise == 'tied' else 'ik,ikj->ikj', resp,
                             np.array([[expected_sq_residual(stats[i], post_means[i, k],
                                                             post_covs[i, k])
                                        for k in range(len(weights))]
                                       for i in range(len(stats))]))
            noise = noise_m_step(sq_k, data.stats.m, resp, self.noise == 'tied')
        return weights, means, covs, a_mean, a_var, nk, noise

    def _e_step(self, data: Prepared, params, resp, labels):
        """Eq. 7 (with each demonstration's marginal likelihood under 'em', eq. 21): the new
        responsibilities (the labels' under a supervised fit), the penalised log-likelihood
        and the weights' posterior means and covariances (the point weights under
        'regression')."""
        weights, means, covs, a_mean, a_var, _, noise = params
        lp_alpha = alpha_log_density(data.alphas, a_mean, a_var)
        chols = [linalg.cho_factor(c, lower=True, check_finite=False) for c in covs]
        new_resp = resp
        if self.method == 'regression':
            lp, maha = _gmm_log_prob(data.W, weights, means, chols)
            lp += lp_alpha                                                         # eq. 7
            if labels is None:
                norm = logsumexp_rows(lp)
                new_resp, ll = np.exp(lp - norm[:, None]), float(norm.sum())
            else:
                ll = float(np.sum(resp * lp))
            post_means, post_covs = data.W, None
            ll += covariance_penalty_of_m_step(chols, resp, maha, data.W.shape[1],
                                                self.prior_strength)
        else:
            new_resp, ll, post_means, post_covs = latent_e_step(
                self._stats, weights, means, covs, noise, lp_alpha,
                resp if labels is not None else None)
            ll += sum(covariance_penalty(c, self.prior_cov_, self.prior_strength)
                      for c in chols)
        ll += alpha_penalty(a_var, self.alpha_prior_var_, self.prior_strength)
        return new_resp, ll, post_means, post_covs

    def _finish(self, data: Prepared, resp, params, fixed_noise):
        """The fitted attributes from EM's last parameters and responsibilities."""
        weights, means, covs, a_mean, a_var, nk, noise = params
        if self.method == 'regression' and fixed_noise is None:
            noise = noise_m_step(data.sq, data.stats.m, resp, self.noise == 'tied')
        self.sample_period_ = float(np.median(data.periods))
        self.noise_time_ = correlation_time(data.acov[:, 0].sum(axis=0),
                                            data.acov[:, 1].sum(axis=0), self.sample_period_)
        self.n_iter_ = len(self.log_likelihood_)
        self.smoothing_ = data.smoothing
        self.weights_, self.means_, self.covariances_ = weights, means, covs
        self.resp_ = resp
        self.noise_var_ = noise
        self.alpha_mean_ = a_mean
        self.alpha_var_ = a_var
        timing = data.timing
        timing_k = np.where(nk > 1e-12, resp.T @ timing / np.maximum(nk, 1e-12), timing.mean())
        self.alpha_std_ = alpha_prior_std(a_var, nk, timing_k)
        self.warp_mean_ = self.warp_sd_ = None       # the linear phase until fit_warps
        self.warp_failed_ = []
        del self._stats

    def _check_params(self):
        if int(self.n_components) != self.n_components or self.n_components < 1:
            raise ValueError(f'n_components must be a positive integer, got '
                             f'{self.n_components!r}')
        if self.method not in ('regression', 'em'):
            raise ValueError(f"method must be 'regression' or 'em', got {self.method!r}")
        try:
            groups = translation_groups(self.translation, 1 << 30)
        except (TypeError, ValueError):
            raise ValueError(f'translation must be disjoint groups of DOF indices, got '
                             f'{self.translation!r}') from None
        if groups and self.method != 'regression':
            raise ValueError("translation is available with method='regression' only")
        if self.smoothing is not None:
            if self.method != 'regression':
                raise ValueError("smoothing is for method='regression' (EM starts from eq. 14's "
                                 'ridge weights and learns the rest)')
            lam = np.asarray(self.smoothing, dtype=float)
            if lam.ndim > 1 or not np.all(np.isfinite(lam) & (lam >= 0)):
                raise ValueError(f'smoothing must be None, a number or one number per DOF, '
                                 f'each >= 0, got {self.smoothing!r}')
        if self.noise not in ('tied', 'per_component'):
            raise ValueError(f"noise must be 'tied' or 'per_component', got {self.noise!r}")
        on = np.asarray(self.observation_noise, dtype=float)
        if on.ndim > 1 or not np.all(np.isfinite(on) & (on >= 0)):
            raise ValueError('observation_noise must be a number or one number per observed DOF, '
                             f'each >= 0 (in the DOF\'s unit), got {self.observation_noise!r}')
        w = self.speed_weight
        if (isinstance(w, bool) or not isinstance(w, (int, float, np.integer, np.floating))
                or not 0.0 <= w <= 1.0):
            raise ValueError(f'speed_weight must be in [0, 1], got {self.speed_weight!r}')

    # ------------------------------------------------------------------ inference
    @property
    def observed_noise_var_(self):
        """Sigma_D of eq. 4 per observed DOF: the learned noise variance of eq. 15 plus the
        online sensor noise; (P,) when tied, (K, P) per component."""
        return self.noise_var_[..., :self.n_observed_] + np.square(self.observation_noise)

    def observed_noise_var_at(self, interval: float):
        """:attr:`observed_noise_var_` for observations at least ``interval`` s apart: the
        learned variance of each DOF times how many samples its residuals stay correlated over
        at that spacing (core.noise: 1 for white residuals), plus the online sensor noise."""
        P = self.n_observed_
        factor = noise_factor(self.noise_time_[:P], self.sample_period_, interval)
        return self.noise_var_[..., :P] * factor + np.square(self.observation_noise)

    def _observed_noise(self, k, interval=None):
        nv = (self.observed_noise_var_ if interval is None
              else self.observed_noise_var_at(interval))
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

    # ------------------------------------------------------------------ the phase that bends
    def fit_warps(self, demonstrations, min_interval: float = 0.05):
        """Learn each component's Gaussian over a monotone phase warp (the thesis's eq. 34,
        core.warp): each demonstration's observed agent at phase z = g(t / T; b), b its MAP
        under its most probable component (``resp_``), the Gaussian of each component learned
        from its members' warps by EM (core.warp.learn_warp_priors). ``demonstrations``: the
        ones the model was fitted to, in that order; each read at samples at least
        ``min_interval`` s apart (the online estimator's decimation: a warp is learned from
        the evidence it will be used on) and as far apart as its residuals stay correlated
        (:attr:`warp_spacing`). Fitted: ``warp_mean_``, ``warp_sd_``
        (K, core.warp.N_WARP) and ``warp_failed_``, the names (else indices) of the
        demonstrations whose fit did not converge (left out of the Gaussian). A model without
        them keeps the linear phase everywhere; with them, the component posterior once the
        movement's end is known (:meth:`warped_component_posterior`) aligns each recording to
        each component, where a pace that changes within the movement misplaces the linear
        phase. Returns self."""
        self._check_fitted()
        if not hasattr(self, 'resp_'):
            raise ValueError('fit_warps needs the responsibilities of a fit; a model read from '
                             'a file has none (fit it again)')
        demos = list(demonstrations)
        if len(demos) != len(self.resp_) or not all(isinstance(d, Demonstration) for d in demos):
            raise ValueError(f'fit_warps needs the {len(self.resp_)} Demonstrations the model '
                             f'was fitted to, got {len(demos)}')
        component = np.argmax(self.resp_, axis=1)
        interval = self._warp_interval(min_interval)
        priors = [self._observed_prior(k) for k in range(self.n_components)]
        evidences = [self._warp_evidence(k, *self._warp_reading(d, interval), interval,
                                         priors[k]) for d, k in zip(demos, component)]
        self.warp_mean_, self.warp_sd_, good = learn_warp_priors(evidences, component,
                                                                 self.n_components)
        self.warp_failed_ = [d.name if d.name else i for i, d in enumerate(demos)
                             if not good[i]]
        return self

    def warp_gains(self, demonstrations, min_interval: float = 0.05) -> np.ndarray:
        """How much better each demonstration's observed agent is predicted with a phase warp
        than at the linear phase (nats; positive: the warp predicts it better), for
        demonstrations held out from this model: log int p(D | k, b) N(b; 0, START_SD^2 I) db
        (Laplace, core.warp) - log p(D | k, b = 0), under k, its most probable component at the
        linear phase, read as :meth:`fit_warps` reads a recording. The warp at the Gaussian
        :meth:`fit_warps` starts from: the criterion needs no warps learned, and so no
        learning per fold. Training's held-out choice of the phase."""
        self._check_fitted()
        demos = list(demonstrations)
        if not all(isinstance(d, Demonstration) for d in demos):
            raise ValueError('warp_gains needs Demonstrations')
        interval = self._warp_interval(min_interval)
        priors = [self._observed_prior(k) for k in range(self.n_components)]
        start = np.zeros(N_WARP), np.full(N_WARP, START_SD)
        gains = np.zeros(len(demos))
        for i, d in enumerate(demos):
            reading = self._warp_reading(d, interval)
            evidences = [self._warp_evidence(k, *reading, interval, priors[k])
                         for k in range(self.n_components)]
            # A recording whose evidence or warp cannot be computed, or whose warp fit did not
            # converge, counts as no gain: it argues for neither phase.
            try:
                linear = np.array([f(start[0])[0] for f in evidences])
                k = int(np.argmax(np.log(self.weights_) + linear + alpha_log_density(
                    [1.0 / d.duration], self.alpha_mean_, self.alpha_std_ ** 2)[0]))
                b, converged = map_warp(evidences[k], *start, gradient=True)
                gain = laplace(evidences[k], b, *start)[0] - linear[k] if converged else 0.0
            except (ValueError, np.linalg.LinAlgError):
                gain = 0.0
            gains[i] = gain if np.isfinite(gain) else 0.0
        return gains

    @property
    def warp_spacing(self) -> float:
        """How far apart (s) the samples a warp is read from are: as far as the observed
        agent's residuals stay correlated, so that each is worth one observation at that
        spacing (core.noise); closer ones would count the same deviation many times and make
        every warp look certain."""
        self._check_fitted()
        return float(np.max(self.noise_time_[:self.n_observed_], initial=0.0))

    def _warp_interval(self, min_interval) -> float:
        """The spacing a recording's warp is read at: :attr:`warp_spacing`, at least
        ``min_interval`` (the estimator's decimation)."""
        try:
            interval = float(min_interval)
        except (TypeError, ValueError):
            interval = np.nan
        if not (np.isfinite(interval) and interval >= 0):
            raise ValueError(f'min_interval must be a number of seconds >= 0, got '
                             f'{min_interval!r}')
        return max(self.warp_spacing, interval)

    @staticmethod
    def _warp_reading(demo, interval):
        """(relative times, observed agent) of ``demo``'s samples with the observed agent seen,
        at least ``interval`` s apart, as the estimator absorbs them."""
        rows = np.flatnonzero(~np.isnan(demo.observed).all(axis=1))
        rows = rows[decimated_rows(demo.t[rows], interval)]
        return demo.phase[rows], demo.observed[rows]

    def _observed_prior(self, k):
        """Component k's Gaussian over the observed agent's weights as its warp evidence takes
        it: (mean, Cholesky factor, precision), computed once for all of k's recordings."""
        do = self.n_observed_ * self.n_basis
        chol = linalg.cho_factor(self.covariances_[k][:do, :do], lower=True)
        return self.means_[k][:do], chol, cho_inverse(chol)

    def _warp_evidence(self, k, u, Y_obs, interval, prior=None):
        """b -> (log p(D | k, b), its gradient): the observed agent at relative times ``u``
        sampled at least ``interval`` s apart (eq. 21), at phases z = g(u; b), under k's
        weights (``prior``: :meth:`_observed_prior`, None: made here). The gradient is
        the posterior expectation of the complete data's: d log p(D) / d psi_i = sum_j
        ((y_ij - psi_i^T m_j) m_j - S_j psi_i) / sigma_j^2 (m_j, S_j the posterior mean and
        covariance of DOF j's weights), through psi's derivative and dz / db (core.warp).
        The last b's answer is kept: Laplace's method asks again at the mode the optimiser
        ended on."""
        P, N = self.n_observed_, self.n_basis
        mean, chol, prec = self._observed_prior(k) if prior is None else prior
        noise = self._observed_noise(k, interval)
        Y = np.nan_to_num(Y_obs)
        seen = ~np.isnan(Y_obs)
        weight = seen / noise                                     # (m, P): 0 where missing
        at = WarpAt(u)
        last = [None, None]

        def evidence(b):
            if last[0] is not None and np.array_equal(b, last[0]):
                return last[1]
            z, dz = at(b)
            psi, dpsi = self.basis_.evaluate(z, order=1)
            m, S, ll = weight_posterior(feature_stats(psi, Y_obs), mean, chol, noise, prec)
            M = m.reshape(P, N)
            blocks = S.reshape(P, N, P, N)[np.arange(P), :, np.arange(P)]     # S_j, (P, N, N)
            dll = (((Y - psi @ M.T) * weight) @ M
                   - np.einsum('ij,jik->ik', weight, psi @ blocks))
            last[:] = np.array(b, dtype=float), (ll, dz.T @ np.einsum('in,in->i', dpsi, dll))
            return last[1]
        return evidence

    def warped_component_posterior(self, u, Y_obs, alpha=None, interval=None):
        """Eq. 11 with each component's own phase: observations Y_obs (m, P) of the observed
        agent at relative times ``u`` = t / T (the movement's end known), at least ``interval``
        s apart (the noise of such samples, :meth:`observed_noise_var_at`; None: the
        recordings' own rate, as :meth:`component_posterior`), under component k at
        phase g(u; b), the warp integrated out under k's Gaussian over it (:meth:`fit_warps`)
        by Laplace's method at its MAP b_k (core.warp.laplace): p(k | D) ~ p(k) int p(D | k, b)
        p(b | k) db, with ``alpha`` = 1/T also p(alpha | k). Returns (p(k | D) (K,),
        b (K, N_WARP)). A component whose evidence cannot be computed at its mode (a
        numerical failure) gets probability 0; if every one does, ValueError."""
        self._check_fitted()
        if self.warp_mean_ is None:
            raise ValueError('the model has no phase warp: fit_warps first')
        u, Y_obs = _validate_observation(u, Y_obs, self.n_observed_)
        lp, b = np.log(self.weights_), np.empty((self.n_components, N_WARP))
        for k in range(self.n_components):
            evidence = self._warp_evidence(k, u, Y_obs, interval)
            prior = self.warp_mean_[k], self.warp_sd_[k]
            b[k] = map_warp(evidence, *prior, gradient=True)[0]
            try:
                lp[k] += laplace(evidence, b[k], *prior)[0]
            except (ValueError, np.linalg.LinAlgError):
                lp[k] = -np.inf
        lp[~np.isfinite(lp)] = -np.inf
        if not np.isfinite(lp).any():
            raise ValueError('no component can explain these observations at any warp')
        if alpha is not None:
            lp += alpha_log_density([alpha], self.alpha_mean_, self.alpha_std_ ** 2)[0]
        return np.exp(lp - logsumexp(lp)), b

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
        return self.score_statistics(stack_stats(stats),
                                 np.array([1.0 / demo.duration for demo in demos]))

    def score_statistics(self, stats: ObservationStats, alphas):
        """:meth:`score_demonstrations` of stacked statistics and their alpha = 1/T."""
        noise = np.broadcast_to(self.noise_var_, (self.n_components, self.noise_var_.shape[-1]))
        lp = np.log(self.weights_) + alpha_log_density(alphas, self.alpha_mean_,
                                                       self.alpha_std_ ** 2)
        for k in range(self.n_components):
            lp[:, k] += log_evidence(stats, self.means_[k], self.covariances_[k], noise[k])
        return logsumexp_rows(lp)

    # --------------------------------------------------------- weight vectors (eqs. 6-7)
    def demonstration_weights(self, demonstrations):
        """The weight vectors that ``fit`` clusters (:meth:`_weights` with the fitted smoothing),
        stacked [observed, controlled]; shape (n, (P+Q) N). Needs every DOF observed."""
        self._check_fitted()
        stats = []
        for demo in demonstrations:
            st = observation_stats(self.basis_, demo.phase,
                                   np.hstack([demo.observed, demo.controlled]))
            if np.any(st.m < 1):
                raise ValueError(f'demonstration {demo.name!r} has a DOF never observed')
            stats.append(st)
        return self._weights(stack_stats(stats), getattr(self, 'smoothing_', None))

    def _weights(self, stats: ObservationStats, smoothing):
        """Each demonstration's weights (n, D N) from stacked statistics: eq. 14 with the
        curvature penalty ``smoothing`` (core.promp.penalised_weights), or, without one (EM's
        start, a model file without a recorded smoothing), eq. 14 with the ridge alone."""
        if smoothing is None:
            return penalised_weights(stats, 0.0, start_ridge(self.ridge, self.method))
        return penalised_weights(stats, smoothing, self.ridge)

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

