"""Robot descriptions: the file format and its checks, frames, and a fourth arm added with a
description file and nothing else."""

import textwrap

import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mixture_ip_ros.robot.description import (DEFAULT_ROBOT, DescriptionError, load_description,
                                              resolve_uri, rpy_matrix, rpy_quaternion,
                                              shipped_robots)
from mixture_ip_ros.robot.kinematics import RobotKinematics, load_arm_model

IIWA = textwrap.dedent('''\
    name: test_arm
    model: package://mixture_ip_ros/models/iiwa14.urdf
    joints: [iiwa_joint_1, iiwa_joint_2, iiwa_joint_3, iiwa_joint_4, iiwa_joint_5,
             iiwa_joint_6, iiwa_joint_7]
    base_frame: iiwa_link_0
    flange_frame: tool0
    home: [0.0, 0.6, 0.0, -1.4, 0.0, 1.1, 0.0]
    ''')

# A fourth arm from example-robot-data (UFactory xArm 7), described here and nowhere else.
XARM = textwrap.dedent('''\
    name: xarm7
    model: package://example-robot-data/robots/xarm_description/urdf/xarm7.urdf
    joints: [joint1, joint2, joint3, joint4, joint5, joint6, joint7]
    base_frame: link_base
    flange_frame: link_eef
    mount: {xyz: [0.25, 0.0, 0.0]}
    home: [0.0, 0.0, 0.0, 1.2, 0.0, 1.2, 0.0]
    tool_rpy: [0.0, 0.0, 3.141592653589793]
    ''')


def _write(tmp_path, text, name='arm.yaml'):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_shipped_robots_and_the_default():
    assert {'iiwa14', 'panda', 'ur5'} <= set(shipped_robots())
    default = load_description()
    assert default.name == DEFAULT_ROBOT == 'iiwa14' and default.source == 'iiwa14'
    assert load_description('panda') is load_description('panda')   # parsed once
    assert load_description(default) is default


def test_a_description_file_loads_like_a_shipped_name(tmp_path):
    path = _write(tmp_path, IIWA)
    d = load_description(str(path))
    assert d.source == str(path.resolve()) and load_description(d.source) == d
    assert d.joint_names == load_description('iiwa14').joint_names
    assert d.mount_xyz == (0.0, 0.0, 0.0) and d.natural_frequency == (60.0,)
    assert d.model_path == load_description('iiwa14').model_path


def test_rpy_and_quaternions_match_scipy():
    rng = np.random.default_rng(0)
    for rpy in rng.uniform(-np.pi, np.pi, (20, 3)):
        oracle = Rotation.from_euler('xyz', rpy)   # extrinsic x, y, z = URDF's Rz Ry Rx
        np.testing.assert_allclose(rpy_matrix(rpy), oracle.as_matrix(), atol=1e-12)
        q = np.array(rpy_quaternion(rpy))
        np.testing.assert_allclose(abs(q @ oracle.as_quat()), 1.0, atol=1e-12)


def test_world_to_base_inverts_the_mount(tmp_path):
    text = IIWA + 'mount: {xyz: [0.3, -0.2, 0.1], rpy: [0.1, -0.2, 0.7]}\n'
    d = load_description(str(_write(tmp_path, text)))
    p = np.random.default_rng(1).normal(size=(5, 3))
    np.testing.assert_allclose(d.world_to_base().apply_array(d.base_to_world().apply_array(p)), p,
                               atol=1e-12)
    np.testing.assert_allclose(d.base_to_world().apply_array(np.zeros(3)), [0.3, -0.2, 0.1])


def test_package_uris_resolve():
    assert resolve_uri('package://mixture_ip_ros/models/iiwa14.urdf').is_file()
    assert resolve_uri('package://example-robot-data/robots/panda_description/urdf/panda.urdf'
                       ).is_file()
    with pytest.raises(FileNotFoundError, match='package'):
        resolve_uri('package://no_such_package/x.urdf')


