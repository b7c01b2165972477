"""sim_node over real DDS: in-process convergence, rejections, stopping and holding, its
lifecycle, and the executable."""

import os
import signal
import subprocess
import sys

import numpy as np
import pytest
from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import PoseStamped
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from conftest import private_domain_id
from mixture_ip_ros.nodes.sim_node import SimNode
from mixture_ip_ros.core.share import config_path
from mixture_ip_ros.robot.description import DEFAULT, JOINT_NAMES, load_description
from mixture_ip_ros.robot.kinematics import RobotKinematics

HOME = DEFAULT.home_array()

RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
PROBE_COMMANDS = {'commander': '', 'command_lease': 0.0}


def _duration(seconds):
    return Duration(sec=int(seconds), nanosec=int(round((seconds % 1) * 1e9)))


def _trajectory(goal, duration, names=JOINT_NAMES, stamp=None):
    msg = JointTrajectory()
    msg.joint_names = list(names)
    if stamp is not None:
        msg.header.stamp = stamp
    point = JointTrajectoryPoint()
    point.positions = [float(x) for x in goal]
    point.velocities = [0.0] * len(goal)
    point.time_from_start = _duration(duration)
    msg.points = [point]
    return msg


class Sim:
    """The sim node in the harness, with a trajectory publisher and recorders of its outputs."""

    def __init__(self, harness, start=True, **overrides):
        # The probe commands the arm, from the sim's own DDS participant (no liveliness).
        params = {'real_time_factor': 0.0, **PROBE_COMMANDS, **overrides}
        self.h = harness
        self.sim_node = harness.add(SimNode(context=harness.context, parameter_overrides=[
            Parameter(k, value=v) for k, v in params.items()]), start=start)
        self.joint_states = harness.subscribe(JointState, 'joint_states', RELIABLE)
        self.poses = harness.subscribe(PoseStamped, 'flange_pose', RELIABLE)
        self.clocks = harness.subscribe(Clock, '/clock', RELIABLE)
        self.pub = harness.publisher(JointTrajectory, 'joint_trajectory', RELIABLE)
        self.spin_until = harness.spin_until


@pytest.fixture
def sim(harness):
    return Sim(harness)


def test_joint_states_converge_to_the_trajectory_end(sim):
    harness = sim
    sim = harness.sim_node.sim
    harness.spin_until(lambda: harness.pub.get_subscription_count() > 0 and harness.joint_states)
    goal = HOME + np.array([0.3, -0.2, 0.25, 0.3, -0.3, 0.2, 0.5])
    harness.pub.publish(_trajectory(goal, 1.0))
    harness.spin_until(lambda: sim.accepted_count == 1)
    sent_at = sim.time
    harness.spin_until(lambda: sim.time > sent_at + 2.0 and harness.joint_states
                       and harness.joint_states[-1].header.stamp.sec >= int(sent_at + 2.0))
    last = harness.joint_states[-1]
    assert list(last.name) == list(JOINT_NAMES)
    np.testing.assert_allclose(last.position, goal, atol=1e-4)
    np.testing.assert_allclose(last.velocity, 0.0, atol=1e-3)
    expected_flange = RobotKinematics().fk(goal)[0]
    pose = harness.poses[-1].pose.position
    np.testing.assert_allclose([pose.x, pose.y, pose.z], expected_flange, atol=1e-3)
    assert harness.poses[-1].header.frame_id == 'iiwa_link_0'
    # Simulated time: stamps are /clock time, 10 ms apart (100 Hz), strictly increasing.
    stamps = np.array([m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec
                       for m in harness.joint_states])
    np.testing.assert_allclose(np.diff(stamps), 0.01, atol=1e-9)
    clocks = np.array([c.clock.sec + 1e-9 * c.clock.nanosec for c in harness.clocks])
    assert np.all(np.diff(clocks) > 0)
    assert set(np.round(stamps, 6)) <= set(np.round(clocks, 6))
    assert harness.sim_node.rejection_count == 0


