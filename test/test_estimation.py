"""The estimator's logic without ROS (estimation/): plans against the OnlineEstimator's own
prediction, the commit rule, the replan schedule on an injected clock, held samples, interaction
records and rejection of bad input."""

import copy

import numpy as np
import pytest

from mixture_ip_ros.core.online import OnlineEstimator
from mixture_ip_ros.core.phase import alpha_log_prior, log_evidence_batch
from mixture_ip_ros.io.model_file import load_model
from mixture_ip_ros.estimation.held import HeldSamples
from mixture_ip_ros.estimation.planner import OnlinePlanner, PlannerSettings, should_commit
from mixture_ip_ros.estimation.plans import (CATCH_UP_RESOLUTION, PHASE_EPS, SLOWDOWN_MARGIN,
                                             Plan, PosteriorSummary, build_plan, check_plan,
                                             posterior_summary, predicted_wrist)
from mixture_ip_ros.estimation.records import LatencyStats
from mixture_ip_ros.estimation.schedule import ReplanSchedule
from mixture_ip_ros.app.training import train_to_file

from mixture_ip_ros.scenarios.synthetic import mixture_demos

HELD_OUT = (0, 13, 30)   # one demonstration of each pattern, not used for training


@pytest.fixture(scope='module')
def trained(tmp_path_factory):
    demos = mixture_demos(seed=0, n_obs=3, n_ctrl=7, n_basis=8)[0]
    train = [d for i, d in enumerate(demos) if i not in HELD_OUT]
    path = tmp_path_factory.mktemp('model') / 'model.npz'
    train_to_file(train, path, n_components=3, n_basis=8)
    model, meta = load_model(path)
    return model, meta, [demos[i] for i in HELD_OUT]


@pytest.fixture(scope='module')
def noisy(tmp_path_factory):
    """A model assuming a noisy sensor (0.8 m): confidence grows over several observations
    instead of after the first one, so the threshold, not min_observations, gates the commit."""
    demos = mixture_demos(seed=0, n_obs=3, n_ctrl=7, n_basis=8)[0]
    train = [d for i, d in enumerate(demos) if i not in HELD_OUT]
    path = tmp_path_factory.mktemp('noisy') / 'model.npz'
    train_to_file(train, path, n_components=3, n_basis=8, observation_noise=0.8)
    model, meta = load_model(path)
    return model, meta, [demos[i] for i in HELD_OUT]


def _feed(est, demo, until=np.inf):
    for t, y in zip(demo.t, demo.observed):
        if t > until:
            break
        est.update(t, y)


def _ns(t):
    return int(round(t * 1e9))


def _t(t):
    """The time the planner sees for an observation stamped onset + t (ns resolution)."""
    return _ns(t) * 1e-9


def test_plan_at_a_given_speed_follows_its_prediction_from_now_to_the_end(trained):
    model, _, held = trained
    demo = held[1]
    est = OnlineEstimator(model)
    _feed(est, demo, until=0.4 * demo.duration)
    t_now = float(demo.t[demo.t <= 0.4 * demo.duration][-1])
    k, alpha = est.map_hypothesis()
    plan = build_plan(est, t_now, n_points=25, lookahead=0.1, alpha=alpha)
    assert (plan.component, plan.alpha, plan.final) == (k, alpha, False)
    assert plan.positions.shape == plan.velocities.shape == plan.accelerations.shape == (25, 7)
    assert plan.times.shape == plan.phases.shape == (25,)
    assert check_plan(plan) is None
    assert np.all(np.diff(plan.times) > 0)
    # time_from_start = z / alpha*, from the lookahead point to the end of the movement
    assert np.allclose(plan.times, plan.phases / alpha, rtol=0, atol=1e-12)
    assert plan.times[0] == pytest.approx(t_now + 0.1, abs=1e-12)
    assert plan.phases[-1] == 1.0
    ref = est.predict(plan.phases)
    assert np.allclose(plan.positions, ref['controlled']['position'], atol=1e-12)
    assert np.allclose(plan.velocities[:-1], ref['controlled']['velocity'][:-1], atol=1e-12)
    assert np.allclose(plan.accelerations[:-1], ref['controlled']['acceleration'][:-1],
                       atol=1e-12)
    assert not plan.velocities[-1].any() and not plan.accelerations[-1].any()
    # the whole predicted wrist movement, phases 0..1
    times, wrist = predicted_wrist(est, plan, 25)
    z = np.linspace(0, 1, 25)
    assert np.allclose(times, z / alpha, rtol=0, atol=1e-12)
    assert np.allclose(wrist, ref_wrist := est.predict(z)['observed']['position'], atol=1e-12)
    assert ref_wrist.shape == (25, 3)


def _tempered(model, weight):
    m = copy.copy(model)
    m.speed_weight = weight
    return m


def _expected_path_oracle(model, demo, until, k, times):
    """The expected controlled path under component k, the speed marginalised, from the batch
    formulas: eq. 18 per grid speed (core.phase.log_evidence_batch), tempered by the model's
    speed weight, times p(alpha | k), normalised; each speed's conditioned mean (eq. 13, the
    estimator's own predict at that grid speed) weighted by it."""
    ref = OnlineEstimator(model)
    _feed(ref, demo, until=until)
    t, y = np.array(ref._times), np.array(ref._values)
    do = model.n_observed_ * model.n_basis
    noise = model.observed_noise_var_at(ref.min_interval)
    lp = np.array([model.speed_weight * log_evidence_batch(
        model.means_[k][:do], model.covariances_[k][:do, :do], model.basis_, t, y, a, noise)
        for a in ref.alphas]) + alpha_log_prior(ref.alphas, model.alpha_mean_,
                                                model.alpha_std_)[k]
    p = np.exp(lp - lp.max())
    keep = p >= 1e-3 * p.max()
    p = np.where(keep, p, 0.0) / p[keep].sum()
    path = sum(p[m] * ref.predict(ref.alphas[m] * times, component=k, alpha=ref.alphas[m],
                                  covariance=False)['controlled']['position']
               for m in np.flatnonzero(keep))
    return path, 1.0 / ref.alphas[keep].min()


@pytest.mark.parametrize('weight', [1.0, 0.2])
def test_plan_marginalises_the_phase_speed_from_now_to_the_slowest_end(trained, weight):
    model, _, held = trained
    model = _tempered(model, weight)
    demo = held[1]
    est = OnlineEstimator(model)
    until = 0.4 * demo.duration
    _feed(est, demo, until=until)
    t_now = float(demo.t[demo.t <= until][-1])
    k = est.map_hypothesis()[0]
    plan = build_plan(est, t_now, n_points=25, lookahead=0.1)
    assert plan.component == k and not plan.final and check_plan(plan) is None
    assert len(est.speed_hypotheses()[0]) > 1                # more than one speed holds it
    oracle, t_end = _expected_path_oracle(model, demo, until, k, plan.times)
    assert plan.times[0] == pytest.approx(t_now + 0.1, abs=1e-12)
    assert plan.times[-1] == pytest.approx(t_end, rel=1e-12)
    assert np.allclose(plan.positions, oracle, atol=1e-10)
    assert not plan.velocities[-1].any() and not plan.accelerations[-1].any()
    # the phases shown are the MAP speed's
    assert plan.alpha == est.alphas[np.argmax(est.speed_posterior(k))]
    assert np.allclose(plan.phases, np.minimum(plan.alpha * plan.times, 1.0))


def test_plan_velocities_are_time_derivatives_of_positions(trained):
    model, _, held = trained
    est = OnlineEstimator(_tempered(model, 0.2))
    _feed(est, held[0], until=0.3)
    for alpha in (est.map_hypothesis()[1], None):
        plan = build_plan(est, 0.3, n_points=2001, lookahead=0.0, alpha=alpha)
        dt = np.diff(plan.times)
        # each speed hypothesis stops at its own end (alpha_m t = 1): its velocity steps there
        ends = 1.0 / est.alphas[est.speed_hypotheses()[0]]
        smooth = ~np.any((plan.times[:-1, None] < ends) & (ends <= plan.times[1:, None]),
                         axis=1)
        smooth[-1] = False                              # the last point is set to rest
        fd_vel = np.diff(plan.positions, axis=0) / dt[:, None]          # midpoints
        mid_vel = 0.5 * (plan.velocities[1:] + plan.velocities[:-1])
        scale = np.abs(plan.velocities).max()
        assert np.abs(fd_vel - mid_vel)[smooth].max() < 1e-4 * scale
        fd_acc = np.diff(plan.velocities, axis=0) / dt[:, None]
        mid_acc = 0.5 * (plan.accelerations[1:] + plan.accelerations[:-1])
        both = smooth[:-1] & smooth[1:]
        assert (np.abs(fd_acc - mid_acc)[:-1][both].max()
                < 1e-3 * np.abs(plan.accelerations).max())


