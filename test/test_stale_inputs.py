"""The planner on stale inputs, on an injected clock: no plan from an old arm state, and an
interaction whose wrist stream goes silent ends with the robot holding."""

import numpy as np
import pytest

from mixture_ip_ros.app.training import train_to_file
from mixture_ip_ros.core.online import OnlineEstimator
from mixture_ip_ros.estimation.planner import OnlinePlanner, PlannerSettings
from mixture_ip_ros.estimation.records import LatencyStats
from mixture_ip_ros.estimation.stale_inputs import StaleInputs
from mixture_ip_ros.io.model_file import load_model
from mixture_ip_ros.nodes.estimator_diagnostics import estimation_values
from mixture_ip_ros.scenarios.synthetic import mixture_demos

HELD_OUT = (0, 13, 30)   # one demonstration of each pattern, not used for training
ONSET = 1_700_000_000_000_000_000
MS = 1_000_000


@pytest.fixture(scope='module')
def trained(tmp_path_factory):
    demos = mixture_demos(seed=0, n_obs=3, n_ctrl=7, n_basis=8)[0]
    path = tmp_path_factory.mktemp('model') / 'model.npz'
    train_to_file([d for i, d in enumerate(demos) if i not in HELD_OUT], path, n_components=3,
                  n_basis=8)
    model, _ = load_model(path)
    return model, [demos[i] for i in HELD_OUT]


def _ns(t):
    return ONSET + int(round(t * 1e9))


def _reported(planner):
    """The values estimator_node puts on /diagnostics for ``planner``."""
    return estimation_values(planner, LatencyStats(), LatencyStats(), {'unknown': 0})


def _planner(model, **settings):
    return OnlinePlanner(OnlineEstimator(model), PlannerSettings(**settings))


def test_ages_are_judged_on_the_callers_clock_once_it_runs_and_each_stale_spell_told_once():
    inputs = StaleInputs()
    assert inputs.stale_state(ONSET, 0.5) == (None, False)          # never heard: not stale
    inputs.joint_state(ONSET)
    assert inputs.stale_state(ONSET + 500 * MS, 0.5) == (None, False)   # exactly the limit
    why, new = inputs.stale_state(ONSET + 501 * MS, 0.5)
    assert new and why == 'no joint state for 0.501 s (max_joint_state_age 0.5 s)'
    assert inputs.stale_state(ONSET + 900 * MS, 0.5)[1] is False    # the same spell
    assert inputs.stale_state(ONSET + 900 * MS, 0.0) == (None, False)   # 0: no check
    inputs.joint_state(ONSET + 900 * MS)
    assert inputs.stale_state(ONSET + 1000 * MS, 0.5) == (None, False)
    assert inputs.stale_state(ONSET + 1500 * MS, 0.5)[1] is True    # a new spell
    assert inputs.stale_state(0, 0.5) == (None, False)   # a clock not running yet: not judged
    # the clock reset (a sim restarted): the state came after the present, it is re-read
    inputs.joint_state(ONSET + 900 * MS)
    why, new = inputs.stale_state(ONSET + 399 * MS, 0.5)
    assert new and why.startswith('the latest joint state came on the clock before it was')
    assert inputs.stale_state(ONSET + 900 * MS, 0.5)[0] == why   # the new clock back there
    inputs.joint_state(ONSET - 300 * MS)                 # the new sim's first state
    assert inputs.stale_state(ONSET - 200 * MS, 0.5) == (None, False)
    assert inputs.silence(0, 2.5) is None
    assert inputs.silence(ONSET, 2.5) is None            # the first reading starts the count
    inputs.heard(0)
    assert inputs.silence(ONSET + 2600 * MS, 2.5) == ('no wrist observation for 2.6 s '
                                                      '(max_wrist_silence 2.5 s)')