def test_the_robot_parameter_makes_it_another_arm(harness):
    """robot:=ur5 and nothing else: six joints at the UR5's home, its frame on the flange pose
    (in its base frame, 10 cm from the scene's origin), and its trajectories executed."""
    ur5 = load_description('ur5')
    h = Sim(harness, robot='ur5')
    sim = h.sim_node.sim
    h.spin_until(lambda: h.pub.get_subscription_count() > 0 and h.joint_states)
    assert list(h.joint_states[-1].name) == list(ur5.joint_names)
    np.testing.assert_allclose(h.joint_states[-1].position, ur5.home, atol=1e-6)
    assert list(h.sim_node.get_parameter('natural_frequency').value) == [60.0] * 6
    goal = ur5.home_array() + np.array([0.3, -0.2, 0.25, 0.3, -0.3, 0.2])
    h.pub.publish(_trajectory(HOME, 1.0))                       # the iiwa's: refused
    h.pub.publish(_trajectory(goal, 1.0, names=ur5.joint_names))
    h.spin_until(lambda: sim.accepted_count == 1 and h.sim_node.rejection_count == 1)
    sent_at = sim.time
    h.spin_until(lambda: sim.time > sent_at + 2.0 and h.poses
                 and h.poses[-1].header.stamp.sec >= int(sent_at + 2.0))
    np.testing.assert_allclose(h.joint_states[-1].position, goal, atol=1e-4)
    pose = h.poses[-1]
    assert pose.header.frame_id == 'base_link'
    np.testing.assert_allclose([pose.pose.position.x, pose.pose.position.y,
                                pose.pose.position.z], RobotKinematics('ur5').fk(goal)[0],
                               atol=1e-3)


def test_topics_resolve_in_the_namespace_and_remap_to_a_ros2_control_controller(harness):
    """No arm's name in the topics: in a namespace they are under it, and a remap points the
    commands at a joint_trajectory_controller's topic, where a command then moves the arm."""
    controller = '/joint_trajectory_controller/joint_trajectory'
    node = harness.add(SimNode(context=harness.context, namespace='/arm', cli_args=[
        '--ros-args', '-r', f'joint_trajectory:={controller}'], parameter_overrides=[
        Parameter(k, value=v) for k, v in {'real_time_factor': 0.0, **PROBE_COMMANDS}.items()]))
    assert node.trajectory_sub.topic_name == controller
    assert node.joint_state_pub.topic_name == '/arm/joint_states'
    assert node.flange_pub.topic_name == '/arm/flange_pose'
    pub = harness.publisher(JointTrajectory, controller, RELIABLE)
    harness.matched(pub)
    pub.publish(_trajectory(HOME + 0.1, 0.5))
    harness.spin_until(lambda: node.sim.accepted_count == 1, what='the command accepted')


def test_bad_trajectories_are_rejected_and_counted(sim):
    harness = sim
    sim = harness.sim_node.sim
    harness.spin_until(lambda: harness.pub.get_subscription_count() > 0 and harness.joint_states)
    harness.spin_until(lambda: sim.time > 2.0)
    harness.pub.publish(_trajectory(HOME, 1.0, names=list(JOINT_NAMES[:6]) + ['wrist']))
    harness.pub.publish(_trajectory([float('nan')] * 7, 1.0))
    # Stamped at t = 0.2 s, its point due at 0.7 s: more than max_delay (1 s) before it
    # arrives once the simulation is past 2 s, refused as stale.
    harness.pub.publish(_trajectory(HOME + 0.1, 0.5, stamp=Time(sec=0, nanosec=200_000_000)))
    harness.spin_until(lambda: harness.sim_node.rejection_count == 3)
    assert 'stale' in harness.sim_node.last_rejection
    harness.spin_until(lambda: sim.time > 3.0)
    # Nothing was executed: the arm still holds its start.
    np.testing.assert_allclose(harness.joint_states[-1].position, HOME, atol=1e-5)
    assert sim.accepted_count == 0


