"""Phase estimation (eqs. 15-20) and the recursive online estimator against the batch eq. 18."""

import numpy as np
import pytest

from mixture_ip_ros.core.demonstration import Demonstration
from mixture_ip_ros.core.interaction import condition_on_observed, trajectory_distribution
from mixture_ip_ros.core.mixture import MixtureIProMP
from mixture_ip_ros.core.online import OnlineEstimator
from mixture_ip_ros.core.phase import (alpha_log_prior, alpha_m_step, alpha_prior_std,
                                       log_density_on_grid, log_evidence_batch,
                                       phase_posterior_batch, tempered_speed_posterior,
                                       timing_variance)

from scipy.special import logsumexp
from scipy.stats import multivariate_normal, norm

from mixture_ip_ros.core.playback import (absorbed_rows, observed_rows, played_to,
                                          prefix_predictions, prefixes, rest_rows)
from mixture_ip_ros.scenarios.synthetic import mixture_demos, random_spd, sample_trajectory


def _feed(est, demo, fraction, step):
    """Update ``est`` with every ``step``-th sample of the first ``fraction`` of ``demo``;
    returns the indices of the samples used."""
    idx = np.arange(0, int(fraction * len(demo.t)), step)
    for i in idx:
        est.update(demo.t[i], demo.observed[i])
    return idx


@pytest.fixture(scope='module')
def model_and_demos():
    demos, labels, _, _ = mixture_demos(seed=1)
    return MixtureIProMP(3, n_basis=8).fit(demos), demos, labels


@pytest.mark.parametrize('n_obs', [3, 1, 4])   # the kernel works on rows of G in threes
def test_recursive_log_evidence_equals_batch_eq18(model_and_demos, n_obs):
    model, demos, _ = model_and_demos
    if n_obs != model.n_observed_:
        demos = mixture_demos(seed=1, n_obs=n_obs)[0]
        model = MixtureIProMP(3, n_basis=8).fit(demos)
    est = OnlineEstimator(model, n_alpha=12, min_interval=0.0)
    demo = demos[4]
    idx = _feed(est, demo, 0.7, 4)
    do = model.n_observed_ * model.n_basis
    for k in range(3):
        for m in range(0, 12, 3):
            ref = log_evidence_batch(model.means_[k][:do], model.covariances_[k][:do, :do],
                                     model.basis_, demo.t[idx], demo.observed[idx],
                                     est.alphas[m], model.observed_noise_var_)
            assert est.log_evidence[k, m] == pytest.approx(ref, rel=1e-8)
    batch = phase_posterior_batch(model, demo.t[idx], demo.observed[idx], est.alphas)
    assert np.allclose(est.joint_posterior(), np.exp(batch), atol=1e-10)


def test_covariances_stay_symmetric_positive_definite_over_long_streams(model_and_demos):
    model, demos, _ = model_and_demos
    est = OnlineEstimator(model, n_alpha=6, min_interval=0.0)
    demo = demos[0]
    t = np.linspace(0, 3 * demo.duration, 3000)       # long past the end: z clamped to 1
    y = demo.observed[-1]
    for ti in t[1:]:
        est.update(ti, y)
    assert np.allclose(est.sigma, est.sigma.transpose(0, 2, 1), atol=0)
    assert np.all(np.linalg.eigvalsh(est.sigma).min(axis=1) > 0)


def test_prediction_equals_conditioning_the_map_hypothesis(model_and_demos):
    model, demos, _ = model_and_demos
    est = OnlineEstimator(model, n_alpha=12, min_interval=0.0)
    demo = demos[20]
    idx = _feed(est, demo, 0.5, 5)
    k, a = est.map_hypothesis()
    z = np.linspace(0, 1, 11)
    out = est.predict(z)
    mean, cov = condition_on_observed(model.means_[k], model.covariances_[k], model.basis_,
                                      model.n_observed_, a * demo.t[idx], demo.observed[idx],
                                      model.observed_noise_var_)
    ref = trajectory_distribution(mean, cov, model.basis_, z, a,
                                  dofs=range(3, 3 + model.n_controlled_))
    for key in ('position', 'velocity', 'acceleration', 'position_cov'):
        assert np.allclose(out['controlled'][key], ref[key], atol=1e-8), key
    assert np.allclose(out['time'], z / a)
    assert out['component'] == k and out['alpha'] == a


