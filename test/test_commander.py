"""One commander for the arm, and an arm that stops when its commander is gone: the decisions
without ROS (robot.commander), the stop within the acceleration limits (robot.trajectory,
robot.sim), and sim_node over DDS with a commander in a DDS participant of its own."""

import numpy as np
import pytest
import rclpy
from builtin_interfaces.msg import Duration
from rclpy.context import Context
from rclpy.parameter import Parameter
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from conftest import private_domain_id
from mixture_ip_ros.nodes import qos
from mixture_ip_ros.nodes.diagnostics import OK, WARN
from mixture_ip_ros.nodes.sim_node import COMMAND_TOPIC, SimNode
from mixture_ip_ros.robot.commander import CommandWatch, Publisher, is_commander
from mixture_ip_ros.robot.description import DEFAULT, JOINT_NAMES
from mixture_ip_ros.robot.sim import RobotSimulation
from mixture_ip_ros.robot.trajectory import (TrajectoryFollower, points_from_arrays,
                                             stopping_trajectory)

HOME = DEFAULT.home_array()
ESTIMATOR = Publisher('/estimator_node', b'e', True)
STRAY = Publisher('/stray', b's', True)


# -- the decisions ------------------------------------------------------------------------
def test_the_commander_is_a_node_name_in_any_namespace_or_a_full_name():
    assert is_commander('/estimator_node', 'estimator_node')
    assert is_commander('/arm/estimator_node', 'estimator_node')
    assert not is_commander('/arm/estimator_node', '/estimator_node')
    assert is_commander('/arm/estimator_node', '/arm/estimator_node')
    assert not is_commander('/estimator_node_2', 'estimator_node')
    assert not is_commander('', 'estimator_node')                 # not named yet
    assert is_commander('/anyone', '') and is_commander('', '')


def test_another_publisher_is_warned_about_once_and_every_command_refused_while_it_is_there():
    watch = CommandWatch('estimator_node')
    assert watch.graph([ESTIMATOR], 1) == [] and watch.accept() == (True, None)
    warnings = watch.graph([ESTIMATOR, STRAY], 2)
    assert len(warnings) == 1 and warnings[0].startswith('/stray publishes on the command')
    assert watch.graph([ESTIMATOR, STRAY], 2) == []                 # once per publisher
    taken, line = watch.accept()
    assert not taken and line == 'commands refused: another publisher on the command topic: ' \
                                 '/stray'
    assert watch.accept() == (False, None)                          # logged once per spell
    assert watch.accept(stop=True) == (True, None)                  # a stop from anyone
    assert (watch.refused, watch.others) == (2, 1)
    assert watch.graph([ESTIMATOR], 1) == [] and watch.blocked is None
    assert watch.accept() == (True, None) and watch.refused == 2


def test_a_matched_publisher_the_graph_does_not_name_blocks_and_one_that_cannot_match_not():
    watch = CommandWatch('estimator_node')
    assert watch.graph([ESTIMATOR, Publisher('', b'u', True)], 2) == []
    assert watch.blocked.startswith('another publisher') and not watch.accept()[0]
    assert watch.graph([ESTIMATOR], 2) == []            # matched before the graph has it
    assert 'does not name yet' in watch.blocked and not watch.accept()[0]
    late = watch.graph([ESTIMATOR, Publisher('/talker', b't', False)], 1)
    assert watch.blocked is None and watch.accept() == (True, None)
    assert late == ['/talker publishes on the command topic with a QoS the sim does not '
                    'accept: none of its messages arrive']
    anyone = CommandWatch('')
    assert anyone.graph([ESTIMATOR, STRAY], 5) == [] and anyone.accept() == (True, None)


def test_a_publisher_lost_stops_a_plan_in_progress_only():
    watch = CommandWatch('estimator_node')
    assert not watch.liveliness(1, 1, 0.5, following=True)           # one came alive
    assert watch.liveliness(0, -1, 2.0, following=True)              # gone, mid-plan: hold
    assert (watch.lapses, watch.holds, watch.last_lapse, watch.alive) == (1, 1, 2.0, 0)
    assert not watch.liveliness(1, 1, 3.0, following=False)          # a restarted commander
    assert not watch.liveliness(0, -1, 4.0, following=False)         # gone, the arm at rest
    assert not watch.liveliness(0, 0, 5.0, following=True)           # a dead one forgotten
    assert (watch.lapses, watch.holds, watch.last_lapse) == (2, 1, 4.0)