def test_no_plan_goes_out_while_the_arm_state_is_stale(trained):
    """Against the same planner without the rule, both fed the same observations and arm states
    on a clock equal to the stamps: the steps agree while the state is at most 0.5 s old; after
    that nothing is sent (counted once, one notice) until a state comes, then plans go out."""
    model, held = trained
    demo = held[1]
    planner = _planner(model, max_joint_state_age=0.5)
    reference = _planner(model)
    q = np.zeros(7)
    cut = 0.3                      # the arm's state stops coming here
    for p in (planner, reference):
        p.onset(ONSET)
    stale_steps = sent_before = 0
    for t, y in zip(demo.t, demo.observed):
        if t > 1.0:
            break
        now = _ns(t)
        if t <= cut:
            state_ns = now
            for p in (planner, reference):
                p.joint_state(q, q, now)
        for p in (planner, reference):
            p.observe(now, y, now)
        step, expected = planner.replan(now), reference.replan(now)
        if expected is None:
            assert step is None
        elif now - state_ns <= 500 * MS:
            assert step.send == expected.send and step.withheld is None
            sent_before += step.send
        elif expected.send:
            assert not step.send and step.withheld.startswith('no joint state for')
            assert (step.notice is not None) == (stale_steps == 0)
            stale_steps += 1
    assert sent_before > 0 and stale_steps > 1
    assert planner.counts.stale_joint_states == 1 and planner.state == 'committed'
    assert _reported(planner)['stale_joint_states'] == 1
    assert planner.counts.plans_sent == sent_before
    planner.joint_state(q, q, _ns(1.0))              # the arm is heard again
    t, y = next((t, y) for t, y in zip(demo.t, demo.observed) if t > 1.05)
    planner.observe(_ns(t), y, _ns(t))
    step = planner.replan(_ns(t))
    assert step.send and step.withheld is None and step.notice is None
    assert planner.counts.stale_joint_states == 1


def _committed(model, demo, **settings):
    """A planner committed on ``demo``'s first half second, clock = stamps; the last stamp."""
    planner = _planner(model, **settings)
    planner.onset(ONSET)
    for t, y in zip(demo.t, demo.observed):
        if t > 0.5:
            break
        planner.observe(_ns(t), y, _ns(t))
        planner.replan(_ns(t))
        last = _ns(t)
    assert planner.state == 'committed'
    return planner, last


def test_a_silent_wrist_stream_ends_the_interaction_and_the_robot_that_moved_holds(trained):
    model, held = trained
    planner, last = _committed(model, held[0], max_wrist_silence=2.5)
    plans = planner.counts.plans_sent
    assert planner.replan(last + 2500 * MS) is None          # 2.5 s: not yet, nothing new
    assert planner.state == 'committed'
    assert planner.tick(last + 2501 * MS)                    # a replan is due: to end it
    step = planner.replan(last + 2501 * MS)
    assert step.hold and not step.send and step.plan is None
    assert step.notice == ('no wrist observation for 2.5 s (max_wrist_silence 2.5 s): the '
                           'interaction ends, the robot holds')
    rec = planner.current
    assert (planner.state, rec.end_reason, rec.end_elapsed) == ('done', 'wrist_silent',
                                                               planner.t_now)
    assert planner.counts.silent_ends == 1 and planner.counts.plans_sent == plans
    assert _reported(planner)['ends_wrist_silent'] == 1
    assert planner.replan(last + 3000 * MS) is None
    assert planner.counts.silent_ends == 1


def test_silence_is_counted_from_the_onset_and_a_robot_never_moved_does_not_hold(trained):
    model, _ = trained
    planner = _planner(model, max_wrist_silence=2.5)
    planner.onset(ONSET)
    planner.tick(ONSET + 100 * MS)                  # the first call after the onset
    assert planner.replan(ONSET + 2600 * MS) is not None and planner.state == 'observing'
    step = planner.replan(ONSET + 2601 * MS)
    assert not step.hold and step.notice.endswith('the interaction ends')
    assert planner.current.end_reason == 'wrist_silent'


def test_an_end_from_the_observer_comes_first_and_zero_turns_the_rules_off(trained):
    model, held = trained
    planner, last = _committed(model, held[0], max_wrist_silence=2.5)
    step = planner.end(last, last + 2000 * MS)      # the observer's max_gap: 2 s
    assert planner.current.end_reason == 'end' and not step.hold
    assert planner.counts.silent_ends == 0
    planner, last = _committed(model, held[0])      # 0: no check
    assert planner.replan(last + 60_000 * MS) is None and planner.state == 'committed'
    for name in ('max_joint_state_age', 'max_wrist_silence'):
        with pytest.raises(ValueError, match=f'{name} must be >= 0 s'):
            PlannerSettings(**{name: -1.0})
