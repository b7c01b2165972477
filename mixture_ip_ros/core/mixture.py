"""Mixture of Interaction ProMPs (thesis 3.3): a Gaussian mixture over stacked human-robot
weights learned by EM (eqs. 6-10) from the patterns found in the metric of paths
(core.patterns). The estimator in scikit-learn's shape: ``fit`` is a short loop of named
steps (``_initialize``, ``_e_step``, ``_m_step``) whose maths are core.gmm's pure functions;
how many components and how much covariance floor is core.selection's. What the fitted
mixture says with the phase known (component posterior, eqs. 11-12, and conditioning of the
most probable component, eq. 13) is its base core.inference.PhaseKnownInference; each
component's phase warp is core.warped's. Labels for every demonstration, or for some (None for
the others), fix the named ones' responsibilities: the supervised mixture, or semi-supervised EM
from the patterns found with the names held (core.named).

``method='em'`` learns the mixture from partially observed demonstrations (chapter 5 future
work): the weights of every demonstration are latent as in 4.2.1, so E-step responsibilities
use each demonstration's marginal likelihood p(D_i | k) and the M step adds the weight
posterior covariances (eqs. 27-30 per component).
"""

from typing import NamedTuple

import numpy as np
from scipy import linalg

from .basis import GaussianBasis
from .checks import (checked_demonstrations, checked_switch_rate, label_indices, labelling,
                     named_indices)
from .gmm import (_gmm_log_prob, covariance_penalty_of_m_step, covariance_prior,
                  gmm_maximization, latent_e_step, noise_m_step)
from .inference import PhaseKnownInference
from .named import named_patterns
from .numerics import logsumexp_rows
from .noise import MAX_LAG_S, correlation_time, residual_autocovariance
from .pattern_space import PatternSpace
from .patterns import PatternMixture, offset_operators, translation_groups
from .phase import (alpha_log_density, alpha_m_step, alpha_penalty, alpha_prior_std,
                    timing_variance)
from .promp import (ObservationStats, covariance_penalty, expected_sq_residual,
                    empirical_bayes_smoothing, observation_stats, penalised_weights, stack_stats,
                    start_ridge)


class Prepared(NamedTuple):
    """What a fit needs of each demonstration on its own, whatever the other demonstrations it
    is fitted with (:meth:`MixtureIProMP.prepare`): the observation statistics (stacked,
    promp.stack_stats), the weights W (n, d) (:meth:`MixtureIProMP._weights`: eq. 14 smoothed
    as the set's recordings are, the smoothing chosen on every demonstration prepared, held-out
    folds included: one unsupervised number per DOF that the folds share), the squared
    residuals at them (n, D), alpha = 1/T and the timing variance (n,), the residuals'
    autocovariances and sample periods (core.noise). Cross-validation computes them once, and
    every fold and K takes its demonstrations from them (:meth:`take`)."""

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


class EMParams(NamedTuple):
    """The parameters of one EM iteration (:meth:`MixtureIProMP._m_step`)."""

    weights: np.ndarray     # (K,) component weights (eq. 8)
    means: np.ndarray       # (K, d) eq. 9
    covs: np.ndarray        # (K, d, d) eq. 10 with the conjugate prior
    alpha_mean: np.ndarray  # (K,) mean of the phase speed alpha = 1/T per component
    alpha_var: np.ndarray   # (K,) its variance
    nk: np.ndarray          # (K,) the responsibilities' sums
    noise: np.ndarray       # noise variances of eq. 15: (D,) tied, (K, D) per component