def test_human_at_rest_gives_a_single_point_at_the_final_posture(trained):
    model, _, held = trained
    demo = held[2]
    est = OnlineEstimator(_tempered(model, 0.2))
    _feed(est, demo)
    k = est.map_hypothesis()[0]
    speeds, p = est.speed_hypotheses()
    assert len(speeds) > 1
    t_now = 1.0 / est.alphas[speeds].min() + 0.2         # past every speed's end
    plan = build_plan(est, t_now, lookahead=0.1, settle_time=0.5)
    assert plan.final and plan.times.tolist() == [t_now + 0.5] and plan.phases.tolist() == [1.0]
    finals = [est.predict([1.0], component=k, alpha=est.alphas[m])['controlled']['position'][0]
              for m in speeds]
    assert np.allclose(plan.positions[0], p @ np.array(finals), atol=1e-12)
    assert not plan.velocities.any() and not plan.accelerations.any()
    assert check_plan(plan) is None
    # the final posture matches the held-out demonstration's (an independent check)
    assert np.abs(plan.positions[0] - demo.controlled[-1]).max() < 0.1


def test_check_plan_refuses_nan_non_increasing_times_and_motion_at_the_end(trained):
    model, _, held = trained
    est = OnlineEstimator(model)
    _feed(est, held[0], until=0.3)
    good = build_plan(est, 0.3, n_points=5)

    def changed(**kw):
        fields = dict(good.__dict__)
        fields.update(kw)
        return Plan(**fields)
    pos = good.positions.copy()
    pos[2, 3] = np.nan
    assert 'positions' in check_plan(changed(positions=pos))
    acc = good.accelerations.copy()
    acc[0, 0] = np.inf
    assert 'accelerations' in check_plan(changed(accelerations=acc))
    times = good.times.copy()
    times[3] = times[2]
    assert 'increasing' in check_plan(changed(times=times))
    vel = good.velocities.copy()
    vel[-1, 0] = 1e-3
    assert 'rest' in check_plan(changed(velocities=vel))


def test_posterior_summary_layout(trained):
    model, _, held = trained
    est = OnlineEstimator(model)
    _feed(est, held[0], until=0.5)
    s = posterior_summary(est, 0.5)
    k, alpha = est.map_hypothesis()
    p = est.component_posterior()
    assert PosteriorSummary.labels(3) == ['p0', 'p1', 'p2', 'alpha', 'phase', 'confidence',
                                          'component']
    assert np.allclose(s.as_array(), list(p) + [alpha, min(alpha * 0.5, 1.0), p[k], k])
    assert (s.component, s.confidence) == (k, p[k])


def test_commit_rule():
    assert not should_commit([0.05, 0.95], 2, 0.9, 3)       # too few observations
    assert not should_commit([0.15, 0.85], 5, 0.9, 3)       # not confident
    assert should_commit([0.1, 0.9], 3, 0.9, 3)


def _planner(model, meta, labels=True, **settings):
    est = OnlineEstimator(model)
    return (OnlinePlanner(est, PlannerSettings(**settings),
                          labels=meta['component_labels'] if labels else None),
            OnlineEstimator(model))


@pytest.mark.parametrize('which, threshold, min_obs, gate', [
    ('trained', 0.9, 3, 'min_observations'),
    ('noisy', 0.9, 1, 'confidence'),
    ('noisy', 0.98, 4, 'confidence'),
])
def test_interaction_commits_when_the_oracle_passes_the_threshold(request, which, threshold,
                                                                   min_obs, gate):
    model, meta, held = request.getfixturevalue(which)
    demo = held[1]
    onset = 1_700_000_000_000_000_000
    planner, oracle = _planner(model, meta, confidence_threshold=threshold,
                               min_observations=min_obs)
    planner.onset(onset)
    expected = None
    for t, y in zip(demo.t, demo.observed):
        result = planner.observe(onset + _ns(t), y)[0]
        used = oracle.update(_t(t), y)
        assert result == ('used' if used else 'skipped')
        step = planner.replan()
        if expected is None and should_commit(oracle.component_posterior(),
                                              oracle.n_observations, threshold, min_obs):
            expected = (oracle.phase(_t(t)), oracle.n_observations, oracle.map_hypothesis()[0],
                        _t(t))
            assert step.send and step.committed_now
        elif expected is None:
            assert not step.send and planner.state == 'observing'
        else:
            assert step.send and not step.committed_now
    assert expected is not None
    if gate == 'confidence':      # the threshold held the robot back after min_observations
        assert expected[1] > min_obs
    else:
        assert expected[1] == min_obs
    rec = planner.current
    assert rec.commit_phase == pytest.approx(expected[0], abs=1e-12)
    assert 0 < rec.commit_phase < 1
    assert rec.commit_observations == expected[1]
    assert rec.commit_component == expected[2]
    assert rec.commit_elapsed == expected[3]
    assert rec.commit_time == pytest.approx(onset * 1e-9 + expected[3], abs=1e-6)
    assert rec.onset_time == onset * 1e-9
    # the pattern is recognised: the chosen component's label is the demonstration's
    assert rec.label == demo.label
    assert rec.n_observations == oracle.n_observations
    final = planner.end(onset + _ns(demo.t[-1]))
    assert final.send and planner.state == 'done' and rec.end_reason == 'end'
    assert rec.end_elapsed == _t(demo.t[-1])
    assert rec.end_time == pytest.approx((onset + _ns(demo.t[-1])) * 1e-9, abs=1e-6)
    assert (rec.final_component, rec.final_label) == (oracle.map_hypothesis()[0],
                                                            demo.label)
    # the end posture: eq. 13 conditioned on the final wrist position at z = 1
    assert np.allclose(final.plan.positions[-1],
                       oracle.predict_at_rest(demo.observed[-1])[0], atol=1e-12)
    assert len(final.plan.times) == 1
    assert planner.replan() is None                     # nothing after the end


def test_end_without_commit_sends_nothing(noisy):
    model, meta, held = noisy
    planner, _ = _planner(model, meta, confidence_threshold=0.999)
    planner.onset(0)
    for t, y in zip(held[0].t[:6], held[0].observed[:6]):
        planner.observe(_ns(t), y)[0]
    step = planner.end(_ns(held[0].t[5]))
    assert not step.send and planner.current.commit_phase is None
    assert planner.counts.plans_sent == 0 and planner.state == 'done'


def test_planner_steps_only_when_something_is_new(trained):
    model, meta, held = trained
    planner, _ = _planner(model, meta)
    assert planner.replan() is None                          # idle
    planner.onset(0)
    assert planner.replan() is not None                      # the prior, after the onset
    assert planner.replan() is None
    planner.observe(_ns(0.1), held[0].observed[10])[0]
    assert planner.replan() is not None


def test_switching_component_mid_way_is_recorded(trained):
    """Start like one pattern, continue like another: the plans follow the MAP component."""
    model, meta, held = trained
    a, b = held[0], held[1]
    planner, oracle = _planner(model, meta)
    planner.onset(0)
    ks = []
    for t, y in [(t, y) for t, y in zip(a.t, a.observed) if t <= 0.1] + \
                [(t, y) for t, y in zip(b.t, b.observed) if t > 0.1]:
        planner.observe(_ns(t), y)[0]
        oracle.update(_t(t), y)
        step = planner.replan()
        if step is not None and step.send:
            ks.append(oracle.map_hypothesis()[0])
            assert step.plan.component == ks[-1]
            assert step.switched_from == (ks[-2] if len(ks) > 1 and ks[-2] != ks[-1] else None)
    expected = [{'from': p, 'to': n} for p, n in zip(ks, ks[1:]) if p != n]
    assert expected, 'the scenario should switch at least once'
    assert [{'from': s.from_component, 'to': s.to_component} for s in planner.current.switches] == expected
    assert planner.current.label == b.label
    assert planner.current.commit_component == ks[0] != planner.current.component
    planner.end(_ns(b.t[-1]))
    assert planner.current.final_component == ks[-1]