# -- the stop -----------------------------------------------------------------------------
def test_the_stop_brakes_at_constant_deceleration_the_slowest_joint_at_its_limit():
    """The follower's references against the closed form of a constant deceleration
    q(t) = q0 + qd0 t - qd0 t^2 / (2 T), T = max |qd0| / a."""
    q0 = np.array([0.1, -0.2, 0.3])
    qd0 = np.array([1.2, -0.5, 0.05])
    limit = np.array([4.0, 10.0, 1.0])
    T = 0.3                                                          # joint 0: 1.2 / 4
    follower = TrajectoryFollower(3)
    follower.set(stopping_trajectory(q0, qd0, limit, 1e-3))
    t = np.linspace(0.0, T, 31)[:-1]                              # at T: at rest, held
    refs = np.array([follower.sample(2.0 + s, q0, qd0) for s in t])
    np.testing.assert_allclose(refs[:, 0], q0 + np.outer(t, qd0) - np.outer(t**2, qd0) / (2 * T),
                               atol=1e-12)
    np.testing.assert_allclose(refs[:, 1], qd0 * (1 - t[:, None] / T), atol=1e-12)
    np.testing.assert_allclose(refs[:, 2], np.broadcast_to(-qd0 / T, (30, 3)), atol=1e-9)
    assert np.all(np.abs(refs[:, 2]) <= limit + 1e-9)
    assert np.isclose(abs(refs[0, 2, 0]), limit[0])
    after = follower.sample(2.0 + T + 0.5, q0, qd0)
    np.testing.assert_allclose(after[0], q0 + qd0 * T / 2, atol=1e-12)
    assert not after[1].any() and not follower.following(2.0 + T + 0.5)
    resting = stopping_trajectory(q0, np.zeros(3), limit, 1e-3)
    assert resting.times[0] == 1e-3 and np.array_equal(resting.positions[0], q0)


def test_the_simulated_arm_stops_within_its_limits_and_holds():
    sim = RobotSimulation()
    goal = HOME + 0.6
    sim.set_trajectory(JOINT_NAMES, points_from_arrays([2.0], goal[None], np.zeros((1, 7))))
    sim.step(1000)
    assert sim.following and np.abs(sim.qd).max() > 0.3
    q, qd = sim.q, sim.qd
    assert sim.stop() and sim.following
    T = np.max(np.abs(qd) / sim.limits.acceleration)
    speeds = []
    for _ in range(int(np.ceil(T / sim.dt)) + 200):
        sim.step(1)
        speeds.append(sim.qd)
    accel = np.abs(np.diff(np.array(speeds), axis=0)) / sim.dt
    assert np.all(accel.max(axis=0) <= 1.05 * sim.limits.acceleration)
    assert not sim.following and np.abs(sim.qd).max() < 1e-3
    np.testing.assert_allclose(sim.q, q + qd * T / 2, atol=2e-4)
    assert not sim.stop()                                            # nothing to stop


# -- sim_node over DDS ----------------------------------------------------------------------
def _trajectory(goal, seconds):
    point = JointTrajectoryPoint(positions=[float(x) for x in goal], velocities=[0.0] * 7,
                                 time_from_start=Duration(sec=int(seconds),
                                                          nanosec=int(seconds % 1 * 1e9)))
    return JointTrajectory(joint_names=list(JOINT_NAMES), points=[point])


@pytest.fixture
def publisher():
    """``publisher(name)``: a node of that name in a DDS participant of its own (its own
    context) and its publisher on the command topic, offering a 0.1 s liveliness lease (as the
    estimator's); nobody needs to spin it."""
    made = []

    def make(name):
        ctx = Context()
        rclpy.init(context=ctx, domain_id=private_domain_id())
        node = rclpy.create_node(name, context=ctx)
        made.append((node, ctx))
        return node, node.create_publisher(JointTrajectory, COMMAND_TOPIC, qos.command(10, 0.1))
    yield make
    for node, ctx in made:
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)


def _sim(harness, **params):
    return harness.add(SimNode(context=harness.context, parameter_overrides=[
        Parameter(k, value=v) for k, v in {'real_time_factor': 1.0, **params}.items()]))


