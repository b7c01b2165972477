"""observer_node: cleans the mocap wrist stream and marks the interaction (onset, end, gaps). A
managed node; the logic is estimation.observer's.

Subscribes  wrist_topic        geometry_msgs/PoseStamped (sensor-data QoS)
Publishes   observation_topic  geometry_msgs/PointStamped in base_frame with the original
                               stamps: every accepted pose, as it comes
            event_topic        std_msgs/Header, frame_id 'onset' | 'end' | 'gap', stamp = when
                               (a gap's stamp is the last sample before the silence)
            /diagnostics       diagnostic_msgs/DiagnosticArray every diagnostics_period s:
                               poses accepted and dropped by reason, stream restarts
Both outputs are reliable with a deep queue: the estimator must not lose observations. A pose's
own observation goes out before the events it settles. Poses that fail a check (malformed, on
another clock, not a person's wrist: estimation.observer) are dropped and counted; a whole stream
on another clock is warned about. A new stream (a replay looping or restarted: estimation.observer
says when) ends the interaction in progress with an 'end' sent before anything of the new
stream, whose onset then starts the next interaction.
"""

from dataclasses import dataclass
import inspect
import time

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped, PoseStamped
from std_msgs.msg import Header

from mixture_ip_ros.core.frames import QUATERNION_TOLERANCE, FrameTransform
from mixture_ip_ros.core.segmentation import MotionSegmenter
from mixture_ip_ros.core.stamps import ns_to_parts, stamp_to_ns
from mixture_ip_ros.estimation.observer import WristObserver
from mixture_ip_ros.estimation.pose_check import HumanLimits
from mixture_ip_ros.nodes import qos
from mixture_ip_ros.nodes.diagnostics import OK, WARN, PublishesDiagnostics, diagnostic_array
from mixture_ip_ros.nodes.managed import ManagedNode, run_node
from mixture_ip_ros.nodes.params import (autostart_param, event_topic_param, finite_list,
                                         observation_topic_param, param, positive)
from mixture_ip_ros.robot.description import (BASE_FRAME, DEFAULT_ROBOT, load_description,
                                              shipped_robots)

# One source for the segmentation defaults: offline training (segment_motion) uses the same, so
# time zero agrees online and offline.
SEGMENTER_DEFAULTS = {name: p.default
                      for name, p in inspect.signature(MotionSegmenter).parameters.items()}


def _unit_quaternion(q):
    why = finite_list(4)(q)
    if why:
        return why
    norm = sum(v * v for v in q) ** 0.5
    return None if abs(norm - 1.0) <= QUATERNION_TOLERANCE else f'is not unit length ({norm:g})'


def _segmenter(name, description, **kw):
    return param(SEGMENTER_DEFAULTS[name], description, **kw)


