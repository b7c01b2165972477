"""Generated scenarios: reproducible, feasible for every shipped robot, shaped like the thesis's
experiments, the human side the same whichever robot, and written to / read back from real
rosbag2 bags."""

import json

import numpy as np
import pytest

from mixture_ip_ros.io.bags import read_bag
from mixture_ip_ros.io.dataset import load_dataset
from mixture_ip_ros.robot.description import shipped_robots
from mixture_ip_ros.robot.kinematics import RobotKinematics
from mixture_ip_ros.robot.scene import POLE_HEIGHT, POLE_RADIUS, POLE_XY
from mixture_ip_ros.scenarios.arm import ROTATION_TOL
from mixture_ip_ros.scenarios.box_assembly import (BOX_LABELS, PLATE_OFFSET, SCREW_HANDOVER,
                                                   SCREWDRIVER_OFFSET, box_assembly)
from mixture_ip_ros.scenarios.folders import (generate, read_labels, read_scenario_robot,
                                              write_scenario_bags)
from mixture_ip_ros.scenarios.letters import missing_data_letters, phase_letters
from mixture_ip_ros.scenarios.pole import (FLANGE_FROM_SPOT, POLE_BOTH_SIDES_Y, WAND_OFFSET,
                                           _pointing_rotation, pole)

ROBOTS = shipped_robots()
# An arm without a spare joint cannot pass the pole on both sides of a spot near the middle
# (pole() raises and says so): the UR5's pole set has every spot on one side only.
POLE_KWARGS = {'ur5': {'both_sides': 0}}


@pytest.fixture(scope='module')
def kins():
    return {r: RobotKinematics(r) for r in ROBOTS}


@pytest.fixture(scope='module')
def kin(kins):
    return kins['iiwa14']


@pytest.fixture(scope='module')
def boxes(kins):
    return {r: box_assembly(seed=7, kinematics=k) for r, k in kins.items()}


@pytest.fixture(scope='module')
def poles(kins):
    return {r: pole(seed=3, kinematics=k, **POLE_KWARGS.get(r, {})) for r, k in kins.items()}


@pytest.fixture(scope='module')
def box(boxes):
    return boxes['iiwa14']


@pytest.fixture(scope='module')
def pole_demos(poles):
    return poles['iiwa14']


def _same(a, b):
    for x, y in zip(a, b):
        assert x.name == y.name and x.label == y.label
        np.testing.assert_array_equal(x.wrist_xyz, y.wrist_xyz)
        np.testing.assert_array_equal(x.joint_q, y.joint_q)
        np.testing.assert_array_equal(x.wrist_t, y.wrist_t)


def test_box_assembly_is_reproducible_and_shuffled(kin, box):
    _same(box, box_assembly(seed=7, kinematics=kin))
    other = box_assembly(seed=8, kinematics=kin)
    assert not np.array_equal(box[0].wrist_xyz[:50], other[0].wrist_xyz[:50])
    labels = [d.label for d in box]
    assert {lab: labels.count(lab) for lab in BOX_LABELS} == {'plate': 15, 'screw': 20,
                                                              'screwdriver': 13}
    assert [d.name for d in box] == [f'demo_{i:03d}' for i in range(48)]
    # Unlabeled in practice: the order does not group the patterns.
    changes = sum(a != b for a, b in zip(labels, labels[1:]))
    assert changes > 15


def _check_feasible(kin, demos):
    for d in demos:
        assert np.all(d.joint_q >= kin.lower) and np.all(d.joint_q <= kin.upper), d.name
        # Velocity limits, checked on finite differences of the sampled path (not the stored qd).
        v = np.abs(np.diff(d.joint_q, axis=0)) / np.diff(d.joint_t)[:, None]
        assert np.all(v <= kin.velocity_limit * 1.001), d.name
        np.testing.assert_allclose(d.joint_qd[1:-1], np.gradient(d.joint_q, d.joint_t, axis=0)[1:-1],
                                   atol=0.02)


