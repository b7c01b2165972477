"""A person who may change their mind (the thesis's chapters 4 and 5): the belief over which
interaction pattern is under way when the person may depart from it at any time.

Departures are a Poisson process of ``rate`` per second (the model's switch rate, calibrated by
training). After one at tau the person follows a pattern from where they are in the movement:
the one believed (a disruption of the same movement: a hold, a hurry, an ending of its own),
or one drawn from the mixture weights p(k) (a change of mind), KEEP to 1 - KEEP. Its weights
are new, so only the samples from tau on speak for it; its phase goes on from the phase believed
at tau, z = z(tau) + alpha (t - tau), give or take SHIFT basis spacings, at a pace of its own
prior p(alpha | k) (PACES). This is the change-point posterior of Adams and MacKay (2007) over
segments: the segment since the onset (the estimator's own hypotheses (k, alpha_m),
core.recursive) and segments started at candidate times tau_r every SPACING s, each a filter
per component and phase line conditioned on the samples since tau_r (core._fast.kalman_update
on a bank of its own). A segment starts with log h + log p(D_<tau) + log p(pattern) + log p(line),
h = 1 - exp(-rate gap) the chance of a departure since the last candidate, and every segment
already there takes log(1 - h); each then gathers its evidence. At most MAX_SEGMENTS started
segments are kept (the least probable gives way when a new one starts), so an observation
costs a bounded number of filters.

The belief in component k sums its segments' masses. With rate 0 there is only the segment
since the onset, and the belief is eq. 11 with the phase marginalised.
"""

import numpy as np

from ._fast import LANES, kalman_update, lane_array, to_lanes
from ._fast_switching import grouped_logsumexp, switching_joint
from .numerics import logsumexp, logsumexp_rows

# Candidate change times this far apart (s): a change is dated to within this, and its
# detection waits for it. Shorter costs a filter bank start more often; a person's change of
# course takes some tenths of a second (a reach's correction).
SPACING = 0.2
# Started segments kept: the most probable change so far and the latest candidate, which
# either proves itself or gives way to the next one.
MAX_SEGMENTS = 2
# Phase speeds of a started segment: the medians of the thirds (1/6, 1/2, 5/6 quantiles) of
# its component's prior p(alpha | k) = N(m_k, s_k^2), each as probable: who turns to another
# movement takes it at a pace of that movement's.
PACES = (-0.9674, 0.0, 0.9674)
# Phases a started segment starts at: the phase believed at its start, and this many basis
# spacings either side. Within a basis spacing of the right phase a path is still explained
# (neighbouring basis functions overlap); the phase believed when a person changes their mind
# is off by more, as their pace within the movement was not the one believed.
SHIFT = 2.0
# The share of change points that keep the pattern believed (a disruption of the same
# movement: a hold, a hurry, an ending of its own) rather than draw one from p(k) (a change of
# mind): one departure from the path in ten is taken for a change of mind. A new pattern must
# then explain what follows its change better than the one believed does from a fresh start
# by log(KEEP / ((1 - KEEP) p(k))), a few nats: a handful of samples of a different path, and
# more than the end of a movement that several patterns share.
KEEP = 0.9
# A started column with less than this share of its component's belief is left out of what the
# component predicts (the onset's part takes it): its path would cost more than it adds.
SUPPORT = 1e-3