@dataclass
class ObserverParameters:
    autostart: bool = autostart_param()
    wrist_topic: str = param('/mocap/wrist', 'geometry_msgs/PoseStamped, sensor-data QoS')
    observation_topic: str = observation_topic_param()
    event_topic: str = event_topic_param()
    expected_frame: str = param('world', "poses in another frame are dropped ('' = any)")
    robot: str = param(DEFAULT_ROBOT, 'the robot: a shipped name (' + ', '.join(shipped_robots())
                       + ') or a description file. Its base frame and the inverse of its '
                       'mount are the defaults of base_frame and mocap_to_base_*')
    base_frame: str = param(BASE_FRAME, 'frame of the published points', from_robot=True)
    mocap_to_base_xyz: list = param([0.0, 0.0, 0.0], 'm; mocap frame origin in the base frame '
                                                     '(p_base = R p_mocap + t)',
                                    check=finite_list(3), rule='3 finite numbers',
                                    from_robot=True)
    mocap_to_base_xyzw: list = param([0.0, 0.0, 0.0, 1.0], 'mocap frame orientation in the base '
                                                           'frame, quaternion x, y, z, w',
                                     check=_unit_quaternion, rule='a unit quaternion',
                                     from_robot=True)
    quaternion_tolerance: float = param(0.01, '| |q| - 1 | above this drops the pose',
                                        low=0.0, high=1.0)
    max_clock_offset: float = param(1.0, 's; poses stamped further than this from the node '
                                         "clock are dropped (another clock); 0 = no check",
                                    low=0.0, high=1e9)
    max_hand_speed: float = param(HumanLimits.max_speed, 'm/s a wrist cannot exceed (faster '
                                                         'implied motion: dropped)',
                                  low=0.0, high=1000.0, check=positive, rule='> 0')
    max_hand_acceleration: float = param(HumanLimits.max_acceleration, 'm/s^2 a wrist cannot '
                                                                       'exceed', low=0.0,
                                         high=1e6, check=positive, rule='> 0')
    position_noise: float = param(HumanLimits.noise, "m, the sensor's position noise per axis "
                                                     '(allowed for in the speed and '
                                                     'acceleration checks)', low=0.0,
                                  high=1.0)
    workspace_min: list = param(list(HumanLimits.workspace_min), 'm; the wrist is in this box '
                                                                 'of the base frame ...',
                                check=finite_list(3), rule='3 finite numbers')
    workspace_max: list = param(list(HumanLimits.workspace_max), '... or dropped',
                                check=finite_list(3), rule='3 finite numbers above the minima')
    onset_speed: float = _segmenter('onset_speed', 'm/s the wrist must exceed ...',
                                    low=0.0, high=100.0, check=positive, rule='> 0')
    onset_hold: float = _segmenter('onset_hold', '... for this long (s) to confirm an onset',
                                   low=0.0, high=10.0)
    end_speed: float = _segmenter('end_speed', 'm/s the wrist must stay below ...', low=0.0,
                                  high=100.0, check=positive, rule='> 0, < onset_speed')
    end_hold: float = _segmenter('end_hold', '... for this long (s) to confirm the end',
                                 low=0.0, high=10.0, check=positive, rule='> 0')
    speed_window: float = _segmenter('speed_window', 's, least-squares velocity window '
                                                     '(longer = less noise, more lag)',
                                     low=0.0, high=10.0, check=positive, rule='> 0')
    min_window_samples: int = _segmenter('min_window_samples', 'fewer samples in the window: '
                                                               'no speed estimate', low=3,
                                         high=100_000)
    gap_timeout: float = _segmenter('gap_timeout', "s without samples = a gap ('gap' event, the "
                                                   'velocity window restarts)', low=0.0,
                                    high=60.0, check=positive, rule='> 0')
    max_gap: float = _segmenter('max_gap', "s without samples during an interaction = tracking "
                                           "lost ('end')", low=0.0, high=600.0, check=positive,
                                rule='>= gap_timeout')
    max_backdate: float = _segmenter('max_backdate', 's, the latest an onset can be dated '
                                                     'before its detection', low=0.0,
                                     high=60.0, check=positive, rule='> 0')
    rest_window: float = _segmenter('rest_window', 's of rest speeds whose level and spread '
                                                   'raise the thresholds above their floors',
                                    low=0.0, high=600.0, check=positive, rule='> 0')
    onset_noise_factor: float = _segmenter('onset_noise_factor', 'onset threshold: max('
                                                                 'onset_speed, rest level + '
                                                                 'this many spreads)',
                                           low=0.0, high=1000.0, check=positive, rule='> 0')
    end_noise_factor: float = _segmenter('end_noise_factor', 'end threshold: max(end_speed, '
                                                             'rest level + this many spreads)',
                                         low=0.0, high=1000.0, check=positive, rule='> 0')
    rest_min: float = _segmenter('rest_min', 's of measured rest before an onset can be '
                                             'confirmed (0: none)', low=0.0, high=600.0,
                                 rule='<= rest_window')
    input_queue_depth: int = param(100, 'mocap subscription depth (best effort)', low=1,
                                   high=1_000_000)
    output_queue_depth: int = param(1000, 'reliable outputs: 2 s of 500 Hz mocap', low=1,
                                    high=1_000_000)
    log_throttle_sec: float = param(2.0, 'at most one drop warning per this many seconds',
                                    low=0.0, high=3600.0)
    restart_after_backwards: int = param(50, 'consecutive older stamps = the stream restarted '
                                             '(0 = never)', low=0, high=1_000_000)
    new_stream_jump_back: float = param(0.1, 's; stamps jumping back by more at once = a new '
                                             'stream (a replay restarted)', low=0.0, high=1e9,
                                        check=positive, rule='> 0')
    new_stream_samples: int = param(3, 'at rest, this many poses in a row out of reach of '
                                       'the last one but a hand\'s path among themselves = '
                                       'a new stream (a replay looping; 0 = never)', low=0,
                                    high=1000)
    diagnostics_period: float = param(1.0, 's between /diagnostics messages', low=0.001,
                                      high=3600.0)


