"""A replay that loops or restarts is a new stream, without ROS (estimation/): the observer
starts afresh and finds the second pass's onset and end exactly where it found the first's,
nothing dropped; the planner ends an interaction whose stream stopped, or whose clock jumped
back, without an error. Every clock here is injected."""

import numpy as np
import pytest

from mixture_ip_ros.core.mixture import MixtureIProMP
from mixture_ip_ros.core.online import OnlineEstimator
from mixture_ip_ros.core.segmentation import MotionSegmenter
from mixture_ip_ros.estimation.observer import WristObserver
from mixture_ip_ros.estimation.planner import OnlinePlanner, PlannerSettings
from mixture_ip_ros.scenarios.human_motion import reach
from mixture_ip_ros.scenarios.synthetic import mixture_demos

Q = (0.0, 0.0, 0.0, 1.0)
PERIOD_NS = 10_000_000                        # 100 Hz
START_NS = 1_700_000_000 * 10**9


def _pass(n_rest_after=80):
    """One pass of a replayed bag: 0.5 s at rest, a 1.2 s reach of 0.4 m, then rest. Positions
    (n, 3) and offsets of the stamps from the pass's first one (ns)."""
    t = np.arange(0.0, 1.7 + n_rest_after * 0.01, 0.01)
    xyz = reach(t, 0.5, 1.2, (0.9, 0.3, 0.1), (0.7, -0.05, 0.35), via_offset=(0, 0, 0.05))
    xyz += np.random.default_rng(0).normal(0.0, 0.001, xyz.shape)
    return xyz, np.arange(len(t), dtype=np.int64) * PERIOD_NS


def _feed(obs, stamps, xyz, clock=None):
    """Every pose, the clock reading ``clock(stamp)`` (default: the stamp). Returns what the
    node would publish, in order: ('point', stamp) and (event kind, stamp)."""
    out = []
    for ns, p in zip(stamps, xyz):
        now = int(ns) if clock is None else clock(int(ns))
        r = obs.on_pose(int(ns), 'world', tuple(p), Q, now_ns=now)
        assert r.rejected is None, (r.rejected, ns)
        if r.held:
            continue
        out += list(r.ended) + [('point', s) for s, _ in r.released] + [('point', int(ns))]
        out += r.events
    return out


def _events(published, origin_ns):
    return [(kind, ns - origin_ns) for kind, ns in published if kind != 'point']


def _observer(**kw):
    return WristObserver(MotionSegmenter(), expected_frame='world', **kw)


@pytest.mark.parametrize('how', ['recorded stamps, no clock',
                                 'recorded stamps, a simulated clock replayed with them',
                                 'stamps that continue (rewritten), a jump in space'])
def test_a_looping_replay_is_a_new_stream_whose_onset_and_end_are_the_first_passes(how):
    xyz, offsets = _pass()
    first = START_NS + offsets
    if how.startswith('recorded'):
        second = first                                   # the stamps jump back 2.5 s
    else:
        second = first[-1] + PERIOD_NS + offsets         # on the same clock, one period on
    clocked = 'clock' in how and 'no clock' not in how
    obs = _observer(max_clock_offset=1.0 if clocked else 0.0)
    published = _feed(obs, np.concatenate([first, second]), np.concatenate([xyz, xyz]))

    assert sum(obs.counts.dropped.values()) == 0 and obs.counts.stream_restarts == 1
    assert obs.counts.accepted == 2 * len(xyz)
    points = [ns for kind, ns in published if kind == 'point']
    assert points == list(first) + list(second)          # every pose, in order, own stamps
    n = len(xyz) + [k for k, _ in published[len(xyz):]].index('point')
    one, two = _events(published[:n], first[0]), _events(published[n:], second[0])
    assert [k for k, _ in one if k != 'gap'] == ['onset', 'end']
    assert one == two                                    # to the nanosecond, as fresh
    assert 0.45 < one[0][1] * 1e-9 < 0.6


