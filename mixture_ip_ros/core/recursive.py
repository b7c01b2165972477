"""The recursive posterior of the online estimator (core.online): p(k, alpha_m | D) over
mixture components k and a grid of phase speeds alpha_m, updated per observation.

Each hypothesis (k, alpha_m) keeps the Gaussian over the observed agent's weights given D and
its log evidence log p(D | k, alpha_m) (eqs. 17-18), updated in Kalman form in O(P d^2) per
observation (core._fast: hypotheses in groups of SIMD lanes, covariances as packed lower
triangles). The basis rows psi(alpha_m t) are computed once per alpha and shared by every
component.
"""

import numpy as np

from ._fast import (LANES, compact_lanes, from_lanes, kalman_update, lane_array, to_lanes,
                    tri_index)
from .checks import checked_switch_rate
from .noise import decimated_rows, spaced
from .numerics import logsumexp, logsumexp_rows
from .phase import alpha_grid, alpha_log_prior, tempered_speed_posterior, tempered_speed_weights
from .switching import ChangeOfMind, ChangePoints


class RecursivePosterior(ChangeOfMind):
    """Recursive p(k, alpha | D) for a fitted :class:`MixtureIProMP` (any layout: P >= 1
    observed DOFs, Q >= 0 controlled); core.online.OnlineEstimator adds what it predicts.

    Decimation: ``min_interval`` (s). An observation closer in time than this to the last one
    used is not absorbed: :meth:`update` returns False for it and counts it in ``n_skipped``;
    it still advances the time the phase refers to (:meth:`phase` without an argument is the
    phase at the latest time offered, used or not). Consecutive motion-capture samples are
    strongly correlated (the residual between a person's path and the model is smooth), so
    feeding every sample as independent evidence makes the posterior overconfident.
    ``min_interval=0`` uses every sample.

    ``prune_below``: after each update (and at each :meth:`prune`), hypotheses whose posterior
    probability is below this are dropped and no longer updated (0: none is, the posterior is
    exact). The ones kept are exact: their log evidence and posterior weights are those of
    eqs. 17-18 given every observation absorbed; the posterior is renormalised over them.
    ``pruned_mass`` sums the probabilities of the dropped ones when they were dropped (each
    below ``prune_below``). A dropped hypothesis is not revived, so this bounds the mass
    dropped at each pruning, not what later evidence could have given it. ``absorb`` does not
    prune, so samples absorbed in any order and then pruned give one result. It must be below
    1 / (K M), so that the most probable hypothesis is kept.

    Phase speed: the component posterior p(k | D) is eq. 11 with the phase marginalised, exact;
    the phase speed of a component is read from its tempered posterior
    p(alpha | D, k) ~ p(D | k, alpha)^eta p(alpha | k), eta the model's ``speed_weight``
    (core.phase.tempered_speed_posterior; 1 gives eq. 16): the MAP alpha, the phase and the
    plans follow it. Pruning keeps a hypothesis while its exact joint posterior or its share of
    the tempered one, p(k | D) p_eta(alpha | D, k), is at least ``prune_below``.

    The samples absorbed are kept (time and position, in the order absorbed), so that a
    hypothesis the grid does not hold can be evaluated exactly when asked
    (OnlineEstimator.posterior_at, OnlineEstimator.end_posterior).

    Changes of mind: ``switch_rate`` (departures per second; None: the model's ``switch_rate``,
    which training calibrates) lets the person turn to another pattern at any time
    (core.switching, whose ChangeOfMind part this class is): p(k | D) is the change points'
    belief, and each component's phase speed is read from its hypotheses since the onset as
    above. With rate 0 it is eq. 11. The change points take the samples in time order; one
    absorbed before a later one already in (the planner's backlog) goes to the hypotheses since
    the onset only. A component pruned whole holds no belief (it has no phase speeds left).
    """

    def __init__(self, model, n_alpha: int, min_interval: float, alpha_range_std: float,
                 prune_below: float, switch_rate: float = None):
        model._check_fitted()
        self.model = model
        self.min_interval = float(min_interval)
        K, N, P = model.n_components, model.n_basis, model.n_observed_
        self.n_components, self.n_basis, self.n_observed = K, N, P
        do = P * N
        self.alphas = alpha_grid(model.alpha_mean_, model.alpha_std_, n_alpha, alpha_range_std)
        M = len(self.alphas)
        self._phase0 = np.zeros(M)
        self._log_prior = (np.log(model.weights_)[:, None]
                           + alpha_log_prior(self.alphas, model.alpha_mean_, model.alpha_std_)
                           ).ravel()
        if not 0.0 <= prune_below < 1.0 / (K * M):
            raise ValueError(f'prune_below must be in [0, 1/(K M) = {1.0 / (K * M):.3g}), '
                             f'got {prune_below}')
        self.prune_below = float(prune_below)
        self.speed_weight = float(model.speed_weight)
        self.switch_rate = checked_switch_rate(
            getattr(model, 'switch_rate', 0.0) if switch_rate is None else switch_rate)
        # Column c of the state is hypothesis (k, m) = divmod(c, M) until pruning reorders them;
        # the columns are padded to whole lane groups with copies of column 0 (never read).
        self._tri = tri_index(do)
        lower = np.tril_indices(do)
        self._hyp0 = np.r_[np.arange(K * M), np.zeros(-(K * M) % LANES, dtype=int)]
        self._cov0 = to_lanes(np.repeat(model.covariances_[:, lower[0], lower[1]], M, 0)
                               [self._hyp0])
        self._mu0 = to_lanes(np.repeat(model.means_[:, :do], M, 0)[self._hyp0])
        # Observation noise per column: tied (P,) or per component (K, P).
        # Samples at least min_interval apart, each worth what its residual's correlation
        # leaves of it (core.noise).
        noise = np.broadcast_to(np.asarray(model.observed_noise_var_at(self.min_interval),
                                           dtype=float), (K, model.n_observed_))
        self._noise0 = to_lanes(np.repeat(noise, M, 0)[self._hyp0])
        self._changes = (ChangePoints(model, noise, self.switch_rate)
                         if self.switch_rate > 0.0 else None)
        self._noise_k = noise
        self._others = []       # change points of other rates (compare_rates)
        self._cov, self._mu, self._noise = (lane_array(a.shape) for a in
                                            (self._cov0, self._mu0, self._noise0))
        self.reset()

    def reset(self):
        """Forget every observation: a new interaction starts (t = 0 at its onset)."""
        # Into the same buffers: an evaluation resets once per recording, and a fresh state
        # each time would cost its page faults again.
        np.copyto(self._cov, self._cov0)
        np.copyto(self._mu, self._mu0)
        np.copyto(self._noise, self._noise0)
        self._hyp = self._hyp0.copy()                       # hypothesis held in each column
        self._loglik = np.zeros(len(self._hyp))
        self._alpha_index = self._hyp % len(self.alphas)    # phase speed of each column
        self._prior = self._log_prior[self._hyp]            # log prior of each column
        self._col = np.arange(len(self._log_prior))         # column of each one, -1: pruned
        self.n_tracked = len(self._col)                     # columns still updated
        self.pruned_mass = 0.0
        self.n_observations = 0
        self.n_skipped = 0
        self._times = []        # the samples absorbed, in the order absorbed
        self._values = []
        self.t_last = None      # time of the last observation used
        self.t_seen = None      # time of the last observation offered (used or skipped)
        self._joint = None      # p(k, alpha_m | D), computed with each update
        self._t_chain = 0.0     # the latest sample's time the change points have seen
        self._marginals = None  # log p(D) after each sample of the latest offer_many
        for changes in self._chains():
            changes.reset()
        self._smallest = 0.0    # smallest p(k, alpha_m | D) of a tracked hypothesis (0: unknown)

    def update(self, t: float, y) -> bool:
        """Add the observed agent's position ``y`` (P,) at ``t`` seconds after onset.

        Returns False when the sample is within ``min_interval`` of the last one used (then
        only ``n_skipped`` and the phase's time advance). Raises ValueError for non-finite or
        misshaped input or time going back.
        """
        y = self._checked(y)
        if not self.admit(t):
            return False
        self._use(t, y)
        return True

    def offer(self, t: float, y) -> bool:
        """:meth:`update` for a recording played back: ``y`` is checked only once the sample is
        admitted. Most samples of a recording come within ``min_interval`` of the last one used
        and are only counted as skipped, and the evaluations and training's calibrations play
        hundreds of recordings."""
        if not self.admit(t):
            return False
        self._use(t, self._checked(y))
        return True

    def _use(self, t, y):
        self._absorb(t, y)
        if self.prune_below > 0.0:
            self.prune()

    def admit(self, t: float) -> bool:
        """Whether an observation at ``t`` is used: times increase and, after the first, are
        at least ``min_interval`` apart. An admitted time becomes the last one; absorb it (now
        or later) with :meth:`absorb`. Raises ValueError for a non-finite, negative or earlier t.
        """
        if not np.isfinite(t):
            raise ValueError('observation time is NaN or Inf')
        t = float(t)        # float32 stamps decimated as offer_many decimates them
        if t < 0:
            raise ValueError(f'time {t} is before the onset (t must be >= 0)')
        if self.t_last is not None:
            if t <= self.t_last:
                raise ValueError(f'time must increase: {t} after {self.t_last}')
            if not spaced(t, self.t_last, self.min_interval):
                self.n_skipped += 1
                self.t_seen = max(float(t), self.t_seen)
                return False
        self.t_last = float(t)
        self.t_seen = float(t) if self.t_seen is None else max(float(t), self.t_seen)
        return True

    def absorb(self, t: float, y) -> None:
        """Condition every hypothesis on ``y`` observed at ``t`` (eqs. 17-18, recursive).

        In any order: the weights do not change over the movement, so the posterior and the
        evidence after a set of observations do not depend on the order they were absorbed in
        (the planner absorbs the samples held before an onset while live ones come in); with
        changes of mind, a sample before one already in speaks for the hypotheses since the
        onset only (the class docstring). It does not prune: call :meth:`prune` once the samples
        held are in.
        """
        y = self._checked(y)
        if not (np.isfinite(t) and t >= 0):
            raise ValueError(f'observation time must be finite and >= 0, got {t}')
        self._absorb(t, y)

    def _absorb(self, t, y):
        self._absorb_many(np.array([float(t)]), y[None])

    def _kalman(self, times, values) -> np.ndarray:
        # With changes of mind the joint posterior is the change points' (_set_joint, once
        # every segment has the samples): the kernel does not make eq. 16's.
        own = self._changes is None
        joint = np.empty(len(self._col) if own else 0)
        trace = np.empty((len(times), len(self._loglik)))
        basis = self.model.basis_
        smallest = kalman_update(self._cov, self._mu, self._loglik, self.n_tracked,
                                 self._alpha_index, self.alphas, self._phase0, times,
                                 basis.centers, basis.width, values, self._noise, self._prior,
                                 self._hyp, joint, trace)
        self.n_observations += len(times)
        self._times.extend(times.tolist())
        self._values.extend(np.array(values))   # copies: the caller may reuse its buffer
        if own:
            self._smallest = smallest
            self._joint = joint.reshape(self.n_components, -1)
            self._joint.flags.writeable = False
        return trace[:, :self.n_tracked]

    def offer_many(self, times, values) -> np.ndarray:
        """:meth:`offer` of each sample in turn, with the same result (and the same error at
        the same sample); returns :meth:`log_marginal` after each sample used (one per sample
        used). Without pruning nothing is read between the samples: the ones admitted are
        absorbed in one pass (core._fast.kalman_update keeps each group of hypotheses in cache
        for all of them). A recording played back to a cut or to its end."""
        times = np.asarray(times, dtype=float)
        if len(values) != len(times):
            raise ValueError(f'{len(times)} times for {len(values)} samples')
        if self.prune_below > 0.0 or not self._ordered(times):
            return self._offer_each(times, values)
        # admit()'s decimation, on times checked above to be finite and increasing.
        picked = decimated_rows(times, self.min_interval, self.t_last)
        if not len(picked):
            self.n_skipped += len(times)
            self.t_seen = max(float(times[-1]), self.t_seen)
            return np.empty(0)
        try:        # only the samples used are read, as offer() reads them
            ys = np.array([values[i] for i in picked], dtype=float)
        except (ValueError, TypeError):
            ys = None
        if ys is None or ys.ndim != 2 or ys.shape[1] != self.n_observed or \
                not np.isfinite(ys).all():
            return self._offer_each(times, values)     # offer()'s error at offer()'s sample
        self.n_skipped += len(times) - len(picked)
        self.t_last = float(times[picked[-1]])
        self.t_seen = float(times[-1]) if self.t_seen is None else max(float(times[-1]),
                                                                      self.t_seen)
        trace = self._absorb_many(times[picked], ys)
        if self._changes is not None:
            return (np.array([self.log_marginal()]) if self._marginals is None
                    else self._marginals)
        return logsumexp_rows(self._prior[:self.n_tracked] + trace)   # log_marginal's sum

    def _offer_each(self, times, values) -> np.ndarray:
        return np.array([self.log_marginal() for t, y in zip(times, values)
                         if self.offer(t, y)])

    def _ordered(self, times) -> bool:
        """Whether ``times`` are finite, >= 0, increasing and after the last one used: what
        admit() would accept of each."""
        return (times.ndim == 1 and bool(np.isfinite(times).all()) and len(times) > 0
                and times[0] >= 0 and bool(np.all(np.diff(times) > 0))
                and (self.t_last is None or times[0] > self.t_last))

    def prune(self) -> int:
        """Drop the tracked hypotheses whose posterior is now below ``prune_below`` (update
        does this after each observation); returns how many. The posterior after absorbing a
        set of samples in any order and then pruning does not depend on that order.
        """
        if self._smallest >= self.prune_below:
            return 0
        hyp = self._hyp[:self.n_tracked]
        joint = self.joint_posterior().ravel().copy()
        share = np.maximum(joint, self._tempered_joint().ravel())
        keep = share[hyp] >= self.prune_below
        dropped = hyp[~keep]
        self.pruned_mass += float(joint[dropped].sum())
        joint[dropped] = 0.0
        joint /= joint.sum()
        self._joint = joint.reshape(self.n_components, -1)
        self._joint.flags.writeable = False
        self._smallest = share[hyp[keep]].min()
        n = int(keep.sum())
        src = np.flatnonzero(keep)
        compact_lanes(self._cov, src)
        compact_lanes(self._mu, src)
        compact_lanes(self._noise, src)
        for a in (self._loglik, self._hyp, self._alpha_index, self._prior):
            a[:n] = a[src]
        self._col[:] = -1
        self._col[self._hyp[:n]] = np.arange(n)
        self.n_tracked = n
        if self._changes is not None:
            self._set_joint()
        return len(dropped)

    def _tempered_joint(self):
        """p(k | D) p_eta(alpha_m | D, k), (K, M): each hypothesis's share of what the plans
        read (0 for a component with nothing tracked)."""
        if self.speed_weight == 1.0:
            return self.joint_posterior()
        M = len(self.alphas)
        lp = tempered_speed_posterior(self.log_evidence_flat.reshape(-1, M),
                                      self._log_prior.reshape(-1, M), self.speed_weight)
        return self.component_posterior()[:, None] * np.exp(lp)

    def _checked(self, y) -> np.ndarray:
        y = np.asarray(y, dtype=float)
        if y.shape != (self.n_observed,):
            raise ValueError(f'observation must have shape ({self.n_observed},), got {y.shape}')
        if not np.isfinite(y).all():
            raise ValueError('observation is NaN or Inf')
        return y

    # ------------------------------------------------------------------ queries
    @property
    def log_evidence_flat(self):
        """log p(D | k, alpha_m) of every hypothesis, flat (K M,); -inf where pruned."""
        out = np.full(len(self._col), -np.inf)
        n = self.n_tracked
        out[self._hyp[:n]] = self._loglik[:n]
        return out

    @property
    def log_evidence(self):
        """log p(D | k, alpha_m), shape (K, M) (read-only); -inf where pruned."""
        view = self.log_evidence_flat.reshape(self.n_components, -1)
        view.flags.writeable = False
        return view

    @property
    def log_prior(self):
        """log p(k) p(alpha_m | k) of every hypothesis, shape (K, M) (read-only)."""
        view = self._log_prior.reshape(self.n_components, -1)
        view.flags.writeable = False
        return view

    @property
    def mu(self):
        """Posterior means of the observed weights, (K M, d); NaN where pruned (a copy)."""
        d = self.n_observed * self.n_basis
        out = np.full((len(self._col), d), np.nan)
        n = self.n_tracked
        out[self._hyp[:n]] = from_lanes(self._mu)[:n]
        return out

    @property
    def sigma(self):
        """Posterior covariances of the observed weights, (K M, d, d); NaN where pruned (a
        copy)."""
        d = self.n_observed * self.n_basis
        out = np.full((len(self._col), d, d), np.nan)
        n = self.n_tracked
        out[self._hyp[:n]] = from_lanes(self._cov)[:n][:, self._tri]
        return out

    def joint_posterior(self):
        """p(k, alpha_m | D), shape (K, M) (read-only); 0 where pruned."""
        if self._joint is None:           # no observation yet: the prior
            p = np.exp(self._log_prior - self._log_prior.max())
            self._joint = (p / p.sum()).reshape(self.n_components, -1)
            self._joint.flags.writeable = False
        return self._joint

    def log_marginal(self) -> float:
        """log p(D) = log sum_(k, m) p(k, alpha_m) p(D | k, alpha_m) (eqs. 16-18): how well the
        model as a whole explains the observations (core.novelty). Over the tracked hypotheses:
        with pruning it is low by at most the log of 1 - ``pruned_mass``. With changes of mind,
        the change-point model's (core.switching): a change to another pattern is explained."""
        n = self.n_tracked
        onset = logsumexp(self._prior[:n] + self._loglik[:n])
        return onset if self._changes is None else self._changes.total(onset)

    def component_posterior(self):
        """p(k | D) (eq. 11 with the phase marginalised)."""
        return self.joint_posterior().sum(axis=1)

    def speed_posterior(self, component=None):
        """p_eta(alpha_m | D, k) of ``component`` k (k* if None) over the grid: the tempered
        posterior the phase speed is read from (see the class docstring), (M,)."""
        k = self._map_indices()[0] if component is None else int(component)
        return np.exp(self._speed_log_posterior(k))

    def speed_log_terms(self, k):
        """(log p(D | k, alpha_m), log p(k) p(alpha_m | k)) over the grid, each (M,): the terms
        of component k's tempered speed posterior for any weight eta
        (core.phase.tempered_speed_posterior). ValueError when every hypothesis of component k
        was pruned."""
        M = len(self.alphas)
        evidence = self.log_evidence_flat[k * M:(k + 1) * M]
        if np.isneginf(evidence).all():
            raise ValueError(f'every hypothesis of component {k} was pruned (posterior below '
                             f'prune_below={self.prune_below:g})')
        return evidence, self._log_prior[k * M:(k + 1) * M]

    def _speed_log_posterior(self, k):
        return tempered_speed_posterior(*self.speed_log_terms(k), self.speed_weight)

    def _speed_log_weights(self, k):
        """:meth:`_speed_log_posterior` before normalising (what an argmax or a ratio needs)."""
        return tempered_speed_weights(*self.speed_log_terms(k), self.speed_weight)

    def alpha_posterior(self):
        """p(alpha_m | D) = sum_k p(k | D) p_eta(alpha_m | D, k) (eq. 16 with the component
        marginalised, for eta = 1)."""
        pk = self.component_posterior()
        return sum(pk[k] * self.speed_posterior(k) for k in range(self.n_components)
                   if pk[k] > 0.0)

    def map_hypothesis(self):
        """(k*, alpha*): the most probable component (eq. 12) and, for it, the grid's MAP alpha
        of the tempered speed posterior (eq. 20 when the speed weight is 1)."""
        k, m = self._map_indices()
        return k, float(self.alphas[m])

    def _map_indices(self):
        k = int(np.argmax(self.component_posterior()))
        return k, self._map_alpha_index(k)

    def _map_alpha_index(self, k):
        return int(np.argmax(self._speed_log_weights(k)))

    def _hypothesis(self, component, alpha):
        """Indices (k, m) of ``component`` (k* if None) and of the grid alpha nearest ``alpha``
        (that component's MAP alpha if None)."""
        k = self._map_indices()[0] if component is None else int(component)
        if alpha is None:
            return k, self._map_alpha_index(k)
        return k, int(np.argmin(np.abs(self.alphas - alpha)))

    def phase(self, t=None):
        """Phase z = alpha* t under the MAP hypothesis, clamped to [0, 1], at ``t`` (s since
        onset; default: the latest observation offered, also when decimation skipped it)."""
        t = self.t_seen if t is None else t
        if t is None:
            return 0.0
        return float(np.clip(self.map_hypothesis()[1] * t, 0.0, 1.0))

    def refined_alpha(self, component=None) -> float:
        """Eq. 20 between grid values: the MAP alpha of ``component`` (k* if None), the vertex
        of the parabola through log p(alpha_m | D, k) at the grid's most probable value and its
        two neighbours (exact where the log posterior is quadratic in alpha, as it is near its
        peak; never more than half a grid step from the grid's MAP). The grid's own MAP at
        either end of the grid, where a neighbour was pruned, or before any observation.

        After part of a movement the posterior over alpha can be narrower than the grid step;
        the grid then limits the phase, and a finer grid costs every update, this nothing."""
        k = self._map_indices()[0] if component is None else int(component)
        m = self._map_alpha_index(k)
        a = self.alphas
        if not self._times or m == 0 or m == len(a) - 1:
            return float(a[m])
        # log p_eta(alpha_m | D, k) up to a constant, from the evidence (no underflow far out)
        lp = self._speed_log_weights(k)[m - 1:m + 2]
        if not np.all(np.isfinite(lp)):
            return float(a[m])
        curvature = lp[0] - 2.0 * lp[1] + lp[2]
        if curvature >= 0.0:                # flat: no peak between the neighbours
            return float(a[m])
        # grid steps are equal (np.linspace); the vertex lies within half a step of a[m]
        return float(a[m] + 0.5 * (lp[0] - lp[2]) / curvature * (a[m + 1] - a[m]))

    def observed_weights(self, k, m):
        """Posterior N(mean, cov) of the observed agent's weights under hypothesis (k, m).
        Raises ValueError if that hypothesis was pruned."""
        g, lane = self._lane(k, m)
        cov = self._cov[g].reshape(-1, LANES)[:, lane][self._tri]
        return self._observed_mean(k, m).copy(), cov

    def _observed_mean(self, k, m):
        """The posterior mean of the observed weights under hypothesis (k, m), a view of the
        kernel's state (no covariance built)."""
        g, lane = self._lane(k, m)
        return self._mu[g].reshape(-1, LANES)[:, lane]

    def _lane(self, k, m):
        """(group, lane) of hypothesis (k, m) in the kernel's state."""
        c = self._col[k * len(self.alphas) + m]
        if c < 0:
            raise ValueError(f'hypothesis (component {k}, alpha {self.alphas[m]:.4g}) was '
                             f'pruned (posterior below prune_below={self.prune_below:g})')
        return divmod(c, LANES)