def test_trajectories_beyond_the_limits_are_refused_one_warning_each_and_the_arm_holds(
        harness, capfd):
    """The probe's commands over DDS: beyond a joint's range, 1e6 rad, too fast between points,
    a first point due more than max_delay before it arrives, 100,000 points (refused by its
    length before it is read)."""
    h = Sim(harness, max_trajectory_points=1000)
    sim = h.sim_node.sim
    h.spin_until(lambda: h.pub.get_subscription_count() > 0 and h.joint_states)
    upper = sim.kinematics.upper
    beyond = HOME.copy()
    beyond[0] = upper[0] + 0.5
    sudden = _trajectory(HOME + 1.0, 0.5)
    sudden.points = [JointTrajectoryPoint(positions=HOME.tolist(), time_from_start=_duration(1.0)),
                     JointTrajectoryPoint(positions=(HOME + 0.5).tolist(),
                                          time_from_start=_duration(1.05))]
    huge = JointTrajectory(joint_names=list(JOINT_NAMES))
    point = JointTrajectoryPoint(positions=HOME.tolist())
    huge.points = [JointTrajectoryPoint(positions=point.positions,
                                        time_from_start=_duration(0.01 * (i + 1)))
                   for i in range(100_000)]
    capfd.readouterr()
    h.spin_until(lambda: sim.time > 2.0)
    stale = _trajectory(HOME + 0.3, 0.0, stamp=Time(sec=0, nanosec=1))
    for msg in (_trajectory(beyond, 2.0), _trajectory(np.full(7, 1e6), 2.0), sudden, stale,
                huge):
        h.pub.publish(msg)
    h.spin_until(lambda: h.sim_node.rejection_count == 5, timeout=30.0)
    now = sim.time
    h.spin_until(lambda: sim.time > now + 0.5)
    assert sim.accepted_count == 0
    assert 'more than the 1000 allowed' in h.sim_node.last_rejection
    np.testing.assert_allclose(h.joint_states[-1].position, HOME, atol=1e-5)   # held
    warnings = [line for line in capfd.readouterr().err.splitlines() if 'rejected' in line]
    assert len(warnings) == 5 and all('[WARN]' in line for line in warnings), warnings
    for words in ('position 3.4', 'position 1e+06', 'on average, above its limit',
                  'stale: the first point was due', '100000 points'):
        assert any(words in line for line in warnings), words


def _executable(*params, **popen):
    env = dict(os.environ, ROS_DOMAIN_ID=str(private_domain_id()))
    args = [sys.executable, '-m', 'mixture_ip_ros.nodes.sim_node', '--ros-args',
            '--params-file', str(config_path('sim.yaml'))]
    for p in params:
        args += ['-p', p]
    return subprocess.Popen(args, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            **popen)


def _interrupt(proc):
    """SIGINT, then the exit code and output. The node exits in 1-2.5 s with two busy processes
    beside it, 4-6 s with six; 30 s (as test_executables) only catches a hang."""
    proc.send_signal(signal.SIGINT)
    try:
        out = proc.communicate(timeout=30)[0]
    except subprocess.TimeoutExpired:
        proc.kill()
        out = proc.communicate()[0]
    return proc.returncode, out.decode(errors='replace')


def test_runs_as_an_executable_with_ros_args(harness):
    proc = _executable('real_time_factor:=1.0', 'publish_rate:=50.0')
    got = harness.subscribe(JointState, 'joint_states', RELIABLE)
    try:
        harness.spin_until(lambda: len(got) >= 5 or proc.poll() is not None,
                           what='joint states from the executable')
        assert len(got) >= 5, proc.stdout.read().decode()
        np.testing.assert_allclose(got[-1].position, HOME, atol=1e-5)
        stamps = [m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in got]
        np.testing.assert_allclose(np.diff(stamps), 0.02, atol=1e-9)   # publish_rate 50 Hz
    finally:
        code, out = _interrupt(proc)
    assert code == 0, out