def test_mean_trajectories_equal_predict_for_every_hypothesis(model_and_demos):
    """The compiled means for robot commands against predict (numpy, GaussianBasis.evaluate),
    phases outside [0, 1] included (basis held, derivatives zero there)."""
    model, demos, _ = model_and_demos
    est = OnlineEstimator(model, n_alpha=12, min_interval=0.0)
    demo = demos[7]
    for i in range(0, len(demo.t) // 2, 6):
        est.update(demo.t[i], demo.observed[i])
    z_c = np.concatenate([[-0.2, 0.0], np.sort(np.random.default_rng(0).uniform(0, 1, 17)),
                          [1.0, 1.3]])
    z_o = np.linspace(-0.1, 1.1, 9)
    for component, alpha in ((None, None), (0, None), (2, est.alphas[3]), (None, 0.77)):
        k, a, (pos, vel, acc), wrist = est.mean_trajectories(z_c, z_o, component, alpha)
        ref = est.predict(z_c, component=component, alpha=alpha, covariance=False)
        assert (k, a) == (ref['component'], ref['alpha'])
        for key, got in zip(('position', 'velocity', 'acceleration'), (pos, vel, acc)):
            assert np.allclose(got, ref['controlled'][key], rtol=1e-12, atol=1e-12), key
        assert not vel[0].any() and not acc[-1].any()        # z = -0.2 and z = 1.3
        assert np.allclose(wrist, est.predict(z_o, component=component, alpha=alpha)
                           ['observed']['position'], rtol=1e-12, atol=1e-12)


def test_posterior_follows_every_update(model_and_demos):
    """The joint posterior is computed once per update: it must change with each one."""
    model, demos, _ = model_and_demos
    est = OnlineEstimator(model, n_alpha=12, min_interval=0.0)
    before = est.joint_posterior().copy()
    est.update(demos[3].t[5], demos[3].observed[5])
    after = est.joint_posterior()
    lp = est.log_prior.ravel() + est.log_evidence_flat
    assert not np.allclose(before, after)
    assert np.allclose(after.ravel(), np.exp(lp - lp.max()) / np.exp(lp - lp.max()).sum())
    est.reset()
    assert np.allclose(est.joint_posterior(), before)


def test_online_selects_true_pattern_and_resets(model_and_demos):
    model, demos, labels = model_and_demos
    est = OnlineEstimator(model, n_alpha=20)
    comp_label = [np.bincount(labels[model.resp_.argmax(1) == k], minlength=3).argmax()
                  for k in range(3)]
    for i in (0, 15, 30):
        est.reset()
        assert est.n_observations == 0
        assert np.allclose(est.component_posterior(), model.weights_)
        for t, y in zip(demos[i].t, demos[i].observed):
            est.update(t, y)
        assert comp_label[est.map_hypothesis()[0]] == labels[i]
        assert est.component_posterior().max() > 0.99
        assert est.phase() == pytest.approx(1.0, abs=0.15)


def test_min_interval_skips_correlated_samples(model_and_demos):
    model, demos, _ = model_and_demos
    est = OnlineEstimator(model, n_alpha=5, min_interval=0.05)
    used = [est.update(t, y) for t, y in zip(demos[0].t[:30], demos[0].observed[:30])]
    assert sum(used) == 6 and est.n_observations == 6      # 100 Hz -> every 5th sample


def test_a_recording_offered_is_what_update_makes_of_it(model_and_demos):
    """offer (feeding a recording) uses and skips the same samples as update, to the same
    posterior; it checks a sample only once it is used."""
    model, demos, _ = model_and_demos
    updated, offered = (OnlineEstimator(model, n_alpha=5, min_interval=0.05) for _ in range(2))
    for t, y in zip(demos[0].t[:61], demos[0].observed[:61]):
        assert updated.update(t, y) == offered.offer(t, y)
    assert (offered.n_observations, offered.n_skipped) == (updated.n_observations,
                                                           updated.n_skipped) == (13, 48)
    assert np.array_equal(offered.joint_posterior(), updated.joint_posterior())
    t_next = float(demos[0].t[61])                       # 10 ms after the last one used
    assert offered.offer(t_next, [np.nan] * 3) is False       # skipped, never looked at
    with pytest.raises(ValueError, match='NaN'):
        updated.update(t_next, [np.nan] * 3)


def _state(est):
    return (est.n_observations, est.n_skipped, est.t_last, est.t_seen, est.log_evidence_flat,
            est.mu, est.sigma, est.joint_posterior(), np.array(est._times),
            np.array(est._values))


def _same_state(a, b):
    return all(x is y or np.array_equal(x, y, equal_nan=True)     # None: nothing yet
               for x, y in zip(_state(a), _state(b)))


@pytest.mark.parametrize('prune_below', [0.0, 1e-3])
def test_a_recording_offered_at_once_is_each_sample_offered_in_turn(model_and_demos,
                                                                     prune_below):
    """offer_many (a recording played to a cut: without pruning, every sample admitted in one
    kernel pass, each group of hypotheses taking them all in turn) leaves the state offer()
    leaves, to the bit, and returns log p(D) after each sample used."""
    model, demos, _ = model_and_demos
    each, many = (OnlineEstimator(model, n_alpha=7, min_interval=0.05, prune_below=prune_below)
                  for _ in range(2))
    t, y = demos[1].t, demos[1].observed
    for lo, hi in ((0, 1), (1, 37), (37, 38), (38, 41), (41, 90)):   # one sample, none used, ...
        marginals = []
        for ti, yi in zip(t[lo:hi], y[lo:hi]):
            if each.offer(ti, yi):
                marginals.append(each.log_marginal())
        got = many.offer_many(t[lo:hi], y[lo:hi])
        assert np.array_equal(got, marginals)
        assert _same_state(each, many)
    assert many.n_observations == 18 and many.n_skipped == 72
    assert len(many.offer_many([], np.zeros((0, 3)))) == 0 and _same_state(each, many)


def test_a_recording_played_to_cuts_is_offer_of_each_sample_to_each_cut(model_and_demos):
    """prefixes (the one way a recording is played to the estimator): reset, then after the
    samples up to each cut (the sample at a cut included, a cut between samples or before the
    first, cuts repeated) the state offer() of each observed sample leaves; a sample with the
    observed agent missing is not offered."""
    model, demos, _ = model_and_demos
    observed = demos[1].observed.copy()
    observed[7] = np.nan                       # the observed agent missing at one sample
    demo = Demonstration(demos[1].t, observed, demos[1].controlled)
    played, each = (OnlineEstimator(model, n_alpha=7, min_interval=0.05) for _ in range(2))
    played.offer(100.0, demo.observed[0])      # before the play: reset forgets it
    cuts = [-1.0, demo.t[3], demo.t[3], 0.5 * (demo.t[40] + demo.t[41]), demo.duration]
    done = 0
    for cut, got in zip(cuts, prefixes(played, demo, cuts)):
        assert got == cut
        for i in range(done, len(demo.t)):
            if demo.t[i] > cut + 1e-9:
                break
            if np.isfinite(demo.observed[i]).all():
                each.offer(demo.t[i], demo.observed[i])
            done = i + 1
        assert _same_state(each, played)
    assert played.n_observations + played.n_skipped == len(demo.t) - 1


def test_absorbed_rows_are_the_samples_an_estimator_fed_the_recording_absorbs(model_and_demos):
    """playback.absorbed_rows: of a recording with the observed agent missing at some samples
    (the first among them), the ones an estimator fed all of it absorbs, in order."""
    model, demos, _ = model_and_demos
    observed = demos[1].observed.copy()
    observed[[0, 7, 8]] = np.nan
    demo = Demonstration(demos[1].t, observed, demos[1].controlled)
    assert np.array_equal(observed_rows(demo), np.setdiff1d(np.arange(len(demo.t)), [0, 7, 8]))
    for min_interval in (0.0, 0.05, 0.13):
        est = OnlineEstimator(model, n_alpha=7, min_interval=min_interval)
        played_to(est, demo, demo.duration)
        rows = absorbed_rows(demo, min_interval)
        assert np.array_equal(est._times, demo.t[rows])
        assert np.array_equal(np.array(est._values), demo.observed[rows])


def test_the_rest_of_a_prefix_is_the_later_samples_with_the_controlled_agent_recorded(
        model_and_demos):
    """playback.rest_rows, where prefix_predictions predicts the controlled agent: after the
    cut (the sample at it excluded), the samples with the controlled agent recorded."""
    model, demos, _ = model_and_demos
    controlled = demos[1].controlled.copy()
    controlled[[30, 60]] = np.nan
    demo = Demonstration(demos[1].t, demos[1].observed, controlled)
    rest = rest_rows(demo, demo.t[29])
    assert np.array_equal(rest, np.setdiff1d(np.arange(30, len(demo.t)), [30, 60]))
    est = OnlineEstimator(model, n_alpha=7)
    for f, p in zip((0.3, 0.6), prefix_predictions(est, demo, (0.3, 0.6))):
        assert np.array_equal(p.rest, rest_rows(demo, f * demo.duration))
        assert p.controlled.shape == (len(p.rest), demo.n_controlled_dofs)


def test_speed_log_terms_give_the_tempered_speed_posterior_at_any_weight(model_and_demos):
    """What training's calibration reads (core.calibration.speed_log_scores): component k's
    log evidence and log prior over the grid, whose tempered posterior at the estimator's own
    weight is speed_posterior(k)."""
    model, demos, _ = model_and_demos
    est = OnlineEstimator(model, n_alpha=12)
    est.offer_many(demos[0].t[:40], demos[0].observed[:40])
    k = est.map_hypothesis()[0]
    evidence, log_prior = est.speed_log_terms(k)
    assert np.array_equal(evidence, est.log_evidence[k])
    assert np.array_equal(log_prior, est.log_prior[k])
    assert np.allclose(np.exp(tempered_speed_posterior(evidence, log_prior, est.speed_weight)),
                       est.speed_posterior(k), rtol=1e-12, atol=0)


def test_the_lanes_past_the_tracked_hypotheses_stay_valid_states(model_and_demos):
    """Pruning leaves the last group's lanes past the tracked columns with the phase speeds of
    hypotheses no longer tracked; the kernel updates them with the others, so their basis rows
    are computed too and their states stay finite."""
    model, demos, _ = model_and_demos
    est = OnlineEstimator(model, n_alpha=7, min_interval=0.05, prune_below=1e-3)
    est.offer_many(demos[2].t, demos[2].observed)
    groups = -(-est.n_tracked // 8)
    assert est.n_tracked % 8 and groups < len(est._cov)        # a part-filled last group
    for state in (est._cov, est._mu):
        assert np.isfinite(state[:groups]).all()


def test_a_bad_sample_offered_at_once_stops_where_offer_stops(model_and_demos):
    """A NaN in a sample used, or a time that goes back: the samples before it are in, the
    error is offer()'s, and the state is what offer() leaves."""
    model, demos, _ = model_and_demos
    t, y = demos[0].t[:40].copy(), demos[0].observed[:40].copy()
    y[20] = np.nan                          # used (every 5th sample is)
    y[22] = np.inf                          # skipped: never looked at
    cases = [(t, y, 'NaN'), (np.r_[t[:10], t[5:15]], np.r_[y[:10], y[5:15]], 'increase')]
    for times, values, message in cases:
        each, many = (OnlineEstimator(model, n_alpha=5, min_interval=0.05) for _ in range(2))
        with pytest.raises(ValueError, match=message):
            for ti, yi in zip(times, values):
                each.offer(ti, yi)
        with pytest.raises(ValueError, match=message):
            many.offer_many(times, values)
        assert many.n_observations > 0 and _same_state(each, many)
    with pytest.raises(ValueError, match='3 times for 2 samples'):
        many.offer_many(t[30:33], y[30:32])
    # Rows as lists, a short one among the skipped (never read, as offer() never reads it);
    # float32 stamps decimated alike.
    rows = [list(r) for r in demos[0].observed[:12]]
    rows[3] = [0.0]
    stamps = np.float32(demos[0].t[:12] + 0.00056342216)
    each, many = (OnlineEstimator(model, n_alpha=5, min_interval=0.05) for _ in range(2))
    used = [each.offer(ti, yi) for ti, yi in zip(stamps, rows)]
    assert len(many.offer_many(stamps, rows)) == sum(used) >= 2 and _same_state(each, many)


def test_online_rejects_bad_input(model_and_demos):
    model, _, _ = model_and_demos
    est = OnlineEstimator(model, n_alpha=5, min_interval=0.0)
    with pytest.raises(ValueError, match='NaN'):
        est.update(0.1, [np.nan, 0, 0])
    with pytest.raises(ValueError, match='shape'):
        est.update(0.1, [0, 0])
    with pytest.raises(ValueError, match='before the onset'):
        est.update(-0.1, [0, 0, 0])
    est.update(0.2, [0, 0, 0])
    with pytest.raises(ValueError, match='increase'):
        est.update(0.1, [0, 0, 0])
    assert est.n_observations == 1 and np.all(np.isfinite(est.log_evidence))


def test_alpha_map_within_ten_percent_after_forty_percent_observed():
    """Thesis 4.3.1: durations differing by 2x; 20 train / 40 test trajectories."""
    rng = np.random.default_rng(11)
    from mixture_ip_ros.core.basis import GaussianBasis
    b = GaussianBasis(10)
    P, Q, N = 2, 1, 10
    zc = b.centers
    mean = np.concatenate([np.sin(2.5 * zc), 0.6 * np.cos(3 * zc) - 0.3, zc ** 2])
    cov = random_spd(rng, (P + Q) * N, 0.002, rank=4)

    def demo():
        w = rng.multivariate_normal(mean, cov)
        t, Y = sample_trajectory(b, w, P + Q, rng.uniform(1.0, 2.0), noise=0.002, rng=rng)
        return Demonstration(t, Y[:, :P], Y[:, P:])
    train = [demo() for _ in range(20)]
    model = MixtureIProMP(1, n_basis=10, observation_noise=0.005).fit(train)
    hits = []
    for _ in range(40):
        d = demo()
        est = OnlineEstimator(model, n_alpha=50)
        n = int(0.4 * len(d.t))
        for t, y in zip(d.t[:n], d.observed[:n]):
            est.update(t, y)
        hits.append(abs(est.map_hypothesis()[1] * d.duration - 1) < 0.1)
    assert np.mean(hits) >= 0.9


def test_alpha_prior_is_the_map_spread_made_predictive_plus_the_timing_resolution():
    durations = np.array([1.0, 1.25, 2.0, 4.0])
    a = 1 / durations
    resp = np.array([[1, 0, 0], [1, 0, 0], [0, 1, 0], [0, 1, 0]], dtype=float)
    v0, s = 0.01, 2.0
    mean, var, nk = alpha_m_step(a, resp, v0, s)
    assert np.allclose(mean[:2], [a[:2].mean(), a[2:].mean()]) and mean[2] == a.mean()
    S = np.array([2 * a[:2].var(), 2 * a[2:].var()])
    assert np.allclose(var[:2], (S + s * v0) / (2 + s)) and var[2] == pytest.approx(v0)
    # Sensor: onset and end each within a sample: var(alpha) = alpha^4 dt^2 / 6.
    tv = timing_variance([2.0], [0.1])
    assert tv[0] == pytest.approx(0.5 ** 4 * 0.01 / 6)
    std = alpha_prior_std(var, nk, tv[0])
    assert np.allclose(std[:2] ** 2, var[:2] * 1.5 + tv[0])
    # Identical durations leave the timing spread, not a fixed 5 % floor.
    demos = mixture_demos(seed=1, durations=((1.5, 1.5),) * 3)[0]
    m = MixtureIProMP(3, n_basis=8).fit(demos)
    assert np.allclose(m.alpha_mean_, 1 / 1.5)
    assert np.all(m.alpha_std_ < 0.01 * m.alpha_mean_)


def test_final_posture_conditions_on_the_final_position_at_phase_one(model_and_demos):
    """predict_at_rest is eq. 13 with D = final wrist position at z = 1: dense check."""
    model, demos, _ = model_and_demos
    est = OnlineEstimator(model, n_alpha=5)
    y = demos[7].observed[-1]
    k = 1
    mean, cov = est.predict_at_rest(y, component=k)
    P = model.n_observed_
    D = P + model.n_controlled_
    A = np.kron(np.eye(D), model.basis_([1.0]))             # every DOF at z = 1
    mu, C = A @ model.means_[k], A @ model.covariances_[k] @ A.T
    S = C[:P, :P] + np.diag(model.observed_noise_var_)
    gain = C[P:, :P] @ np.linalg.inv(S)
    assert np.allclose(mean, mu[P:] + gain @ (y - mu[:P]), atol=1e-9)
    assert np.allclose(cov, C[P:, P:] - gain @ C[:P, P:], atol=1e-9)


def test_decimation_is_counted_and_the_phase_refers_to_the_latest_time_offered(model_and_demos):
    model, demos, _ = model_and_demos
    est = OnlineEstimator(model, n_alpha=12, min_interval=0.05)
    demo = demos[3]
    used = [est.update(t, y) for t, y in zip(demo.t, demo.observed)]
    assert est.n_observations == sum(used) and est.n_skipped == len(used) - sum(used)
    assert est.t_seen == demo.t[-1] and est.t_last <= demo.t[-1]
    k, a = est.map_hypothesis()
    assert est.phase() == pytest.approx(min(1.0, a * demo.t[-1]))
    assert est.phase(0.2) == pytest.approx(min(1.0, a * 0.2))


def test_per_component_noise_online_equals_batch_eq18_with_each_components_noise():
    demos = mixture_demos(seed=2, n_obs=2, n_ctrl=1)[0]
    model = MixtureIProMP(3, n_basis=8, noise='per_component').fit(demos)
    assert model.observed_noise_var_.shape == (3, 2)
    est = OnlineEstimator(model, n_alpha=6, min_interval=0.0)
    demo = demos[5]
    idx = _feed(est, demo, 1.0, 7)
    do = 2 * model.n_basis
    for k in range(3):
        for m in (0, 5):
            ref = log_evidence_batch(model.means_[k][:do], model.covariances_[k][:do, :do],
                                     model.basis_, demo.t[idx], demo.observed[idx],
                                     est.alphas[m], model.observed_noise_var_[k])
            assert est.log_evidence[k, m] == pytest.approx(ref, rel=1e-8)


def test_every_hypothesis_posterior_equals_dense_conditioning(model_and_demos):
    """mu and Sigma of each (k, alpha_m), read back from the lane groups, against eqs. 3-5 with
    the dense observed-agent block (phases alpha_m t)."""
    model, demos, _ = model_and_demos
    est = OnlineEstimator(model, n_alpha=7, min_interval=0.0)     # 21 columns: a partial group
    demo = demos[11]
    idx = _feed(est, demo, 0.6, 7)
    do = model.n_observed_ * model.n_basis
    mu, sigma = est.mu, est.sigma
    for k in range(3):
        for m, a in enumerate(est.alphas):
            mean, cov = condition_on_observed(model.means_[k], model.covariances_[k],
                                              model.basis_, model.n_observed_, a * demo.t[idx],
                                              demo.observed[idx], model.observed_noise_var_)
            h = k * len(est.alphas) + m
            np.testing.assert_allclose(mu[h], mean[:do], rtol=1e-8, atol=1e-10)
            np.testing.assert_allclose(sigma[h], cov[:do, :do], rtol=1e-7, atol=1e-12)
            got = est.observed_weights(k, m)
            np.testing.assert_array_equal(got[0], mu[h])
            np.testing.assert_array_equal(got[1], sigma[h])


def _stream(demo, stop=0.8):
    n = int(stop * len(demo.t))
    return demo.t[:n], demo.observed[:n]


def test_pruning_keeps_the_kept_hypotheses_exact_and_tracks_the_dropped_mass(model_and_demos):
    """Side by side with the exact estimator: each hypothesis is dropped only when its posterior,
    renormalised over those still tracked, is below prune_below; pruned_mass adds exactly those
    probabilities; the kept ones have the exact log evidence and the exact posterior
    renormalised over them."""
    model, demos, _ = model_and_demos
    tau = 1e-12
    exact = OnlineEstimator(model, n_alpha=12, min_interval=0.0)
    pruned = OnlineEstimator(model, n_alpha=12, min_interval=0.0, prune_below=tau)
    tracked = np.ones(exact.log_evidence_flat.size, dtype=bool)
    mass = 0.0
    for t, y in zip(*_stream(demos[4])):
        exact.update(t, y)
        pruned.update(t, y)
        lp = exact._log_prior + exact.log_evidence_flat
        p = np.where(tracked, np.exp(lp - lp[tracked].max()), 0.0)
        p /= p.sum()
        now = np.isfinite(pruned.log_evidence_flat)
        assert not (now & ~tracked).any()
        dropped = tracked & ~now
        assert np.all(p[dropped] < tau)
        mass += p[dropped].sum()
        tracked = now
        assert pruned.n_tracked == tracked.sum()
        np.testing.assert_allclose(pruned.log_evidence_flat[tracked],
                                   exact.log_evidence_flat[tracked], rtol=1e-12)
        q = np.where(tracked, p, 0.0)
        np.testing.assert_allclose(pruned.joint_posterior().ravel(), q / q.sum(), atol=1e-12)
    assert pruned.n_tracked < 36 / 4 and pruned.pruned_mass == pytest.approx(mass, rel=1e-12)
    assert 0 < pruned.pruned_mass < (36 - pruned.n_tracked) * tau
    assert pruned.map_hypothesis() == exact.map_hypothesis()
    assert exact.prune() == 0 and exact.n_tracked == 36          # prune_below = 0: exact
    k, m = np.argwhere(~tracked.reshape(3, -1))[0]
    assert pruned.joint_posterior()[k, m] == 0 and pruned.log_evidence[k, m] == -np.inf
    assert np.isnan(pruned.mu[k * 12 + m]).all() and np.isnan(pruned.sigma[k * 12 + m]).all()
    with pytest.raises(ValueError, match='pruned'):
        pruned.observed_weights(k, m)
    z = np.linspace(0, 1, 5)
    np.testing.assert_allclose(pruned.predict(z)['controlled']['position'],
                               exact.predict(z)['controlled']['position'], atol=1e-9)
    pruned.reset()
    assert pruned.n_tracked == 36 and pruned.pruned_mass == 0
    assert np.isfinite(pruned.log_evidence).all()
    np.testing.assert_allclose(pruned.joint_posterior(),
                               OnlineEstimator(model, n_alpha=12).joint_posterior(), atol=1e-15)


def test_samples_absorbed_in_any_order_then_pruned_give_one_result(model_and_demos):
    """absorb does not prune: held samples absorbed after live ones, in a shuffled order, then
    prune(), keep the hypotheses the time-ordered absorb + prune() keeps, with the batch eq. 18
    log evidence of all the samples."""
    model, demos, _ = model_and_demos
    t, Y = _stream(demos[30])
    t, Y = t[::3], Y[::3]
    estimators = []
    for order in (np.arange(len(t)), np.random.default_rng(3).permutation(len(t))):
        est = OnlineEstimator(model, n_alpha=12, min_interval=0.0, prune_below=1e-12)
        for i in order:
            est.absorb(t[i], Y[i])
        assert est.n_tracked == 36
        assert est.prune() == 36 - est.n_tracked > 0 and est.prune() == 0
        estimators.append(est)
    ordered, shuffled = estimators
    np.testing.assert_array_equal(shuffled.joint_posterior() > 0, ordered.joint_posterior() > 0)
    np.testing.assert_allclose(shuffled.joint_posterior(), ordered.joint_posterior(), atol=1e-9)
    assert shuffled.joint_posterior().sum() == pytest.approx(1.0)
    do = model.n_observed_ * model.n_basis
    for k, m in np.argwhere(shuffled.joint_posterior() > 0):
        ref = log_evidence_batch(model.means_[k][:do], model.covariances_[k][:do, :do],
                                 model.basis_, t, Y, shuffled.alphas[m], model.observed_noise_var_)
        assert shuffled.log_evidence[k, m] == pytest.approx(ref, rel=1e-8)


def test_pruning_never_empties_the_posterior_or_makes_it_nan(model_and_demos):
    """Observations no hypothesis explains (a wrist 50 m away) give log evidences of -1e9 and
    below: the most probable hypothesis is always kept."""
    model, _, _ = model_and_demos
    est = OnlineEstimator(model, n_alpha=12, min_interval=0.0, prune_below=1.0 / 36 - 1e-9)
    for i, t in enumerate(np.linspace(0.05, 2.0, 30)):
        est.update(t, [50.0 * (-1) ** i, -50.0, 50.0])
        joint = est.joint_posterior()
        assert est.n_tracked >= 1 and np.isfinite(joint).all()
        assert joint.sum() == pytest.approx(1.0)
    assert np.isfinite(est.predict([0.5])['controlled']['position']).all()
    for bad in (-1e-3, 1.0 / 36, 0.5):
        with pytest.raises(ValueError, match='prune_below'):
            OnlineEstimator(model, n_alpha=12, prune_below=bad)


def _dense_evidence(model, k, z, Y):
    """log N(D; A mu_k, Sigma_D + A Sigma_k A^T) of the observed agent, D stacked DOF-major."""
    P = model.n_observed_
    do = P * model.n_basis
    A = np.kron(np.eye(P), model.basis_(z))
    S = (np.diag(np.repeat(model.observed_noise(k), len(z)))
         + A @ model.covariances_[k][:do, :do] @ A.T)
    return multivariate_normal(A @ model.means_[k][:do], S).logpdf(Y.T.ravel())


def test_posterior_at_is_the_grid_state_on_the_grid_and_dense_conditioning_between(
        model_and_demos):
    model, demos, _ = model_and_demos
    est = OnlineEstimator(model, n_alpha=9, min_interval=0.0)
    demo = demos[11]
    idx = np.arange(0, int(0.6 * len(demo.t)), 6)
    for i in idx[::-1]:                                   # any order: the weights are static
        est.absorb(demo.t[i], demo.observed[i])
    for k in range(3):
        for m in (0, 4, 8):
            mean, cov, ll = est.posterior_at(k, est.alphas[m])
            want_mean, want_cov = est.observed_weights(k, m)
            assert np.allclose(mean, want_mean, rtol=1e-8, atol=1e-10)
            assert np.allclose(cov, want_cov, rtol=1e-7, atol=1e-12)
            assert ll == pytest.approx(est.log_evidence[k, m], rel=1e-9)
    alpha = 0.5 * (est.alphas[3] + est.alphas[4])             # between two grid values
    z = alpha * demo.t[idx]
    mean, cov, ll = est.posterior_at(1, alpha)
    assert ll == pytest.approx(_dense_evidence(model, 1, z, demo.observed[idx]), rel=1e-9)
    do = model.n_observed_ * model.n_basis
    A = np.kron(np.eye(model.n_observed_), model.basis_(z))
    C = model.covariances_[1][:do, :do]
    S = np.diag(np.repeat(model.observed_noise_var_, len(z))) + A @ C @ A.T
    gain = C @ A.T @ np.linalg.inv(S)
    assert np.allclose(mean, model.means_[1][:do] + gain @ (demo.observed[idx].T.ravel()
                                                            - A @ model.means_[1][:do]))
    assert np.allclose(cov, C - gain @ A @ C, atol=1e-10)
    with pytest.raises(ValueError, match='alpha must be a positive number'):
        est.posterior_at(0, -1.0)
    with pytest.raises(ValueError, match='no observation absorbed'):
        OnlineEstimator(model, n_alpha=3).posterior_at(0, 1.0)


def test_refined_alpha_is_the_vertex_of_the_batch_log_posterior_parabola(model_and_demos):
    model, demos, _ = model_and_demos
    est = OnlineEstimator(model, n_alpha=15, min_interval=0.0)
    demo = demos[25]
    idx = _feed(est, demo, 0.5, 4)
    k, a = est.map_hypothesis()
    m = int(np.argmin(np.abs(est.alphas - a)))
    assert 0 < m < 14
    batch = phase_posterior_batch(model, demo.t[idx], demo.observed[idx], est.alphas)[k]
    x = est.alphas[m - 1:m + 2]
    c2, c1, _ = np.polyfit(x - x[1], batch[m - 1:m + 2], 2)
    refined = est.refined_alpha()
    assert refined == pytest.approx(x[1] - c1 / (2 * c2), rel=1e-9)
    assert abs(refined - a) <= 0.5 * (est.alphas[1] - est.alphas[0])
    assert est.refined_alpha(k) == refined
    # Before any observation, and at the ends of the grid: the grid value.
    fresh = OnlineEstimator(model, n_alpha=15)
    assert fresh.refined_alpha() == fresh.map_hypothesis()[1]


def test_refined_alpha_from_a_coarse_grid_is_nearer_the_fine_grid_map_than_the_coarse_map():
    """Sampled demonstrations of one pattern, durations 1-2 s: after 40 % the coarse grid's
    (15 values) MAP is off by up to half its step (a quarter on average); the refined alpha is
    within a tenth of a step of a 2000-value grid's MAP (a few % on average). The bounds leave
    room for the draws, which differ between numpy releases."""
    rng = np.random.default_rng(11)
    from mixture_ip_ros.core.basis import GaussianBasis
    b = GaussianBasis(10)
    zc = b.centers
    mean = np.concatenate([np.sin(2.5 * zc), 0.6 * np.cos(3 * zc) - 0.3])
    cov = random_spd(rng, 20, 0.002, rank=4)

    def demo():
        w = rng.multivariate_normal(mean, cov)
        t, Y = sample_trajectory(b, w, 2, rng.uniform(1.0, 2.0), noise=0.002, rng=rng)
        return Demonstration(t, Y)
    model = MixtureIProMP(1, n_basis=10).fit([demo() for _ in range(20)])
    coarse_err, refined_err = [], []
    for _ in range(10):
        d = demo()
        coarse = OnlineEstimator(model, n_alpha=15, min_interval=0.0)
        fine = OnlineEstimator(model, n_alpha=2000, min_interval=0.0)
        for t, y in zip(d.t[:int(0.4 * len(d.t)):3], d.observed[:int(0.4 * len(d.t)):3]):
            coarse.update(t, y)
            fine.update(t, y)
        step = coarse.alphas[1] - coarse.alphas[0]
        best = fine.map_hypothesis()[1]
        coarse_err.append(abs(coarse.map_hypothesis()[1] - best) / step)
        refined_err.append(abs(coarse.refined_alpha() - best) / step)
    assert np.mean(refined_err) < 0.15 * np.mean(coarse_err) and max(refined_err) < 0.1


def test_end_posterior_is_the_batch_posterior_with_the_phase_known(model_and_demos):
    """Once the end time T is known the phase is 1 there: p(k | D, T) is eq. 11 with z = t / T
    and alpha = 1/T's evidence p(alpha | k), against dense conditioning."""
    model, demos, _ = model_and_demos
    est = OnlineEstimator(model, n_alpha=10, min_interval=0.05)
    demo = demos[30]
    used = [i for i, (t, y) in enumerate(zip(demo.t, demo.observed)) if est.update(t, y)]
    T = demo.duration
    lp = np.array([np.log(model.weights_[k])
                   + norm(model.alpha_mean_[k], model.alpha_std_[k]).logpdf(1 / T)
                   + _dense_evidence(model, k, demo.t[used] / T, demo.observed[used])
                   for k in range(3)])
    want = np.exp(lp - logsumexp(lp))
    assert np.allclose(est.end_posterior(T), want, rtol=1e-8, atol=1e-12)
    assert np.allclose(est.end_posterior(T), model.component_posterior(
        demo.t[used] / T, demo.observed[used], alpha=1 / T), rtol=1e-12)
    # A later end: the samples sit earlier in the movement.
    lp_later = [np.log(model.weights_[k])
                + norm(model.alpha_mean_[k], model.alpha_std_[k]).logpdf(1 / (1.2 * T))
                + _dense_evidence(model, k, demo.t[used] / (1.2 * T), demo.observed[used])
                for k in range(3)]
    assert np.allclose(est.end_posterior(1.2 * T), np.exp(lp_later - logsumexp(lp_later)),
                       rtol=1e-8, atol=1e-12)
    # An end dated back before the last samples (the hand at rest since): those at phase 1.
    z_early = np.minimum(demo.t[used] / (0.8 * T), 1.0)
    lp_early = [np.log(model.weights_[k])
                + norm(model.alpha_mean_[k], model.alpha_std_[k]).logpdf(1 / (0.8 * T))
                + _dense_evidence(model, k, z_early, demo.observed[used]) for k in range(3)]
    assert np.allclose(est.end_posterior(0.8 * T), np.exp(lp_early - logsumexp(lp_early)),
                       rtol=1e-8, atol=1e-12)
    for bad in (0.0, -1.0, np.nan):
        with pytest.raises(ValueError, match='positive number of seconds'):
            est.end_posterior(bad)
    with pytest.raises(ValueError, match='no observation absorbed'):
        OnlineEstimator(model, n_alpha=3).end_posterior(1.0)
    est.reset()
    with pytest.raises(ValueError, match='no observation absorbed'):
        est.end_posterior(T)


def test_tempered_speed_posterior_spans_eq16_to_the_prior(model_and_demos):
    """Weight 1: each component's row of the exact joint posterior (eq. 16), normalised;
    weight 0: p(alpha | k); the component posterior (eq. 11) does not depend on the weight, and
    the MAP speed is the tempered posterior's."""
    import copy
    model, demos, _ = model_and_demos
    estimators = {}
    for w in (1.0, 0.3, 0.0):
        m = copy.copy(model)
        m.speed_weight = w
        est = estimators[w] = OnlineEstimator(m, n_alpha=30)
        _feed(est, demos[4], 0.4, 3)
    exact, K = estimators[1.0], model.n_components
    joint = exact.joint_posterior()
    prior = np.exp(alpha_log_prior(exact.alphas, model.alpha_mean_, model.alpha_std_))
    for k in range(K):
        if joint[k].sum() > 1e-100:             # a component the evidence left is all zeros
            assert np.allclose(exact.speed_posterior(k), joint[k] / joint[k].sum(), atol=1e-9)
        assert np.allclose(estimators[0.0].speed_posterior(k), prior[k], atol=1e-12)
        lp = 0.3 * exact.log_evidence[k] + np.log(prior[k])
        assert np.allclose(estimators[0.3].speed_posterior(k), np.exp(lp - logsumexp(lp)),
                           atol=1e-12)
    for est in estimators.values():
        assert np.allclose(est.component_posterior(), exact.component_posterior(), atol=1e-12)
        k, a = est.map_hypothesis()
        assert a == est.alphas[np.argmax(est.speed_posterior(k))]
        assert np.isclose(est.alpha_posterior().sum(), 1.0)
    assert np.allclose(exact.alpha_posterior(), joint.sum(axis=0), atol=1e-12)
    # a pruned hypothesis stays out of it
    assert tempered_speed_posterior(np.array([-np.inf, 0.0, -1.0]), np.zeros(3), 0.0)[0] == -np.inf


def test_log_density_on_grid_is_the_density_of_a_fine_grid_posterior():
    grid = np.linspace(0.2, 1.8, 400)
    lp = norm.logpdf(grid, 1.0, 0.1)
    lp -= logsumexp(lp)
    for a in (0.85, 1.0, 1.23):
        assert log_density_on_grid(lp, grid, a) == pytest.approx(norm.logpdf(a, 1.0, 0.1),
                                                                 abs=1e-3)
    assert log_density_on_grid(lp, grid, 2.5) == pytest.approx(np.log(1e-12))


def test_pruning_keeps_the_speeds_the_tempered_posterior_holds(model_and_demos):
    """A speed the exact posterior rules out but the tempered one (what the plans read) still
    holds is not pruned; a component with nothing left is refused by name."""
    import copy
    model, demos, _ = model_and_demos
    tempered = copy.copy(model)
    tempered.speed_weight = 0.0
    full = OnlineEstimator(tempered, n_alpha=30)
    pruned = OnlineEstimator(tempered, n_alpha=30, prune_below=1e-4)
    exact = OnlineEstimator(model, n_alpha=30, prune_below=1e-4)
    for est in (full, pruned, exact):
        _feed(est, demos[4], 0.4, 3)
    k = full.map_hypothesis()[0]
    share = full.component_posterior()[k] * full.speed_posterior(k)
    kept = pruned.log_evidence[k] > -np.inf
    assert np.all(kept[share >= 1e-4])
    assert kept.sum() > (exact.log_evidence[k] > -np.inf).sum()
    t = np.linspace(0.5, 3.0, 20)
    assert np.allclose(pruned.expected_controlled(t, k)[1], full.expected_controlled(t, k)[1],
                       atol=1e-3 * np.abs(full.expected_controlled(t, k)[1]).max())
    gone = [c for c in range(model.n_components) if np.all(exact.log_evidence[c] == -np.inf)]
    assert gone
    with pytest.raises(ValueError, match=f'every hypothesis of component {gone[0]} was pruned'):
        exact.expected_controlled(t, gone[0])
