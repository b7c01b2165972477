"""bag_player: replay a rosbag2 bag like `ros2 bag play` (which is not available from PyPI).

Publishes every message of the bag with its original timing (scaled by ``rate``), optionally looping,
remapping topics (``remap: ['/from:=/to']``), publishing /clock with the bag time and rewriting
header stamps to the current time. The wrist (``sensor_data_topics``) goes out with sensor-data
QoS like a mocap driver; every other topic is reliable.

Messages are stored as CDR, which is what DDS carries, so they are published as serialized bytes
(after a check at load that each one deserializes into the installed rclpy message class); only
with ``rewrite_stamps`` are they deserialized to set ``header.stamp`` to the time the message is
scheduled for on the node's clock (the current time, without the player's scheduling jitter).

Looping: each pass starts one mean message period after the last message of the previous one.
With ``rewrite_stamps`` the stamps go on with the clock and the wrist jumps back to where the
bag starts; without, the stamps (and /clock, with ``publish_clock``) jump back to the bag's
start. Either is a new stream to the observer (estimation.observer), so each pass is a new
interaction.

Start: after ``start_delay`` s, counted once every played topic has ``wait_for_subscribers``
matched subscriptions (and, under use_sim_time, the first /clock has come).

Pacing: playback runs in its own thread that sleeps on the monotonic clock until each message is
due (no busy wait). With ``use_sim_time`` the player follows the node's simulated clock instead
(checked every 2 ms): it starts at the first /clock it receives and publishes each message when
the simulated time reaches its recorded offset / rate, so playback stays in step with a
simulator running slower or faster than real time, and stops while the simulation does. A
simulated clock that jumps back (a simulation restarted) ends the playback: the rest of the bag
belongs to the time that is gone.
"""

from collections import deque
from dataclasses import dataclass
import importlib
import threading
import time

from builtin_interfaces.msg import Time
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from rosgraph_msgs.msg import Clock

from mixture_ip_ros.core.stamps import ns_to_parts
from mixture_ip_ros.io.bags import JOINT_TOPIC, JOINT_TYPE, WRIST_TOPIC, WRIST_TYPE, BagError, \
    read_messages, typestore
from mixture_ip_ros.nodes import qos
from mixture_ip_ros.nodes.managed import run_node
from mixture_ip_ros.nodes.params import declare, param, positive


def message_class(msgtype: str):
    """The rclpy class of 'pkg/msg/Type'. Only types of ROS 2 Jazzy's own message packages (the
    rosbags type store) are resolved: a type string read from a bag never names a module to
    import. ValueError otherwise."""
    if msgtype not in typestore().types:
        raise ValueError(f'message type {msgtype!r} is not a ROS 2 Jazzy message type')
    pkg, kind, name = msgtype.split('/')
    try:
        return getattr(importlib.import_module(f'{pkg}.{kind}'), name)
    except (ImportError, AttributeError) as exc:
        raise ValueError(f'message type {msgtype!r} is not installed here') from exc


def parse_remaps(entries, what: str = 'remap') -> dict:
    """['/from:=/to', ...] -> {'/from': '/to'}; empty entries are ignored."""
    out = {}
    for entry in entries:
        if not entry:
            continue
        src, sep, dst = entry.partition(':=')
        if not sep or not src.strip() or not dst.strip():
            raise ValueError(f"{what} entry {entry!r} is not of the form 'a:=b'")
        out[src.strip()] = dst.strip()
    return out


SIM_POLL = 0.002  # s between looks at a simulated clock
# A simulated clock that goes back further than this (s) was restarted: the bag's time on it is
# gone, and the rest of the pass is not played into the new clock.
CLOCK_JUMP_BACK = 1.0


def _to_time(ns: int) -> Time:
    sec, nanosec = ns_to_parts(ns)
    return Time(sec=sec, nanosec=nanosec)


@dataclass
class BagPlayerParameters:
    bag: str = param('', 'rosbag2 directory to play (required)')
    rate: float = param(1.0, 'playback speed factor (2.0 = twice as fast)', low=0.0,
                        high=1000.0, check=positive, rule='> 0')
    loop: bool = param(False, 'start over when the bag ends')
    remap: list = param([], "bag topic := published topic, e.g. ['/mocap/wrist:=/replay']")
    topics: list = param([], 'play only these topics (default: all)')
    sensor_data_topics: list = param(['/mocap/wrist'], 'published with sensor-data QoS '
                                                       '(best effort)')
    publish_clock: bool = param(False, "publish rosgraph_msgs/Clock on /clock with each "
                                       "message's bag time")
    rewrite_stamps: bool = param(False, 'set header.stamp to the time the message is '
                                        'scheduled for')
    start_paused: bool = param(False, 'wait for resume() before the first message')
    start_delay: float = param(0.0, 's to wait before the first message (lets subscribers '
                                    'match)', low=0.0, high=3600.0)
    wait_for_subscribers: int = param(0, 'before start_delay, wait until every played topic '
                                         'has this many matched subscriptions (0: no wait)',
                                      low=0, high=1000)
    queue_depth: int = param(10, 'history depth of the reliable publishers', low=1,
                             high=1_000_000)
    clock_warning_period: float = param(5.0, 's of waiting for a first /clock (use_sim_time) '
                                             'or for subscribers between warnings',
                                        low=0.001, high=3600.0)
    topic_types: list = param([f'{WRIST_TOPIC}:={WRIST_TYPE}', f'{JOINT_TOPIC}:={JOINT_TYPE}'],
                              "topic:=pkg/msg/Type the bag's topics must have: a bag that "
                              'stores one of them as another type is refused')