def test_ctrl_c_while_simulating_flat_out_exits_cleanly(harness):
    """At real_time_factor 0 the node is nearly always inside a callback when SIGINT shuts the
    context down. Started as a shell's background job (SIGINT ignored until rclpy installs its
    handler, so no KeyboardInterrupt), that must still end in exit code 0, no traceback.

    Each run listens with a subscription of its own: the one before it still held the last
    node's joint states, which a busy machine left unread, and fifty of those sent the next
    SIGINT while that node was still importing, with SIGINT ignored: it never stopped."""
    for _ in range(3):
        got = []
        listener = harness.probe.create_subscription(JointState, 'joint_states', got.append,
                                                     RELIABLE)
        proc = _executable('real_time_factor:=0.0',
                           preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
        try:
            harness.spin_until(lambda: len(got) >= 50 or proc.poll() is not None,
                               what='the executable simulating')
        finally:
            code, text = _interrupt(proc)
            harness.probe.destroy_subscription(listener)
        assert code == 0 and 'Traceback' not in text, text


def test_an_empty_trajectory_stops_the_motion_and_holds(sim):
    s = sim.sim_node.sim
    sim.h.matched(sim.pub)
    goal = HOME + 0.4
    sim.pub.publish(_trajectory(goal, 2.0))
    sim.spin_until(lambda: s.accepted_count == 1 and s.time > 0.7)
    sim.pub.publish(JointTrajectory(joint_names=list(JOINT_NAMES)))
    sim.spin_until(lambda: not s.follower.active)
    stopped_at, q_stop = s.time, s.q
    assert np.abs(q_stop - HOME).max() > 0.1 and np.abs(q_stop - goal).max() > 0.1  # mid-way
    sim.spin_until(lambda: s.time > stopped_at + 1.0)
    assert np.abs(s.q - q_stop).max() < 0.02 and np.abs(s.qd).max() < 1e-3
    assert sim.sim_node.rejection_count == 0


def test_deactivating_drops_the_trajectory_and_holds_while_time_goes_on(sim):
    s = sim.sim_node.sim
    sim.h.matched(sim.pub)
    sim.pub.publish(_trajectory(HOME + 0.4, 2.0))
    sim.spin_until(lambda: s.accepted_count == 1 and s.time > 0.7)
    sim.sim_node.trigger_deactivate()
    stopped_at, q_stop = s.time, s.q
    sim.spin_until(lambda: s.time > stopped_at + 1.0 and len(sim.clocks) > 0)
    assert np.abs(s.q - q_stop).max() < 0.02 and np.abs(s.qd).max() < 1e-3
    assert sim.h.probe.count_subscribers('joint_trajectory') == 0
    sim.sim_node.trigger_activate()
    sim.spin_until(lambda: sim.pub.get_subscription_count() == 1, what='resubscribed')
    sim.pub.publish(_trajectory(HOME, 1.0))
    sim.spin_until(lambda: s.accepted_count == 2)


def test_wall_clock_mode_stamps_ros_time_and_maps_trajectory_stamps(harness):
    h = Sim(harness, simulated_time=False)
    sim = h.sim_node.sim
    h.spin_until(lambda: h.pub.get_subscription_count() > 0 and h.joint_states)
    assert h.clocks == []   # no /clock in wall-clock mode
    now = h.h.probe.get_clock().now()
    stamp = h.joint_states[-1].header.stamp
    assert abs(stamp.sec + 1e-9 * stamp.nanosec - now.nanoseconds * 1e-9) < 1.0
    goal = HOME + 0.2
    # Stamped with ROS time: starts now on the simulation's own clock.
    h.pub.publish(_trajectory(goal, 0.5, stamp=now.to_msg()))
    h.spin_until(lambda: sim.accepted_count == 1)
    h.spin_until(lambda: np.allclose(h.joint_states[-1].position, goal, atol=1e-4))
    # Stamped 10 s ago with a 0.5 s trajectory: its point was due 9.5 s before it arrived,
    # stale (ROS time mapped onto the simulation's clock).
    old = Time(sec=now.to_msg().sec - 10, nanosec=now.to_msg().nanosec)
    h.pub.publish(_trajectory(HOME, 0.5, stamp=old))
    h.spin_until(lambda: h.sim_node.rejection_count == 1)
    assert 'stale: the first point was due' in h.sim_node.last_rejection