def test_bad_input_is_counted_and_estimation_goes_on(trained):
    model, meta, held = trained
    demo = held[2]
    planner, oracle = _planner(model, meta)
    onset = 5_000_000_000
    # before any onset: held, then dropped when the onset turns out to be later
    assert planner.observe(onset - _ns(0.5), demo.observed[0])[0] == 'held'
    # arrives before its onset event but is stamped after it: taken at the onset
    assert planner.observe(onset + _ns(demo.t[0]), demo.observed[0])[0] == 'held'
    assert planner.onset(onset)                            # absorbed at once: replan due
    assert planner.n_backlog == 0 and planner.estimator.n_observations == 1
    oracle.update(_t(demo.t[0]), demo.observed[0])
    assert planner.current.n_observations == 1
    assert planner.observe(onset - 1, demo.observed[1])[0] == 'before_onset'
    assert planner.observe(onset + _ns(0.3), [np.nan, 0.0, 0.0])[0] == 'non_finite'
    assert planner.observe(onset + _ns(0.3), [0.0, 0.0])[0] == 'non_finite'
    for t, y in zip(demo.t[1:], demo.observed[1:]):
        assert planner.observe(onset + _ns(t), y)[0] in ('used', 'skipped')
        oracle.update(_t(t), y)
    assert planner.observe(onset + _ns(demo.t[5]), demo.observed[5])[0] == 'time_backwards'
    assert planner.observe(onset + _ns(demo.t[-1]), demo.observed[-1])[0] == 'time_backwards'
    assert planner.counts.rejected == {'wrong_frame': 0, 'non_finite': 2, 'before_onset': 1,
                                'time_backwards': 2, 'exception': 0, 'bad_joint_state': 0}
    assert planner.current.n_rejected == 5
    step = planner.replan()
    assert step.send
    assert np.allclose(step.plan.positions, oracle.expected_controlled(step.plan.times)[1],
                       atol=1e-12)
    planner.end(onset + _ns(demo.t[-1]))
    # after the end: held for a possible next onset, never fed to the finished interaction
    n = planner.current.n_observations
    assert planner.observe(onset + _ns(demo.t[-1] + 0.1), demo.observed[-1])[0] == 'held'
    assert planner.current.n_observations == n and planner.n_held == 1


def test_held_observations_cover_the_hold_window(trained):
    model, meta, held = trained
    planner, _ = _planner(model, meta, hold_window=0.025)
    results = [planner.observe(_ns(0.01 * i), held[0].observed[i])[0] for i in range(5)]
    assert results == ['held'] * 5
    assert planner.n_held == 3                             # 0.02, 0.03, 0.04
    planner.onset(_ns(0.03))                               # takes 0.03 and 0.04
    assert planner.current.n_received == 2 and planner.n_held == 0
    assert planner.counts.n_rejected == 0
    planner.end(_ns(0.5))
    for i in range(3):
        planner.observe(_ns(10.0 + 0.01 * i), held[0].observed[i])[0]
    planner.observe(_ns(10.005), held[0].observed[1])      # the stamps' clock restarted
    assert planner.n_held == 1
    planner.onset(_ns(10.0))                               # nothing of the old clock mixed in
    assert planner.current.n_received == 1


def test_backlog_absorbed_after_live_observations_gives_the_time_ordered_posterior(trained):
    """Samples held before the onset, absorbed in slices after live ones: the posterior equals
    the time-ordered one (the weights are static)."""
    model, meta, held = trained
    demo = held[1]
    planner, oracle = _planner(model, meta, confidence_threshold=0.5, min_observations=1,
                               backlog_slice=1)
    onset = 7_000_000_000
    n_held = int(0.6 * len(demo.t))
    for t, y in zip(demo.t[:n_held], demo.observed[:n_held]):
        assert planner.observe(onset + _ns(t), y)[0] == 'held'
    planner.onset(onset)                                   # the first slice
    n_backlog = planner.n_backlog
    assert n_backlog == planner.current.n_observations - 1 > 6
    live = [(t, y) for t, y in zip(demo.t[n_held:], demo.observed[n_held:])][:5]
    for t, y in live:
        planner.observe(onset + _ns(t), y)
    # live ones at once, one slice of the backlog per call: most of it still waits
    assert planner.n_backlog == n_backlog - 5
    assert planner.estimator.n_observations == planner.current.n_observations - n_backlog + 5
    assert not planner.replan().send                       # no commit before it is all in
    while planner.n_backlog:
        planner.tick()
    for t, y in zip(demo.t, demo.observed):
        if t <= live[-1][0]:
            oracle.update(_t(t), y)
    assert planner.estimator.n_observations == oracle.n_observations
    np.testing.assert_allclose(planner.estimator.log_evidence, oracle.log_evidence,
                               rtol=1e-9, atol=1e-8)
    np.testing.assert_allclose(planner.estimator.sigma, oracle.sigma, rtol=1e-8, atol=1e-12)
    step = planner.replan()
    assert step.send and step.committed_now
    assert np.allclose(step.plan.positions, oracle.expected_controlled(step.plan.times)[1],
                       atol=1e-10)


def test_end_absorbs_what_is_left_of_the_backlog(trained):
    model, meta, held = trained
    demo = held[0]
    planner, oracle = _planner(model, meta, confidence_threshold=0.5, min_observations=1)
    for t, y in zip(demo.t, demo.observed):
        planner.observe(_ns(t), y)[0]
        oracle.update(_t(t), y)
    planner.onset(0)
    assert planner.n_backlog == oracle.n_observations - PlannerSettings().backlog_slice
    step = planner.end(_ns(demo.t[-1]))
    assert planner.n_backlog == 0 and step.send
    assert planner.estimator.n_observations == oracle.n_observations


def test_new_onset_closes_the_unfinished_interaction(trained):
    model, meta, held = trained
    planner, _ = _planner(model, meta)
    planner.onset(0)
    planner.observe(_ns(0.1), held[0].observed[10])[0]
    planner.onset(_ns(2.0))
    assert [r.end_reason for r in planner.interactions] == ['new_onset', None]
    assert planner.estimator.n_observations == 0 and planner.state == 'observing'


def test_invalid_settings_are_refused(trained):
    model, _, _ = trained
    est = OnlineEstimator(model)
    for kw in ({'confidence_threshold': 0.0}, {'confidence_threshold': 1.5},
               {'min_observations': 0}, {'n_points': 1}, {'lookahead': -0.1},
               {'settle_time': 0.0}, {'backlog_slice': 0}, {'replan_period': 0.0},
               {'hold_window': float('nan')}):
        with pytest.raises(ValueError, match=next(iter(kw))):
            PlannerSettings(**kw)
    with pytest.raises(ValueError, match='1 component labels for 3'):
        OnlinePlanner(est, labels=['a'])
    planner = OnlinePlanner(est)
    with pytest.raises(ValueError, match='confidence_threshold'):
        planner.update_settings(confidence_threshold=2.0, n_points=9)
    assert planner.settings == PlannerSettings()          # nothing changed


def test_latency_stats():
    s = LatencyStats()
    for v in (1e-4, 3e-4, 2e-4):
        s.add(v)
    assert (s.count, s.last_us, s.max_us) == (3, pytest.approx(200), pytest.approx(300))
    assert s.mean_us == pytest.approx(200)


def test_plans_pass_the_controllers_trajectory_acceptance(trained):
    """joint_trajectory_controller semantics (robot.trajectory): finite, strictly increasing,
    at rest at the end, not over before 'now' (start = onset, now = the latest observation
    plus some delivery latency), and within the iiwa's joint limits from where it stands."""
    from mixture_ip_ros.robot.trajectory import points_from_arrays, validate_trajectory
    from mixture_ip_ros.robot.description import JOINT_NAMES
    model, _, held = trained
    demo = held[0]
    est = OnlineEstimator(model)
    onset = 100.0
    for frac in (0.2, 0.6, 1.0, 1.3):
        t_now = frac * demo.duration
        est.reset()
        _feed(est, demo, until=t_now)
        plan = build_plan(est, t_now, n_points=25, lookahead=0.1, settle_time=0.5)
        # final once the slowest speed the posterior holds has ended (at the recording's own
        # end that depends on how sure the model is of its speed; a third later every
        # hypothesis has ended)
        slowest = est.alphas[est.speed_hypotheses(plan.component)[0]].min()
        assert plan.final == (t_now + 0.1 >= (1.0 - PHASE_EPS) / slowest)
        assert plan.final == (frac >= 1.0) or frac == 1.0
        pts = points_from_arrays(plan.times, plan.positions, plan.velocities, plan.accelerations)
        accepted = validate_trajectory(list(JOINT_NAMES), pts, onset, onset + t_now + 0.05,
                                       list(JOINT_NAMES), limits=_iiwa_limits(),
                                       positions_now=plan.positions[0])
        assert not isinstance(accepted, str), accepted


def test_final_posture_time_does_not_recede_while_the_human_rests(trained):
    model, meta, held = trained
    demo = held[2]
    planner, oracle = _planner(model, meta, settle_time=0.5, lookahead=0.1)
    planner.onset(0)
    finals = []
    rest_t = demo.t[-1] + 0.01 * np.arange(1, 80)         # the human holds still 0.8 s
    for t, y in list(zip(demo.t, demo.observed)) + [(t, demo.observed[-1]) for t in rest_t]:
        planner.observe(_ns(t), y)[0]
        step = planner.replan()
        if step is not None and step.send and step.plan.final:
            finals.append((_t(t), step.plan.times[0]))
    assert len(finals) > 10
    anchor, anchors = None, 0
    for t_now, t_final in finals:
        if anchor is None or not anchor >= t_now + 0.1:   # kept while >= lookahead ahead
            anchor = t_now + 0.5
            anchors += 1
        assert t_final == anchor
    assert anchors >= 2                             # the 0.8 s rest outlasts the first one


