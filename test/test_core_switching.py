"""Changes of mind (core.switching, core.recursive): the change-point belief against a brute-force
enumeration of every segmentation, rate 0 against eq. 11, the kernels it runs on against plain
formulas, other rates followed alongside, and what the belief makes of a stream that changes
pattern."""

import copy
import itertools
import json

import numpy as np
import pytest
from scipy import linalg
from scipy.special import logsumexp
from scipy.stats import multivariate_normal, norm

from mixture_ip_ros.core._fast import LANES, from_lanes, kalman_update, to_lanes, tri_index
from mixture_ip_ros.core._fast_switching import grouped_logsumexp, switching_joint
from mixture_ip_ros.core.basis import GaussianBasis
from mixture_ip_ros.core.mixture import MixtureIProMP
from mixture_ip_ros.core.online import OnlineEstimator
from mixture_ip_ros.core.phase import log_evidence_batch, phase_posterior_batch
from mixture_ip_ros.core.promp import observation_stats, weight_posterior
from mixture_ip_ros.core.splice import BLEND, splice
from mixture_ip_ros.core.switching import KEEP, PACES, SHIFT, SPACING, ChangePoints
from mixture_ip_ros.io.model_file import load_model, save_model
from mixture_ip_ros.scenarios.synthetic import mixture_demos, random_spd

INTERVAL = 0.05         # the estimators' decimation (s)


def _truth(model, demo):
    """The component that explains a whole demonstration best, its phase known (eq. 11): the
    fit is unsupervised, so the generating label need not be the component's index."""
    return int(np.argmax(model.component_posterior(demo.phase, demo.observed,
                                                   alpha=1.0 / demo.duration)))


@pytest.fixture(scope='module')
def three():
    """Three well separated patterns, three observed DOFs (test_core_online's model), at the
    paces of people's interactions (3-6 s: the change points' spacing and the turn are in
    seconds)."""
    demos = mixture_demos(seed=1, durations=((3.6, 5.4), (4.5, 7.2), (3.0, 4.8)))[0]
    model = MixtureIProMP(3, n_basis=8).fit(demos)
    return model, demos, np.array([_truth(model, d) for d in demos])


def _played(est, demo):
    """Update ``est`` with every sample of ``demo``; (times used, belief p(k | D) after each)."""
    times, beliefs = [], []
    for t, y in zip(demo.t, demo.observed):
        if est.update(t, y):
            times.append(t)
            beliefs.append(est.component_posterior().copy())
    return np.array(times), np.array(beliefs)


def _splice_of(demos, truth, first, second, at=0.5):
    """The splice of the first demonstration of component ``first`` into the first of
    ``second``, at the share ``at``."""
    a = demos[int(np.flatnonzero(truth == first)[0])]
    b = demos[int(np.flatnonzero(truth == second)[0])]
    return splice(a, b, at)


# ------------------------------------------------------------------ kernels
def test_grouped_logsumexp_is_scipys_logsumexp_of_each_group():
    rng = np.random.default_rng(0)
    n_groups = 6
    values = rng.normal(0.0, 30.0, 200)
    groups = rng.integers(0, n_groups - 1, 200)          # the last group is left empty
    values[rng.random(200) < 0.2] = -np.inf
    values[groups == 3] = -np.inf                          # a group with no finite value
    values[np.flatnonzero(groups == 1)[:1]] = 700.0        # exp overflows without the shift
    out = grouped_logsumexp(values, groups, n_groups)
    assert out.shape == (n_groups,)
    for g in range(n_groups - 1):
        want = logsumexp(values[groups == g])
        if np.isneginf(want):
            assert np.isneginf(out[g])
        else:
            assert out[g] == pytest.approx(want, rel=1e-14, abs=1e-12)
    assert np.isneginf(out[3]) and np.isneginf(out[n_groups - 1])
    assert np.isfinite(out[[0, 1, 2, 4]]).all()
    # the order of the columns does not matter
    order = rng.permutation(200)
    assert np.allclose(grouped_logsumexp(values[order], groups[order], n_groups)[[0, 1, 2, 4]],
                       out[[0, 1, 2, 4]], rtol=1e-14)


