"""The command relay of the closed loop's delay tests: each command held for ``delay`` of
simulated time, then passed on byte for byte, in order."""

from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from mixture_ip_ros.nodes.command_delay import CommandDelay
from mixture_ip_ros.nodes import qos
from ros_harness import time_msg

S = 10**9


def _command(seconds):
    point = JointTrajectoryPoint(positions=[0.1, 0.2], velocities=[0.0, 0.0])
    point.time_from_start.sec = seconds
    return JointTrajectory(joint_names=['a', 'b'], points=[point])


def test_commands_are_held_for_the_delay_of_simulated_time_then_passed_on_unchanged(harness):
    relay = harness.add(CommandDelay(context=harness.context, parameter_overrides=[
        Parameter('delay', value=0.05)]))
    out = harness.subscribe(JointTrajectory, '/joint_trajectory', qos.reliable(100))
    raw_in, raw_out = [], []           # the serialized messages as DDS delivers them
    for topic, got in (('/estimator/joint_trajectory', raw_in),
                       ('/joint_trajectory', raw_out)):
        harness.probe.create_subscription(JointTrajectory, topic, got.append, qos.reliable(100),
                                          raw=True)
    commands = harness.publisher(JointTrajectory, '/estimator/joint_trajectory')
    clock = harness.publisher(Clock, '/clock')
    harness.matched(commands, clock)

    def tick(ns):
        clock.publish(Clock(clock=time_msg(ns)))
        harness.spin_until(lambda: relay._now_ns == ns, what=f'/clock {ns}')
    tick(1 * S)
    commands.publish(_command(1))
    commands.publish(_command(2))
    harness.spin_until(lambda: len(relay._held) == 2, what='the commands held')
    tick(1 * S + 40_000_000)                 # 40 ms later: still held
    assert relay.relayed == 0 and out == []
    tick(1 * S + 50_000_000)                 # the delay has passed: both, in order
    harness.spin_until(lambda: len(out) == 2 and len(raw_out) == 2, what='the relayed commands')
    assert [m.points[0].time_from_start.sec for m in out] == [1, 2]
    assert raw_out == raw_in
    # The delay changes at run time.
    assert relay.set_parameters([Parameter('delay', value=0.2)])[0].successful
    commands.publish(_command(3))
    harness.spin_until(lambda: len(relay._held) == 1, what='the command held')
    tick(1 * S + 240_000_000)
    assert relay.relayed == 2
    tick(1 * S + 250_000_000)
    harness.spin_until(lambda: len(out) == 3, what='the third command')
    assert not relay.set_parameters([Parameter('delay', value=-1.0)])[0].successful