@pytest.mark.parametrize('edit,message', [
    (lambda t: t.replace('base_frame: iiwa_link_0\n', ''), r"missing keys \['base_frame'\]"),
    (lambda t: t + 'colour: red\n', r"unknown keys \['colour'\]"),
    (lambda t: t.replace('iiwa14.urdf', 'iiwa15.urdf'), 'model: .*no such file'),
    (lambda t: t.replace('home: [0.0, 0.6,', 'home: [0.6,'), 'home must be 7 numbers'),
    (lambda t: t + 'controller: {natural_frequency: [60.0, 60.0]}\n',
     'one number or 7'),
    (lambda t: t + 'controller: {natural_frequency: -1.0}\n', 'finite and positive'),
    (lambda t: t + 'mount: {xyz: [0.0, 0.0]}\n', 'mount.xyz must be 3 numbers'),
    (lambda t: t + 'mount: {height: 1.0}\n', r"mount: unknown keys \['height'\]"),
    (lambda t: t.replace('iiwa_joint_7]', 'iiwa_joint_6]'), 'duplicates'),
    (lambda t: t + 'scenarios: {link_radius: 0.0}\n', 'link_radius must be finite and positive'),
    (lambda t: '- just\n- a list\n', 'YAML mapping'),
])
def test_bad_description_files_say_what_is_wrong(tmp_path, edit, message):
    path = _write(tmp_path, edit(IIWA))
    with pytest.raises(DescriptionError, match=message) as err:
        load_description(str(path))
    assert str(path) in str(err.value)   # the message names the file


def test_unknown_robot_names_the_shipped_ones():
    with pytest.raises(DescriptionError, match=r"unknown robot 'kuka'.*iiwa14"):
        load_description('kuka')
    with pytest.raises(DescriptionError, match='does not exist'):
        load_description('/nowhere/arm.yaml')


@pytest.mark.parametrize('edit,message', [
    (lambda t: t.replace('iiwa_joint_7]', 'iiwa_joint_8]'), "no joint 'iiwa_joint_8'"),
    (lambda t: t.replace('[iiwa_joint_1, iiwa_joint_2', '[iiwa_joint_2, iiwa_joint_1'),
     'chain order'),
    (lambda t: t.replace('flange_frame: tool0', 'flange_frame: iiwa_link_5'),
     'hangs on the joints'),
    (lambda t: t.replace('flange_frame: tool0', 'flange_frame: gripper'),
     "flange_frame 'gripper' is not a frame"),
    (lambda t: t.replace('base_frame: iiwa_link_0', 'base_frame: iiwa_link_1'),
     "must be the model's root frame"),
    (lambda t: t.replace('home: [0.0, 0.6,', 'home: [3.1, 0.6,'), 'outside the joint limits'),
    (lambda t: t + 'scenarios: {clearance_frames: [elbow]}\n', "no frame 'elbow'"),
])
def test_descriptions_that_do_not_fit_their_model_are_refused(tmp_path, edit, message):
    d = load_description(str(_write(tmp_path, edit(IIWA))))
    with pytest.raises(DescriptionError, match=message):
        load_arm_model(d)


def test_joints_that_are_not_one_dof_are_refused(tmp_path):
    # Kinova's Jaco 2 in example-robot-data has continuous joints (cos/sin, 2 coordinates).
    text = textwrap.dedent('''\
        model: package://example-robot-data/robots/kinova_description/robots/kinova.urdf
        joints: [j2s6s200_joint_1, j2s6s200_joint_2, j2s6s200_joint_3, j2s6s200_joint_4,
                 j2s6s200_joint_5, j2s6s200_joint_6]
        base_frame: world
        flange_frame: j2s6s200_end_effector
        home: [0.0, 3.0, 3.0, 0.0, 0.0, 0.0]
        ''')
    with pytest.raises(DescriptionError, match='not a 1-DOF revolute or prismatic joint'):
        RobotKinematics(str(_write(tmp_path, text)))


def test_joints_left_out_are_welded_in_both_models():
    """The Panda's fingers: not in the description, so neither Pinocchio nor MuJoCo moves them,
    and their mass still counts (the total mass agrees)."""
    from mixture_ip_ros.robot.scene import build_scene
    kin = RobotKinematics('panda')
    assert kin.model.nq == 7 and 'panda_finger_joint1' not in list(kin.model.names)
    scene = build_scene(robot='panda')
    assert scene.nq == 7
    pin_mass = sum(kin.model.inertias[i].mass for i in range(1, kin.model.njoints))
    mj_mass = sum(scene.body_mass[i] for i in range(scene.nbody)
                  if scene.body_weldid[i] != 0)       # bodies that move with a joint
    assert mj_mass == pytest.approx(pin_mass, rel=1e-12)
    assert mj_mass > scene.body_mass[scene.body('panda_leftfinger').id] > 0