class BagPlayer(Node):
    """Publishes a bag's messages with their original timing; see the module docstring."""

    NODE_NAME = 'bag_player'

    def __init__(self, **kwargs):
        super().__init__(self.NODE_NAME, **kwargs)
        p = self.params = declare(self, BagPlayerParameters)
        bag = p.bag
        self._rate = p.rate
        self._loop = p.loop
        remaps = parse_remaps(p.remap)
        topics = p.topics
        sensor_topics = set(p.sensor_data_topics)
        self._publish_clock = p.publish_clock
        self._rewrite = p.rewrite_stamps
        self._start_delay = p.start_delay
        depth = p.queue_depth
        if not bag:
            raise ValueError("parameter 'bag' (path of the rosbag2 directory) is required")

        expected = parse_remaps(p.topic_types, 'topic_types')
        messages = read_messages(bag, topics=topics or None)
        types = {}
        for m in messages:
            types.setdefault(m.topic, m.msgtype)
        for topic, msgtype in types.items():
            if topic in expected and msgtype != expected[topic]:
                raise BagError(bag, f'topic {topic} is stored as {msgtype}, expected '
                                    f'{expected[topic]} (parameter topic_types)')
        classes = {topic: message_class(msgtype) for topic, msgtype in types.items()}
        # A message that does not deserialize would break every subscriber: drop it here, counted.
        self.dropped = 0
        self._messages = []
        for m in messages:
            try:
                deserialize_message(m.data, classes[m.topic])
            except Exception as exc:  # the C deserializer raises several types on bad CDR
                self.dropped += 1
                self.get_logger().warning(f'dropping undecodable {m.msgtype} on {m.topic} at '
                                          f'{m.log_time_ns} ns: {exc}')
                continue
            self._messages.append(m)
        if not self._messages:
            raise BagError(bag, 'no playable messages')
        self._has_header = {topic: hasattr(cls(), 'header') for topic, cls in classes.items()}
        self._classes = classes
        self._topic_pubs = {}
        for topic, cls in classes.items():
            profile = qos.sensor_data() if topic in sensor_topics else qos.reliable(depth)
            self._topic_pubs[topic] = self.create_publisher(cls, remaps.get(topic, topic),
                                                            profile)
        self._clock_pub = None
        if self._publish_clock:
            self._clock_pub = self.create_publisher(Clock, '/clock', qos.clock())

        self.published = 0
        self.published_per_topic = {topic: 0 for topic in classes}
        self.loops_completed = 0
        self.max_lateness = 0.0  # seconds a message went out after it was due
        self.paused_total = 0.0  # seconds of the pacing clock spent paused during playback
        self._clock_seen = 0.0   # the latest pacing-clock reading (s)
        self.holding = False     # the playback thread is waiting in a pause
        self.recent_lateness = deque(maxlen=10000)  # per message, seconds (negative = early)
        self.first_sent = self.last_sent = None     # monotonic times of first / last publish
        self._sim_time = bool(self.get_parameter('use_sim_time').value)
        self._cond = threading.Condition()
        self._paused = p.start_paused
        self._stop = False
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._play, name='bag_player', daemon=True)
        t0 = self._messages[0].log_time_ns
        span = (self._messages[-1].log_time_ns - t0) / 1e9
        self.get_logger().info(
            f'playing {bag}: {len(self._messages)} messages on {sorted(classes)} over {span:.2f} s '
            f'at rate {self._rate}' + (' (looping)' if self._loop else '')
            + (f', remapped {remaps}' if remaps else '')
            + (' [paused]' if self._paused else ''))
        self._thread.start()

    # ------------------------------------------------------------------ control (thread-safe)
    def pause(self):
        with self._cond:
            self._paused = True
            self._cond.notify_all()

    def resume(self):
        with self._cond:
            self._paused = False
            self._cond.notify_all()

    @property
    def paused(self) -> bool:
        return self._paused

    @property
    def finished(self) -> bool:
        """True once every message was published (never while looping, unless stopped)."""
        return self._done.is_set()

    def wait_until_finished(self, timeout=None) -> bool:
        return self._done.wait(timeout)

    def matched_subscriptions(self) -> dict:
        """{bag topic: number of matched subscriptions}."""
        return {topic: pub.get_subscription_count() for topic, pub in self._topic_pubs.items()}

    def destroy_node(self):
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)
        return super().destroy_node()

    # ------------------------------------------------------------------ playback thread
    def _now(self) -> float:
        """Seconds on the pacing clock: the node's (simulated) ROS clock under use_sim_time,
        else the monotonic clock."""
        if self._sim_time:
            return self.get_clock().now().nanoseconds / 1e9
        return time.monotonic()

    def _wait_until(self, due: float, shift: list) -> bool:
        """Sleep until pacing-clock time ``due + shift[0]``; time spent paused extends shift[0].

        Returns False if asked to stop. Simulated time cannot be slept on directly (it may run
        faster or slower than real time, or stop), so it is checked every SIM_POLL seconds.
        """
        with self._cond:
            while True:
                if self._stop:
                    return False
                if self._paused:
                    began = self._now()
                    self.holding = True
                    while self._paused and not self._stop:
                        self._cond.wait()
                    self.holding = False
                    paused = self._now() - began
                    shift[0] += paused
                    self.paused_total += paused
                    continue
                now = self._now()
                if self._sim_time and now < self._clock_seen - CLOCK_JUMP_BACK:
                    self.get_logger().warning(
                        f'the simulated clock jumped back from {self._clock_seen:.3f} s to '
                        f'{now:.3f} s (a restarted simulation): playback stopped')
                    return False
                self._clock_seen = max(self._clock_seen, now)
                remaining = due + shift[0] - now
                if remaining <= 0:
                    return True
                self._cond.wait(min(remaining, SIM_POLL) if self._sim_time else remaining)

    def _unheard(self) -> list:
        """The played topics with fewer than wait_for_subscribers matched subscriptions: a
        best-effort wrist published before its observer matched would be lost, and with it the
        rest before the first movement (separate processes take seconds to discover each
        other on a loaded machine)."""
        n = self.params.wait_for_subscribers
        return [t for t, c in self.matched_subscriptions().items() if c < n]

    def _wait_to_start(self) -> bool:
        """Wait while paused, for wait_for_subscribers and, under use_sim_time, until /clock has
        been received (the clock reads 0 before); a warning every clock_warning_period s.
        Returns False if asked to stop."""
        warn_at = time.monotonic() + self.params.clock_warning_period
        with self._cond:
            while True:
                no_clock = self._sim_time and self.get_clock().now().nanoseconds == 0
                unheard = self._unheard()
                if not (self._paused or no_clock or unheard):
                    break
                if self._stop:
                    return False
                self._cond.wait(SIM_POLL if no_clock or unheard else None)
                if self._paused or time.monotonic() < warn_at:
                    continue
                warn_at = time.monotonic() + self.params.clock_warning_period
                if no_clock:
                    self.get_logger().warning(
                        'use_sim_time is true but no /clock has come: waiting for the '
                        'simulation (is sim_node running, on this domain?)')
                if unheard:
                    self.get_logger().warning(
                        f'waiting for {self.params.wait_for_subscribers} subscriber(s) on '
                        f'{unheard} (parameter wait_for_subscribers)')
        return not self._stop

    def _stamp_offset_ns(self) -> int:
        """Pacing-clock seconds -> node-clock nanoseconds, for stamps at the scheduled time."""
        if self._sim_time:
            return 0
        return self.get_clock().now().nanoseconds - int(round(time.monotonic() * 1e9))

    def _play(self):
        try:
            if not self._wait_to_start():
                return
            t0 = self._messages[0].log_time_ns
            shift = [0.0]
            start = self._now() + self._start_delay
            stamp_offset = self._stamp_offset_ns()
            while True:
                for m in self._messages:
                    due = start + (m.log_time_ns - t0) / 1e9 / self._rate
                    if not self._wait_until(due, shift):
                        return
                    sent = self._now()
                    self._publish(m, stamp_offset + int(round((due + shift[0]) * 1e9)))
                    if self.first_sent is None:
                        self.first_sent = sent
                    self.last_sent = sent
                    late = sent - (due + shift[0])
                    self.recent_lateness.append(late)
                    self.max_lateness = max(self.max_lateness, late)
                self.loops_completed += 1
                if not self._loop:
                    self.get_logger().info(f'playback finished: {self.published} messages')
                    return
                # Next loop starts one mean message period after the last message.
                period = (self._messages[-1].log_time_ns - t0) / 1e9 / max(len(self._messages) - 1, 1)
                start = due + shift[0] + period / self._rate
                shift = [0.0]
        except Exception as exc:  # e.g. the context was shut down under us
            if not self._stop:
                self.get_logger().error(f'playback stopped: {type(exc).__name__}: {exc}')
        finally:
            self._done.set()

    def _publish(self, m, stamp_ns: int):
        if self._clock_pub is not None:
            self._clock_pub.publish(Clock(clock=_to_time(m.log_time_ns)))
        pub = self._topic_pubs[m.topic]
        if self._rewrite and self._has_header[m.topic]:
            msg = deserialize_message(m.data, self._classes[m.topic])
            msg.header.stamp = _to_time(stamp_ns)
            pub.publish(msg)
        else:
            pub.publish(m.data)
        self.published += 1
        self.published_per_topic[m.topic] += 1


def main(args=None):
    # Exits when the bag has been played (like `ros2 bag play`); spinning serves parameters.
    return run_node(BagPlayer, args, done=lambda node: node.finished)


if __name__ == '__main__':
    raise SystemExit(main())