def test_interaction_records_are_bounded(trained):
    model, meta, _ = trained
    planner, _ = _planner(model, meta, max_records=3)
    for i in range(5):
        planner.onset(_ns(10.0 * i))
    assert [r.onset_stamp_ns for r in planner.interactions] == [_ns(20.0), _ns(30.0),
                                                                   _ns(40.0)]


def _limits(n, velocity, acceleration):
    from mixture_ip_ros.estimation.plans import JointLimits
    return JointLimits(np.full(n, -10.0), np.full(n, 10.0), np.full(n, velocity),
                       np.full(n, acceleration))


def _blend_ok(T, q, qd, p1, v1, limits):
    """Whether the controller's blend (cubic from (q, qd) into (p1, v1) in T s) stays within
    ``limits``, sampled at 401 instants (an oracle independent of blend_within_limits' vertex
    and end-point analysis); the plan's own speed v1 clipped to the limits, as build_plan's."""
    v1 = np.clip(v1, -limits.velocity, limits.velocity)
    s = np.linspace(0.0, 1.0, 401)[:, None]   # Hermite basis derivatives at s = t / T
    d00, d10, d01, d11 = 6 * s**2 - 6 * s, 3 * s**2 - 4 * s + 1, -6 * s**2 + 6 * s, 3 * s**2 - 2 * s
    a00, a10, a01, a11 = 12 * s - 6, 6 * s - 4, -12 * s + 6, 6 * s - 2
    speed = (d00 * q + d10 * T * qd + d01 * p1 + d11 * T * v1) / T
    accel = (a00 * q + a10 * T * qd + a01 * p1 + a11 * T * v1) / T**2
    return bool(np.all(np.abs(speed) <= np.maximum(limits.velocity, np.abs(qd)) + 1e-9)
                and np.all(np.abs(accel) <= limits.acceleration + 1e-9))


def _forty_observed(trained):
    """(model, an estimator fed the first 40 samples of a held-out demonstration, their end)."""
    model, _, demos = trained
    est = OnlineEstimator(model, n_alpha=10, min_interval=0.0)
    est.offer_many(demos[0].t[:40], demos[0].observed[:40])
    return model, est, demos[0].t[39]


def test_catch_up_drops_points_the_robot_cannot_reach_in_time(trained):
    """An arm far from the plan gets a later first point, one the controller's blend from its
    state reaches within the limits; an arm on the path, moving with it, gets the whole plan."""
    model, est, t_now = _forty_observed(trained)
    free = build_plan(est, t_now, n_points=25)
    limits = _limits(model.n_controlled_, 0.5, 20.0)
    far = (free.positions[0] + 1.0, np.zeros(model.n_controlled_))   # at rest, 1 rad away
    plan = build_plan(est, t_now, n_points=25, robot=far, limits=limits)
    assert plan.times[0] >= t_now + 1.0 / 0.5
    assert _blend_ok(plan.times[0] - t_now, *far, plan.positions[0], plan.velocities[0], limits)
    assert len(plan.times) < len(free.times)
    assert np.all(np.diff(plan.times) > 0)
    _, q, qd, _ = est.expected_controlled([t_now])
    on_path = _limits(model.n_controlled_, 2 * np.abs(free.velocities).max(), 1e4)
    near = build_plan(est, t_now, n_points=25, robot=(q[0], qd[0]), limits=on_path)
    assert np.array_equal(near.times, free.times)


def test_catch_up_rejoins_the_path_at_the_earliest_time_it_can_reach_it(trained):
    """Behind its plan, the arm's first point is the earliest time on the expected path that
    the controller's blend from its state reaches within the limits (a brute-force search at
    1 ms), not the next of the plan's points that happens to be reachable; the points after it
    are the free plan's."""
    model, est, t_now = _forty_observed(trained)
    free = build_plan(est, t_now, n_points=6)
    limits = _limits(model.n_controlled_, 1.0, 20.0)
    robot = (free.positions[0] + 0.2, np.zeros(model.n_controlled_))   # at rest, 0.2 rad away
    plan = build_plan(est, t_now, n_points=6, robot=robot, limits=limits)
    kept = len(plan.times) - 1
    assert 0 < kept < len(free.times) - 1      # a point dropped, one inserted before the rest
    assert np.array_equal(plan.times[1:], free.times[-kept:])
    assert np.array_equal(plan.positions[1:], free.positions[-kept:])
    grid = np.arange(t_now + 0.1, plan.times[1], 1e-3)
    _, pos, vel, _ = est.expected_controlled(grid)
    reachable = [_blend_ok(t - t_now, *robot, p, v, limits) for t, p, v in zip(grid, pos, vel)]
    earliest = grid[int(np.argmax(reachable))]
    assert any(reachable)
    assert earliest - 1e-3 <= plan.times[0] <= earliest + CATCH_UP_RESOLUTION
    _, p0, v0, a0 = est.expected_controlled([plan.times[0]])
    assert np.allclose(plan.positions[0], p0[0], rtol=0, atol=1e-12)
    assert np.allclose(plan.velocities[0], v0[0], rtol=0, atol=1e-12)
    assert _blend_ok(plan.times[0] - t_now, *robot, plan.positions[0], plan.velocities[0],
                     limits)


def test_catch_up_keeps_the_path_after_the_arm_rejoins_it_and_never_divides_by_zero(trained):
    """Every plan point after the time the arm rejoins the path is kept (none between is
    skipped); with lookahead 0 the point due now counts as unreachable (no division by zero,
    which the suite turns into an error), and the plan starts after the present."""
    model, est, t_now = _forty_observed(trained)
    free = build_plan(est, t_now, n_points=40, lookahead=0.0)
    limits = _limits(model.n_controlled_, 1.0, 20.0)
    robot = (free.positions[0] + 0.2, np.zeros(model.n_controlled_))
    plan = build_plan(est, t_now, n_points=40, lookahead=0.0, robot=robot, limits=limits)
    assert t_now < plan.times[0] < plan.times[1]
    assert np.array_equal(plan.times[1:], free.times[free.times > plan.times[0] + 0.005])
    assert _blend_ok(plan.times[0] - t_now, *robot, plan.positions[0], plan.velocities[0],
                     limits)


def test_a_catch_up_plan_is_still_reachable_when_it_reaches_the_controller_late(trained):
    """With a delivery margin, the point where an arm at rest rejoins its path is one the
    controller's blend reaches within the limits also when the plan arrives up to the margin
    after the present, as the sim's acceptance check sees it: no re-timing (delay 0) at any
    arrival in [0, margin]; an arm on its path gets the same plan as without the margin."""
    from mixture_ip_ros.robot.trajectory import points_from_arrays, validate_trajectory
    model, est, t_now = _forty_observed(trained)
    n = model.n_controlled_
    free = build_plan(est, t_now, n_points=6)
    limits = _limits(n, 1.0, 20.0)
    robot = (free.positions[0] + 0.2, np.zeros(n))   # at rest, 0.2 rad away
    edge = build_plan(est, t_now, n_points=6, robot=robot, limits=limits)
    plan = build_plan(est, t_now, n_points=6, robot=robot, limits=limits, margin=0.05)
    assert plan.times[0] > edge.times[0]
    names = [f'j{i}' for i in range(n)]

    def delay(p, arrival):
        points = points_from_arrays(p.times - t_now, p.positions, p.velocities,
                                    p.accelerations)
        return validate_trajectory(names, points, t_now, t_now + arrival, names,
                                   limits=limits, positions_now=robot[0],
                                   velocities_now=robot[1], control_period=1e-3).delay
    assert delay(edge, 0.05) > 0               # at the edge of reach: re-timed when late
    for arrival in np.linspace(0.0, 0.05, 11):
        assert delay(plan, arrival) == 0.0
        assert _blend_ok(plan.times[0] - t_now - arrival, *robot, plan.positions[0],
                         plan.velocities[0], limits)
    _, q, qd, _ = est.expected_controlled([t_now])
    on_path = _limits(n, 2 * np.abs(free.velocities).max(), 1e4)
    near = build_plan(est, t_now, n_points=6, robot=(q[0], qd[0]), limits=on_path, margin=0.05)
    assert np.array_equal(near.times, free.times)


def test_plan_starts_from_the_present_when_observations_lag(trained):
    """The first point is lookahead ahead of the present (clock_now), not of the latest
    observation, when the two differ by a plausible processing lag; another clock is ignored."""
    model, meta, demos = trained
    demo = demos[0]
    results = {}
    for clock_now in (None, 0.3, 50.0):
        planner, _ = _planner(model, meta)
        onset = 5_000_000_000
        planner.onset(onset)
        for t, y in zip(demo.t[:60], demo.observed[:60]):
            planner.observe(onset + _ns(t), y)[0]
        step = planner.replan(None if clock_now is None else onset + round((demo.t[59] + clock_now) * 1e9))
        results[clock_now] = step.plan.times[0]
    assert results[50.0] == pytest.approx(results[None])
    assert results[0.3] == pytest.approx(results[None] + 0.3, abs=1e-9)


