"""The arm models: the iiwa 14's URDF facts; for every shipped robot, Pinocchio vs MuJoCo
agreement, scene contents and IK over the task region."""

import math

import mujoco
import numpy as np
import pytest

from mixture_ip_ros.robot.description import DEFAULT, JOINT_NAMES, shipped_robots
from mixture_ip_ros.robot.kinematics import RobotKinematics
from mixture_ip_ros.robot.scene import (actuator_names, FLANGE_SITE, HUMAN_WRIST, TABLE_TOP_Z,
                                        build_scene)

HOME = DEFAULT.home_array()


@pytest.fixture(scope='module')
def kin():
    return RobotKinematics()


@pytest.fixture(scope='module')
def scene():
    return build_scene()


@pytest.fixture(scope='module', params=shipped_robots())
def arm(request):
    """(kinematics, compiled scene) of one shipped robot."""
    return RobotKinematics(request.param), build_scene(robot=request.param)


def test_the_three_arms_are_shipped():
    assert {'iiwa14', 'panda', 'ur5'} <= set(shipped_robots())
    assert [RobotKinematics(r).dof for r in ('iiwa14', 'panda', 'ur5')] == [7, 7, 6]


def test_urdf_limits_are_the_data_sheet_values(kin):
    deg = np.radians
    assert kin.joint_names == [f'iiwa_joint_{i}' for i in range(1, 8)]
    np.testing.assert_allclose(kin.upper, deg([170, 120, 170, 120, 170, 120, 175]), rtol=1e-12)
    np.testing.assert_allclose(kin.lower, -kin.upper)
    np.testing.assert_allclose(kin.velocity_limit, deg([85, 85, 100, 75, 130, 135, 135]),
                               rtol=1e-12)
    np.testing.assert_allclose(kin.effort_limit, [320, 320, 176, 176, 110, 40, 40])


def test_stretched_arm_is_the_sum_of_the_link_offsets(kin):
    p, R = kin.fk(np.zeros(7))
    height = 0.1575 + 0.2025 + 0.2045 + 0.2155 + 0.1845 + 0.2155 + 0.081 + 0.045
    np.testing.assert_allclose(p, [0, 0, height], atol=1e-12)
    np.testing.assert_allclose(R, np.eye(3), atol=1e-12)
    # Link masses as published (sum of the seven moving links).
    masses = [kin.model.inertias[i].mass for i in range(1, 8)]
    np.testing.assert_allclose(masses, [5.76, 6.35, 3.5, 3.5, 3.5, 1.8, 1.2])


def test_pinocchio_and_mujoco_agree_at_100_random_configurations(arm):
    """Two independent loaders of the same model file: flange pose (MuJoCo's in the world, moved
    into the base frame by the mount), mass matrix, Coriolis + gravity (gravity along the world's
    -z, which Pinocchio sees in the base frame)."""
    kin, scene = arm
    n = kin.dof
    to_base = kin.description.world_to_base()
    data = mujoco.MjData(scene)
    site = scene.site(FLANGE_SITE).id
    rng = np.random.default_rng(7)
    M_mj = np.zeros((n, n))
    for _ in range(100):
        q = rng.uniform(kin.lower, kin.upper)
        qd = rng.normal(size=n)
        data.qpos[:] = q
        data.qvel[:] = qd
        mujoco.mj_forward(scene, data)
        mujoco.mj_fullM(scene, data, M_mj)
        p, R = kin.fk(q)
        np.testing.assert_allclose(p, to_base.apply_array(data.site_xpos[site]), atol=1e-6)
        np.testing.assert_allclose(R, to_base.rotation @ data.site_xmat[site].reshape(3, 3),
                                   atol=1e-6)
        np.testing.assert_allclose(kin.mass_matrix(q), M_mj, atol=1e-6)
        # Coriolis + gravity too: the controller relies on them.
        np.testing.assert_allclose(kin.rnea(q, qd, np.zeros(n)), data.qfrc_bias, atol=1e-6)