@pytest.mark.parametrize('robot', ROBOTS)
def test_robot_joints_within_position_and_velocity_limits(kins, boxes, poles, robot):
    _check_feasible(kins[robot], boxes[robot])
    _check_feasible(kins[robot], poles[robot])


@pytest.mark.parametrize('robot', ROBOTS)
def test_robot_moves_exactly_during_the_human_movement(boxes, poles, robot):
    for d in boxes[robot] + poles[robot]:
        before = d.joint_t < d.onset
        after = d.joint_t > d.end
        assert before.sum() >= 25 and after.sum() >= 35  # 0.3 s / 0.4 s of rest at 100 Hz
        np.testing.assert_array_equal(d.joint_q[before], np.tile(d.joint_q[0], (before.sum(), 1)))
        np.testing.assert_array_equal(d.joint_q[after], np.tile(d.joint_q[-1], (after.sum(), 1)))
        # ... and is already moving 10 % into the movement, still moving 10 % before its end.
        early = np.argmin(np.abs(d.joint_t - (d.onset + 0.1 * d.duration)))
        late = np.argmin(np.abs(d.joint_t - (d.end - 0.1 * d.duration)))
        assert np.abs(d.joint_q[early] - d.joint_q[0]).max() > 1e-3
        assert np.abs(d.joint_q[late] - d.joint_q[-1]).max() > 1e-3
        # The human is still (noise only) before the onset and after the end.
        w_before = d.wrist_xyz[d.wrist_t < d.onset]
        assert np.all(np.nanstd(w_before, axis=0) < 0.002)
        assert np.linalg.norm(np.nanmean(d.wrist_xyz[d.wrist_t > d.end + 0.05], axis=0)
                              - d.wrist_goal) < 0.003


@pytest.mark.parametrize('robot', ROBOTS)
def test_flange_meets_the_hand_for_plate_and_screwdriver(kins, boxes, robot):
    kin = kins[robot]
    to_world = kin.description.base_to_world()
    tool = kin.description.tool_rotation()
    for d in boxes[robot]:
        p_base, R_base = kin.fk(d.joint_q[-1])
        p_end = to_world.apply_array(p_base)                 # the world frame of the human
        axis = (to_world.rotation @ R_base @ tool.T)[:, 2]   # the tool's approach axis
        if d.label == 'plate':
            np.testing.assert_allclose(p_end, d.wrist_goal + PLATE_OFFSET, atol=3e-3)
            assert axis[2] < -np.cos(ROTATION_TOL)  # carried gripper-down
        elif d.label == 'screwdriver':
            np.testing.assert_allclose(p_end, d.wrist_goal + SCREWDRIVER_OFFSET, atol=3e-3)
            assert axis[2] > -0.2 and axis[0] > 0.9  # pointing at the human
        else:
            assert np.linalg.norm(p_end - SCREW_HANDOVER) < 0.03
        if d.label != 'screw':
            gap = np.linalg.norm(p_end - d.wrist_goal)
            assert 0.05 < gap < 0.15  # close, but not colliding


def test_the_human_side_does_not_depend_on_the_robot(boxes):
    """Same seed, another arm: the same human movements, except where an arm could not follow
    one and it was redrawn (for that arm only)."""
    reference = boxes['iiwa14']
    for robot, demos in boxes.items():
        same = 0
        for a, b in zip(reference, demos):
            assert a.name == b.name and a.label == b.label
            if a.extra['attempt'] == b.extra['attempt']:
                np.testing.assert_array_equal(a.wrist_t, b.wrist_t)
                np.testing.assert_array_equal(a.wrist_xyz, b.wrist_xyz)
                same += 1
            else:
                assert not np.array_equal(a.wrist_xyz[-50:], b.wrist_xyz[-50:])
        assert same >= 40, robot   # measured: 43-48 of 48 at this seed
        assert all(d.robot.name == robot for d in demos)