# -- the replan schedule on a fake clock ---------------------------------------------------

def test_schedule_replans_once_per_period_of_stamps_and_clock():
    s = ReplanSchedule(0.1)
    ms = 1_000_000
    assert s.due_on_observation(0.0, 0)                   # the first one replans
    s.observation_replanned(0.0)
    s.replanned(0)
    assert not s.due_on_observation(0.05, 50 * ms)       # within the period
    assert not s.due_on_timer(50 * ms)
    assert not s.due_on_observation(0.1, 60 * ms)        # stamps due, clock not: fast replay
    assert s.due_on_observation(0.1, 100 * ms)
    s.observation_replanned(0.1)
    s.replanned(100 * ms)
    assert not s.due_on_timer(150 * ms) and s.due_on_timer(200 * ms)   # a pause: the timer
    s.replanned(200 * ms)
    assert not s.due_on_observation(0.25, 250 * ms)     # at most one replan per clock period
    assert s.due_on_observation(0.3, 300 * ms)
    assert s.due_on_timer(10 * ms)                       # the clock was reset: not stuck
    s.restart()                                          # a new interaction: stamps from zero
    assert s.due_on_observation(0.0, None)
    s.on_observation = False
    assert not s.due_on_observation(5.0, 10**12)
    with pytest.raises(ValueError, match='positive'):
        s.period = 0.0


def test_planner_replans_on_the_schedule_and_stamps_steps_with_their_trigger(trained):
    """Fed at 100 Hz with the clock following the stamps, replans come at 10 Hz; each step
    carries the stamp of the latest observation it rests on."""
    model, meta, held = trained
    demo = held[1]
    planner, _ = _planner(model, meta, replan_period=0.1)
    onset = 3_000_000_000
    planner.onset(onset)
    steps = []
    for t, y in zip(demo.t, demo.observed):
        stamp = onset + _ns(t)
        _, due = planner.observe(stamp, y, now_ns=stamp)
        if due:
            steps.append((stamp, planner.replan(stamp)))
    assert len(steps) == pytest.approx(demo.duration / 0.1, abs=1.5)
    assert all(step.trigger_ns == stamp for stamp, step in steps)
    assert all(b - a >= _ns(0.1) for (a, _), (b, _) in zip(steps, steps[1:]))
    final = planner.end(onset + _ns(demo.t[-1] + 0.2))
    assert final.trigger_ns == onset + _ns(demo.t[-1] + 0.2)


def test_deactivating_ends_the_interaction(trained):
    model, meta, held = trained
    planner, _ = _planner(model, meta)
    planner.onset(0)
    planner.observe(_ns(0.1), held[0].observed[10])
    planner.deactivate()
    assert planner.state == 'done' and planner.current.end_reason == 'deactivated'
    assert planner.replan() is None
    planner.deactivate()                                 # idempotent


def test_held_samples_keep_the_window_and_restart_with_the_clock():
    held = HeldSamples(0.1)
    for i in range(20):
        held.add(_ns(0.01 * i), i)
    assert len(held) == 11                               # 0.09 .. 0.19 s
    assert [y for _, y in held.take_from(_ns(0.15))] == [15, 16, 17, 18, 19]
    assert len(held) == 0
    held.add(_ns(5.0), 'a')
    held.add(_ns(1.0), 'b')                              # older: another clock
    assert [y for _, y in held.take_from(0)] == ['b']
    with pytest.raises(ValueError, match='hold_window'):
        HeldSamples(0.0)


# -- the observer's logic -----------------------------------------------------------------

def _observer(**kw):
    from mixture_ip_ros.core.segmentation import MotionSegmenter
    from mixture_ip_ros.estimation.observer import WristObserver
    kw.setdefault('max_clock_offset', 0.0)     # stamps here are not on any clock
    return WristObserver(MotionSegmenter(), expected_frame='world', **kw)


def test_observer_reports_one_gap_per_silence_on_the_callers_clock():
    obs = _observer()
    q = (0.0, 0.0, 0.0, 1.0)
    period = 10_000_000
    for k in range(60):                                  # 0.6 s at rest, 100 Hz
        out = obs.on_pose(k * period, 'world', (0.2, 0.1, 1.0), q, now_ns=k * period)
        assert out.rejected is None and out.events == []
    last = 59 * period
    assert obs.on_timer(last + 5 * period) == []         # 50 ms: not yet a gap
    assert obs.on_timer(last + 20 * period) == [('gap', last)]
    assert obs.on_timer(last + 40 * period) == []        # the same silence: once
    out = obs.on_pose(last + 50 * period, 'world', (0.2, 0.1, 1.0), q, now_ns=last + 50 * period)
    assert out.events == []                              # not reported again on resumption
    assert obs.counts.published == {'observations': 61, 'onset': 0, 'end': 0, 'gap': 1}


def test_observer_drops_bad_poses_and_takes_a_replayed_stream_as_new():
    """Stamps going back by less than new_stream_jump_back: dropped, until
    restart_after_backwards of them in a row make a new stream."""
    obs = _observer(restart_after_backwards=3)
    q = (0.0, 0.0, 0.0, 1.0)
    for k in range(5):
        assert obs.on_pose(10**9 + k, 'world', (0, 0, 1), q, now_ns=1).rejected is None
    assert obs.on_pose(10**9 + 9, 'camera', (0, 0, 1), q, now_ns=1).rejected == 'wrong_frame'
    assert obs.on_pose(10**9 + 9, 'world', (0, 0, 1), (0, 0, 0, 0), now_ns=1).rejected == \
        'bad_quaternion'
    assert obs.on_pose(10**9 + 4, 'world', (0, 0, 1), q, now_ns=1).rejected == 'duplicate_stamp'
    back = 10**9 - 5_000_000                                  # 5 ms before the stream
    assert [obs.on_pose(back, 'world', (0, 0, 1), q, now_ns=1).rejected,
            obs.on_pose(back + 1, 'world', (0, 0, 1), q, now_ns=1).rejected] == \
        ['stamp_backwards'] * 2
    out = obs.on_pose(back + 2, 'world', (0, 0, 1), q, now_ns=1)   # the third: a new stream
    assert out.rejected is None and out.restarted and obs.counts.stream_restarts == 1
    assert {k: v for k, v in obs.counts.dropped.items() if v} == {
        'bad_quaternion': 1, 'wrong_frame': 1, 'duplicate_stamp': 1, 'stamp_backwards': 2}


# -- is it a person's wrist? -----------------------------------------------------------------

def _reach_stream(rate=100.0, start_ns=1_700_000_000 * 10**9):
    from mixture_ip_ros.scenarios.human_motion import reach
    t = np.arange(0.0, 2.5, 1.0 / rate)
    xyz = reach(t, 0.5, 1.2, (1.2, 0.24, 0.08), (0.85, -0.1, 0.35), via_offset=(0, 0, 0.05))
    xyz += np.random.default_rng(0).normal(0.0, 0.001, xyz.shape)
    return start_ns + np.round(t * 1e9).astype(np.int64), xyz


def _run(obs, stamps, xyz, inject=None, clock_offset_ns=0):
    """Feed the stream (the clock reading each stamp + offset); ``inject`` {index: (stamp,
    position)} adds a pose before the sample. Returns the events and the rejections."""
    q = (0.0, 0.0, 0.0, 1.0)
    events, rejected = [], []
    for i, (ns, p) in enumerate(zip(stamps, xyz)):
        if inject and i in inject:
            s, bad = inject[i]
            out = obs.on_pose(int(s), 'world', bad, q, now_ns=int(ns) + clock_offset_ns)
            rejected.append(out.rejected)
            events += out.events
        out = obs.on_pose(int(ns), 'world', tuple(p), q, now_ns=int(ns) + clock_offset_ns)
        if out.rejected:
            rejected.append(out.rejected)
        events += out.events
    return events, rejected


def test_no_generated_wrist_stream_loses_a_pose_to_the_plausibility_checks():
    from mixture_ip_ros.core.segmentation import MotionSegmenter
    from mixture_ip_ros.estimation.observer import WristObserver
    from mixture_ip_ros.scenarios.box_assembly import box_assembly
    for g in box_assembly(seed=0):
        ok = ~np.isnan(g.wrist_xyz).any(axis=1)
        stamps = 10**18 + np.round(g.wrist_t[ok] * 1e9).astype(np.int64)
        obs = WristObserver(MotionSegmenter(), expected_frame='world')
        events, rejected = _run(obs, stamps, g.wrist_xyz[ok])
        assert rejected == [], g.name
        assert [k for k, _ in events if k != 'gap'] == ['onset', 'end'], g.name