def test_a_replay_restarted_mid_movement_ends_that_interaction_before_the_new_stream():
    xyz, offsets = _pass()
    cut = 110                                            # 1.1 s: in the middle of the reach
    obs = _observer(max_clock_offset=0.0)
    stamps = START_NS + offsets
    published = _feed(obs, np.concatenate([stamps[:cut], stamps]),
                      np.concatenate([xyz[:cut], xyz]))
    kinds = [k for k, _ in published]
    restart = cut + kinds[cut:].index('end')
    # The interaction in progress ends at its last sample, before the new stream's first pose.
    assert published[restart] == ('end', stamps[cut - 1])
    assert kinds[:restart].count('onset') == 1 and kinds[restart + 1] == 'point'
    assert [k for k in kinds[restart + 1:] if k not in ('point', 'gap')] == ['onset', 'end']
    assert sum(obs.counts.dropped.values()) == 0


@pytest.mark.parametrize('ahead_ns', [0, 300_000_000])
def test_a_stray_pose_older_than_the_clock_allows_is_dropped_and_the_stream_goes_on(ahead_ns):
    """Stamps going back while the clock did not: a pose delivered late, not a new stream,
    also when the stream is stamped ahead of the clock (a burst) and the stray is not."""
    xyz, offsets = _pass()
    stamps = START_NS + offsets
    clean = _feed(_observer(max_clock_offset=1.0), stamps, xyz, clock=lambda ns: ns - ahead_ns)
    obs = _observer(max_clock_offset=1.0)
    events = []
    for i, (ns, p) in enumerate(zip(stamps, xyz)):
        now = int(ns) - ahead_ns
        if i == 100:
            stray = obs.on_pose(int(ns) - 1_000_000_000, 'world', tuple(p), Q, now_ns=now)
            assert stray.rejected == 'stamp_backwards'
        events += obs.on_pose(int(ns), 'world', tuple(p), Q, now_ns=now).events
    assert events == [e for e in clean if e[0] != 'point']
    assert obs.counts.stream_restarts == 0


@pytest.mark.parametrize('samples, moving', [(2, False), (6, True)])
def test_a_jump_that_comes_back_is_a_glitch_dropped_not_a_new_stream(samples, moving):
    """At rest, fewer than new_stream_samples poses elsewhere; while moving, any number (as
    long as no hand could have gone there and back)."""
    xyz, offsets = _pass()
    stamps = START_NS + offsets
    at = 100 if moving else 20
    seen = xyz.copy()
    seen[at:at + samples] += (0.0, 0.0, 0.6)
    obs = _observer(max_clock_offset=0.0)
    verdicts = [obs.on_pose(int(ns), 'world', tuple(p), Q, now_ns=int(ns))
                for ns, p in zip(stamps, seen)]
    assert obs.counts.stream_restarts == 0
    assert obs.counts.dropped['implausible_speed'] >= min(samples, 2)
    assert [v.rejected for v in verdicts[:at]] == [None] * at
    assert all(v.rejected is None for v in verdicts[at + samples + 3:])


def test_new_stream_settings_are_checked():
    with pytest.raises(ValueError, match='new_stream_jump_back must be > 0 s'):
        _observer(new_stream_jump_back=0.0)
    with pytest.raises(ValueError, match='new_stream_samples must be a whole number'):
        _observer(new_stream_samples=1.5)


# -- the planner --------------------------------------------------------------------------------
@pytest.fixture(scope='module')
def estimator():
    demos = mixture_demos(seed=0, n_obs=3, n_ctrl=2, n_basis=6)[0]
    return OnlineEstimator(MixtureIProMP(1, n_basis=6).fit(demos[:12])), demos[12]


def _observed(planner, demo, onset_ns, clock_lag_ns=1_000_000):
    """The demonstration's observations from ``onset_ns``, each arriving ``clock_lag_ns`` after
    its stamp; the clock of the last one."""
    now = onset_ns
    for t, y in zip(demo.t, demo.observed):
        stamp = onset_ns + int(round(t * 1e9))
        now = stamp + clock_lag_ns
        planner.observe(stamp, y, now_ns=now)
        planner.replan(now)
    return now