def _named(harness, node, name):
    harness.spin_until(lambda: any(i.node_name == name for i in
                                   node.get_publishers_info_by_topic(COMMAND_TOPIC)),
                       what=f'{name} in the graph')


def test_a_stray_publishers_commands_are_refused_and_counted_the_commanders_taken(
        harness, publisher, capfd):
    node = _sim(harness)
    sim = node.sim
    _, pub = publisher('estimator_node')
    harness.matched(pub)
    _named(harness, node, 'estimator_node')
    pub.publish(_trajectory(HOME + 0.1, 30.0))
    harness.spin_until(lambda: sim.accepted_count == 1, what="the commander's command")
    stray_node, stray = publisher('stray')
    harness.matched(stray)
    _named(harness, node, 'stray')
    stray.publish(_trajectory(HOME + 0.3, 0.5))
    harness.spin_until(lambda: node.watch.refused == 1, what='the stray command refused')
    pub.publish(_trajectory(HOME + 0.2, 0.5))           # cannot be told from the stray's
    harness.spin_until(lambda: node.watch.refused == 2, what='the next command refused')
    assert sim.following                                 # on the commander's 30 s plan
    stray.publish(JointTrajectory(joint_names=list(JOINT_NAMES)))      # a stop: taken
    harness.spin_until(lambda: not sim.following, what='the stop')
    assert sim.accepted_count == 1 and node.rejection_count == 0
    report = node.diagnostics_msg().status[0]
    values = {kv.key: kv.value for kv in report.values}
    assert (values['commands_refused_sender'], values['other_publishers']) == ('2', '1')
    assert report.level == WARN and node.diagnostics_msg().status[0].level == OK   # once
    stray_node.destroy_publisher(stray)
    harness.spin_until(lambda: node.trajectory_sub.get_publisher_count() == 1 and not any(
        i.node_name == 'stray' for i in node.get_publishers_info_by_topic(COMMAND_TOPIC)),
                       what='the stray gone')
    pub.publish(_trajectory(HOME + 0.2, 0.5))
    harness.spin_until(lambda: sim.accepted_count == 2, what="the commander's command again")
    assert node.watch.refused == 2
    err = capfd.readouterr().err
    assert err.count('/stray publishes on the command topic too') == 1
    assert err.count('commands refused: another publisher') == 1


def test_a_publisher_without_a_lease_is_not_matched_and_is_reported(harness):
    node = _sim(harness, real_time_factor=0.0)
    harness.publisher(JointTrajectory, COMMAND_TOPIC, qos.reliable(10))
    harness.spin_until(lambda: node.watch.incompatible == 1, what='the incompatible QoS event')
    assert node.trajectory_sub.get_publisher_count() == 0


def test_the_arm_stops_within_its_limits_and_holds_when_its_commander_is_gone(harness,
                                                                              publisher):
    """The commander destroyed 0.6 s into a 2 s plan: DDS reports it gone, the arm brakes to
    rest at the rate of its most constrained joint and holds there (simulated time; the
    waits are on events and the simulated clock)."""
    node = _sim(harness)
    sim = node.sim
    cmd, pub = publisher('estimator_node')
    harness.matched(pub)
    _named(harness, node, 'estimator_node')
    goal = HOME + 0.8
    pub.publish(_trajectory(goal, 2.0))
    harness.spin_until(lambda: sim.accepted_count == 1 and sim.time > 0.6, what='moving')
    stops = []
    original = sim.stop

    def stop():
        stops.append((sim.time, sim.q, sim.qd))
        return original()
    sim.stop = stop
    cmd.destroy_node()
    harness.spin_until(lambda: node.watch.holds == 1, what='the hold')
    t0, q0, qd0 = stops[0]
    assert t0 < 2.0 and np.abs(qd0).max() > 0.3           # it was moving when it stopped
    T = np.max(np.abs(qd0) / sim.limits.acceleration)
    harness.spin_until(lambda: sim.time > t0 + T + 0.5, what='simulated time')
    assert not sim.following and np.abs(sim.qd).max() < 1e-3
    np.testing.assert_allclose(sim.q, q0 + qd0 * T / 2, atol=1e-3)
    assert np.abs(sim.q - goal).max() > 0.3                # the plan was not followed on
    values = {kv.key: kv.value for kv in node.diagnostics_msg().status[0].values}
    assert (values['liveliness_lapses'], values['holds_source_lost'], values['state']) == (
        '1', '1', 'holding')