def test_patterns_differ_where_the_human_reaches(box):
    goals = {lab: np.array([d.wrist_goal for d in box if d.label == lab]) for lab in BOX_LABELS}
    centres = {lab: g.mean(axis=0) for lab, g in goals.items()}
    for a in BOX_LABELS:
        for b in BOX_LABELS:
            if a < b:
                assert np.linalg.norm(centres[a] - centres[b]) > 0.25
    # Every two patterns' wrist end positions are separated by >= 5 cm along some axis.
    for a in BOX_LABELS:
        for b in BOX_LABELS:
            if a < b:
                gap = np.maximum(goals[b].min(axis=0) - goals[a].max(axis=0),
                                 goals[a].min(axis=0) - goals[b].max(axis=0))
                assert gap.max() >= 0.05, (a, b)
    # Plate goals spread over a region; the robot's screw handover place does not follow the hand.
    assert np.ptp(goals['plate'][:, 1]) > 0.25
    flanges = np.array([d.flange_goal for d in box if d.label == 'screw'])
    assert np.all(flanges.std(axis=0) < 0.015)


def test_durations_spread(box, pole_demos):
    for lab in BOX_LABELS:
        dur = [d.duration for d in box if d.label == lab]
        assert max(dur) / min(dur) >= 1.5, lab
    dur = [d.duration for d in pole_demos]
    assert max(dur) / min(dur) >= 1.5


def test_human_reach_shapes_vary(box):
    plate = [d for d in box if d.label == 'plate']
    vias = np.array([d.extra['via'] for d in plate])
    assert np.all(vias.std(axis=0) > 0.01)


def test_occlusion_gaps(kin):
    demos = box_assembly(seed=2, occlusion=1.0, counts={'plate': 3, 'screw': 3}, kinematics=kin)
    for d in demos:
        missing = np.isnan(d.wrist_xyz).any(axis=1)
        assert np.isnan(d.wrist_xyz[missing]).all()
        tm = d.wrist_t[missing]
        assert 0.09 <= tm[-1] - tm[0] + 0.01 <= 0.31
        assert np.all(np.diff(np.flatnonzero(missing)) == 1)  # one contiguous gap
        assert d.onset < tm[0] and tm[-1] < d.end


@pytest.mark.parametrize('robot', ROBOTS)
def test_pole_demos_avoid_the_pole_and_split_into_two_sides(kins, poles, robot):
    kin, pole_demos = kins[robot], poles[robot]
    d0 = kin.description
    to_world = d0.base_to_world()
    tool = d0.tool_rotation()
    assert len(pole_demos) == 28
    labels = [d.label for d in pole_demos]
    assert 8 <= labels.count('left') <= 20
    required = POLE_RADIUS + d0.link_radius  # pole + link radius, before the generator's margin
    # The robot's polyline (shoulder, elbow, wrist, flange ...), from Pinocchio directly.
    frames = list(d0.clearance_frames)
    for d in pole_demos:
        for q in d.joint_q[::3]:
            pts = to_world.apply_array(kin.frame_positions(q, frames))
            assert np.all(pts[1:, 2] > 0.0)  # above the table
            # Flange path and elbow/wrist frames, and the links between them (sampled).
            seg = np.vstack([a + s * (b - a) for a, b in zip(pts[:-1], pts[1:])
                             for s in np.linspace(0, 1, 15)])
            low = seg[:, 2] <= POLE_HEIGHT
            dist = np.linalg.norm(seg[low, :2] - np.asarray(POLE_XY), axis=1)
            assert np.all(dist >= required), d.name
        # The flange ends 5 cm from the spot the human pointed at, pointing at it (within 0.2 rad).
        p_base, R_base = kin.fk(d.joint_q[-1])
        p_end = to_world.apply_array(p_base)
        tool_axis = (to_world.rotation @ R_base @ tool.T)[:, 2]
        spot = d.extra['spot']
        axis = _pointing_rotation(1 if d.label == 'left' else -1)[:, 2]
        np.testing.assert_allclose(p_end, spot - FLANGE_FROM_SPOT * axis, atol=2.5e-3)
        assert tool_axis @ axis > np.cos(ROTATION_TOL + 1e-6)
        np.testing.assert_allclose(d.wrist_goal - spot, WAND_OFFSET, atol=0.04)
        assert (d.label == 'left') == (tool_axis[1] < 0)  # tilted in from its side
        if abs(spot[1]) > POLE_BOTH_SIDES_Y:
            assert d.label == ('left' if spot[1] > 0 else 'right')