def test_an_end_long_after_the_stream_stopped_ends_the_interaction_without_a_plan(estimator):
    """The player stopped mid-interaction: the observer's 'end' comes max_gap (2 s) after the
    last observation, dated at it. No plan (it would start 2 s in the past), no refusal."""
    est, demo = estimator
    planner = OnlinePlanner(est, PlannerSettings(max_clock_offset=1.0))
    onset = START_NS
    planner.onset(onset)
    now = _observed(planner, demo, onset)
    last = onset + int(round(demo.t[-1] * 1e9))
    assert planner.end(last, now_ns=now + 2_020_000_000) is None
    rec = planner.current
    assert planner.state == 'done' and rec.end_reason == 'stream_stopped'
    assert rec.end_elapsed == pytest.approx(demo.t[-1])
    assert planner.counts.plan_refusals['off_clock'] == 0


def test_an_end_on_another_clock_altogether_is_still_refused(estimator):
    est, demo = estimator
    planner = OnlinePlanner(est, PlannerSettings(max_clock_offset=1.0))
    planner.onset(START_NS)
    years = 10**18
    now = _observed(planner, demo, START_NS, clock_lag_ns=years)
    step = planner.end(START_NS + int(round(demo.t[-1] * 1e9)), now_ns=now)
    assert not step.send and 'from this node' in step.problem
    assert planner.current.end_reason == 'end'


def test_a_clock_jumping_back_ends_the_interaction_and_the_next_one_starts_on_the_new_time(
        estimator):
    est, demo = estimator
    planner = OnlinePlanner(est, PlannerSettings(max_clock_offset=1.0))
    planner.onset(START_NS)
    now = _observed(planner, demo, START_NS)
    planner.tick(now + 50_000_000)                       # the clock goes on
    assert planner.active
    restarted = 5 * 10**9                                # a simulated clock back at 5 s
    planner.tick(restarted)
    assert planner.state == 'done' and planner.current.end_reason == 'clock_reset'
    planner.onset(restarted)
    _observed(planner, demo, restarted)
    assert len(planner.interactions) == 2 and planner.active
    assert planner.current.n_observations == planner.interactions[0].n_observations > 0
    assert sum(planner.counts.rejected.values()) == 0


def test_a_clock_not_yet_running_refuses_no_plan_and_the_interaction_commits(estimator):
    """Under simulated time a node's clock reads 0 until its first /clock (a replay publishing
    its own clock, heard by the estimator after the observer): no time to judge the stamps
    against, as for the observer, so no plan is refused as off the clock."""
    est, demo = estimator
    planner = OnlinePlanner(est, PlannerSettings(max_clock_offset=1.0))
    planner.onset(START_NS)
    problems = []
    for i, (t, y) in enumerate(zip(demo.t, demo.observed)):
        stamp = START_NS + int(round(t * 1e9))
        now = 0 if i < 10 else stamp + 1_000_000
        planner.observe(stamp, y, now_ns=now)
        step = planner.replan(now)
        problems += [] if step is None or step.problem is None else [(i, step.problem)]
    assert problems == []
    assert planner.counts.plan_refusals['off_clock'] == 0
    assert planner.state == 'committed'


def test_a_clock_jumping_back_after_the_commit_ends_the_interaction_and_the_robot_holds(estimator):
    """The arm moves on a committed plan when the simulated clock restarts: the next replan
    returns the interaction's last Step, no plan and a hold, once; it is counted."""
    est, demo = estimator
    planner = OnlinePlanner(est, PlannerSettings(max_clock_offset=1.0))
    planner.onset(START_NS)
    _observed(planner, demo, START_NS)
    assert planner.state == 'committed'
    assert planner.tick(5 * 10**9)                      # a reset asks for a replan
    step = planner.replan(5 * 10**9)
    assert step is not None and step.hold and not step.send and step.plan is None
    assert 'clock jumped back' in step.notice and 'holds' in step.notice
    assert planner.current.end_reason == 'clock_reset' and planner.counts.clock_resets == 1
    assert planner.replan(5 * 10**9 + 10**8) is None    # said once
