"""A hand path made an arm's joint path, for every shipped arm: the shoulder, the reach and its
scale, FK(IK(p)) = p where reachable, continuity, the position and speed limits."""

import numpy as np
import pytest

from mixture_ip_ros.robot import retarget
from mixture_ip_ros.robot.description import shipped_robots
from mixture_ip_ros.robot.kinematics import RobotKinematics

RATE = 30.0


@pytest.fixture(scope='module', params=shipped_robots())
def kin(request):
    return RobotKinematics(request.param)


def _handshake_like(shoulder, n=90):
    """A hand 0.5 m from the shoulder sweeping forward and up over 3 s at 30 Hz, then back."""
    s = 0.5 - 0.5 * np.cos(np.linspace(0.0, 2 * np.pi, n))
    return shoulder + np.column_stack([0.15 + 0.3 * s, -0.15 + 0.1 * s, -0.35 + 0.3 * s])


def test_the_shoulder_is_on_the_first_axis_at_the_second_joint():
    np.testing.assert_allclose(retarget.shoulder(RobotKinematics('iiwa14')), [0, 0, 0.36],
                               atol=1e-9)
    np.testing.assert_allclose(retarget.shoulder(RobotKinematics('panda')), [0, 0, 0.333],
                               atol=1e-9)
    np.testing.assert_allclose(retarget.shoulder(RobotKinematics('ur5')), [0, 0, 0.089159],
                               atol=1e-6)


def test_reach_is_an_annulus_about_the_shoulder(kin):
    near, far = retarget.reach(kin)
    assert 0.9 < far < 1.0 and 0.0 < near < far
    rng = np.random.default_rng(1)
    d = np.linalg.norm(kin.fk_positions(rng.uniform(kin.lower, kin.upper, (500, kin.dof)))
                       - retarget.shoulder(kin), axis=1)
    assert d.max() <= far + 1e-9 and d.min() >= near - 0.05


def test_the_scale_is_one_unless_hand_positions_are_out_of_reach():
    kin = RobotKinematics('iiwa14')
    near, far = retarget.reach(kin)
    fits = np.array([[0.5, 0.0, 0.0], [0.0, 0.6, 0.0]])
    assert retarget.reach_scale(kin, fits, 0.9) == 1.0
    too_far = np.array([[0.5, 0.0, 0.0], [0.0, 0.0, -1.2]])
    assert retarget.reach_scale(kin, too_far, 0.9) == pytest.approx(0.9 * far / 1.2)
    too_near = np.array([[0.2, 0.0, 0.0], [0.0, 0.7, 0.0]])      # the iiwa folds to ~0.32 m
    s = retarget.reach_scale(kin, too_near, 0.9)
    assert s == pytest.approx(0.9 * far / 0.7) and s > 1     # bounded by the far one
    with pytest.raises(ValueError, match='margin'):
        retarget.reach_scale(kin, fits, 1.5)


def test_a_placement_maps_shoulder_to_shoulder_and_scales_about_it():
    p = retarget.Placement((0.0, -0.15, 0.0), (0.0, 0.0, 0.36), yaw=np.pi / 2, scale=2.0)
    np.testing.assert_allclose(p.apply([[0.0, -0.15, 0.0]]), [[0, 0, 0.36]], atol=1e-12)
    np.testing.assert_allclose(p.apply([[0.1, -0.15, 0.0]]), [[0, 0.2, 0.36]], atol=1e-12)
    assert np.isnan(p.apply([[np.nan] * 3])).all()
    with pytest.raises(ValueError, match='scale'):
        retarget.Placement((0, 0, 0), (0, 0, 0), scale=0.0)


def test_a_reachable_path_is_followed_exactly_continuously_within_the_limits(kin):
    targets = _handshake_like(retarget.shoulder(kin))
    speed = kin.velocity_limit
    path = retarget.joint_path(kin, targets, 1.0 / RATE, kin.description.home_array(),
                               speed_limit=speed, limit_margin=0.1)
    # FK(IK(p)) = p: this path is slow enough for every arm.
    np.testing.assert_allclose(kin.fk_positions(path.q), targets, atol=1e-3)
    assert np.nanmax(path.error) < 1e-3
    assert np.all(path.q >= kin.lower + 0.1 - 1e-9) and np.all(path.q <= kin.upper - 0.1 + 1e-9)
    steps = np.abs(np.diff(path.q, axis=0))
    assert np.all(steps <= speed / RATE + 1e-12)             # within the speed limits ...
    assert path.max_step < 0.1                               # ... and no branch flip


def test_a_hand_faster_than_the_arm_is_followed_late_and_caught_up(kin):
    shoulder = retarget.shoulder(kin)
    targets = np.repeat([shoulder + [0.45, -0.2, -0.1]], 40, axis=0)
    targets[10:] = shoulder + [0.45, 0.25, 0.15]             # 52 cm in one sample
    path = retarget.joint_path(kin, targets, 1.0 / RATE, kin.description.home_array(),
                               speed_limit=0.5 * kin.velocity_limit)
    steps = np.abs(np.diff(path.q, axis=0))
    assert np.all(steps <= 0.5 * kin.velocity_limit / RATE + 1e-12)
    assert path.error[10] > 0.3                               # behind at the jump ...
    assert path.error[-1] < 1e-3                              # ... caught up in under 1 s


def test_targets_out_of_reach_get_the_nearest_the_limits_allow_and_missing_ones_hold(kin):
    shoulder = retarget.shoulder(kin)
    targets = np.repeat([shoulder + [0.5, 0.0, 0.0]], 12, axis=0)
    targets[4:8] = np.nan                                     # a glitch: no target
    targets[8:] = shoulder + [1.5, 0.0, 0.0]                  # beyond every arm's reach
    path = retarget.joint_path(kin, targets, 1.0 / RATE, kin.description.home_array())
    assert np.isnan(path.error[4:8]).all()
    np.testing.assert_array_equal(path.q[4:8], np.repeat(path.q[3:4], 4, axis=0))
    assert np.all(path.error[8:] > 0.5) and np.all(np.isfinite(path.q))
    with pytest.raises(ValueError, match='every row is missing'):
        retarget.joint_path(kin, np.full((3, 3), np.nan), 0.1, kin.description.home_array())