def test_a_pose_no_hand_can_reach_is_dropped_and_the_reach_goes_on():
    from mixture_ip_ros.core.segmentation import MotionSegmenter
    from mixture_ip_ros.estimation.observer import WristObserver
    stamps, xyz = _reach_stream()
    clean, _ = _run(WristObserver(MotionSegmenter(), expected_frame='world'), stamps, xyz)
    mid = len(stamps) // 2
    cases = {
        'outside_workspace': (xyz[mid] + (100.0, 0.0, 0.0)),       # a reflection 100 m away
        'implausible_speed': (xyz[mid] + (0.0, 0.4, 0.0)),        # 40 cm in 5 ms
    }
    for reason, bad in cases.items():
        obs = WristObserver(MotionSegmenter(), expected_frame='world')
        events, rejected = _run(obs, stamps, xyz,
                                inject={mid: (stamps[mid] - 5_000_000, tuple(bad))})
        assert rejected == [reason]
        assert events == clean                  # onset and end untouched


def test_an_impossible_acceleration_is_dropped():
    from mixture_ip_ros.estimation.pose_check import HumanLimits, MotionPlausibility
    check = MotionPlausibility(HumanLimits())
    t = np.arange(0.0, 0.2, 0.01)
    x = 0.0
    for ti in t:                                   # 3 m/s along x, steadily
        x = 3.0 * ti
        assert check.check(ti, (x, 0.0, 0.0)) is None
        check.accept(ti, (x, 0.0, 0.0))
    verdicts = []
    for k in range(1, 8):                          # then back at 3 m/s at once: 600 m/s^2
        point = (x - 3.0 * 0.01 * k, 0.0, 0.0)
        verdicts.append(check.check(t[-1] + 0.01 * k, point))
        if verdicts[-1] is None:
            check.accept(t[-1] + 0.01 * k, point)
    assert 'implausible_acceleration' in verdicts
    assert set(verdicts) <= {None, 'implausible_acceleration'}
    with pytest.raises(ValueError, match='workspace'):
        HumanLimits(workspace_min=(0.0, 0.0, 1.0), workspace_max=(1.0, 1.0, 0.0))


def _tracker_glitch(samples, rate=30.0):
    """A reach at ``rate`` whose tracker puts the hand 0.55 m lower for ``samples`` samples
    from sample 30 on (as Nuitrack does), and the hand's true path."""
    from mixture_ip_ros.scenarios.human_motion import reach
    t = np.arange(0.0, 3.0, 1.0 / rate)
    true = reach(t, 0.5, 1.5, (0.1, -0.25, -0.55), (0.5, 0.05, 0.0), via_offset=(0, 0, 0.05))
    seen = true.copy()
    seen[30:30 + samples] -= (0.0, 0.0, 0.55)
    return t, seen, true


def test_offline_acceptance_is_what_the_observer_accepts():
    from mixture_ip_ros.estimation.pose_check import accepted_online
    t, seen, _ = _tracker_glitch(6)
    stamps = 10**18 + np.round(t * 1e9).astype(np.int64)
    obs = _observer()
    q = (0.0, 0.0, 0.0, 1.0)
    online = [obs.on_pose(int(ns), 'world', tuple(p), q, now_ns=int(ns)).rejected is None
              for ns, p in zip(stamps, seen)]
    mask = accepted_online(t, seen)
    np.testing.assert_array_equal(mask, online)
    # After 0.1 s of refusals the jump is within what a hand covers in that time: online, the
    # glitch's last samples get through, and the first ones back are refused.
    assert not mask[30:32].any() and mask[32:36].all() and not mask[36:39].any()


def test_a_track_judged_with_hindsight_loses_the_whole_glitch_and_nothing_else():
    from mixture_ip_ros.estimation.pose_check import plausible_track
    for samples in (1, 4, 11):
        t, seen, _ = _tracker_glitch(samples)
        ok = plausible_track(t, seen)
        expected = np.ones(len(t), dtype=bool)
        expected[30:30 + samples] = False
        np.testing.assert_array_equal(ok, expected)
    # A jump that stays longer than max_glitch is the tracker finding the hand again elsewhere.
    t, seen, _ = _tracker_glitch(30)
    assert plausible_track(t, seen, max_glitch=0.5).all()
    seen[5] = np.nan                                   # NaN rows are not samples
    ok = plausible_track(t, seen)
    assert not ok[5] and ok[np.arange(len(t)) != 5].all()


def test_a_pose_stamped_years_ahead_is_dropped_and_the_stream_keeps_its_time():
    from mixture_ip_ros.core.segmentation import MotionSegmenter
    from mixture_ip_ros.estimation.observer import WristObserver
    stamps, xyz = _reach_stream()
    clean, _ = _run(WristObserver(MotionSegmenter(), expected_frame='world'), stamps, xyz)
    year_2038 = 2_150_000_000 * 10**9
    obs = WristObserver(MotionSegmenter(), expected_frame='world')
    events, rejected = _run(obs, stamps, xyz, inject={50: (year_2038, tuple(xyz[50]))})
    assert rejected == ['off_clock'] and events == clean


def test_a_stream_on_another_clock_is_dropped_with_one_warning():
    from mixture_ip_ros.core.segmentation import MotionSegmenter
    from mixture_ip_ros.estimation.observer import OFF_CLOCK_STREAM, WristObserver
    stamps, xyz = _reach_stream()
    obs = WristObserver(MotionSegmenter(), expected_frame='world')
    warnings = []
    q = (0.0, 0.0, 0.0, 1.0)
    for ns, p in zip(stamps, xyz):           # the node's clock: simulated, from 1000 s
        out = obs.on_pose(int(ns), 'world', tuple(p), q,
                          now_ns=int(ns - stamps[0]) + 1000 * 10**9)
        assert out.rejected == 'off_clock' and not out.events
        if out.warning:
            warnings.append(out.warning)
    assert len(warnings) == 1 and '+1.7e+09 s' in warnings[0] and 'another clock' in warnings[0]
    assert obs.counts.accepted == 0 and obs.counts.dropped['off_clock'] == len(stamps)
    assert OFF_CLOCK_STREAM < len(stamps)


# -- limits are law ---------------------------------------------------------------------------

def _iiwa_limits():
    from mixture_ip_ros.estimation.plans import JointLimits
    from mixture_ip_ros.robot.kinematics import RobotKinematics
    k = RobotKinematics()
    return JointLimits(k.lower, k.upper, k.velocity_limit, k.acceleration_limit)


def test_a_plan_too_fast_for_the_robot_is_slowed_down_along_the_same_path(trained):
    from mixture_ip_ros.estimation.plans import within_limits
    model, _, held = trained
    est = OnlineEstimator(model)
    _feed(est, held[1], until=0.3 * held[1].duration)
    plan = build_plan(est, 0.3, n_points=25)
    slow = _iiwa_limits()
    slow = type(slow)(slow.lower, slow.upper, 0.3 * np.abs(plan.velocities).max(axis=0) + 1e-9,
                      np.full(7, 1e3))
    scaled, why, s = within_limits(plan, slow, 0.3)
    assert why is None and s == _limit_numbers_numpy(plan, slow) and 3.3 < s < 4
    # Within every speed the controller checks: the points' and the means between them.
    assert np.all(np.abs(scaled.velocities) < slow.velocity)
    assert np.all(np.abs(np.diff(scaled.positions, axis=0))
                  < slow.velocity * np.diff(np.round(scaled.times * 1e9) * 1e-9)[:, None])
    np.testing.assert_array_equal(scaled.positions, plan.positions)    # the same path ...
    np.testing.assert_allclose(scaled.times - 0.3, s * (plan.times - 0.3), rtol=1e-12)
    np.testing.assert_allclose(scaled.velocities, plan.velocities / s, rtol=1e-12)  # ... slower
    np.testing.assert_allclose(scaled.accelerations, plan.accelerations / s ** 2, rtol=1e-12)
    slower = type(slow)(slow.lower, slow.upper, slow.velocity / 2, slow.acceleration)
    # half the speed limit: twice as slow
    assert within_limits(plan, slower, 0.3)[1].startswith(f'would have to be {2 * s:.1f} times '
                                                           'slower')
    assert within_limits(plan, _iiwa_limits(), 0.3) == (plan, None, 1.0)


def test_an_outlier_that_reaches_the_estimator_never_reaches_the_joints(trained):
    """A wrist sample 100 m away (past the observer) conditions the estimate on nonsense: the
    plan it gives is beyond the joints' limits and is refused, counted, never sent."""
    model, meta, held = trained
    demo = held[1]
    est = OnlineEstimator(model)
    planner = OnlinePlanner(est, PlannerSettings(), labels=meta['component_labels'],
                            limits=_iiwa_limits())
    planner.onset(0)
    n = len(demo.t) // 2
    for t, y in zip(demo.t[:n], demo.observed[:n]):
        planner.observe(_ns(t), y)
    assert planner.replan().send
    assert planner.observe(_ns(demo.t[n - 1] + 0.1), demo.observed[n] + 100.0)[0] == 'used'
    step = planner.replan()
    assert not step.send and 'beyond its limits' in step.problem
    assert np.abs(step.plan.positions).max() > 10           # what would have gone out
    assert planner.counts.plan_refusals['beyond_limits'] == 1


