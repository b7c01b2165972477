"""A person who changes their mind mid-reach (issue 50), in the closed loop: box-assembly bags
spliced (scenarios.change_of_mind) and replayed through the real nodes (bag_player -> observer
-> estimator -> sim, on simulated time, in one process) as `mixture-ip demo --scenario
change_of_mind` replays them.

The splice bags are checked against their sources (no ROS). The loop runs once with the model
as training ships it, the three held-out reaches unchanged and three splices (each pattern
turning into another once, at shares over the demo's range), at twice real time (the nodes run
on simulated time: only the wall clock changes). The same splices run again with the same
model without its novelty thresholds (the estimator then commits on confidence alone): the
change-point belief, the planner's switch and the arm past the novelty test.
"""

import numpy as np
import pytest

from conftest import private_domain_id
from mixture_ip_ros.core.splice import BLEND
from mixture_ip_ros.io.bags import ONSET_KEY, read_bag
from mixture_ip_ros.io.dataset import load_demonstration
from mixture_ip_ros.scenarios.change_of_mind import (CHANGE_KEY, FIRST_KEY, SHARE_KEY,
                                                     read_splices, splice_recordings,
                                                     write_change_of_mind_bags)
from mixture_ip_ros.scenarios.folders import read_labels

pytestmark = pytest.mark.filterwarnings('ignore::DeprecationWarning')
# Each pattern turns into another once; the shares span the demo's (0.3 to 0.6).
TURNS = (('screw', 'plate', 0.3), ('plate', 'screwdriver', 0.45), ('screwdriver', 'screw', 0.6))
# The splice's last plan rests on B's last wrist position, as the unchanged replay of B's own
# bag does: its hand should end where that one's ended, up to the 0.5 cm test_integration
# allows the loop (which wrist sample at rest, 1 mm of noise apart, the last plan is
# conditioned on, and a plan late under load). The aim (issue 50) is 1.5x.
SLACK = 0.005


@pytest.fixture(scope='module')
def setup(box_loop, tmp_path_factory):
    """The session's box-assembly bags and model (conftest.box_loop); the three splices of
    TURNS between the held-out bags."""
    root = tmp_path_factory.mktemp('change_of_mind')
    bag = {box_loop['labels'][n]: n for n in box_loop['held']}
    plan = [(bag[a], bag[b], share) for a, b, share in TURNS]
    folder = root / 'splices'
    data = box_loop['data']
    write_change_of_mind_bags([(data / a, data / b, s) for a, b, s in plan], folder)
    return {**box_loop, 'folder': folder, 'recipe': read_splices(folder), 'root': root}


def _replay(model, setup, held):
    from mixture_ip_ros.app.change_of_mind import replay
    from mixture_ip_ros.app.closed_loop import ClosedLoop
    from mixture_ip_ros.robot.kinematics import RobotKinematics
    loop = ClosedLoop(model, domain_id=private_domain_id(), real_time_factor=2.0)
    try:
        records, report = replay(loop, setup['data'], setup['labels'], held, setup['folder'],
                                 setup['recipe'], RobotKinematics(), setup['info'],
                                 progress=lambda line: None)
    finally:
        loop.close()
    return report


@pytest.fixture(scope='module')
def shipped(setup):
    """The held-out bags unchanged, then the splices, with the model as trained."""
    return _replay(setup['model'], setup, setup['held'])


@pytest.fixture(scope='module')
def without_novelty(setup, shipped):
    """The splices with the same model, its novelty thresholds removed."""
    from mixture_ip_ros.io.model_file import load_model, save_model
    model, meta = load_model(setup['model'])
    model.novelty_ = None
    path = setup['root'] / 'model_without_novelty.npz'
    save_model(path, model, observed_names=meta['observed_names'],
               controlled_names=meta['controlled_names'], observed_frame=meta['observed_frame'],
               component_labels=meta['component_labels'])
    return _replay(path, setup, [])


def _unchanged_error(shipped, bag):
    row, = [r for r in shipped['unchanged']['interactions'] if r['name'] == bag]
    return row['hand_error_cm'] / 100


# ------------------------------------------------------------------ the bags