class MixtureIProMP(PhaseKnownInference):
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
    (penalised, monotone), ``resp_`` (n, K), ``classes_`` (the name of each component where
    labels were given, None for a component no label names; else None), ``warps_`` the phase
    warps (core.warped.PhaseWarps; None: the linear phase).

    ``prior_strength`` pseudo-samples of a shared covariance ``prior_cov_`` regularise every
    component covariance (conjugate prior, so EM stays monotone in the penalised likelihood):
    core.gmm.covariance_prior of the initial clusters (:meth:`initial_clusters`, or the labels
    of a supervised fit) with a floor of ``prior_scale``. Every component shrinks towards the
    same target with the same strength, so their likelihoods stay comparable; this keeps every
    component positive definite with fewer members than weights. Training calibrates the floor
    on held-out folds (core.selection.calibrated_heldout_curves).

    Noise: ``noise='tied'`` (default) learns one variance per DOF shared by all components
    (pooled residuals), so components are compared on the same noise floor; 'per_component'
    learns one per component and DOF. ``noise_var`` (per DOF, or a scalar) fixes the noise
    instead of learning it: separately fitted models (one per class) given the same
    ``noise_var`` share the noise model. ``observation_noise`` (per observed DOF or a scalar, in
    the DOF's unit) is extra sensor noise of the online stream, added to the learned variance
    when conditioning on new observations (none by default).

    ``speed_weight`` (eta in [0, 1]) is how much the online phase-speed posterior trusts the
    observations: p(alpha | D, k) proportional to p(D | k, alpha)^eta p(alpha | k) (eta = 1:
    eqs. 16-18; core.phase.tempered_speed_posterior): people speed up and slow down within
    one movement, so the speed that explains a prefix says less about the rest than eq. 16
    claims. Fitting does not use it; training calibrates it on held-out demonstrations
    (core.calibration.speed_log_scores).

    ``switch_rate`` (switches per second, >= 0) is how readily the online belief lets a person
    change their mind mid-movement (core.switching; 0: never, eq. 11). Fitting does not use it;
    training calibrates it on held-out demonstrations spliced into changes of mind
    (core.calibration.calibrated_switch_rate).

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
                 speed_weight: float = 1.0, translation=(), smoothing=None,
                 switch_rate: float = 0.0):
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
        self.switch_rate = switch_rate

    # ------------------------------------------------------------------ learning
    def fit(self, demonstrations, labels=None, init=None):
        """Learn the mixture from ``demonstrations`` (a list of Demonstrations, or what
        :meth:`prepare` made of them): unlabeled, EM (eqs. 7-10) from the patterns found in
        the metric of their paths (:meth:`initial_clusters`, or ``init``, one component index
        per demonstration).

        ``labels`` (n,), optional: a supervised fit with one component per distinct label
        (sorted; ``n_components`` must equal their number) and the responsibilities fixed to
        the labels, i.e. one Interaction ProMP per class sharing the noise model and the
        covariance prior. ``classes_`` then names the components. With None for the
        demonstrations that have no label, semi-supervised EM: one component per distinct
        label (sorted, the first ones; ``n_components`` at least their number), a named
        demonstration's responsibilities fixed to its label's, the others' learned, from
        :meth:`named_start` (or ``init``, the names overriding it); ``classes_`` names the
        components, None for the components no label names. Every label None is no label.
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
        resp, fixed_noise, fixed = self._initialize(data, labels, init)
        params = self._m_step(data, resp, data.W, None, fixed_noise)
        self.log_likelihood_ = []
        self.converged_ = False
        previous = -np.inf
        for it in range(self.max_iter):
            new_resp, ll, post_means, post_covs = self._e_step(data, params, resp, fixed)
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
        demos = checked_demonstrations(demonstrations)
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
        """EM's start (eq. 7's r_ik): the demonstrations' patterns, found from their
        time-warped paths (core.pattern_space: a t mixture of core.patterns in a few
        coordinates), each demonstration in its most probable one."""
        return np.argmax(self._pattern_mixture(self._pattern_coordinates(data)).resp_, axis=1)

    def _pattern_coordinates(self, data: Prepared):
        space = PatternSpace(self.n_basis, data.n_observed, min_components=self.n_components - 1,
                             translation=self.translation)
        return space.fit_transform(data.W)

    def _pattern_mixture(self, X, resp=None, fixed=None):
        return PatternMixture(self.n_components, self.prior_strength, n_init=self.n_init,
                              random_state=self.random_state).fit(X, resp, fixed)

    def named_start(self, data: Prepared, index, n_names: int):
        """EM's start where some demonstrations are named (``index`` (n,): each one's name
        0..n_names-1, -1 where it has none): the patterns found as :meth:`initial_clusters`
        finds them, with the named demonstrations held in their names' patterns
        (core.named.named_patterns); without a name, :meth:`initial_clusters`."""
        X = self._pattern_coordinates(data)
        clusters = np.argmax(self._pattern_mixture(X).resp_, axis=1)
        if n_names == 0:
            return clusters
        return named_patterns(X, clusters, index, n_names, self.n_components,
                              lambda resp, fixed: self._pattern_mixture(X, resp, fixed))

    def _initialize(self, data: Prepared, labels, init):
        """The fitted attributes known before EM, the starting responsibilities (labels, the
        given ``init`` or :meth:`initial_clusters`; with some demonstrations named,
        :meth:`named_start`) and the covariance priors they define; returns (responsibilities
        (n, K), the fixed noise variances or None, which demonstrations' responsibilities
        stay as they start (n,) bool, or None for none)."""
        n, K = len(data.W), self.n_components
        self.basis_ = GaussianBasis(self.n_basis)
        self.n_observed_ = data.n_observed
        D = data.sq.shape[1]
        self.n_controlled_ = D - data.n_observed
        fixed_noise = None
        if self.noise_var is not None:
            fixed_noise = np.broadcast_to(np.asarray(self.noise_var, dtype=float), (D,)).copy()
            if not np.all(np.isfinite(fixed_noise) & (fixed_noise > 0)):
                raise ValueError(f'noise_var must be positive and finite, got {self.noise_var!r}')
        alphas = data.alphas
        fixed = None
        if labels is None:
            self.classes_ = None
            init = self.initial_clusters(data) if init is None else np.asarray(init)
        elif labelling(labels) == 'all':
            self.classes_, init = label_indices(labels, n, K)
            fixed = np.ones(n, dtype=bool)
        else:
            # Some named, or none: one EM for both, which is the unlabelled fit where no
            # demonstration is named and the supervised one where every one is.
            names, index = named_indices(labels, n, K)
            self.classes_ = names + [None] * (K - len(names)) if names else None
            fixed = index >= 0
            init = (self.named_start(data, index, len(names)) if init is None
                    else np.where(fixed, index, np.asarray(init)))
        # A component is a joint p(w, alpha | k) = p(w | k) p(alpha | k) over shape and phase
        # speed alpha = 1/T (eq. 17's independence of w and alpha within a pattern): patterns
        # that differ in speed are told apart by it, and p(alpha | k) is the online prior.
        # With missing data ('em') the starting weights are unreliable where a demonstration
        # has gaps, so the weights' prior is the diagonal floor alone.
        self.prior_cov_ = covariance_prior(data.W, init, K, self.prior_scale,
                                           pooled=self.method == 'regression')
        # The alpha prior's variance: the within-cluster variance pooled over the initial
        # clusters, at least what the sampling leaves (timing).
        a_within = alphas - np.array([alphas[init == k].mean() if np.any(init == k)
                                      else alphas.mean() for k in range(K)])[init]
        self.alpha_prior_var_ = float(max(np.mean(a_within ** 2), data.timing.mean(),
                                          (1e-6 * alphas.mean()) ** 2))
        self._stats = None
        if self.method == 'em':
            st = data.stats
            self._stats = [ObservationStats(st.G[i], st.b[i], st.yy[i], st.m[i])
                           for i in range(n)]
        return np.eye(K)[init], fixed_noise, fixed

    def _m_step(self, data: Prepared, resp, post_means, post_covs, fixed_noise,
                previous: EMParams = None) -> EMParams:
        """Eqs. 8-10 (with the latent weights' posterior covariances under 'em', eqs. 27-30),
        the phase-speed priors and the noise: the parameters of these responsibilities."""
        weights, means, covs = gmm_maximization(post_means, resp, self.prior_cov_,
                                                self.prior_strength, post_covs)
        a_mean, a_var, nk = alpha_m_step(data.alphas, resp, self.alpha_prior_var_,
                                         self.prior_strength)
        if fixed_noise is not None:
            noise = fixed_noise
        elif previous is None or self.method == 'regression':
            # Regression fits keep the first noise until the end (:meth:`_finish`).
            noise = (noise_m_step(data.sq, data.stats.m, resp, self.noise == 'tied')
                     if previous is None else previous.noise)
        else:
            stats = self._stats
            sq_k = np.einsum('ik,ikj->ij' if self.noise == 'tied' else 'ik,ikj->ikj', resp,
                             np.array([[expected_sq_residual(stats[i], post_means[i, k],
                                                             post_covs[i, k])
                                        for k in range(len(weights))]
                                       for i in range(len(stats))]))
            noise = noise_m_step(sq_k, data.stats.m, resp, self.noise == 'tied')
        return EMParams(weights, means, covs, a_mean, a_var, nk, noise)

    def _e_step(self, data: Prepared, params: EMParams, resp, fixed):
        """Eq. 7 (with each demonstration's marginal likelihood under 'em', eq. 21): the new
        responsibilities (a named demonstration's, ``fixed``, stay its name's), the penalised
        log-likelihood and the weights' posterior means and covariances (the point weights
        under 'regression'). With some demonstrations named the likelihood is that of EM with
        their components observed: log p(w_i, k_i) for a named one, log p(w_i) for the others,
        which EM's steps never decrease, as without names."""
        lp_alpha = alpha_log_density(data.alphas, params.alpha_mean, params.alpha_var)
        chols = [linalg.cho_factor(c, lower=True, check_finite=False) for c in params.covs]
        new_resp = resp
        if self.method == 'regression':
            lp, maha = _gmm_log_prob(data.W, params.weights, params.means, chols)
            lp += lp_alpha                                                         # eq. 7
            if fixed is None:
                norm = logsumexp_rows(lp)
                new_resp, ll = np.exp(lp - norm[:, None]), float(norm.sum())
            else:
                free = ~fixed
                norm = logsumexp_rows(lp[free])
                new_resp = resp.copy()
                new_resp[free] = np.exp(lp[free] - norm[:, None])
                ll = float(np.sum(resp[fixed] * lp[fixed]) + norm.sum())
            post_means, post_covs = data.W, None
            ll += covariance_penalty_of_m_step(chols, resp, maha, data.W.shape[1],
                                                self.prior_strength)
        else:
            new_resp, ll, post_means, post_covs = latent_e_step(
                self._stats, params.weights, params.means, params.covs, params.noise,
                lp_alpha, fixed=None if fixed is None else (resp, fixed))
            ll += sum(covariance_penalty(c, self.prior_cov_, self.prior_strength)
                      for c in chols)
        ll += alpha_penalty(params.alpha_var, self.alpha_prior_var_, self.prior_strength)
        return new_resp, ll, post_means, post_covs

    def _finish(self, data: Prepared, resp, params: EMParams, fixed_noise):
        """The fitted attributes from EM's last parameters and responsibilities."""
        noise = params.noise
        if self.method == 'regression' and fixed_noise is None:
            noise = noise_m_step(data.sq, data.stats.m, resp, self.noise == 'tied')
        self.sample_period_ = float(np.median(data.periods))
        self.noise_time_ = correlation_time(data.acov[:, 0].sum(axis=0),
                                            data.acov[:, 1].sum(axis=0), self.sample_period_)
        self.n_iter_ = len(self.log_likelihood_)
        self.smoothing_ = data.smoothing
        self.weights_, self.means_, self.covariances_ = params.weights, params.means, params.covs
        self.resp_ = resp
        self.noise_var_ = noise
        self.alpha_mean_ = params.alpha_mean
        self.alpha_var_ = params.alpha_var
        timing, nk = data.timing, params.nk
        timing_k = np.where(nk > 1e-12, resp.T @ timing / np.maximum(nk, 1e-12), timing.mean())
        self.alpha_std_ = alpha_prior_std(params.alpha_var, nk, timing_k)
        self.warps_ = None              # the linear phase until core.warped.PhaseWarps is fitted
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
        checked_switch_rate(self.switch_rate)

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

    def _check_fitted(self):
        if not hasattr(self, 'means_'):
            raise RuntimeError('this MixtureIProMP is not fitted yet; call fit() first')