@pytest.mark.parametrize('robot', ['iiwa14', 'panda'])
def test_pole_same_spot_both_sides_gives_very_different_postures(poles, robot):
    by_spot = {}
    for d in poles[robot]:
        by_spot.setdefault(tuple(np.round(d.extra['spot'], 9)), []).append(d)
    pairs = [v for v in by_spot.values() if len(v) == 2]
    assert len(pairs) == 6
    for a, b in pairs:
        assert {a.label, b.label} == {'left', 'right'}
        assert np.linalg.norm(a.joint_q[-1] - b.joint_q[-1]) > 1.0  # radians, final posture
        assert abs(a.joint_q[-1, 0] - b.joint_q[-1, 0]) > 0.4       # base joint swung apart


def test_pole_is_reproducible(kin, pole_demos):
    a = pole(seed=5, n=6, both_sides=1, kinematics=kin)
    _same(a, pole(seed=5, n=6, both_sides=1, kinematics=kin))
    assert not np.array_equal(a[0].wrist_xyz[:50], pole_demos[0].wrist_xyz[:50])


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_generate_write_load_round_trip(tmp_path, kin, storage):
    from mixture_ip_ros.core.segmentation import segment_motion
    demos = box_assembly(seed=1, occlusion=0.5, kinematics=kin,
                         counts={'plate': 2, 'screw': 2, 'screwdriver': 2})
    paths = write_scenario_bags('box_assembly', tmp_path / 'bags', seed=1, storage=storage,
                                demos=demos)
    assert [p.name for p in paths] == [d.name for d in demos]
    labels = json.loads((tmp_path / 'bags' / 'labels.json').read_text())
    assert labels['labels'] == {d.name: d.label for d in demos}
    assert read_labels(tmp_path / 'bags') == labels['labels']
    for d, path in zip(demos, paths):
        rec = read_bag(path)
        present = ~np.isnan(d.wrist_xyz).any(axis=1)
        np.testing.assert_allclose(rec.wrist_t, d.wrist_t[present], atol=1e-9)
        np.testing.assert_array_equal(rec.wrist_xyz, d.wrist_xyz[present])
        np.testing.assert_allclose(rec.joint_t, d.joint_t, atol=1e-9)
        np.testing.assert_array_equal(rec.joint_q, d.joint_q)
        np.testing.assert_array_equal(rec.joint_qd, d.joint_qd)
        assert rec.label == d.label and rec.wrist_frame == 'world'
    loaded, skipped = load_dataset(tmp_path / 'bags')
    assert skipped == [] and [x.name for x in loaded] == [d.name for d in demos]
    for x, d in zip(loaded, demos):
        assert x.label == d.label
        present = ~np.isnan(d.wrist_xyz).any(axis=1)
        onset, end = segment_motion(d.wrist_t, d.wrist_xyz)
        grid = onset + x.t
        # Oracle: plain linear interpolation of the generated samples at the loaded time base.
        ok = ~np.isnan(x.observed).any(axis=1)
        expect = np.column_stack([np.interp(grid, d.wrist_t[present], d.wrist_xyz[present, i])
                                  for i in range(3)])
        np.testing.assert_allclose(x.observed[ok], expect[ok], atol=1e-9)
        expect_q = np.column_stack([np.interp(grid, d.joint_t, d.joint_q[:, j]) for j in range(7)])
        np.testing.assert_allclose(x.controlled, expect_q, atol=1e-9)
        assert abs(x.duration - (end - onset)) < 0.011
    with pytest.raises(ValueError, match='not empty'):
        write_scenario_bags('box_assembly', tmp_path / 'bags', demos=demos)