def test_a_plan_resting_on_another_clock_is_not_sent(trained):
    model, meta, held = trained
    demo = held[1]
    planner = OnlinePlanner(OnlineEstimator(model), PlannerSettings(max_clock_offset=1.0))
    onset = 1_700_000_000 * 10**9
    planner.onset(onset)
    for t, y in zip(demo.t, demo.observed):
        planner.observe(onset + _ns(t), y)
    step = planner.replan(now_ns=onset + _ns(demo.t[-1]) - 10**18)   # a clock ~32 years behind
    assert not step.send and 'from this node' in step.problem
    assert planner.counts.plan_refusals == {'invalid': 0, 'beyond_limits': 0, 'off_clock': 1}
    planner.observe(onset + _ns(demo.t[-1] + 0.01), demo.observed[-1])
    assert planner.replan(now_ns=onset + _ns(demo.t[-1] + 0.02)).send   # on the clock: sent


def test_the_last_plan_is_sent_although_its_end_is_dated_back_beyond_the_clock_check(trained):
    """The observer confirms an end after end_hold s of rest and dates it back to when the hand
    stopped: with end_hold 1.5 s the end's stamp is 1.5 s old when it arrives, and the last plan
    still goes out, judged on the latest observation; a stale stream still does not."""
    model, meta, held = trained
    demo = held[1]
    onset = 1_700_000_000 * 10**9

    def run(rest_stamp_ns):
        planner = OnlinePlanner(OnlineEstimator(model), PlannerSettings(max_clock_offset=1.0))
        planner.onset(onset)
        for t, y in zip(demo.t, demo.observed):
            planner.observe(onset + _ns(t), y)
        assert planner.replan(now_ns=onset + _ns(demo.t[-1])).send
        end_ns = onset + _ns(demo.t[-1])
        planner.observe(rest_stamp_ns, demo.observed[-1])     # at rest since the end
        return planner, planner.end(end_ns, now_ns=end_ns + _ns(1.5))

    planner, step = run(onset + _ns(demo.t[-1] + 1.45))
    assert step.send and step.plan.final
    planner, step = run(onset + _ns(demo.t[-1] + 0.05))      # nothing fresh for 1.45 s
    assert not step.send and 'from this node' in step.problem


def test_pruning_waits_for_the_held_samples_and_keeps_the_decision(trained):
    """With pruning, the planner prunes only once no held sample waits (so the order of
    absorption cannot matter) and commits to the same component at the same observation."""
    model, meta, held = trained
    demo = held[1]
    runs = {}
    for prune in (0.0, 1e-12):
        planner = OnlinePlanner(OnlineEstimator(model, prune_below=prune),
                                PlannerSettings(backlog_slice=1))
        n_held = len(demo.t) // 3
        for t, y in zip(demo.t[:n_held], demo.observed[:n_held]):
            planner.observe(_ns(t), y)
        planner.onset(0)
        tracked = []
        commit = None
        for t, y in zip(demo.t[n_held:], demo.observed[n_held:]):
            planner.observe(_ns(t), y)
            tracked.append((planner.n_backlog, planner.estimator.n_tracked))
            step = planner.replan()
            if commit is None and step is not None and step.committed_now:
                commit = (planner.current.commit_observations, step.plan.component)
        runs[prune] = (commit, tracked)
    assert runs[1e-12][0] == runs[0.0][0] is not None
    n_all = OnlineEstimator(model).log_evidence_flat.size
    assert all(n == n_all for backlog, n in runs[1e-12][1] if backlog)     # none while held
    assert runs[1e-12][1][-1][1] < n_all                                  # pruned after


# -- commit only to movements the model knows --------------------------------------------------

def _run_planner(model, novelty, t, Y, onset=0):
    planner = OnlinePlanner(OnlineEstimator(model), PlannerSettings(), novelty=novelty)
    planner.onset(onset)
    steps = []
    for ti, y in zip(t, Y):
        planner.observe(onset + _ns(ti), y)
        step = planner.replan()
        if step is not None:
            steps.append(step)
    return planner, steps


def test_a_reach_commits_as_it_did_and_a_return_to_rest_never(trained):
    model, meta, held = trained
    assert model.novelty_ is not None                # calibrated by train_to_file
    for demo in held:
        with_gate, steps = _run_planner(model, model.novelty_, demo.t, demo.observed)
        without, _ = _run_planner(model, None, demo.t, demo.observed)
        assert with_gate.current.commit_observations == without.current.commit_observations
        assert with_gate.current.commit_phase == without.current.commit_phase
        assert not any(s.unexplained for s in steps)
        back, steps = _run_planner(model, model.novelty_, demo.t, demo.observed[::-1])
        assert not any(s.send for s in steps) and back.counts.plans_sent == 0
        assert steps[-1].unexplained and back.current.unexplained
        plain, _ = _run_planner(model, None, demo.t, demo.observed[::-1])
        assert plain.counts.plans_sent > 0               # what the gate prevents


def test_the_observation_after_a_gap_is_not_judged_held_or_live(trained):
    """Two silences of 0.25 s, one among the samples held before the onset (absorbed from the
    backlog), one live: each first sample after them is left out of the novelty statistics, as
    the calibration leaves it out (core.novelty), and the reach commits as without the gate."""
    from mixture_ip_ros.core.novelty import GapWatch
    model, meta, held = trained
    demo = held[0]
    keep = ~(((demo.t > 0.1) & (demo.t < 0.35)) | ((demo.t > 0.7) & (demo.t < 0.95)))
    t, Y = demo.t[keep], demo.observed[keep]
    runs = {}
    for novelty in (model.novelty_, None):
        planner = OnlinePlanner(OnlineEstimator(model), PlannerSettings(), novelty=novelty)
        before = t < 0.5
        for ti, y in zip(t[before], Y[before]):
            planner.observe(_ns(ti), y)
        planner.onset(0)
        steps = [planner.replan()]
        for ti, y in zip(t[~before], Y[~before]):
            planner.observe(_ns(ti), y)
            steps.append(planner.replan())
        runs[novelty is None] = planner, [s for s in steps if s is not None]
    planner, steps = runs[False]
    est, watch = OnlineEstimator(model), GapWatch(model.novelty_.min_interval)
    used = [ti for ti, y in zip(t, Y) if est.update(float(ti), y)]
    assert sum(watch.after_gap(ti) for ti in used) == 2
    assert planner._novelty.n_judged == planner.estimator.n_observations - 2 == len(used) - 2
    assert not any(s.unexplained for s in steps)
    assert planner.current.commit_observations == runs[True][0].current.commit_observations


def test_a_committed_robot_holds_when_the_movement_stops_being_explained(trained):
    """A second reach from where the first ended, without a rest: after the commit the movement
    becomes unexplained; the planner says hold once and the interaction ends there."""
    model, meta, held = trained
    first, second = held[1], held[0]
    t = np.concatenate([first.t, first.t[-1] + 0.01 + second.t])
    Y = np.vstack([first.observed, second.observed - second.observed[0] + first.observed[-1]])
    planner, steps = _run_planner(model, model.novelty_, t, Y)
    holds = [s for s in steps if s.hold]
    assert len(holds) == 1 and not holds[0].send
    assert planner.counts.holds == 1 and planner.current.end_reason == 'unexplained'
    assert planner.current.committed and planner.state == 'done'
    assert planner.current.end_elapsed > first.duration   # after the first reach was done


def test_poses_lost_before_the_observer_are_counted_from_the_stamps():
    """A 5 kHz burst of which the queue let 28 % through: the missing ones are counted."""
    obs = _observer()
    q = (0.0, 0.0, 0.0, 1.0)
    rng = np.random.default_rng(3)
    period = 200_000                                  # 5 kHz
    stamps = 10**18 + period * np.arange(5000)
    kept = np.sort(np.r_[np.arange(50), 50 + rng.choice(4950, 1386, replace=False)])
    for i in kept:                                   # the first 50 all there: the rate is seen
        assert obs.on_pose(int(stamps[i]), 'world', (0.2, 0.1, 1.0), q, now_ns=1).rejected is None
    assert obs.period == pytest.approx(period * 1e-9, rel=0.05)
    assert obs.counts.missing == pytest.approx((kept[-1] + 1) - len(kept), rel=0.02)


def _check_plan_numpy(plan):
    """check_plan as numpy statements (the oracle of its compiled form, _fast.plan_problem)."""
    for name in ('times', 'positions', 'velocities', 'accelerations'):
        if not np.isfinite(getattr(plan, name)).all():
            return f'non-finite {name}'
    ns = np.round(plan.times * 1e9)
    if ns[0] < 0 or (ns[1:] <= ns[:-1]).any():
        return 'times not strictly increasing (or negative)'
    if plan.velocities[-1].any() or plan.accelerations[-1].any():
        return 'last point not at rest'
    return None


