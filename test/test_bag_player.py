"""bag_player publishes a real rosbag2 bag over real DDS (in-process, private domain)."""

import threading
import time

import numpy as np
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy

from conftest import private_domain_id
from mixture_ip_ros.io.bags import BagError, DEFAULT_START_TIME_NS, write_demonstration_bag
from mixture_ip_ros.nodes.bag_player import BagPlayer, main, parse_remaps
from mixture_ip_ros.core.share import config_path


@pytest.fixture
def bag(tmp_path):
    t = 0.01 * np.arange(60)
    xyz = np.column_stack([t, 2 * t, 3 * t])
    xyz[20:30] = np.nan  # occlusion: no wrist messages there
    q = np.column_stack([t + j for j in range(7)])
    return write_demonstration_bag(tmp_path / 'demo', t, xyz, t, q, label='plate'), t, xyz, q


class Recorder(Node):
    def __init__(self, wrist_topic='/mocap/wrist', clock=False, **kwargs):
        super().__init__('recorder', **kwargs)
        deep_best_effort = QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT)
        from geometry_msgs.msg import PoseStamped
        from sensor_msgs.msg import JointState
        from rosgraph_msgs.msg import Clock
        self.wrist, self.joints, self.clock = [], [], []
        self.create_subscription(PoseStamped, wrist_topic,
                                 lambda m: self.wrist.append((time.monotonic(), m)), deep_best_effort)
        self.create_subscription(JointState, '/joint_states',
                                 lambda m: self.joints.append((time.monotonic(), m)),
                                 QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
        if clock:
            self.create_subscription(Clock, '/clock', lambda m: self.clock.append(m), deep_best_effort)


def _spin(ctx, *nodes):
    executor = SingleThreadedExecutor(context=ctx)
    for n in nodes:
        executor.add_node(n)
    thread = threading.Thread(target=executor.spin, daemon=True)
    thread.start()
    return executor, thread


def _wait(pred, timeout=10.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(0.01)
    return pred()


def _ns(stamp):
    return stamp.sec * 10**9 + stamp.nanosec


def _play(ctx, bag_path, recorder_kwargs=None, **params):
    overrides = [Parameter('bag', value=str(bag_path)), Parameter('start_paused', value=True)]
    overrides += [Parameter(k, value=v) for k, v in params.items()]
    rec = Recorder(context=ctx, **(recorder_kwargs or {}))
    player = BagPlayer(context=ctx, parameter_overrides=overrides)
    executor, thread = _spin(ctx, rec, player)
    assert _wait(lambda: all(c > 0 for c in player.matched_subscriptions().values()))
    return rec, player, executor, thread


def _stop(executor, thread, *nodes):
    executor.shutdown()
    thread.join(timeout=5)
    for n in nodes:
        n.destroy_node()


def test_plays_every_message_in_order_with_original_timing(ros_context, bag):
    path, t, xyz, q = bag
    rec, player, executor, thread = _play(ros_context, path, rate=2.0)
    try:
        player.resume()
        assert player.wait_until_finished(timeout=10)
        present = ~np.isnan(xyz).any(axis=1)
        assert _wait(lambda: len(rec.wrist) == present.sum() and len(rec.joints) == t.size, 5)
    finally:
        _stop(executor, thread, rec, player)
    assert player.published == present.sum() + t.size and player.dropped == 0
    expected_w = DEFAULT_START_TIME_NS + np.round(t[present] * 1e9).astype(np.int64)
    expected_j = DEFAULT_START_TIME_NS + np.round(t * 1e9).astype(np.int64)
    # Every message, in order, unchanged (stamps untouched without rewrite_stamps).
    np.testing.assert_array_equal([_ns(m.header.stamp) for _, m in rec.wrist], expected_w)
    np.testing.assert_array_equal([_ns(m.header.stamp) for _, m in rec.joints], expected_j)
    np.testing.assert_array_equal([[m.pose.position.x, m.pose.position.y, m.pose.position.z]
                                   for _, m in rec.wrist], xyz[present])
    np.testing.assert_array_equal([m.position for _, m in rec.joints], q)
    # Timing, measured where the player publishes: never before a message is due (the schedule
    # is original offsets / rate on a monotonic clock), and late only by scheduling noise (the
    # bound is loose: this machine's 2 cores are shared).
    late = np.array(player.recent_lateness)
    assert late.size == player.published and np.all(late >= 0)
    assert np.median(late) < 0.05
    span = (t[-1] - t[0]) / 2.0  # bag span at rate 2
    # the first message may itself be late by late[0], which shortens the measured span
    assert span - late[0] - 1e-3 <= player.last_sent - player.first_sent <= span + 0.5


def test_remap_rewrite_stamps_and_clock(ros_context, bag):
    path, t, xyz, _ = bag
    rec, player, executor, thread = _play(
        ros_context, path, recorder_kwargs={'wrist_topic': '/replay/wrist', 'clock': True},
        rate=4.0, remap=['/mocap/wrist:=/replay/wrist'], rewrite_stamps=True, publish_clock=True)
    try:
        before = player.get_clock().now().nanoseconds
        player.resume()
        assert player.wait_until_finished(timeout=10)
        present = ~np.isnan(xyz).any(axis=1)
        assert _wait(lambda: len(rec.wrist) == present.sum() and len(rec.joints) == t.size, 5)
        after = player.get_clock().now().nanoseconds
    finally:
        _stop(executor, thread, rec, player)
    stamps = np.array([_ns(m.header.stamp) for _, m in rec.wrist + rec.joints])
    assert np.all((stamps >= before) & (stamps <= after))  # rewritten to "now"
    np.testing.assert_array_equal([m.pose.position.x for _, m in rec.wrist], xyz[present, 0])
    # /clock carries bag time, never going backwards, and only times of bag messages.
    clock = np.array([_ns(c.clock) for c in rec.clock])
    assert clock.size > 0 and np.all(np.diff(clock) >= 0)
    bag_times = set(DEFAULT_START_TIME_NS + np.round(t * 1e9).astype(np.int64))
    assert set(clock) <= bag_times


def test_loop_and_pause(ros_context, bag):
    path, t, xyz, _ = bag
    n = (~np.isnan(xyz).any(axis=1)).sum() + t.size
    rec, player, executor, thread = _play(ros_context, path, rate=5.0, loop=True)
    try:
        assert player.paused and player.published == 0
        time.sleep(0.2)
        assert player.published == 0  # start_paused holds playback
        player.resume()
        assert _wait(lambda: player.loops_completed >= 2, 10)
        player.pause()
        time.sleep(0.1)
        held = player.published
        time.sleep(0.2)
        assert player.published == held and not player.finished
    finally:
        _stop(executor, thread, rec, player)
    assert held >= 2 * n
    assert player.finished  # the playback thread ended on destroy


def test_topic_filter(ros_context, bag):
    path, t, _, _ = bag
    rec, player, executor, thread = _play(ros_context, path, rate=5.0, topics=['/joint_states'])
    try:
        player.resume()
        assert player.wait_until_finished(timeout=10)
        assert _wait(lambda: len(rec.joints) == t.size, 5)
    finally:
        _stop(executor, thread, rec, player)
    assert rec.wrist == [] and player.published_per_topic == {'/joint_states': t.size}


def test_bad_parameters_and_bad_bag(ros_context, bag, tmp_path):
    path = bag[0]
    with pytest.raises(ValueError, match="'bag'.*required"):
        BagPlayer(context=ros_context)
    with pytest.raises(ValueError, match="'rate' must be > 0"):
        BagPlayer(context=ros_context, parameter_overrides=[Parameter('bag', value=str(path)),
                                                            Parameter('rate', value=0.0)])
    with pytest.raises(ValueError, match='remap entry'):
        BagPlayer(context=ros_context, parameter_overrides=[Parameter('bag', value=str(path)),
                                                            Parameter('remap', value=['/a=/b'])])
    with pytest.raises(BagError, match='does not exist'):
        BagPlayer(context=ros_context,
                  parameter_overrides=[Parameter('bag', value=str(tmp_path / 'missing'))])
    assert parse_remaps(['/a:=/b', '', ' /c := /d ']) == {'/a': '/b', '/c': '/d'}


def test_params_file_loads(bag):
    from rclpy.context import Context
    ctx = Context()
    rclpy.init(context=ctx, domain_id=private_domain_id(),
               args=['--ros-args', '--params-file', str(config_path('bag_player.yaml')),
                     '-p', f'bag:={bag[0]}', '-p', 'start_paused:=true'])
    try:
        player = BagPlayer(context=ctx)
        assert player.get_parameter('rate').value == 1.0
        assert player.get_parameter('sensor_data_topics').value == ['/mocap/wrist']
        assert player.paused
        player.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)


def test_main_plays_to_the_end_and_reports_bad_bags(bag, tmp_path, monkeypatch):
    monkeypatch.setenv('ROS_DOMAIN_ID', str(private_domain_id()))
    assert main(args=['--ros-args', '-p', f'bag:={bag[0]}', '-p', 'rate:=20.0']) == 0
    assert main(args=['--ros-args', '-p', f'bag:={tmp_path / "nope"}']) == 1


def test_undecodable_message_is_dropped_not_fatal(ros_context, tmp_path):
    from rosbags.rosbag2 import Writer
    from mixture_ip_ros.io.bags import typestore
    ts = typestore()
    T = ts.types
    writer = Writer(tmp_path / 'b', version=9)
    writer.open()
    conn = writer.add_connection('/joint_states', 'sensor_msgs/msg/JointState', typestore=ts)
    for k in range(5):
        ns = DEFAULT_START_TIME_NS + k * 10**7
        msg = T['sensor_msgs/msg/JointState'](
            header=T['std_msgs/msg/Header'](stamp=T['builtin_interfaces/msg/Time'](
                sec=ns // 10**9, nanosec=ns % 10**9), frame_id=''),
            name=['a'], position=np.array([float(k)]), velocity=np.zeros(0), effort=np.zeros(0))
        data = b'\x00\x01\x00\x00\x07' if k == 2 else ts.serialize_cdr(msg, 'sensor_msgs/msg/JointState')
        writer.write(conn, ns, data)
    writer.close()
    rec, player, executor, thread = _play(ros_context, tmp_path / 'b', rate=5.0)
    try:
        player.resume()
        assert player.wait_until_finished(timeout=10)
        assert _wait(lambda: len(rec.joints) == 4, 5)
    finally:
        _stop(executor, thread, rec, player)
    assert player.dropped == 1 and player.published == 4
    assert [m.position[0] for _, m in rec.joints] == [0.0, 1.0, 3.0, 4.0]


def test_follows_a_simulated_clock(ros_context, bag):
    """Under use_sim_time the player paces on /clock: at 3x real time, and not at all while the
    clock stands still; rewritten stamps are the scheduled simulated times."""
    from rosgraph_msgs.msg import Clock
    path, t, xyz, _ = bag
    clock_node = Node('fake_sim', context=ros_context)
    clock_pub = clock_node.create_publisher(Clock, '/clock', 10)
    state = {'ns': 5 * 10**9, 'running': True, 'stop': False}

    def tick():
        while not state['stop']:
            if state['running']:
                state['ns'] += 6 * 10**6  # 6 ms of simulated time per 2 ms: 3x real time
            clock_pub.publish(Clock(clock=_ns_to_time(state['ns'])))
            time.sleep(0.002)

    ticker = threading.Thread(target=tick, daemon=True)
    ticker.start()
    rec, player, executor, thread = _play(ros_context, path, rate=1.0, rewrite_stamps=True,
                                          use_sim_time=True)
    executor.add_node(clock_node)
    try:
        player.resume()
        assert _wait(lambda: player.published > 20, 10)
        state['running'] = False          # the simulation stops: so does playback
        time.sleep(0.1)
        held = player.published
        time.sleep(0.3)
        assert player.published == held
        state['running'] = True
        assert player.wait_until_finished(timeout=10)
        present = ~np.isnan(xyz).any(axis=1)
        assert _wait(lambda: len(rec.wrist) == present.sum() and len(rec.joints) == t.size, 5)
    finally:
        state['stop'] = True
        ticker.join(timeout=2)
        _stop(executor, thread, rec, player, clock_node)
    assert np.all(np.array(player.recent_lateness) >= 0)  # in simulated seconds
    stamps = np.array([_ns(m.header.stamp) for _, m in rec.joints])
    assert stamps[0] >= 5 * 10**9
    # Stamps are the scheduled simulated times: first stamp + recorded offsets, exactly (a clock
    # standing still adds no simulated time, so the stop leaves no trace in the stamps).
    offsets = np.round((t - t[0]) * 1e9).astype(np.int64)
    np.testing.assert_allclose(stamps - stamps[0], offsets, atol=2)


def _ns_to_time(ns):
    from builtin_interfaces.msg import Time
    return Time(sec=ns // 10**9, nanosec=ns % 10**9)