# ------------------------------------------------------------------------------- a fourth arm
@pytest.fixture(scope='module')
def xarm(tmp_path_factory):
    return str(_write(tmp_path_factory.mktemp('xarm'), XARM, 'xarm7.yaml'))


def test_a_fourth_arm_needs_only_its_description_file(xarm, tmp_path):
    """xArm 7 (not shipped): kinematics and dynamics agree between Pinocchio and MuJoCo, the
    controller tracks a move, the simulation refuses a wrong trajectory, the box-assembly
    demonstrations are generated for it (the human side as for the iiwa), and a model trained on
    them commands its joints."""
    from mixture_ip_ros.app.training import train_to_file
    from mixture_ip_ros.io.model_file import load_model
    from mixture_ip_ros.robot.scene import FLANGE_SITE, build_scene
    from mixture_ip_ros.robot.sim import RobotSimulation
    from mixture_ip_ros.robot.trajectory import points_from_arrays
    from mixture_ip_ros.scenarios.box_assembly import box_assembly
    kin = RobotKinematics(xarm)
    assert kin.description.name == 'xarm7' and kin.dof == 7
    np.testing.assert_allclose(kin.velocity_limit, 3.14, atol=0.01)   # from the URDF
    # Pinocchio vs MuJoCo, 30 random configurations.
    scene = build_scene(robot=xarm)
    data = mujoco.MjData(scene)
    to_base = kin.description.world_to_base()
    M = np.zeros((7, 7))
    rng = np.random.default_rng(0)
    for _ in range(30):
        q, qd = rng.uniform(kin.lower, kin.upper), rng.normal(size=7)
        data.qpos[:], data.qvel[:] = q, qd
        mujoco.mj_forward(scene, data)
        mujoco.mj_fullM(scene, data, M)
        np.testing.assert_allclose(kin.fk(q)[0], to_base.apply_array(
            data.site_xpos[scene.site(FLANGE_SITE).id]), atol=1e-6)
        np.testing.assert_allclose(kin.mass_matrix(q), M, atol=1e-6)
        np.testing.assert_allclose(kin.rnea(q, qd, np.zeros(7)), data.qfrc_bias, atol=1e-6)
    # Tracking a 1.5 s minimum-jerk move from home.
    sim = RobotSimulation(robot=xarm)
    home = kin.description.home_array()
    goal = home + np.array([0.6, 0.3, -0.4, -0.3, 0.5, 0.3, 0.6])
    t = np.linspace(0.0, 1.5, 16)
    s = (t / 1.5)[:, None]
    pos = home + (10 * s**3 - 15 * s**4 + 6 * s**5) * (goal - home)
    vel = (30 * s**2 - 60 * s**3 + 30 * s**4) / 1.5 * (goal - home)
    acc = (60 * s - 180 * s**2 + 120 * s**3) / 1.5**2 * (goal - home)
    assert sim.set_trajectory(sim.joint_names, points_from_arrays(t, pos, vel, acc)) is None
    sim.step(2000)
    assert sim.tracking_error()['rms'] < 0.5e-3
    np.testing.assert_allclose(sim.q, goal, atol=1e-4)
    assert 'unknown joint' in sim.set_trajectory(load_description().joint_names,
                                                 points_from_arrays(t, pos))
    # Its box-assembly demonstrations, and a model of them.
    demos = box_assembly(seed=7, kinematics=kin, counts={'plate': 4, 'screw': 4,
                                                         'screwdriver': 4})
    iiwa = box_assembly(seed=7, counts={'plate': 4, 'screw': 4, 'screwdriver': 4})
    same = [np.array_equal(a.wrist_xyz, b.wrist_xyz) for a, b in zip(demos, iiwa)
            if a.extra['attempt'] == b.extra['attempt']]
    assert len(same) >= 10 and all(same)
    model_path = tmp_path / 'model.npz'
    train_to_file([d.to_demonstration() for d in demos], model_path, robot=xarm,
                  n_components=3)
    _, meta = load_model(model_path, controlled_names=kin.joint_names)
    assert meta['observed_frame'] == 'link_base' and meta['extra']['robot'] == 'xarm7'
