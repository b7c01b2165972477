"""Observer: cleans the mocap wrist stream and marks the interaction (onset, end, gaps).

Subscribes  /mocap/wrist     geometry_msgs/PoseStamped (sensor-data QoS)
Publishes   /observer/wrist  geometry_msgs/PointStamped in the robot base frame with the
                             original stamps: every accepted pose, as it comes
            /observer/event  std_msgs/Header, frame_id 'onset' | 'end' | 'gap', stamp = when
                             (a gap's stamp is the last sample before the silence)
Both outputs are reliable with a deep queue: the estimator must not lose observations.
An onset is confirmed some 0.1-1 s after the hand left rest and back-dated to then: the
estimator holds the recent samples and takes those from the onset on when the event comes
(forwarding them only then would send a burst of ~40 messages that live samples queue
behind). A pose's own observation goes out before the events it settles. Poses that fail a
check are dropped and counted (``drop_counts``); the logic lives in core.pose_validation and
core.segmentation, which are tested without ROS.
"""

import copy
import inspect
import time

from builtin_interfaces.msg import Time
from geometry_msgs.msg import PointStamped, PoseStamped
import rclpy
from rclpy.node import Node
from rclpy.qos import (
    DurabilityPolicy, HistoryPolicy, qos_profile_sensor_data, QoSProfile, ReliabilityPolicy)
from std_msgs.msg import Header

from mixture_ip_ros.core.frames import FrameTransform
from mixture_ip_ros.core.stamps import ns_to_parts, stamp_to_ns
from mixture_ip_ros.robot.description import DEFAULT_ROBOT, load_description
from mixture_ip_ros.estimation.pose_check import check_pose, POSE_REJECT_REASONS
from mixture_ip_ros.core.segmentation import Event, MotionSegmenter
from mixture_ip_ros.nodes.spinning import spin_until_shutdown

SEGMENTER_DEFAULTS = {name: p.default
                      for name, p in inspect.signature(MotionSegmenter).parameters.items()}