def test_another_robots_bags_carry_its_joints_and_load_into_its_base_frame(tmp_path, kins):
    """The Panda stands 20 cm from the world origin: bags keep the human in the world frame and
    the Panda's joint names; loading with its transform gives what the generator meant."""
    from mixture_ip_ros.robot.description import load_description
    panda = load_description('panda')
    assert panda.mount_xyz != (0.0, 0.0, 0.0)
    demos = box_assembly(seed=1, kinematics=kins['panda'],
                         counts={'plate': 1, 'screw': 1, 'screwdriver': 1})
    write_scenario_bags('box_assembly', tmp_path / 'bags', seed=1, demos=demos)
    assert read_scenario_robot(tmp_path / 'bags') == 'panda'
    rec = read_bag(tmp_path / 'bags' / demos[0].name, joint_names=panda.joint_names)
    assert rec.joint_names == panda.joint_names and rec.wrist_frame == 'world'
    with pytest.raises(ValueError):   # not the iiwa's joints
        read_bag(tmp_path / 'bags' / demos[0].name)
    loaded, skipped = load_dataset(tmp_path / 'bags', joint_names=panda.joint_names,
                                   transform=panda.world_to_base())
    assert skipped == []
    for x, d in zip(loaded, demos):
        truth = d.to_demonstration()
        # The same wrist positions in the Panda's base frame: world minus its mount.
        np.testing.assert_allclose(x.observed[-1], d.wrist_goal - np.array(panda.mount_xyz),
                                   atol=0.005)
        np.testing.assert_allclose(truth.observed[-1], x.observed[-1], atol=0.005)
        assert x.controlled.shape[1] == 7
    with pytest.raises(ValueError, match='several robots'):
        write_scenario_bags('box_assembly', tmp_path / 'mixed',
                            demos=demos + box_assembly(seed=1, counts={'plate': 1}))


def test_to_demonstration_uses_the_true_interval(box):
    d = box[0]
    demo = d.to_demonstration(dt=0.01)
    assert abs(demo.duration - d.duration) < 0.01 and demo.label == d.label
    np.testing.assert_allclose(demo.observed[-1], d.wrist_goal, atol=0.005)


def test_phase_letters(tmp_path):
    data = phase_letters(seed=0)
    assert len(data.train) == len(data.test) == 20
    again = phase_letters(seed=0)
    np.testing.assert_array_equal(data.train[3].observed, again.train[3].observed)
    steps = np.array([d.t.size for d in data.train + data.test])
    assert steps.min() >= 350 and steps.max() <= 1131 and steps.max() / steps.min() > 1.5
    for d, alpha in zip(data.train, data.train_alpha):
        assert d.observed.shape == (d.t.size, 2) and d.controlled.shape == (d.t.size, 0)
        np.testing.assert_allclose(d.duration, 1 / alpha, atol=0.006)
        assert not np.isnan(d.observed).any()
    # All letters share the shape: each is close to the mean letter in the phase domain.
    z = np.linspace(0, 1, 50)
    paths = np.array([[np.interp(z * d.duration, d.t, d.observed[:, i]) for i in range(2)]
                      for d in data.train])
    spread = np.linalg.norm(paths - paths.mean(axis=0), axis=1).mean()
    assert 0.02 < spread < 0.5
    assert len({d.name for d in data.train + data.test}) == 40


def test_missing_data_letters():
    data = missing_data_letters(seed=0)
    for d, full in zip(data.train, data.train_complete):
        missing = np.isnan(d.observed).all(axis=1)
        assert missing.sum() == 180
        idx = np.flatnonzero(missing)
        assert np.all(np.diff(idx) == 1)
        np.testing.assert_array_equal(d.observed[~missing], full.observed[~missing])
    assert all(not np.isnan(d.observed).any() for d in data.test)
    with pytest.raises(ValueError, match='does not fit'):
        missing_data_letters(seed=0, gap_steps=5000)


def test_unknown_scenario_and_patterns(tmp_path):
    with pytest.raises(ValueError, match='unknown scenario'):
        generate('juggling')
    with pytest.raises(ValueError, match='unknown box-assembly patterns'):
        box_assembly(counts={'hammer': 3})