class ChangePoints:
    """The segments started since the onset and the belief they make with the segment since the
    onset (see the module docstring). ``model`` a fitted MixtureIProMP, ``noise`` the
    observation noise per component (K, P) at the estimator's decimation, ``rate`` > 0 the
    departures per second."""

    def __init__(self, model, noise, rate: float, spacing: float = SPACING,
                 max_segments: int = MAX_SEGMENTS, paces=PACES):
        K, N, P = model.n_components, model.n_basis, model.n_observed_
        do = P * N
        self.rate, self.spacing = float(rate), float(spacing)
        # phases at the start: the one believed, and SHIFT basis spacings either side
        step = SHIFT / (N - 1)
        self.shifts = np.repeat((-step, 0.0, step), len(paces))
        self.paces = np.tile(np.asarray(paces, dtype=float), 3)
        self.n_components, self.max_segments = K, int(max_segments)
        self._log_weights = np.log(model.weights_)
        A = len(self.paces)
        self.width = K * A                      # columns per segment: (k, pace)
        n = max_segments * self.width
        self._n = n
        lower = np.tril_indices(do)
        comp = np.tile(np.repeat(np.arange(K), A), max_segments)
        pad = np.r_[comp, np.zeros(-n % LANES, dtype=int)]
        self._component = comp
        # each column's own phase speed (k's quantiles, slot after slot) and phase at t = 0
        mean, std = np.asarray(model.alpha_mean_), np.asarray(model.alpha_std_)
        rates = np.maximum(mean[:, None] + std[:, None] * self.paces[None], 0.25 * mean[:, None])
        self._rates = np.r_[np.tile(rates.ravel(), max_segments), np.ones(-n % LANES)]
        self._phase0 = np.zeros(len(self._rates))
        self._cov0 = to_lanes(model.covariances_[:, lower[0], lower[1]][pad])
        self._mu0 = to_lanes(model.means_[:, :do][pad])
        self._cov, self._mu = lane_array(self._cov0.shape), lane_array(self._mu0.shape)
        self._noise = to_lanes(np.broadcast_to(np.asarray(noise, dtype=float), (K, P))[pad])
        self._loglik = np.zeros(len(pad))
        # each column its own phase function; no posterior over them from kalman_update (the
        # belief sums them with the segment since the onset's)
        self._alpha_index = self._columns = np.arange(len(pad))
        self._zeros, self._no_joint = np.zeros(len(pad)), np.empty(0)
        self._scratch = np.empty((1, len(pad)))     # a trace nobody reads (absorb)
        self.reset()

    def reset(self):
        """Forget every segment: a new interaction starts."""
        np.copyto(self._cov, self._cov0)
        np.copyto(self._mu, self._mu0)
        self._loglik[:] = 0.0
        self._start = np.full(self.max_segments, np.nan)     # start of each slot; NaN: free
        # columns up to the last slot started (slots are taken in order): the filters of a
        # slot never started would be reset before they were read, so they are not run
        self._live = 0
        # log mass of each column before its evidence: log h + log p(D_<tau) + log p(k, pace)
        self._offset = np.full(self._n, -np.inf)
        self._stay = 0.0        # sum of log(1 - h) over the candidates passed
        self._last = 0.0        # the last candidate time (the onset at first)
        self.n_started = 0

    def masses(self, onset_evidence):
        """(log mass of the segment since the onset per component (K,), log mass of every
        started segment's column (n,)), given that segment's log p(k) + log p(D | k) (K,)."""
        return onset_evidence + self._stay, self._offset + self._loglik[:self._n]

    def belief(self, onset_evidence) -> np.ndarray:
        """log p(k | D) (K,), normalised."""
        onset, started = self.masses(onset_evidence)
        per_k = np.logaddexp(onset, grouped_logsumexp(started, self._component,
                                                      self.n_components))
        top = per_k.max()
        return per_k - (top + np.log(np.exp(per_k - top).sum()))

    def joint(self, log_prior, loglik, n, hypothesis, n_alpha, out) -> float:
        """b(k) p(alpha_m | D, k) into ``out`` (K M,) from the estimator's hypotheses since the
        onset (its first ``n`` columns; core._fast.switching_joint); returns the smallest
        probability of one of them."""
        return switching_joint(log_prior, loglik, n, hypothesis, n_alpha, self.n_components,
                               self._stay, self._offset, self._loglik, self._component, out)

    def lines(self, component: int, onset_evidence):
        """What component k is predicted from: (the share of its hypotheses since the onset,
        started columns of k (indices), their shares; the shares sum to 1). The pattern the
        hypotheses since the onset explain best is predicted by them alone: they hold every
        sample of its movement (a disruption of it keeps its path; a restart conditioned on
        the latest samples predicts it worse). Another pattern is one the person may have
        turned to, whose hypotheses since the onset absorbed the first pattern's samples: the
        part of its belief after a change is predicted by its segments. A column with less
        than SUPPORT of k's belief is left out."""
        onset, started = self.masses(onset_evidence)
        mine = np.flatnonzero(self._component == component)
        m = np.r_[onset[component], started[mine]]
        if component == int(np.argmax(onset)) or not np.isfinite(m.max()):
            return 1.0, mine[:0], np.zeros(0)
        p = np.exp(m - m.max())
        p /= p.sum()
        keep = np.flatnonzero(p[1:] >= SUPPORT * p.max())
        return 1.0 - p[1:][keep].sum(), mine[keep], p[1:][keep]

    def column(self, c: int):
        """(weight mean (d,), phase at t = 0, phase speed) of started column ``c``."""
        g, lane = divmod(int(c), LANES)
        return (self._mu[g].reshape(-1, LANES)[:, lane].copy(), float(self._phase0[c]),
                float(self._rates[c]))

    def due(self, t: float) -> bool:
        """Whether a candidate change time has come by ``t`` (s since onset)."""
        return t >= self._last + self.spacing - 1e-9

    def start(self, t: float, onset_evidence, onset_phase: float):
        """A segment starting at ``t`` (the next sample absorbed is its first), given the
        segment since the onset's log p(k) p(D | k) (K,) so far and the phase its MAP
        hypothesis holds at ``t``. The segment's phase lines start around the phase of the
        most probable hypothesis of any segment; none starts within SHIFT basis spacings of
        the end of the movement."""
        onset, started = self.masses(onset_evidence)
        total = np.logaddexp(logsumexp(onset), logsumexp(started))
        # a change since the last candidate, or none
        gap = t - self._last
        log_switch, log_stay = np.log(-np.expm1(-self.rate * gap)), -self.rate * gap
        self._last = t
        self._stay += log_stay
        self._offset += log_stay
        c = int(np.argmax(started))
        phase = (onset_phase if started[c] <= onset.max() else
                 float(self._phase0[c] + self._rates[c] * t))
        if phase >= 1.0 - self.shifts.max():
            # The new segment's phase lines would reach the movement's end: nothing would be
            # left to tell its pattern by (the ending many patterns share is no change of mind).
            return
        free = np.flatnonzero(np.isnan(self._start))
        if free.size:
            slot = int(free[0])
        else:   # drop the least probable segment
            per_slot = [logsumexp(s) for s in started.reshape(self.max_segments, -1)]
            slot = int(np.argmin(per_slot))
            if per_slot[slot] + log_stay > log_switch + total:
                return     # every kept segment is more probable than a new one
        cols = np.arange(slot * self.width, (slot + 1) * self.width)
        self._phase0[cols] = (min(phase, 1.0) + np.tile(self.shifts, self.n_components)
                              - self._rates[cols] * t)
        self._loglik[cols] = 0.0
        # the new segment's pattern: the one believed (a disruption of the same movement) or
        # one drawn from p(k) (a change of mind)
        belief = np.logaddexp(onset, grouped_logsumexp(started, self._component,
                                                       self.n_components)) - total
        pattern = np.logaddexp(np.log(KEEP) + belief, np.log1p(-KEEP) + self._log_weights)
        self._offset[cols] = (log_switch + total - np.log(len(self.paces))
                              + pattern[self._component[cols]])
        for c in cols:
            g, lane = divmod(int(c), LANES)
            self._cov[g].reshape(-1, LANES)[:, lane] = self._cov0[g].reshape(-1, LANES)[:, lane]
            self._mu[g].reshape(-1, LANES)[:, lane] = self._mu0[g].reshape(-1, LANES)[:, lane]
        self._start[slot] = t
        self._live = max(self._live, (slot + 1) * self.width)
        self.n_started += 1

    def absorb(self, times, values, basis, trace: bool = True):
        """Condition every started segment on ``values`` (J, P) at ``times`` (J,); returns each
        column's log evidence after each sample (J, n) (-inf before any segment started; the
        columns of a slot not started yet, whose offset is -inf, read anything), or None with
        ``trace=False`` (one sample at a time: the belief is read after it, not the trace)."""
        if not trace and len(times) == 1:
            out = self._scratch
        else:
            out = np.full((len(times), len(self._loglik)), -np.inf)
        if self._live:
            kalman_update(self._cov, self._mu, self._loglik, self._live, self._alpha_index,
                          self._rates, self._phase0, times, basis.centers, basis.width, values,
                          self._noise, self._zeros, self._columns, self._no_joint, out)
        return out[:, :self._n] if trace else None

    def total(self, onset_total: float) -> float:
        """log p(D) of the change-point model, from the segment since the onset's log p(D)."""
        return float(self.log_evidence(np.array([onset_total]),
                                       self._loglik[None, :self._n])[0])

    def log_evidence(self, onset_totals, started_logliks) -> np.ndarray:
        """log p(D) of the change-point model after each of some samples: from the segment
        since the onset's log p(D) (J,) and the started columns' log evidence (J, n) after
        each (ChangePoints.absorb's trace)."""
        started = self._offset + started_logliks
        top = np.max(started, axis=1)
        safe = np.where(np.isfinite(top), top, 0.0)
        with np.errstate(divide='ignore'):
            total = safe + np.log(np.exp(started - safe[:, None]).sum(axis=1))
        return np.logaddexp(onset_totals + self._stay, total)