class ObserverNode(Node):

    def __init__(self, **kwargs):
        super().__init__('observer_node', **kwargs)
        self.declare_parameter('wrist_topic', '/mocap/wrist')
        self.declare_parameter('observation_topic', '/observer/wrist')
        self.declare_parameter('event_topic', '/observer/event')
        # Frame the mocap poses must carry ('' accepts any) and the frame published.
        self.declare_parameter('expected_frame', 'world')
        # The robot (a shipped name or a description file) gives the defaults of base_frame and
        # of the mocap-to-base transform (the inverse of its mount in the scene).
        self.declare_parameter('robot', DEFAULT_ROBOT)
        robot = load_description(self.get_parameter('robot').value)
        mocap_to_base = robot.world_to_base()
        self.declare_parameter('base_frame', robot.base_frame)
        # Mocap frame origin and orientation in the base frame: p_base = R p_mocap + t.
        self.declare_parameter('mocap_to_base_xyz', mocap_to_base.translation.tolist())
        self.declare_parameter('mocap_to_base_xyzw', list(mocap_to_base.quaternion))
        self.declare_parameter('quaternion_tolerance', 0.01)
        for name, default in SEGMENTER_DEFAULTS.items():
            self.declare_parameter(name, default)
        self.declare_parameter('input_queue_depth', 100)
        self.declare_parameter('output_queue_depth', 1000)
        self.declare_parameter('log_throttle_sec', 2.0)
        # Consecutive poses older than the last accepted one after which the stream is taken
        # to have restarted (bag replayed, mocap clock reset); 0 never restarts.
        self.declare_parameter('restart_after_backwards', 50)

        param = self._param
        self._expected_frame = param('expected_frame')
        self._base_frame = param('base_frame')
        self._quat_tol = float(param('quaternion_tolerance'))
        self._throttle = float(param('log_throttle_sec'))
        self._restart_after = int(param('restart_after_backwards'))
        self.transform = FrameTransform(list(param('mocap_to_base_xyz')),
                                        list(param('mocap_to_base_xyzw')))
        self.segmenter = MotionSegmenter(**{name: param(name) for name in SEGMENTER_DEFAULTS})
        self.moving = False   # between an 'onset' and its 'end'
        self._gap_timeout = self.segmenter.gap_timeout

        # Counters for monitoring and tests.
        self.drop_counts = {reason: 0 for reason in POSE_REJECT_REASONS}
        self.accepted = 0
        self.published = {'observations': 0, 'onset': 0, 'end': 0, 'gap': 0}
        self.stream_restarts = 0

        self._last_stamp_ns = None   # last accepted stamp
        self._t_ref_ns = None        # stream times are seconds since this stamp (float precision)
        self._last_arrival_ns = None  # node clock when the last pose was accepted
        self._backwards = 0
        self._next_drop_log = 0.0

        reliable = QoSProfile(history=HistoryPolicy.KEEP_LAST,
                              depth=int(param('output_queue_depth')),
                              reliability=ReliabilityPolicy.RELIABLE,
                              durability=DurabilityPolicy.VOLATILE)
        sensor = copy.copy(qos_profile_sensor_data)  # best effort, volatile ...
        sensor.depth = int(param('input_queue_depth'))  # ... with room for 500 Hz bursts
        self._obs_pub = self.create_publisher(PointStamped, param('observation_topic'), reliable)
        self._event_pub = self.create_publisher(Header, param('event_topic'), reliable)
        self.create_subscription(PoseStamped, param('wrist_topic'), self.on_pose, sensor)
        self.create_timer(max(self._gap_timeout / 4.0, 0.005), self.on_timer)
        self.get_logger().info(
            f"observing {param('wrist_topic')} (frame {self._expected_frame or 'any'}) -> "
            f"{param('observation_topic')} in {self._base_frame}, "
            f"events on {param('event_topic')}")

    def _param(self, name):
        return self.get_parameter(name).value

    # -- callbacks: never raise ---------------------------------------------------------
    def on_pose(self, msg: PoseStamped) -> None:
        try:
            self._handle_pose(msg)
        except Exception as exc:  # a bad message must not kill the node
            self.drop_counts['exception'] += 1
            self._log_drop(f'wrist pose dropped, callback failed: {exc!r}')

    def on_timer(self) -> None:
        try:
            if self._last_arrival_ns is None:
                return
            silence = (self.get_clock().now().nanoseconds - self._last_arrival_ns) * 1e-9
            if silence > self._gap_timeout:
                # Stream time now, judged by our clock: mocap and node clocks may be offset.
                t_now = self.segmenter.last_time + silence
                self._publish_events(self.segmenter.gap(t_now))
        except Exception as exc:
            self.get_logger().error(f'gap check failed: {exc!r}',
                                    throttle_duration_sec=self._throttle)

    # -- logic --------------------------------------------------------------------------
    def _handle_pose(self, msg: PoseStamped) -> None:
        stamp = msg.header.stamp
        stamp_ns = stamp_to_ns(stamp)
        p = msg.pose.position
        q = msg.pose.orientation
        position = (p.x, p.y, p.z)
        reason = check_pose(stamp_ns, msg.header.frame_id, position, (q.x, q.y, q.z, q.w),
                            self._last_stamp_ns, self._expected_frame, self._quat_tol)
        if reason == 'stamp_backwards' and self._restarted(stamp_ns):
            reason = None
        if reason is not None:
            self.drop_counts[reason] += 1
            if time.monotonic() >= self._next_drop_log:
                self._log_drop(f'wrist pose dropped ({reason}, frame {msg.header.frame_id!r}, '
                               f'stamp {stamp.sec}.{stamp.nanosec:09d})')
            return
        self._backwards = 0
        if self._t_ref_ns is None:
            self._t_ref_ns = stamp_ns
        self._last_stamp_ns = stamp_ns
        now_ns = self.get_clock().now().nanoseconds
        # Zero: sim time whose /clock has not started yet; no basis to judge silences on.
        self._last_arrival_ns = now_ns if now_ns > 0 else None
        self.accepted += 1
        t = (stamp_ns - self._t_ref_ns) * 1e-9
        xyz = self.transform.apply(*position)
        out = PointStamped()
        out.header.stamp = stamp
        out.header.frame_id = self._base_frame
        out.point.x, out.point.y, out.point.z = xyz
        self._obs_pub.publish(out)
        self.published['observations'] += 1
        self._publish_events(self.segmenter.update(t, xyz))

    def _restarted(self, stamp_ns: int) -> bool:
        """Count a pose older than the last accepted one; True once the stream restarted."""
        if self._restart_after <= 0:
            return False
        self._backwards += 1
        if self._backwards < self._restart_after:
            return False
        self.get_logger().warning(
            f'{self._backwards} consecutive wrist poses older than the last accepted one: '
            f'taking the stream as restarted')
        last_t = self.segmenter.last_time
        if self.moving and last_t is not None:
            self._publish_events([Event('end', last_t)])
        self.segmenter.reset()
        self.moving = False
        self._t_ref_ns = None
        self._last_stamp_ns = None
        self._last_arrival_ns = None
        self._backwards = 0
        self.stream_restarts += 1
        return True

    def _publish_events(self, events) -> None:
        for ev in events:
            self._event_pub.publish(Header(frame_id=ev.kind, stamp=self._to_stamp(ev.time)))
            self.published[ev.kind] += 1
            if ev.kind in ('onset', 'end'):
                self.moving = ev.kind == 'onset'

    def _to_stamp(self, t: float) -> Time:
        sec, nanosec = ns_to_parts(self._t_ref_ns + round(t * 1e9))
        return Time(sec=sec, nanosec=nanosec)

    def _log_drop(self, text: str) -> None:
        now = time.monotonic()
        if now < self._next_drop_log:  # a logger call costs ~0.4 ms even when throttled
            return
        self._next_drop_log = now + self._throttle
        drops = {k: v for k, v in self.drop_counts.items() if v}
        self.get_logger().warning(f'{text}; drops so far: {drops}',
                                  throttle_duration_sec=self._throttle)


def main(args=None):
    rclpy.init(args=args)
    node = None
    try:
        node = ObserverNode()
        spin_until_shutdown(node)
    except KeyboardInterrupt:
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
