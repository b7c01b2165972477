"""sim_node over real DDS: in-process convergence, rejections, params file, the executable."""

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import rclpy
import yaml
from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import PoseStamped
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from conftest import private_domain_id
from mixture_ip_ros.nodes.sim_node import SimNode
from mixture_ip_ros.core.share import config_path
from mixture_ip_ros.robot.description import JOINT_NAMES
from mixture_ip_ros.robot.kinematics import RobotKinematics
from mixture_ip_ros.robot.description import DEFAULT

HOME = DEFAULT.home_array()

RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)


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


class Harness:
    """The node under test plus a client node, spun by one executor on the test's context."""

    def __init__(self, ctx, **overrides):
        params = [Parameter('real_time_factor', value=0.0)]
        params += [Parameter(k, value=v) for k, v in overrides.items()]
        self.sim_node = SimNode(context=ctx, parameter_overrides=params)
        self.client = rclpy.create_node('sim_node_test_client', context=ctx)
        self.joint_states, self.poses, self.clocks = [], [], []
        self.client.create_subscription(JointState, 'joint_states', self.joint_states.append,
                                        RELIABLE)
        self.client.create_subscription(PoseStamped, 'iiwa/flange_pose', self.poses.append,
                                        RELIABLE)
        self.client.create_subscription(Clock, '/clock', self.clocks.append, RELIABLE)
        self.pub = self.client.create_publisher(JointTrajectory, 'iiwa/joint_trajectory',
                                                RELIABLE)
        self.executor = SingleThreadedExecutor(context=ctx)
        self.executor.add_node(self.sim_node)
        self.executor.add_node(self.client)

    def spin_until(self, condition, timeout=20.0):
        end = time.monotonic() + timeout
        while not condition():
            assert time.monotonic() < end, 'timed out'
            self.executor.spin_once(timeout_sec=0.01)

    def close(self):
        self.executor.shutdown()
        self.sim_node.destroy_node()
        self.client.destroy_node()


@pytest.fixture
def harness(ros_context):
    h = Harness(ros_context)
    yield h
    h.close()


def test_joint_states_converge_to_the_trajectory_end(harness):
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


def test_the_robot_parameter_makes_it_another_arm(ros_context):
    """robot:=ur5 and nothing else: six joints at the UR5's home, its frame on the flange pose
    (in its base frame, 10 cm from the scene's origin), and its trajectories executed."""
    from mixture_ip_ros.robot.description import load_description
    ur5 = load_description('ur5')
    h = Harness(ros_context, robot='ur5')
    try:
        sim = h.sim_node.sim
        h.spin_until(lambda: h.pub.get_subscription_count() > 0 and h.joint_states)
        assert list(h.joint_states[-1].name) == list(ur5.joint_names)
        np.testing.assert_allclose(h.joint_states[-1].position, ur5.home, atol=1e-6)
        assert list(h.sim_node.get_parameter('natural_frequency').value) == [60.0] * 6
        goal = np.array(ur5.home) + np.array([0.3, -0.2, 0.25, 0.3, -0.3, 0.2])
        h.pub.publish(_trajectory(HOME, 1.0))                       # the iiwa's: refused
        h.pub.publish(_trajectory(goal, 1.0, names=ur5.joint_names))
        h.spin_until(lambda: sim.accepted_count == 1 and h.sim_node.rejection_count == 1)
        sent_at = sim.time
        h.spin_until(lambda: sim.time > sent_at + 2.0)
        h.spin_until(lambda: len(h.poses) > 1 and h.poses[-1].header.stamp.sec >= int(sim.time))
        np.testing.assert_allclose(h.joint_states[-1].position, goal, atol=1e-4)
        pose = h.poses[-1]
        assert pose.header.frame_id == 'base_link'
        np.testing.assert_allclose([pose.pose.position.x, pose.pose.position.y,
                                    pose.pose.position.z], RobotKinematics('ur5').fk(goal)[0],
                                   atol=1e-3)
    finally:
        h.close()


def test_bad_trajectories_are_rejected_and_counted(harness):
    sim = harness.sim_node.sim
    harness.spin_until(lambda: harness.pub.get_subscription_count() > 0 and harness.joint_states)
    harness.spin_until(lambda: sim.time > 1.0)
    harness.pub.publish(_trajectory(HOME, 1.0, names=list(JOINT_NAMES[:6]) + ['wrist']))
    harness.pub.publish(_trajectory([float('nan')] * 7, 1.0))
    # Stamped at t = 0.2 s, ends at 0.7 s: in the past once the simulation is past 1 s.
    harness.pub.publish(_trajectory(HOME + 0.1, 0.5, stamp=Time(sec=0, nanosec=200_000_000)))
    harness.spin_until(lambda: harness.sim_node.rejection_count == 3)
    assert 'ends in the past' in harness.sim_node.last_rejection
    harness.spin_until(lambda: sim.time > 2.0)
    # Nothing was executed: the arm still holds its start.
    np.testing.assert_allclose(harness.joint_states[-1].position, HOME, atol=1e-5)
    assert sim.accepted_count == 0