def test_switching_joint_is_the_belief_times_each_components_speed_posterior():
    """b(k) p(alpha_m | D, k): b(k) the normalised sum of the segment since the onset's mass
    (its hypotheses' log p(k, alpha_m) p(D | k, alpha_m), plus the log(1 - h) summed) and the
    started segments' masses of component k; over the tracked hypotheses in the order pruning
    left them (one component pruned whole, with no started segment either), 0 for the others."""
    rng = np.random.default_rng(2)
    K, M = 3, 5
    hypothesis = rng.permutation(K * M)
    hypothesis = hypothesis[hypothesis // M != 1]                  # component 1 pruned whole
    n = len(hypothesis) - 2                                        # two more past the tracked
    log_prior, loglik = rng.normal(-3, 1, len(hypothesis)), rng.normal(0, 20, len(hypothesis))
    component = np.repeat(np.arange(K), 4)
    offset, started = rng.normal(-5, 3, len(component)), rng.normal(0, 20, len(component) + 3)
    offset[component == 2] = -np.inf                               # no started segment of 2
    offset[component == 1] = -np.inf                               # nor of the pruned one
    stay = -0.7
    joint = np.full(K * M, np.nan)
    smallest = switching_joint(log_prior, loglik, n, hypothesis, M, K, stay, offset, started,
                               component, joint)
    lw = log_prior[:n] + loglik[:n]
    k_of = hypothesis[:n] // M
    onset = np.array([logsumexp(lw[k_of == k]) if (k_of == k).any() else -np.inf
                      for k in range(K)])
    per_k = np.logaddexp(onset + stay, [logsumexp((offset + started[:len(offset)])
                                                  [component == k]) for k in range(K)])
    belief = np.exp(per_k - logsumexp(per_k))
    want = np.zeros(K * M)
    want[hypothesis[:n]] = belief[k_of] * np.exp(lw - onset[k_of])
    assert np.allclose(joint, want, rtol=1e-12, atol=1e-300)
    assert smallest == pytest.approx(want[hypothesis[:n]].min(), rel=1e-12)
    assert np.all(joint[hypothesis[n:]] == 0) and np.all(joint.reshape(K, M)[1] == 0)
    assert joint.sum() == pytest.approx(1.0, abs=1e-12)


def test_kalman_update_with_a_phase_at_onset_is_the_batch_posterior_at_those_phases():
    """Each column's phase function z = phase0 + a t (phase0 negative, zero or positive, phases
    past both ends of [0, 1] where the basis holds): the recursive posterior and evidence equal
    eqs. 17-18 in batch (core.promp.weight_posterior) at those phases."""
    rng = np.random.default_rng(5)
    basis, P = GaussianBasis(6), 2
    d = P * basis.n_basis
    n, C = 2 * LANES - 3, 2 * LANES                 # tracked columns; the rest pad the group
    lower = np.tril_indices(d)
    means = rng.normal(0, 0.5, (C, d))
    covs = np.array([random_spd(rng, d, 0.1) for _ in range(C)])
    noise = rng.uniform(0.01, 0.05, (C, P))
    rates = rng.uniform(0.4, 1.5, C)
    phase0 = rng.uniform(-0.4, 0.8, C)
    phase0[:3] = 0.0
    times = np.sort(rng.uniform(0.0, 1.4, 9))
    ys = rng.normal(0.0, 0.5, (len(times), P))
    cov, mu = to_lanes(covs[:, lower[0], lower[1]]), to_lanes(means)
    loglik = np.zeros(C)
    log_prior = rng.normal(0, 1, C)
    joint, trace = np.empty(C), np.empty((len(times), C))
    smallest = kalman_update(cov, mu, loglik, n, np.arange(C), rates, phase0, times,
                             basis.centers, basis.width, ys, to_lanes(noise), log_prior,
                             np.arange(C), joint, trace)
    z_all = phase0[:, None] + rates[:, None] * times[None]
    assert (z_all < 0).any() and (z_all > 1).any()          # both clamped ends are met
    post_cov = from_lanes(cov)[:, tri_index(d)]
    post_mu = from_lanes(mu)
    for c in range(n):
        chol = linalg.cho_factor(covs[c], lower=True)
        want_mu, want_cov, want_ll = weight_posterior(
            observation_stats(basis, z_all[c], ys), means[c], chol, noise[c])
        assert np.allclose(post_mu[c], want_mu, rtol=1e-9, atol=1e-12)
        assert np.allclose(post_cov[c], want_cov, rtol=1e-8, atol=1e-13)
        assert loglik[c] == pytest.approx(want_ll, rel=1e-10)
        assert trace[-1, c] == loglik[c]
        ll3 = weight_posterior(observation_stats(basis, z_all[c, :3], ys[:3]), means[c], chol,
                               noise[c])[2]
        assert trace[2, c] == pytest.approx(ll3, rel=1e-10)
    want = np.exp(log_prior[:n] + loglik[:n] - logsumexp(log_prior[:n] + loglik[:n]))
    assert np.allclose(joint[:n], want, rtol=1e-12, atol=1e-300)
    assert smallest == pytest.approx(want.min(), rel=1e-12)


# ------------------------------------------------------------------ rate 0: eq. 11
def test_rate_zero_is_eq11_with_the_phase_marginalised(three):
    """Rate 0, given or the model's, keeps no change points and holds the batch posterior of
    eq. 16 over the grid (eq. 11 when summed), the same to the bit either way."""
    model, demos, _ = three
    quick = copy.copy(model)
    quick.switch_rate = 0.3
    given = OnlineEstimator(quick, n_alpha=10, min_interval=0.0, switch_rate=0.0)
    own = OnlineEstimator(model, n_alpha=10, min_interval=0.0)             # the model's: 0
    assert model.switch_rate == 0.0 and given.switch_rate == own.switch_rate == 0.0
    assert given._changes is None and own._changes is None
    assert OnlineEstimator(quick, n_alpha=10)._changes is not None        # None: the model's
    demo = demos[4]
    idx = np.arange(0, int(0.7 * len(demo.t)), 4)
    for i in idx:
        assert given.update(demo.t[i], demo.observed[i]) and own.update(demo.t[i],
                                                                          demo.observed[i])
    for read in (lambda e: e.component_posterior(), lambda e: e.joint_posterior(),
                 lambda e: e.log_evidence):
        assert np.array_equal(read(given), read(own))
    batch = np.exp(phase_posterior_batch(model, demo.t[idx], demo.observed[idx], own.alphas))
    assert np.allclose(own.joint_posterior(), batch, rtol=1e-8, atol=1e-12)
    assert np.allclose(own.component_posterior(), batch.sum(axis=1), rtol=1e-8, atol=1e-12)
    do = model.n_observed_ * model.n_basis
    for k in range(3):
        for m in (0, 5, 9):
            ref = log_evidence_batch(model.means_[k][:do], model.covariances_[k][:do, :do],
                                     model.basis_, demo.t[idx], demo.observed[idx],
                                     own.alphas[m], model.observed_noise(k))
            assert own.log_evidence[k, m] == pytest.approx(ref, rel=1e-9)


# ------------------------------------------------------------------ the oracle
@pytest.fixture(scope='module')
def tiny():
    """Two patterns, one observed DOF, five basis functions, noisy enough that the belief is
    not all on one of them."""
    demos = mixture_demos(seed=3, counts=(8, 8), n_obs=1, n_ctrl=1, n_basis=5, noise=0.02,
                          spread=0.01, durations=((1.0, 1.3), (1.0, 1.3)))[0]
    model = MixtureIProMP(2, n_basis=5).fit(demos)
    return model, demos, np.array([_truth(model, d) for d in demos])


def _log_gauss(model, k, z, Y, noise):
    """log N(Y; A mu_k, R + A Sigma_k A^T) of the observed agent's samples Y (m, P) at phases
    z, stacked DOF-major (eq. 18, dense)."""
    P = Y.shape[1]
    do = P * model.n_basis
    A = np.kron(np.eye(P), model.basis_(z))
    S = np.diag(np.repeat(noise, len(z))) + A @ model.covariances_[k][:do, :do] @ A.T
    return multivariate_normal(A @ model.means_[k][:do], S).logpdf(Y.T.ravel())


class _Segmentations:
    """p(k | D) by enumerating every segmentation of the samples: every subset S of the
    candidate change times reached, in order, with the pattern and phase line of each segment
    (Adams and MacKay's change-point model, written out).

    A segmentation's probability: the hazard h_r = 1 - exp(-rate gap_r) at each candidate of S
    and 1 - h_r at each other candidate; the segment since the onset with p(k) and the phase
    speed alpha_m of the grid with its prior (normalised over the grid), its weights from
    component k's prior; a segment started at tau_r with the pattern prior KEEP p(k | D_<tau_r)
    + (1 - KEEP) p(k) (p(k | D_<tau_r) this enumeration's own belief from the samples before
    tau_r), one of 9 phase lines z = z_r + shift + a (t - tau_r) with probability 1/9 each
    (shift in -SHIFT, 0, SHIFT basis spacings; a = max(m_k + s_k q, m_k / 4) for the paces q),
    its weights fresh from component k's prior; dense Gaussian evidence of each segment's
    samples. The patterns and lines of the segments before the last are summed segment by
    segment (the sum of a product of independent factors); the last one's pattern is the one
    the belief is about. The starting phases z_r follow the estimator's rule (the phase of the
    most probable hypothesis at tau_r, :meth:`start_phase`), from this enumeration's
    masses."""

    def __init__(self, model, alphas, noise, rate, times, values):
        self.model, self.alphas, self.noise, self.rate = model, alphas, noise, rate
        self.t, self.Y = np.asarray(times), np.asarray(values)
        K = model.n_components
        lp = norm(model.alpha_mean_[:, None], model.alpha_std_[:, None]).logpdf(alphas[None])
        self.log_alpha_prior = lp - logsumexp(lp, axis=1, keepdims=True)
        self.log_w = np.log(model.weights_)
        step = SHIFT / (model.n_basis - 1)
        self.lines = [[(shift, max(model.alpha_mean_[k] + model.alpha_std_[k] * q,
                                   0.25 * model.alpha_mean_[k]))
                       for shift in (-step, 0.0, step) for q in PACES] for k in range(K)]
        # candidate change times: a sample at least SPACING after the last candidate (the onset
        # the first)
        self.candidates, last = [], 0.0
        for j, t in enumerate(self.t):
            if t >= last + SPACING - 1e-9:
                self.candidates.append(j)
                last = t
        taus = self.t[self.candidates]
        gaps = np.diff(np.r_[0.0, taus])
        self.log_h, self.log_stay = np.log(-np.expm1(-rate * gaps)), -rate * gaps
        self._cache = {}

    def onset_terms(self, b):
        """log p(k) p(alpha_m | k) p(D_[0, b) | k, alpha_m) (K, M)."""
        key = ('onset', b)
        if key not in self._cache:
            t, Y = self.t[:b], self.Y[:b]
            self._cache[key] = self.log_w[:, None] + self.log_alpha_prior + np.array(
                [[_log_gauss(self.model, k, a * t, Y, self.noise[k]) for a in self.alphas]
                 for k in range(len(self.log_w))])
        return self._cache[key]

    def onset(self, b):
        """log p(k) p(D_[0, b) | k) (K,), the phase speed marginalised."""
        return logsumexp(self.onset_terms(b), axis=1)

    def line_terms(self, r, b):
        """log p(D_[j_r, b) | k, line i of a segment started at candidate r) (K, 9)."""
        key = ('lines', r, b)
        if key not in self._cache:
            j = self.candidates[r]
            tau, z0 = self.t[j], self.start_phase(r)
            t, Y = self.t[j:b], self.Y[j:b]
            self._cache[key] = np.array([
                [_log_gauss(self.model, k, z0 + shift + a * (t - tau), Y, self.noise[k])
                 for shift, a in lines] for k, lines in enumerate(self.lines)])
        return self._cache[key]

    def started(self, r, b):
        """log p(D_[j_r, b) | k, a segment started at candidate r) (K,), its 9 lines each 1/9."""
        return logsumexp(self.line_terms(r, b), axis=1) - np.log(9)

    def start_phase(self, r):
        """The phase a segment started at candidate r starts its lines around: that of the most
        probable hypothesis at tau_r (the estimator's rule): the phase alpha_m tau_r of the
        most probable (k, alpha_m) since the onset, unless a line of an earlier segment is
        more probable than the most probable component since the onset is, then that line's
        phase at tau_r; at most 1."""
        key = ('phase', r)
        if key in self._cache:
            return self._cache[key]
        j, tau = self.candidates[r], self.t[self.candidates[r]]

        def stayed(since):          # log(1 - h) of the candidates from ``since`` to r
            return sum(self.log_stay[since:r])

        onset = self.onset_terms(j)
        phase = self.alphas[np.unravel_index(np.argmax(onset), onset.shape)[1]] * tau
        best = logsumexp(onset, axis=1).max() + stayed(0)
        for q in range(r):                      # the lines of the segments started before
            if self.gated(q):
                continue
            mass = (self.log_h[q] + self.log_total(self.candidates[q])
                    + self.log_pattern_prior(q)[:, None] - np.log(9) + stayed(q + 1)
                    + self.line_terms(q, j))
            k, i = np.unravel_index(np.argmax(mass), mass.shape)
            if mass[k, i] > best:
                shift, a = self.lines[k][i]
                best = mass[k, i]
                phase = self.start_phase(q) + shift + a * (tau - self.t[self.candidates[q]])
        self._cache[key] = min(phase, 1.0)
        return self._cache[key]

    def gated(self, r):
        """No segment starts at candidate r: its phase is within SHIFT basis spacings of the
        end (its lines would reach the end), as the estimator rules."""
        return self.start_phase(r) >= 1.0 - SHIFT / (self.model.n_basis - 1)

    def log_total(self, b):
        """log p(D_[0, b)) summed over every segmentation."""
        self.log_belief(b)
        return self._cache[('total', b)]

    def log_pattern_prior(self, r):
        before = np.exp(self.log_belief(self.candidates[r]))
        return np.log(KEEP * before + (1 - KEEP) * np.exp(self.log_w))

    def log_belief(self, b):
        """log p(k | D) of the last segment's pattern, D the first b samples (b >= 1)."""
        key = ('belief', b)
        if key in self._cache:
            return self._cache[key]
        reached = [r for r, j in enumerate(self.candidates) if j < b]
        open_ = [r for r in reached if not self.gated(r)]
        terms = []
        for size in range(len(open_) + 1):
            for S in itertools.combinations(open_, size):
                lw = sum(self.log_h[r] if r in S else self.log_stay[r] for r in reached)
                ends = [self.candidates[r] for r in S] + [b]
                lw += logsumexp(self.onset(ends[0])) if S else 0.0
                for r, end in zip(S[:-1], ends[1:-1]):          # the segments in between
                    lw += logsumexp(self.log_pattern_prior(r) + self.started(r, end))
                last = (self.onset(b) if not S else
                        self.log_pattern_prior(S[-1]) + self.started(S[-1], b))
                terms.append(lw + last)
        per_k = logsumexp(np.array(terms), axis=0)
        self._cache[('total', b)] = logsumexp(per_k)
        self._cache[key] = per_k - logsumexp(per_k)
        return self._cache[key]


def test_the_belief_is_the_enumeration_of_every_segmentation(tiny):
    """A spliced stream of 1.1 s (five candidate change times, the last ones too near the end to
    start a segment)
    under a chain that keeps every segment it starts (max_segments large enough that none is
    dropped): after every sample the estimator's belief is the enumeration's, and its joint
    posterior that belief times each component's phase-speed posterior since the onset."""
    model, demos, truth = tiny
    s = _splice_of(demos, truth, 0, 1)
    rate = 1.0
    est = OnlineEstimator(model, n_alpha=6, min_interval=INTERVAL, switch_rate=rate)
    noise = np.broadcast_to(model.observed_noise_var_at(INTERVAL), (2, 1))
    est._changes = chain = ChangePoints(model, noise, rate, max_segments=12)
    eq11 = OnlineEstimator(model, n_alpha=6, min_interval=INTERVAL, switch_rate=0.0)
    times, values, beliefs, joints, started, plain = [], [], [], [], [], []
    for t, y in zip(s.demo.t, s.demo.observed):
        if not est.update(t, y):
            continue
        eq11.update(t, y)
        times.append(t)
        values.append(y)
        beliefs.append(est.component_posterior().copy())
        joints.append(est.joint_posterior().copy())
        plain.append(eq11.component_posterior().copy())
        if chain.n_started > len(started):          # a segment started at this sample
            slot = chain.n_started - 1
            assert chain._start[slot] == t
            cols = np.arange(slot * chain.width, (slot + 1) * chain.width)
            z_at_start = chain._phase0[cols] + chain._rates[cols] * t
            z0 = z_at_start - np.tile(chain.shifts, 2)
            assert np.allclose(z0, z0[0], rtol=0, atol=1e-12)     # 9 lines around one phase
            started.append(float(z0[0]))
    oracle = _Segmentations(model, est.alphas, noise, rate, times, values)
    assert len(oracle.candidates) == 5
    # the segments started are the candidates not near the end (at least one is, here)
    open_ = [r for r in range(5) if not oracle.gated(r)]
    assert 3 <= len(open_) == len(started) < 5
    assert np.array_equal(np.asarray(times)[np.array(oracle.candidates)[open_]],
                          chain._start[:len(started)])
    assert np.allclose([oracle.start_phase(r) for r in open_], started, rtol=0, atol=1e-12)
    assert len(set(np.round(started, 6))) == len(started)
    for b, belief in enumerate(beliefs, start=1):
        want = np.exp(oracle.log_belief(b))
        assert np.allclose(belief, want, rtol=1e-9, atol=1e-300), (b, belief, want)
        assert belief.sum() == pytest.approx(1.0, abs=1e-12)
        # each component's phase speed from the segment since the onset: b(k) p(alpha_m | D, k)
        speed = oracle.onset_terms(b)
        speed = np.exp(speed - logsumexp(speed, axis=1, keepdims=True))
        assert np.allclose(joints[b - 1], want[:, None] * speed, rtol=1e-9, atol=1e-300)
    # the change points carry weight here: the belief is not eq. 11's
    assert np.abs(np.array(beliefs) - np.array(plain)).max() > 0.1


# ------------------------------------------------------------------ behaviour
@pytest.mark.decision
@pytest.mark.parametrize('first, second, at', [(0, 1, 0.5), (2, 0, 0.6), (1, 2, 0.5)])
def test_a_change_of_mind_moves_the_belief_to_the_new_pattern(three, first, second, at):
    """A's beginning spliced into B's rest: with changes of mind the belief is on A before the
    change and on B within 0.7 s of it (the turn, then a candidate change time and the samples
    that tell B), to the end, and no later than eq. 11 (rate 0), which weighs the samples
    before the change as much as those after."""
    model, demos, truth = three
    s = _splice_of(demos, truth, first, second, at)

    def settled(t, k):          # when the belief came to B for good (inf: never)
        wrong = np.flatnonzero(k != second)
        return -np.inf if not wrong.size else (np.inf if wrong[-1] == len(k) - 1
                                               else t[wrong[-1] + 1])
    t, beliefs = _played(OnlineEstimator(model, n_alpha=20, min_interval=INTERVAL,
                                         switch_rate=0.0), s.demo)
    eq11 = settled(t, beliefs.argmax(axis=1))
    for rate in (0.1, 0.3, 1.0):
        t, beliefs = _played(OnlineEstimator(model, n_alpha=20, min_interval=INTERVAL,
                                             switch_rate=rate), s.demo)
        k = beliefs.argmax(axis=1)
        assert (k[(t >= 0.3 * s.t_change) & (t < s.t_change)] == first).all(), rate
        assert settled(t, k) <= min(eq11, s.t_change + 0.7), rate


@pytest.mark.decision
def test_an_unchanged_movement_keeps_its_pattern(three):
    model, demos, truth = three
    for k in range(3):
        demo = demos[int(np.flatnonzero(truth == k)[1])]
        for rate in (0.1, 0.3, 1.0):
            t, beliefs = _played(OnlineEstimator(model, n_alpha=20, min_interval=INTERVAL,
                                                 switch_rate=rate), demo)
            assert (beliefs[t >= 0.3 * demo.duration].argmax(axis=1) == k).all(), (k, rate)


def test_other_rates_followed_alongside_are_those_rates_estimators(three):
    """compare_rates: the beliefs of other rates on the same samples equal those of estimators
    run with those rates, whatever the estimator's own rate."""
    model, demos, truth = three
    s = _splice_of(demos, truth, 0, 1)
    rates = (0.1, 0.3)
    alone = [OnlineEstimator(model, n_alpha=12, min_interval=INTERVAL, switch_rate=r)
             for r in rates]
    for own in (0.0, 0.3):
        est = OnlineEstimator(model, n_alpha=12, min_interval=INTERVAL, switch_rate=own)
        est.compare_rates(rates)
        for e in [est] + alone:
            e.reset()
        n = 0
        for t, y in zip(s.demo.t, s.demo.observed):
            used = est.update(t, y)
            assert all(e.update(t, y) == used for e in alone)
            if used:
                n += 1
                got = est.rate_beliefs()
                assert len(got) == 2
                for b, e in zip(got, alone):
                    assert np.allclose(b, e.component_posterior(), rtol=0, atol=1e-9)
        assert n > 20
        if own:
            assert np.allclose(est.component_posterior(), alone[1].component_posterior(),
                               rtol=0, atol=1e-9)
    assert alone[0].component_posterior().argmax() == 1


def test_a_recording_offered_at_once_is_each_sample_offered_in_turn(three):
    """offer_many splits the samples at the candidate change times: the same belief as the
    samples offered one by one."""
    model, demos, truth = three
    s = _splice_of(demos, truth, 2, 0)
    each = OnlineEstimator(model, n_alpha=12, min_interval=INTERVAL, switch_rate=0.3)
    once = OnlineEstimator(model, n_alpha=12, min_interval=INTERVAL, switch_rate=0.3)
    for t, y in zip(s.demo.t, s.demo.observed):
        each.offer(t, y)
    once.offer_many(s.demo.t, s.demo.observed)
    assert once.n_observations == each.n_observations
    assert np.allclose(once.component_posterior(), each.component_posterior(), rtol=1e-12,
                       atol=1e-300)
    assert np.allclose(once.joint_posterior(), each.joint_posterior(), rtol=1e-12, atol=1e-300)


def test_the_end_posterior_is_the_batch_posterior_with_the_end_known(three):
    """With changes of mind the end posterior is eq. 11's with the phase known, as without
    (the end time does not correct the segments' phase lines); a distribution."""
    model, demos, truth = three
    s = _splice_of(demos, truth, 1, 2)
    for demo in [demos[int(np.flatnonzero(truth == k)[2])] for k in range(3)] + [s.demo]:
        est = OnlineEstimator(model, n_alpha=20, min_interval=INTERVAL, switch_rate=0.3)
        plain = OnlineEstimator(model, n_alpha=20, min_interval=INTERVAL, switch_rate=0.0)
        _played(est, demo)
        _played(plain, demo)
        for T in (demo.duration, 1.2 * demo.duration):
            p = est.end_posterior(T)
            assert np.array_equal(p, plain.end_posterior(T))
            assert p.sum() == pytest.approx(1.0, abs=1e-12)


def _pruned_run(model, demo, prune_below):
    est = OnlineEstimator(model, n_alpha=20, min_interval=INTERVAL, switch_rate=0.3,
                          prune_below=prune_below)
    out = []
    for t, y in zip(demo.t, demo.observed):
        if est.update(t, y):
            joint = est.joint_posterior()
            out.append((joint.sum(), np.isfinite(joint).all(), est.map_hypothesis()[0],
                        est.n_tracked))
    return out


@pytest.mark.parametrize('changed', [False, True])
def test_pruning_keeps_a_normalised_joint_posterior_and_its_argmax(three, changed):
    """Pruning with changes of mind: the joint posterior stays a distribution after every
    sample, unchanged movement or change of mind, and on an unchanged movement its most
    probable component is the exact posterior's."""
    model, demos, truth = three
    demo = (_splice_of(demos, truth, 2, 0, 0.4).demo if changed
            else demos[int(np.flatnonzero(truth == 1)[3])])
    exact = _pruned_run(model, demo, 0.0)
    for prune_below in (1e-6, 1e-4):
        pruned = _pruned_run(model, demo, prune_below)
        assert len(pruned) == len(exact)
        assert pruned[-1][3] < exact[-1][3]                  # hypotheses were dropped
        for (total, finite, k, _), (_, _, k_exact, _) in zip(pruned, exact):
            assert finite and total == pytest.approx(1.0, abs=1e-9)
            # a component pruned whole holds no belief (RecursivePosterior), so only an
            # unchanged movement keeps the exact posterior's pattern throughout
            assert changed or k == k_exact


# ------------------------------------------------------------------ parameters and files
OBS = ['wrist_x', 'wrist_y', 'wrist_z']
CTRL = [f'iiwa_joint_{i}' for i in range(1, 5)]


def test_a_bad_switch_rate_is_refused(three):
    model, demos, _ = three
    for bad in (-1, -0.1, np.nan, np.inf, True, 'x', None):
        with pytest.raises(ValueError, match='switch_rate'):
            MixtureIProMP(3, n_basis=8, switch_rate=bad).fit(demos)
    for bad in (-1, -1e-9, np.nan, np.inf, True, 'x', [0.1]):
        with pytest.raises(ValueError, match='switch_rate'):
            OnlineEstimator(model, n_alpha=5, switch_rate=bad)
    fitted = copy.copy(model)
    fitted.switch_rate = -1.0               # a model changed after its fit: its rate is checked
    with pytest.raises(ValueError, match='switch_rate'):
        OnlineEstimator(fitted, n_alpha=5)


def test_the_switch_rate_round_trips_a_model_file(tmp_path, three):
    model = copy.copy(three[0])
    model.switch_rate = 0.3
    path = save_model(tmp_path / 'm.npz', model, observed_names=OBS, controlled_names=CTRL)
    loaded = load_model(path)[0]
    assert loaded.switch_rate == 0.3
    assert OnlineEstimator(loaded, n_alpha=5).switch_rate == 0.3
    # a file written before the rate existed: no changes of mind
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(str(arrays['metadata']))
    del meta['params']['switch_rate']
    arrays['metadata'] = np.array(json.dumps(meta))
    with open(path, 'wb') as f:
        np.savez(f, **arrays)
    old = load_model(path)[0]
    assert old.switch_rate == 0.0 and OnlineEstimator(old, n_alpha=5)._changes is None


# ------------------------------------------------------------------ calibration
@pytest.mark.decision
def test_the_calibrated_switch_rate_lets_held_out_changes_of_mind_be_followed():
    """Clearly different patterns, held-out movements unchanged and spliced into changes of
    mind: a rate of the grid that follows the changes scores above rate 0, which cannot; with one
    component there is nothing to change to."""
    from mixture_ip_ros.core.calibration import SWITCH_RATES, calibrated_switch_rate
    from mixture_ip_ros.core.crossval import prepare_for_cv
    demos = mixture_demos(seed=1, counts=(6, 6, 6))[0]
    params = {'n_basis': 8, 'method': 'regression'}
    data = prepare_for_cv(demos, params)
    rate, scores = calibrated_switch_rate(demos, data, 3, None, 3, params)
    assert rate in SWITCH_RATES and rate > 0
    assert list(scores) == [f'{r:g}' for r in SWITCH_RATES]
    values = np.array(list(scores.values()))
    assert np.all((values >= 0) & (values <= 2))     # two shares of samples named right
    assert scores[f'{rate:g}'] == values.max() and values.argmax() == SWITCH_RATES.index(rate)
    assert scores['0'] < values.max() - 0.2
    assert calibrated_switch_rate(demos, data, 1, None, 3, params) == (0.0, None)