def test_a_splice_bag_is_the_first_reach_then_the_second(setup):
    data, folder = setup['data'], setup['folder']
    recipe = setup['recipe']
    assert sorted((r['first'], r['second'], r['share']) for r in recipe.values()) == \
        sorted(TURNS)
    assert read_labels(folder) == {n: r['second'] for n, r in recipe.items()}
    for name, r in recipe.items():
        s, a, b = (read_bag(p) for p in (folder / name, data / r['first_bag'],
                                          data / r['second_bag']))
        assert s.label == r['second'] and s.custom_data[FIRST_KEY] == r['first']
        assert float(s.custom_data[SHARE_KEY]) == r['share']
        t_change = (int(s.custom_data[CHANGE_KEY]) - s.start_time_ns) * 1e-9
        onset = (int(s.custom_data[ONSET_KEY]) - s.start_time_ns) * 1e-9
        spliced = load_demonstration(folder / name, cut='recorded')
        own = [load_demonstration(data / r[k], cut='recorded') for k in ('first_bag',
                                                                         'second_bag')]
        # A up to its share, B from the same share of its own movement to its end
        assert t_change - onset == pytest.approx(r['change_after_onset_s'], abs=1e-6)
        assert t_change - onset == pytest.approx(r['share'] * own[0].duration, abs=0.02)
        assert spliced.duration == pytest.approx(r['share'] * own[0].duration
                                                 + (1 - r['share']) * own[1].duration, abs=0.03)
        # before the change: A's recording as it was, from its start
        head = s.wrist_t < t_change - 1e-6
        k = int(head.sum())
        np.testing.assert_allclose(s.wrist_xyz[head], a.wrist_xyz[:k], atol=1e-9)
        np.testing.assert_allclose(s.wrist_t[head], a.wrist_t[:k], atol=1e-8)
        # once faded in: B's recording, shifted in time, to its last sample (joints too)
        tail = s.wrist_t >= t_change + BLEND + 1e-6
        n = int(tail.sum())
        np.testing.assert_allclose(s.wrist_xyz[tail], b.wrist_xyz[-n:], atol=1e-9)
        np.testing.assert_allclose(np.diff(s.wrist_t[tail]), np.diff(b.wrist_t[-n:]),
                                   atol=1e-8)
        np.testing.assert_allclose(s.joint_q[-1], b.joint_q[-1], atol=1e-9)
        # no jump where it turns: the step there is no larger than the recordings' own
        turn = np.linalg.norm(s.wrist_xyz[k] - s.wrist_xyz[k - 1])
        own_step = max(np.linalg.norm(np.diff(x.wrist_xyz, axis=0), axis=1).max()
                       for x in (a, b))
        assert turn <= own_step, name


def test_splicing_refuses_what_it_cannot_join(setup):
    data, held = setup['data'], setup['held']
    a, b = (read_bag(data / n) for n in held[:2])
    with pytest.raises(ValueError, match=r'share of the first movement must be in \(0, 1\)'):
        splice_recordings(a, b, 1.0)
    with pytest.raises(ValueError, match='shorter than the .* fade'):
        splice_recordings(a, b, 0.9, blend=2.0)
    with pytest.raises(ValueError, match='not empty'):
        write_change_of_mind_bags([(data / held[0], data / held[1], 0.5)], setup['folder'])


# ------------------------------------------------------------------ the loop

def test_the_unchanged_reaches_are_still_recognised(shipped):
    rows = shipped['unchanged']['interactions']
    assert sorted(r['true_pattern'] for r in rows) == ['plate', 'screw', 'screwdriver']
    for r in rows:
        assert r['chosen_pattern'] == r['true_pattern'], r['name']
        assert r['hand_error_cm'] < 4.0, r['name']        # test_integration's HAND_BOUND
        assert r['points_beyond_limits'] == 0 and r['plans_refused'] == 0, r['name']


def test_a_change_of_mind_never_drives_the_arm_beyond_its_limits(shipped, without_novelty):
    for report in (shipped, without_novelty):
        assert report['n'] == len(TURNS)
        for r in report['interactions']:
            assert r['points_beyond_limits'] == 0, r['name']
            assert r['plans_refused'] == 0 and r['commands_refused'] == 0, r['name']
            assert r['non_finite_commands'] == 0, r['name']


@pytest.mark.decision
def test_past_the_novelty_test_the_arm_follows_the_change(setup, shipped, without_novelty):
    """The belief follows the person to B, the planner switches the committed arm, and the
    hand ends at B's target as the unchanged replay of B's own bag ended, in two of the three
    turns at least: a turn late in a fast reach (0.6 of it) leaves the change points little
    of the movement (none starts within two basis spacings of its end)."""
    rows = without_novelty['interactions']
    assert sum(r['final_plan_pattern'] == r['true_pattern'] for r in rows) >= 2
    for r in rows:
        assert r['end_reason'] == 'end', r['name']
        if r['final_plan_pattern'] != r['true_pattern']:
            continue
        assert r['belief_settled_s'] is not None, r['name']
        if r['commit_pattern'] == r['first_pattern']:
            assert r['switches'] and r['switches'][-1]['to'] == r['true_pattern'], r['name']
        b = setup['recipe'][r['name']]['second_bag']
        assert r['hand_error_cm'] / 100 < _unchanged_error(shipped, b) + SLACK, r['name']


def test_with_the_novelty_test_a_turn_is_followed_or_held(shipped):
    """With the model as trained, the novelty test (thresholds from unchanged held-out
    recordings) may take the turn for a movement the model does not know: the arm then holds
    where it is and the interaction ends 'unexplained'; or the test speaks before the commit
    (on a loaded machine the estimator, behind on its observations, commits later) and the
    interaction ends with the arm never having moved. It never goes on to A's target."""
    for r in shipped['interactions']:
        assert r['end_reason'] in ('end', 'unexplained'), (r['name'], r['end_reason'])
        if r['end_reason'] == 'end' and r['commit_pattern'] is None:
            assert r['commands'] == 0 and r['unexplained'] is not None, r
        elif r['end_reason'] == 'end':
            assert r['final_plan_pattern'] == r['true_pattern'], r
