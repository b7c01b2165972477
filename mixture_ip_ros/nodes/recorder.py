"""recorder: listens to the closed loop and keeps what a report, plot or video needs.

Not an executable: the demo and the integration tests spin it beside the real nodes. It also
watches every JointTrajectory command and counts the non-finite ones (there must be none).
"""

from dataclasses import dataclass
import math
import threading

import numpy as np
from geometry_msgs.msg import PointStamped
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, Header
from trajectory_msgs.msg import JointTrajectory

from mixture_ip_ros.core.stamps import stamp_to_ns
from mixture_ip_ros.nodes import qos
from mixture_ip_ros.nodes.params import declare, param


def _sec(stamp) -> float:
    return stamp_to_ns(stamp) * 1e-9


@dataclass
class RecorderParameters:
    joint_state_topic: str = param('/joint_states', 'sensor_msgs/JointState of the robot')
    observation_topic: str = param('/observer/wrist', "the observer's wrist observations")
    event_topic: str = param('/observer/event', "the observer's events")
    posterior_topic: str = param('/estimator/posterior', "the estimator's posterior summary")
    trajectory_topic: str = param('joint_trajectory', 'the commands to the robot')


class InteractionRecorder(Node):

    def __init__(self, **kwargs):
        super().__init__('recorder', **kwargs)
        p = declare(self, RecorderParameters)
        depth = qos.reliable(1000)
        self._lock = threading.Lock()
        self.clear()
        self.create_subscription(JointState, p.joint_state_topic, self._on_joints, depth)
        self.create_subscription(PointStamped, p.observation_topic, self._on_wrist, depth)
        self.create_subscription(Header, p.event_topic, self._on_event, depth)
        self.create_subscription(Float64MultiArray, p.posterior_topic, self._on_posterior, depth)
        self.create_subscription(JointTrajectory, p.trajectory_topic, self._on_trajectory, depth)

    def clear(self):
        with self._lock:
            self.joints, self.wrist = [], []
            self.events, self.posterior, self.trajectories = [], [], []
            self.non_finite_commands = 0

    def snapshot(self):
        """Copies of everything recorded so far."""
        with self._lock:
            return {k: list(getattr(self, k)) for k in
                    ('joints', 'wrist', 'events', 'posterior', 'trajectories')}

    def plans_received(self) -> int:
        """How many trajectories with points arrived since the last clear (holds have none)."""
        with self._lock:
            return sum(len(msg.points) > 0 for _, msg in self.trajectories)

    def _on_joints(self, msg):
        with self._lock:
            self.joints.append((_sec(msg.header.stamp), np.array(msg.position)))

    def _on_wrist(self, msg):
        p = msg.point
        with self._lock:
            self.wrist.append((_sec(msg.header.stamp), np.array([p.x, p.y, p.z])))

    def _on_event(self, msg):
        with self._lock:
            self.events.append((_sec(msg.stamp), msg.frame_id))

    def _on_posterior(self, msg):
        with self._lock:
            self.posterior.append((self.get_clock().now().nanoseconds * 1e-9, np.array(msg.data)))

    def _on_trajectory(self, msg):
        values = [v for pt in msg.points for v in (*pt.positions, *pt.velocities,
                                                    *pt.accelerations)]
        with self._lock:
            if not all(math.isfinite(v) for v in values):
                self.non_finite_commands += 1
            self.trajectories.append((self.get_clock().now().nanoseconds * 1e-9, msg))