def test_each_arm_stands_at_its_mount_with_one_actuator_per_joint(arm):
    kin, scene = arm
    d = kin.description
    n = kin.dof
    assert scene.nq == scene.nv == scene.nu == n     # other joints (Panda fingers) welded
    assert [scene.actuator(i).name for i in range(n)] == actuator_names(d)
    assert [scene.joint(i).name for i in range(n)] == list(d.joint_names)
    np.testing.assert_allclose(scene.actuator_ctrlrange[:, 1], kin.effort_limit)
    np.testing.assert_allclose(scene.dof_damping, 0.0)
    data = mujoco.MjData(scene)
    mujoco.mj_forward(scene, data)
    base = scene.body(d.base_frame).id
    np.testing.assert_allclose(data.xpos[base], d.mount_xyz, atol=1e-12)
    np.testing.assert_allclose(data.xmat[base].reshape(3, 3), d.mount_rotation, atol=1e-12)


def test_perturbed_model_scales_mass_matrix_and_gravity(kin):
    heavy = RobotKinematics(mass_scale=1.1)
    q = HOME
    np.testing.assert_allclose(heavy.mass_matrix(q), 1.1 * kin.mass_matrix(q), rtol=1e-12,
                               atol=1e-12)
    np.testing.assert_allclose(heavy.gravity(q), 1.1 * kin.gravity(q), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(heavy.fk(q)[0], kin.fk(q)[0])
    with pytest.raises(ValueError):
        RobotKinematics(mass_scale=0.0)


def test_scene_actuators_table_pole_and_wrist(scene):
    assert scene.opt.timestep == pytest.approx(0.001)
    assert scene.nq == 7 and scene.nu == 7
    assert [scene.actuator(i).name for i in range(7)] == actuator_names()
    assert actuator_names() == [f'{name}_torque' for name in JOINT_NAMES]
    np.testing.assert_allclose(scene.actuator_ctrlrange[:, 1], [320, 320, 176, 176, 110, 40, 40])
    np.testing.assert_allclose(scene.actuator_ctrlrange[:, 0], -scene.actuator_ctrlrange[:, 1])
    np.testing.assert_allclose(scene.actuator_gainprm[:, 0], 1.0)   # ctrl is torque in Nm
    np.testing.assert_allclose(scene.dof_damping, 0.0)
    np.testing.assert_allclose(scene.dof_armature, 0.0)
    for i, name in enumerate(JOINT_NAMES):
        assert scene.joint(name).qposadr[0] == i
    assert scene.body(HUMAN_WRIST).mocapid[0] == 0
    assert scene.site(HUMAN_WRIST).id >= 0
    data = mujoco.MjData(scene)
    mujoco.mj_forward(scene, data)
    top = scene.geom('table_top')
    assert data.geom_xpos[top.id][2] + top.size[2] == pytest.approx(TABLE_TOP_Z)
    assert 'pole' not in [scene.geom(i).name for i in range(scene.ngeom)]
    with_pole = build_scene(pole=True, pole_xy=(0.6, 0.1), pole_height=0.5)
    pole = with_pole.geom('pole')
    np.testing.assert_allclose(pole.pos, [0.6, 0.1, 0.25])
    for name in ('plate_stand', 'screw_stand'):
        assert scene.geom(name).id >= 0
    assert 'plate_stand' not in [build_scene(stands=False).geom(i).name
                                 for i in range(build_scene(stands=False).ngeom)]


def test_arm_collides_with_table_but_not_with_itself(scene):
    data = mujoco.MjData(scene)
    # Shoulder tilted forward 115 deg, elbow bent down: the forearm goes through the table top.
    data.qpos[:] = [0.0, 2.0, 0.0, -1.0, 0.0, 0.0, 0.0]
    mujoco.mj_forward(scene, data)
    table = scene.geom('table_top').id
    pairs = {(data.contact.geom1[i], data.contact.geom2[i]) for i in range(data.ncon)}
    assert any(table in pair for pair in pairs)
    robot_bodies = {scene.body(f'iiwa_link_{i}').id for i in range(8)}
    for g1, g2 in pairs:
        assert not {scene.geom_bodyid[g1], scene.geom_bodyid[g2]} <= robot_bodies


def test_ik_reaches_handover_region(arm):
    """Positions in front of the robot over the table (world frame), for every arm from its
    home posture."""
    kin, _ = arm
    home = kin.description.home_array()
    to_base = kin.description.world_to_base()
    rng = np.random.default_rng(3)
    for _ in range(60):
        target = to_base.apply_array(rng.uniform([0.45, -0.4, 0.1], [0.8, 0.4, 0.5]))
        q = kin.ik(target, home)
        assert np.linalg.norm(kin.fk(q)[0] - target) < 1e-3
        assert kin.within_limits(q)


def test_ik_with_orientation_recovers_a_reachable_pose(arm):
    kin, _ = arm
    home = kin.description.home_array()
    mid, half = (kin.upper + kin.lower) / 2, (kin.upper - kin.lower) / 2
    rng = np.random.default_rng(4)
    for _ in range(20):
        q_true = rng.uniform(mid - 0.7 * half, mid + 0.7 * half)
        p, R = kin.fk(q_true)
        q = kin.ik(p, home, rotation=R, rotation_tol=1e-2)
        p2, R2 = kin.fk(q)
        assert np.linalg.norm(p2 - p) < 1e-3
        angle = math.acos(np.clip((np.trace(R2.T @ R) - 1) / 2, -1, 1))
        assert angle < 1e-2


def test_ik_warm_start_gives_a_smooth_path(kin):
    q = HOME
    path = []
    for s in np.linspace(0, 1, 101):
        target = np.array([0.4 + 0.4 * s, -0.3 + 0.6 * s, 0.15 + 0.3 * s])
        q = kin.ik(target, q)
        path.append(q)
    path = np.array(path)
    # 101 targets 9 mm apart: each joint step stays a small multiple of the Cartesian step.
    assert np.abs(np.diff(path[1:], axis=0)).max() < 0.05


def test_ik_rejects_unreachable_and_bad_input(kin):
    with pytest.raises(ValueError, match='did not converge'):
        kin.ik([2.0, 0.0, 0.3], HOME, restarts=2)
    with pytest.raises(ValueError):
        kin.ik([np.nan, 0.0, 0.3], HOME)
    with pytest.raises(ValueError):
        kin.ik([0.5, 0.0, 0.3], np.zeros(6))


def test_a_posture_preference_costs_no_accuracy_and_picks_the_posture_nearest_it(kin):
    """The same targets from the same start: with a preferred posture the flange is as exact,
    and the redundant joints end nearer that posture than without it."""
    rng = np.random.default_rng(6)
    preferred = HOME + np.array([0.0, 0.0, 0.6, 0.0, -0.5, 0.0, 0.4])
    nearer = 0
    for _ in range(20):
        target = rng.uniform([0.45, -0.3, 0.15], [0.7, 0.3, 0.45])
        free = kin.ik(target, HOME, restarts=0)
        held = kin.ik(target, HOME, restarts=0, posture=preferred, posture_weight=0.05)
        assert np.linalg.norm(kin.fk(held)[0] - target) < 1e-3
        nearer += np.linalg.norm(held - preferred) < np.linalg.norm(free - preferred)
    assert nearer == 20
    with pytest.raises(ValueError, match='posture_weight'):
        kin.ik([0.5, 0.0, 0.3], HOME, posture=HOME, posture_weight=-1.0)
    with pytest.raises(ValueError, match='posture'):
        kin.ik([0.5, 0.0, 0.3], HOME, posture=HOME[:3], posture_weight=0.1)


def test_closest_reaches_what_ik_reaches_and_says_how_far_it_stays_otherwise(arm):
    kin, _ = arm
    home = kin.description.home_array()
    target = kin.fk(home + 0.2)[0]
    q, error = kin.closest(target, home)
    assert error < 1e-3 and np.linalg.norm(kin.fk(q)[0] - target) == pytest.approx(error)
    far = np.array([3.0, 0.0, 0.4])                 # beyond every arm's reach: no exception
    q, error = kin.closest(far, home, limit_margin=0.05)
    assert error == pytest.approx(np.linalg.norm(kin.fk(q)[0] - far)) and error > 1.5
    assert kin.within_limits(q, margin=0.05 - 1e-9)


def test_fk_positions_matches_fk(arm):
    kin, _ = arm
    Q = np.random.default_rng(5).uniform(kin.lower, kin.upper, size=(10, kin.dof))
    P = kin.fk_positions(Q)
    for q, p in zip(Q, P):
        np.testing.assert_allclose(p, kin.fk(q)[0], atol=1e-12)