def _limit_numbers_numpy(plan, limits):
    """within_limits' numbers as numpy statements (the oracle of _fast.limit_ratios): (first
    joint beyond its positions, its worst position) or the time scale."""
    low, high = plan.positions < limits.lower, plan.positions > limits.upper
    if low.any() or high.any():
        j = int(np.flatnonzero((low | high).any(axis=0))[0])
        return j, (plan.positions[:, j].min() if low[:, j].any()
                   else plan.positions[:, j].max())
    mean_speed = (np.abs(np.diff(plan.positions, axis=0)) / np.diff(plan.times)[:, None]
                  / limits.velocity)
    scale = max(1.0, float(np.max(np.abs(plan.velocities) / limits.velocity)),
                float(np.max(mean_speed, initial=0.0)),
                float(np.sqrt(np.max(np.abs(plan.accelerations) / limits.acceleration))))
    return scale * (1.0 + SLOWDOWN_MARGIN) if scale > 1.0 else scale


def test_plan_checks_equal_their_numpy_statements():
    """check_plan and within_limits on random plans with every kind of fault, against the
    numpy statements they compile: the same verdicts, joints, worst positions and scales."""
    from mixture_ip_ros.estimation.plans import JointLimits, within_limits
    rng = np.random.default_rng(5)
    limits = JointLimits(-np.full(7, 2.0), np.full(7, 2.0), np.full(7, 1.5), np.full(7, 10.0))
    verdicts = set()
    for trial in range(600):
        n = int(rng.integers(1, 30))
        times = np.sort(rng.uniform(0, 3, n))
        pos = rng.normal(0, 0.9, (n, 7))
        vel, acc = rng.normal(0, 0.6, (2, n, 7)) * rng.choice([0.1, 1.0, 4.0])
        vel[-1] = acc[-1] = 0.0
        fault = trial % 7
        if fault == 1:
            field = [times, pos.ravel(), vel.ravel(), acc.ravel()][rng.integers(4)]
            field[rng.integers(field.size)] = rng.choice([np.nan, np.inf, -np.inf])
        elif fault == 2 and n > 1:
            times[rng.integers(1, n)] = times[0] - rng.choice([0.0, 1e-10, 1.0])
        elif fault == 3:
            (vel, acc)[rng.integers(2)][-1, rng.integers(7)] = 1e-3
        elif fault == 4:
            times[0] = -rng.choice([1e-10, 1.0])
        plan = Plan(times=times, phases=times, positions=pos, velocities=vel,
                    accelerations=acc, component=0, alpha=1.0, final=False)
        why = check_plan(plan)
        assert why == _check_plan_numpy(plan)
        verdicts.add(why)
        if why is None:
            expected = _limit_numbers_numpy(plan, limits)
            scaled, why, scale = within_limits(plan, limits, 0.2)
            if isinstance(expected, tuple):
                j, worst = expected
                assert why == (f'joint {j + 1} at {worst:.3f} rad, beyond its limits '
                               f'[{limits.lower[j]:.3f}, {limits.upper[j]:.3f}]')
                verdicts.add('position')
            else:
                assert scale == expected
                verdicts.add('scaled' if scale > 1 else 'as is')
    assert len(verdicts) == 10, verdicts     # None, every problem, and all three outcomes


def test_plan_phases_are_numpys_linspace():
    from mixture_ip_ros.estimation._fast import linspace
    rng = np.random.default_rng(8)
    for _ in range(2000):
        start = rng.choice([rng.uniform(-2, 1), 0.0, 1.0 - 1e-17, 5e-324])
        stop = rng.choice([1.0, start, rng.uniform(-3, 3)])
        num = int(rng.integers(2, 60))
        assert np.array_equal(linspace(start, stop, num), np.linspace(start, stop, num))


# -- hedged plans before the commit -------------------------------------------------------------

def test_the_predictive_path_weights_every_likely_components_path_by_its_probability(noisy):
    """predictive_controlled: sum_k p(k | D) of each component's expected path (the dense
    oracle: the batch formulas of _expected_path_oracle per component), over the components
    holding the posterior, renormalised; the hedged plan runs to the latest of their ends."""
    model, _, held = noisy
    demo = held[1]
    est = OnlineEstimator(model)
    until = demo.t[4]
    _feed(est, demo, until=until)
    components, probs = est.likely_components()
    assert len(components) > 1 and np.isclose(probs.sum(), 1.0)    # still uncertain
    p = est.component_posterior()
    assert np.allclose(probs, p[components] / p[components].sum())
    plan = build_plan(est, float(until), n_points=25, lookahead=0.1, hedged=True)
    paths = [_expected_path_oracle(model, demo, until, k, plan.times) for k in components]
    assert plan.times[-1] == pytest.approx(max(end for _, end in paths), rel=1e-12)
    oracle = sum(q * path for q, (path, _) in zip(probs, paths))
    assert np.allclose(plan.positions, oracle, atol=1e-10)
    assert check_plan(plan) is None and plan.component == est.map_hypothesis()[0]
    positions, none, nothing = est.predictive_controlled(plan.times, derivatives=False)
    assert np.array_equal(positions, plan.positions) and none is nothing is None
    with pytest.raises(ValueError, match='hedged'):
        build_plan(est, float(until), alpha=est.alphas[3], hedged=True)


def test_a_hedging_robot_moves_before_it_commits_and_commits_as_without(noisy):
    """With hedge, plans go out from min_observations on, before p(k* | D) reaches the
    threshold; the commit (phase, observations, component) is the one without hedge, and
    every plan after it is the same plan."""
    model, meta, held = noisy
    demo = held[1]
    runs = {}
    for hedge in (False, True):
        planner, _ = _planner(model, meta, confidence_threshold=0.98, min_observations=2,
                              hedge=hedge)
        planner.onset(0)
        steps = []
        for t, y in zip(demo.t, demo.observed):
            planner.observe(_ns(t), y)
            steps.append(planner.replan())
        runs[hedge] = planner, steps
    (plain, plain_steps), (hedging, hedge_steps) = runs[False], runs[True]
    for name in ('commit_phase', 'commit_observations', 'commit_component', 'commit_elapsed'):
        assert getattr(hedging.current, name) == getattr(plain.current, name)
    commit = next(i for i, s in enumerate(plain_steps) if s is not None and s.committed_now)
    early = [s for s in hedge_steps[:commit] if s is not None and s.send]
    assert hedging.current.hedged_plans == len(early) > 0
    assert not any(s.send for s in plain_steps[:commit] if s is not None)
    assert hedge_steps[commit].committed_now and hedge_steps[commit].switched_from is None
    assert hedging.current.switches == plain.current.switches
    for a, b in zip(plain_steps[commit:], hedge_steps[commit:]):
        assert (a is None) == (b is None)
        if a is not None:
            assert a.send == b.send and np.array_equal(a.plan.positions, b.plan.positions)


def test_a_hedging_robot_never_moves_for_a_movement_the_model_does_not_know(trained, noisy):
    """The novelty gate holds hedged plans too: a return to rest sends nothing; a movement
    that stops being explained once hedged plans went out (the noisy sensor's model stays
    below the threshold) makes the robot hold."""
    model, meta, held = trained
    for demo in held:
        planner = OnlinePlanner(OnlineEstimator(model), PlannerSettings(hedge=True),
                                novelty=model.novelty_)
        planner.onset(0)
        steps = [planner.replan() for t, y in zip(demo.t, demo.observed[::-1])
                 if planner.observe(_ns(t), y) is not None]
        assert planner.counts.plans_sent == 0 and not any(s.send for s in steps if s)
    # a second reach from where the first ended, without a rest
    # (test_a_committed_robot_holds_when_the_movement_stops_being_explained)
    model, meta, held = noisy
    first, second = held[1], held[0]
    t = np.concatenate([first.t, first.t[-1] + 0.01 + second.t])
    Y = np.vstack([first.observed, second.observed - second.observed[0] + first.observed[-1]])
    planner = OnlinePlanner(OnlineEstimator(model),
                            PlannerSettings(hedge=True, confidence_threshold=1.0),
                            novelty=model.novelty_)
    planner.onset(0)
    holds = []
    for ti, y in zip(t, Y):
        planner.observe(_ns(ti), y)
        step = planner.replan()
        if step is not None and step.hold:
            holds.append(step)
    assert planner.current.hedged_plans > 0 and planner.current.commit_phase is None
    assert len(holds) == 1 and not holds[0].send and planner.counts.holds == 1
    assert planner.current.end_reason == 'unexplained' and planner.state == 'done'
    assert planner.current.end_elapsed > first.duration   # after the first reach was done