class ObserverNode(PublishesDiagnostics, ManagedNode):

    NODE_NAME = 'observer_node'
    SCHEMA = ObserverParameters

    def __init__(self, **kwargs):
        super().__init__(self.NODE_NAME, **kwargs)
        self.observer = None
        self._sub = self._timer = None
        self._next_drop_log = 0.0

    @staticmethod
    def robot_defaults(robot: str) -> dict:
        description = load_description(robot)
        to_base = description.world_to_base()
        return {'base_frame': description.base_frame,
                'mocap_to_base_xyz': to_base.translation.tolist(),
                'mocap_to_base_xyzw': [float(v) for v in to_base.quaternion]}

    # -- lifecycle ----------------------------------------------------------------------
    def configure(self) -> None:
        p = self.params
        segmenter = MotionSegmenter(**{name: getattr(p, name) for name in SEGMENTER_DEFAULTS})
        limits = HumanLimits(max_speed=p.max_hand_speed,
                             max_acceleration=p.max_hand_acceleration, noise=p.position_noise,
                             workspace_min=tuple(p.workspace_min),
                             workspace_max=tuple(p.workspace_max))
        self.observer = WristObserver(
            segmenter, FrameTransform(p.mocap_to_base_xyz, p.mocap_to_base_xyzw),
            expected_frame=p.expected_frame, quaternion_tolerance=p.quaternion_tolerance,
            restart_after_backwards=p.restart_after_backwards,
            max_clock_offset=p.max_clock_offset, limits=limits,
            new_stream_jump_back=p.new_stream_jump_back,
            new_stream_samples=p.new_stream_samples)
        out = qos.reliable(p.output_queue_depth)
        publisher = self.create_lifecycle_publisher
        self.observation_pub = publisher(PointStamped, p.observation_topic, out)
        self._point = PointStamped()
        self._point.header.frame_id = p.base_frame
        self.event_pub = publisher(Header, p.event_topic, out)
        self.diagnostics_pub = publisher(DiagnosticArray, '/diagnostics', out)
        self._diag_seen = 0
        self.get_logger().info(
            f"observing {p.wrist_topic} (frame {p.expected_frame or 'any'}) -> "
            f'{p.observation_topic} in {p.base_frame}, events on {p.event_topic}')

    def activate(self) -> None:
        p = self.params
        self._sub = self.create_subscription(PoseStamped, p.wrist_topic, self.on_pose,
                                             qos.sensor_data(p.input_queue_depth))
        self._timers = [self.create_timer(max(p.gap_timeout / 4.0, 0.005), self.on_timer),
                        self.create_timer(p.diagnostics_period, self.publish_diagnostics)]

    def deactivate(self) -> None:
        if self._sub is not None:
            self.destroy_subscription(self._sub)
            for timer in self._timers:
                self.destroy_timer(timer)
        self._sub, self._timers = None, []

    def cleanup(self) -> None:
        for name in ('observation_pub', 'event_pub', 'diagnostics_pub'):
            pub = getattr(self, name, None)
            if pub is not None:
                self.destroy_lifecycle_publisher(pub)
            setattr(self, name, None)
        self.observer = None

    # -- queries (counts since configure) -------------------------------------------------
    @property
    def accepted(self) -> int:
        return self.observer.counts.accepted

    @property
    def drop_counts(self) -> dict:
        return self.observer.counts.dropped

    @property
    def published(self) -> dict:
        return self.observer.counts.published

    @property
    def moving(self) -> bool:
        return self.observer.moving

    # -- callbacks: never raise ---------------------------------------------------------
    def on_pose(self, msg: PoseStamped) -> None:
        try:
            stamp = msg.header.stamp
            p, q = msg.pose.position, msg.pose.orientation
            out = self.observer.on_pose(stamp_to_ns(stamp), msg.header.frame_id,
                                        (p.x, p.y, p.z), (q.x, q.y, q.z, q.w),
                                        self.get_clock().now().nanoseconds)
        except Exception as exc:  # a bad message must not kill the node
            self.observer.drop('exception')
            self._log_drop(f'wrist pose dropped, callback failed: {exc!r}')
            return
        if out.warning is not None:
            self.get_logger().warning(out.warning)
        if out.rejected is not None:
            self._log_drop(f'wrist pose dropped ({out.rejected}, frame '
                           f'{msg.header.frame_id!r}, stamp {stamp.sec}.{stamp.nanosec:09d})')
            return
        if out.held:
            return
        if out.restarted:
            # A replay looping or restarted: expected, and what follows is a stream as any.
            self.get_logger().info(f'a new wrist stream: {out.restarted}')
        # The old stream's end before anything of the new one, whose poses held back to
        # recognise it go out first, with their own stamps.
        self._publish_events(out.ended)
        for stamp_ns, xyz in out.released:
            sec, nanosec = ns_to_parts(stamp_ns)
            self._publish_point(Time(sec=sec, nanosec=nanosec), xyz)
        self._publish_point(stamp, out.point)
        self._publish_events(out.events)

    def _publish_point(self, stamp, xyz) -> None:
        point = self._point          # one message, filled per pose (publish serializes it)
        point.header.stamp = stamp
        point.point.x, point.point.y, point.point.z = xyz
        self.observation_pub.publish(point)

    def on_timer(self) -> None:
        try:
            self._publish_events(self.observer.on_timer(self.get_clock().now().nanoseconds))
        except Exception as exc:
            self.get_logger().error(f'gap check failed: {exc!r}',
                                    throttle_duration_sec=self.params.log_throttle_sec)

    def diagnostics_msg(self) -> DiagnosticArray:
        counts = self.observer.counts
        dropped = sum(counts.dropped.values())
        new = dropped - self._diag_seen
        self._diag_seen = dropped
        values = {'accepted': counts.accepted, 'moving': self.observer.moving,
                  'missing_estimated': counts.missing,
                  'sample_period_s': self.observer.period,
                  **{f'dropped_{k}': v for k, v in counts.dropped.items()},
                  **{f'published_{k}': v for k, v in counts.published.items()},
                  'stream_restarts': counts.stream_restarts,
                  'clock_offset_s': self.observer.clock_offset}
        message = (f'{new} poses dropped since the last report' if new else
                   'moving' if self.observer.moving else 'at rest')
        return diagnostic_array(self.get_clock().now().to_msg(), 'observer_node: mocap',
                                WARN if new else OK, message, values)

    def _publish_events(self, events) -> None:
        for kind, stamp_ns in events:
            sec, nanosec = ns_to_parts(stamp_ns)
            self.event_pub.publish(Header(frame_id=kind, stamp=Time(sec=sec, nanosec=nanosec)))

    def _log_drop(self, text: str) -> None:
        # A logger call is costly even when throttled: decide here first.
        now = time.monotonic()
        if now < self._next_drop_log:
            return
        self._next_drop_log = now + self.params.log_throttle_sec
        drops = {k: v for k, v in self.drop_counts.items() if v}
        self.get_logger().warning(f'{text}; drops so far: {drops}')


def main(args=None):
    return run_node(ObserverNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