class ChangeOfMind:
    """What core.recursive.RecursivePosterior does with change points: it absorbs samples through
    :meth:`_absorb_many`, which runs its own filters (``_kalman``) and every ChangePoints of
    its (``_changes`` for its switch rate, ``_others`` for :meth:`compare_rates`) at the same
    candidate times, and makes the joint posterior b(k) p(alpha_m | D, k)."""

    def _absorb_many(self, times, values) -> np.ndarray:
        """Condition on the samples ``values`` (J, P) at ``times`` (J,), checked, in order;
        returns each tracked column's log evidence after each sample (J, n_tracked)."""
        chains = self._chains()
        if not chains:
            return self._kalman(times, values)
        # The change points' segments start between samples, from the state then (every rate's
        # at the same candidate times).
        changes, traces, j = chains[0], [], 0
        if len(times) == 1 and times[0] >= self._t_chain:     # the node's case: one sample
            if changes.due(times[0]):
                self._start_segments(float(times[0]), chains)
            trace = self._kalman(times, values)
            for chain in chains:
                chain.absorb(times, values, self.model.basis_, trace=False)
            self._t_chain = float(times[0])
            if self._changes is not None:
                self._set_joint()
                self._marginals = None          # log_marginal() when asked
            return trace
        marginals = []
        while j < len(times):
            end = j + 1
            while end < len(times) and not changes.due(times[end]):
                end += 1
            if times[j] < self._t_chain:        # before a sample already in: the onset's only
                traces.append(self._kalman(times[j:j + 1], values[j:j + 1]))
                marginals.append([self.log_marginal()])
                j += 1
                continue
            if changes.due(times[j]):
                self._start_segments(float(times[j]), chains)
            traces.append(self._kalman(times[j:end], values[j:end]))
            started = [chain.absorb(times[j:end], values[j:end], self.model.basis_)
                       for chain in chains]
            if self._changes is not None:
                marginals.append(self._changes.log_evidence(
                    logsumexp_rows(self._prior[:self.n_tracked] + traces[-1]), started[0]))
            self._t_chain = float(times[end - 1])
            j = end
        if self._changes is not None:
            self._set_joint()
            self._marginals = np.concatenate(marginals)
        return np.vstack(traces)

    def _start_segments(self, t, chains):
        onset, phase = self._onset_log_evidence()[0], self._onset_phase(t)
        for chain in chains:
            chain.start(t, onset, phase)

    def _chains(self):
        return ([] if self._changes is None else [self._changes]) + self._others

    def compare_rates(self, rates) -> None:
        """Also follow the beliefs that other switch ``rates`` (> 0) would hold on the same
        samples (:meth:`rate_beliefs`): the calibration of the rate (core.calibration) plays each
        movement once for all of them. Before the first sample (or after :meth:`reset`)."""
        if self.n_observations:
            raise ValueError('compare_rates before the first sample of an interaction')
        self._others = [ChangePoints(self.model, self._noise_k, float(r)) for r in rates]

    def rate_beliefs(self) -> list:
        """p(k | D) under each rate of :meth:`compare_rates`, in its order."""
        onset = self._onset_log_evidence()[0]
        return [np.exp(chain.belief(onset)) for chain in self._others]

    def _onset_log_evidence(self):
        """(log p(k) p(D | k) of the segment since the onset (K,; -inf for a component pruned
        whole), each tracked column's log p(k, alpha_m) p(D | k, alpha_m) (n,), its component
        (n,))."""
        n = self.n_tracked
        k_of = self._hyp[:n] // len(self.alphas)
        lw = self._prior[:n] + self._loglik[:n]
        return grouped_logsumexp(lw, k_of, self.n_components), lw, k_of

    def _onset_phase(self, t) -> float:
        """The phase at ``t`` of the MAP hypothesis (k, alpha_m) since the onset."""
        n = self.n_tracked
        c = int(np.argmax(self._prior[:n] + self._loglik[:n]))
        return float(self.alphas[self._alpha_index[c]] * t)

    def _set_joint(self):
        """p(k, alpha_m | D) = b(k) p(alpha_m | D, k): the belief from the change points, each
        component's phase speed from the segment since the onset."""
        joint = np.empty(len(self._col))
        self._smallest = self._changes.joint(self._prior, self._loglik, self.n_tracked,
                                             self._hyp, len(self.alphas), joint)
        self._joint = joint.reshape(self.n_components, -1)
        self._joint.flags.writeable = False