def test_params_file_is_the_node_parameters():
    path = config_path('sim.yaml')
    values = yaml.safe_load(path.read_text())['sim_node']['ros__parameters']
    ctx = Context()
    rclpy.init(context=ctx, domain_id=private_domain_id(),
               args=['--ros-args', '--params-file', str(path)])
    try:
        node = SimNode(context=ctx)
        builtin = {'use_sim_time', 'start_type_description_service'}
        declared = set(node._parameters) - builtin
        # Not written in the file: the robot's description gives them (the file says so).
        from mixture_ip_ros.robot.description import load_description
        robot = load_description(values['robot'])
        frequency, damping = robot.gains()
        derived = {'initial_positions': list(robot.home), 'natural_frequency': frequency.tolist(),
                   'damping_ratio': damping.tolist(), 'base_frame': robot.base_frame}
        assert declared == set(values) | set(derived)
        for name, value in {**values, **derived}.items():
            assert node.get_parameter(name).value == pytest.approx(value)
        np.testing.assert_allclose(node.sim.q, robot.home)
        assert node.steps_per_publish == round(1000 / values['publish_rate'])
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)


def test_runs_as_an_executable_with_ros_args(ros_context):
    env = dict(os.environ, ROS_DOMAIN_ID=str(private_domain_id()))
    proc = subprocess.Popen(
        [sys.executable, '-m', 'mixture_ip_ros.nodes.sim_node', '--ros-args',
         '--params-file', str(config_path('sim.yaml')), '-p', 'real_time_factor:=1.0',
         '-p', 'publish_rate:=50.0'],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    client = rclpy.create_node('sim_node_exec_client', context=ros_context)
    got = []
    client.create_subscription(JointState, 'joint_states', got.append, RELIABLE)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(client)
    try:
        end = time.monotonic() + 20
        while len(got) < 5 and time.monotonic() < end and proc.poll() is None:
            executor.spin_once(timeout_sec=0.05)
        assert len(got) >= 5, proc.stdout.read().decode() if proc.poll() is not None else ''
        np.testing.assert_allclose(got[-1].position, HOME, atol=1e-5)
        stamps = [m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in got]
        np.testing.assert_allclose(np.diff(stamps), 0.02, atol=1e-9)   # publish_rate 50 Hz
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            code = proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            code = proc.wait()
        executor.shutdown()
        client.destroy_node()
    assert code == 0



def test_ctrl_c_while_simulating_flat_out_exits_cleanly():
    """At real_time_factor 0 the node is nearly always inside a callback when SIGINT shuts the
    context down. Started as a shell's background job (SIGINT ignored until rclpy installs its
    handler, so no KeyboardInterrupt), that ended in an RCLError traceback and exit code 1."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(private_domain_id()))
    for _ in range(3):
        proc = subprocess.Popen(
            [sys.executable, '-m', 'mixture_ip_ros.nodes.sim_node', '--ros-args',
             '--params-file', str(config_path('sim.yaml')), '-p', 'real_time_factor:=0.0'],
            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
        out = b''
        try:
            deadline = time.monotonic() + 20
            while b' sim: dt' not in out and time.monotonic() < deadline:   # started up
                out += proc.stdout.readline()
            time.sleep(1.0)
            proc.send_signal(signal.SIGINT)
            out += proc.communicate(timeout=10)[0]
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        text = out.decode(errors='replace')
        assert proc.returncode == 0 and 'Traceback' not in text, text

def test_wall_clock_mode_stamps_ros_time_and_maps_trajectory_stamps(ros_context):
    h = Harness(ros_context, simulated_time=False)
    try:
        sim = h.sim_node.sim
        h.spin_until(lambda: h.pub.get_subscription_count() > 0 and h.joint_states)
        assert h.clocks == []   # no /clock in wall-clock mode
        now = h.client.get_clock().now()
        stamp = h.joint_states[-1].header.stamp
        assert abs(stamp.sec + 1e-9 * stamp.nanosec - now.nanoseconds * 1e-9) < 1.0
        goal = HOME + 0.2
        # Stamped with ROS time: starts now on the simulation's own clock.
        h.pub.publish(_trajectory(goal, 0.5, stamp=now.to_msg()))
        h.spin_until(lambda: sim.accepted_count == 1)
        h.spin_until(lambda: np.allclose(h.joint_states[-1].position, goal, atol=1e-4))
        # Stamped 10 s ago with a 0.5 s trajectory: over before it arrived.
        old = Time(sec=now.to_msg().sec - 10, nanosec=now.to_msg().nanosec)
        h.pub.publish(_trajectory(HOME, 0.5, stamp=old))
        h.spin_until(lambda: h.sim_node.rejection_count == 1)
        assert 'ends in the past' in h.sim_node.last_rejection
    finally:
        h.close()
