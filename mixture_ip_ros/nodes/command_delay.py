"""command_delay: a slow link between the estimator and the robot. Each JointTrajectory command is
held for ``delay`` s of simulated time, then passed on unchanged (the same serialized bytes).

Not an executable: the closed loop (``ClosedLoop(command_delay=...)``, ``mixture-ip demo
--command-delay``) puts it between the estimator, whose trajectory_topic is remapped to
input_topic, and the sim's command topic, to see how the loop behaves with latency.

Subscribes  input_topic  trajectory_msgs/JointTrajectory (serialized), reliable
            /clock       rosgraph_msgs/Clock: the simulated time
Publishes   output_topic trajectory_msgs/JointTrajectory, reliable: each command once /clock
            reaches the time it arrived (the latest /clock then) plus ``delay``, in arrival
            order. /clock ticks once per publish period of the sim (10 ms by default), so a
            command is held between ``delay`` and ``delay`` + one period.
"""

from collections import deque
from dataclasses import dataclass

from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from trajectory_msgs.msg import JointTrajectory

from mixture_ip_ros.core.stamps import seconds_to_ns, stamp_to_ns
from mixture_ip_ros.nodes import qos
from mixture_ip_ros.nodes.params import declare, param


@dataclass
class CommandDelayParameters:
    input_topic: str = param('/estimator/joint_trajectory', "the estimator's commands (its "
                                                            'trajectory_topic remapped here)')
    output_topic: str = param('joint_trajectory', "the robot's command topic (relative: in "
                                                  "the node's namespace)")
    delay: float = param(0.05, 's of simulated time each command is held', low=0.0,
                         high=60.0, dynamic=True)


class CommandDelay(Node):

    def __init__(self, **kwargs):
        super().__init__('command_delay', **kwargs)
        p = declare(self, CommandDelayParameters, on_change=self._on_change)
        self._delay_ns = seconds_to_ns(p.delay)
        self._now_ns = 0               # the latest simulated time seen on /clock
        self._held = deque()           # (release at ns, serialized message)
        self.relayed = 0
        self._pub = self.create_publisher(JointTrajectory, p.output_topic, qos.reliable(100))
        self.create_subscription(JointTrajectory, p.input_topic, self._on_command,
                                 qos.reliable(100), raw=True)
        self.create_subscription(Clock, '/clock', self._on_clock, qos.clock())

    def _on_change(self, changes: dict) -> None:
        if 'delay' in changes:
            self._delay_ns = seconds_to_ns(changes['delay'])

    def _on_command(self, data: bytes) -> None:
        self._held.append((self._now_ns + self._delay_ns, data))

    def _on_clock(self, msg: Clock) -> None:
        self._now_ns = stamp_to_ns(msg.clock)
        while self._held and self._held[0][0] <= self._now_ns:
            self._pub.publish(self._held.popleft()[1])
            self.relayed += 1
