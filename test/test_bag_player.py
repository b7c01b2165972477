"""bag_player publishes a real rosbag2 bag over real DDS (in-process, private domain)."""

from geometry_msgs.msg import PoseStamped
import numpy as np
import pytest
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from mixture_ip_ros.core.stamps import stamp_to_ns
from mixture_ip_ros.io.bags import BagError, DEFAULT_START_TIME_NS, write_demonstration_bag
from mixture_ip_ros.nodes.bag_player import BagPlayer, main, parse_remaps

DEEP_BEST_EFFORT = QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT)
DEEP_RELIABLE = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
SIM_START_NS = 5 * 10**9


@pytest.fixture
def bag(tmp_path):
    t = 0.01 * np.arange(60)
    xyz = np.column_stack([t, 2 * t, 3 * t])
    xyz[20:30] = np.nan  # occlusion: no wrist messages there
    q = np.column_stack([t + j for j in range(7)])
    return write_demonstration_bag(tmp_path / 'demo', t, xyz, t, q, label='plate'), t, xyz, q


class Playback:
    """A paused player in the harness and recorders of what it publishes."""

    def __init__(self, harness, bag_path, wrist_topic='/mocap/wrist', **params):
        overrides = [Parameter('bag', value=str(bag_path)), Parameter('start_paused', value=True)]
        overrides += [Parameter(k, value=v) for k, v in params.items()]
        self.h = harness
        self.wrist = harness.subscribe(PoseStamped, wrist_topic, DEEP_BEST_EFFORT)
        self.joints = harness.subscribe(JointState, '/joint_states', DEEP_RELIABLE)
        self.clock = harness.subscribe(Clock, '/clock', DEEP_BEST_EFFORT)
        self.player = harness.add(BagPlayer(context=harness.context,
                                            parameter_overrides=overrides))
        harness.spin_until(lambda: all(c > 0 for c in
                                       self.player.matched_subscriptions().values()),
                           what='discovery')

    def received(self, n_wrist, n_joints):
        self.h.spin_until(lambda: len(self.wrist) == n_wrist and len(self.joints) == n_joints,
                          what='every message')


def test_plays_every_message_in_order_with_original_timing(harness, bag):
    path, t, xyz, q = bag
    pb = Playback(harness, path, rate=2.0)
    player = pb.player
    player.resume()
    harness.spin_until(lambda: player.finished, what='the end of the bag')
    present = ~np.isnan(xyz).any(axis=1)
    pb.received(present.sum(), t.size)
    assert player.published == present.sum() + t.size and player.dropped == 0
    expected_w = DEFAULT_START_TIME_NS + np.round(t[present] * 1e9).astype(np.int64)
    expected_j = DEFAULT_START_TIME_NS + np.round(t * 1e9).astype(np.int64)
    # Every message, in order, unchanged (stamps untouched without rewrite_stamps).
    np.testing.assert_array_equal([stamp_to_ns(m.header.stamp) for m in pb.wrist], expected_w)
    np.testing.assert_array_equal([stamp_to_ns(m.header.stamp) for m in pb.joints], expected_j)
    np.testing.assert_array_equal([[m.pose.position.x, m.pose.position.y, m.pose.position.z]
                                   for m in pb.wrist], xyz[present])
    np.testing.assert_array_equal([m.position for m in pb.joints], q)
    # Timing, measured where the player publishes: never before a message is due (the schedule
    # is original offsets / rate on a monotonic clock).
    late = np.array(player.recent_lateness)
    assert late.size == player.published and np.all(late >= 0)


def test_remap_rewrite_stamps_and_clock(harness, bag):
    path, t, xyz, _ = bag
    pb = Playback(harness, path, wrist_topic='/replay/wrist', rate=4.0,
                  remap=['/mocap/wrist:=/replay/wrist'], rewrite_stamps=True, publish_clock=True)
    player = pb.player
    before = player.get_clock().now().nanoseconds
    player.resume()
    harness.spin_until(lambda: player.finished, what='the end of the bag')
    present = ~np.isnan(xyz).any(axis=1)
    pb.received(present.sum(), t.size)
    after = player.get_clock().now().nanoseconds
    stamps = np.array([stamp_to_ns(m.header.stamp) for m in pb.wrist + pb.joints])
    assert np.all((stamps >= before) & (stamps <= after))  # rewritten to "now"
    np.testing.assert_array_equal([m.pose.position.x for m in pb.wrist], xyz[present, 0])
    # /clock carries bag time, never going backwards, and only times of bag messages.
    clock = np.array([stamp_to_ns(c.clock) for c in pb.clock])
    assert clock.size > 0 and np.all(np.diff(clock) >= 0)
    bag_times = set(DEFAULT_START_TIME_NS + np.round(t * 1e9).astype(np.int64))
    assert set(clock) <= bag_times


def test_loops(harness, bag):
    path, t, xyz, _ = bag
    n = (~np.isnan(xyz).any(axis=1)).sum() + t.size
    pb = Playback(harness, path, rate=5.0, loop=True)
    player = pb.player
    player.resume()
    harness.spin_until(lambda: player.loops_completed >= 2, what='two loops')
    assert player.published >= 2 * n and not player.finished


def test_topic_filter(harness, bag):
    path, t, _, _ = bag
    pb = Playback(harness, path, rate=5.0, topics=['/joint_states'])
    pb.player.resume()
    harness.spin_until(lambda: pb.player.finished, what='the end of the bag')
    pb.received(0, t.size)
    assert pb.player.published_per_topic == {'/joint_states': t.size}


def test_bad_parameters_and_bad_bag(ros_context, bag, tmp_path):
    path = bag[0]
    with pytest.raises(ValueError, match="'bag'.*required"):
        BagPlayer(context=ros_context)
    with pytest.raises(ValueError, match='parameter rate: must be > 0'):
        BagPlayer(context=ros_context, parameter_overrides=[Parameter('bag', value=str(path)),
                                                            Parameter('rate', value=0.0)])
    with pytest.raises(ValueError, match='remap entry'):
        BagPlayer(context=ros_context, parameter_overrides=[Parameter('bag', value=str(path)),
                                                            Parameter('remap', value=['/a=/b'])])
    with pytest.raises(BagError, match='does not exist'):
        BagPlayer(context=ros_context,
                  parameter_overrides=[Parameter('bag', value=str(tmp_path / 'missing'))])
    assert parse_remaps(['/a:=/b', '', ' /c := /d ']) == {'/a': '/b', '/c': '/d'}


def test_main_plays_to_the_end_and_reports_bad_bags(bag, tmp_path, monkeypatch):
    from conftest import private_domain_id
    monkeypatch.setenv('ROS_DOMAIN_ID', str(private_domain_id()))
    assert main(args=['--ros-args', '-p', f'bag:={bag[0]}', '-p', 'rate:=20.0']) == 0
    assert main(args=['--ros-args', '-p', f'bag:={tmp_path / "nope"}']) == 1


def test_undecodable_message_is_dropped_not_fatal(harness, tmp_path):
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
    pb = Playback(harness, tmp_path / 'b', rate=5.0)
    pb.player.resume()
    harness.spin_until(lambda: pb.player.finished, what='the end of the bag')
    pb.received(0, 4)
    assert pb.player.dropped == 1 and pb.player.published == 4
    assert [m.position[0] for m in pb.joints] == [0.0, 1.0, 3.0, 4.0]


def test_follows_a_simulated_clock_and_holds_while_paused(harness, bag):
    """Under use_sim_time the player paces on /clock: no message goes out before the simulated
    clock reaches its recorded offset, and a pause shifts the rest of the bag by the simulated
    time it lasted (nothing goes out meanwhile). Rewritten stamps are the scheduled simulated
    times."""
    path, t, xyz, _ = bag
    pb = Playback(harness, path, rewrite_stamps=True, use_sim_time=True)
    player = pb.player
    present = ~np.isnan(xyz).any(axis=1)
    offsets = np.sort(np.concatenate([t[present], t])) * 1e9       # every message, from 0
    step = 6_000_000
    now = [SIM_START_NS]

    def advance(paused_ns=0):
        # The clock moves on only once everything due so far is out: the pace is the clock's,
        # however slowly the playback thread gets to run.
        due = int(np.sum(offsets <= now[0] - SIM_START_NS - paused_ns + 1))
        harness.spin_until(lambda: player.published >= due, what='the due messages')
        now[0] += step
        harness.set_clock(now[0])
    harness.set_clock(now[0])
    player.resume()
    while player.published < 40:       # the clock runs
        advance()
    player.pause()
    harness.spin_until(lambda: player.holding, what='playback to pause')
    pause_ns = 300_000_000
    for _ in range(pause_ns // step):  # 0.3 s of simulated time while paused
        now[0] += step
        harness.set_clock(now[0])
    player.resume()
    harness.spin_until(lambda: player.paused_total > 0, what='playback to resume')
    assert player.paused_total * 1e9 == pytest.approx(pause_ns, abs=step)
    while not player.finished:
        advance(round(player.paused_total * 1e9))
    pb.received(present.sum(), t.size)
    assert np.all(np.array(player.recent_lateness) >= 0)     # never early (simulated s)
    stamps = np.array([stamp_to_ns(m.header.stamp) for m in pb.joints])
    assert stamps[0] >= SIM_START_NS
    # Consecutive stamps keep the recorded offsets, but for one step: the pause.
    extra = np.diff(stamps) - np.diff(np.round(t * 1e9).astype(np.int64))
    shifted = np.flatnonzero(np.abs(extra) > 2)
    assert shifted.size == 1
    assert pause_ns - step <= extra[shifted[0]] <= pause_ns + step


def test_a_simulated_clock_that_jumps_back_ends_the_playback(harness, bag):
    """A simulation restarted mid-bag restarts its clock: the rest of the bag is not played
    into the new clock's time (its messages belong to the time that is gone)."""
    path, t, xyz, _ = bag
    player = Playback(harness, path, rewrite_stamps=True, use_sim_time=True).player
    now = SIM_START_NS
    harness.set_clock(now)
    player.resume()
    while player.published < 10:
        now += 6_000_000
        harness.set_clock(now)
        harness.spin_until(lambda: player._clock_seen * 1e9 >= now - 1, what='the clock')
    sent = player.published
    harness.set_clock(1_000_000)                           # the restarted simulation's clock
    harness.spin_until(lambda: player.finished, what='the playback to end')
    # its clock comes back past where the old one was: nothing more is played
    harness.set_clock(now + 10**10)
    assert player.published <= sent + 1 and player.loops_completed == 0


def test_params_file_loads(harness, bag):
    from mixture_ip_ros.core.share import config_path
    player = harness.add(BagPlayer(context=harness.context, cli_args=[
        '--ros-args', '--params-file', str(config_path('bag_player.yaml')),
        '-p', f'bag:={bag[0]}', '-p', 'start_paused:=true']))
    assert player.get_parameter('rate').value == 1.0
    assert player.get_parameter('sensor_data_topics').value == ['/mocap/wrist']
    assert player.paused


def _bag_with(path, topic, msgtype, msg):
    from rosbags.rosbag2 import Writer
    from mixture_ip_ros.io.bags import typestore
    ts = typestore()
    writer = Writer(path, version=9)
    writer.open()
    conn = writer.add_connection(topic, msgtype, typestore=ts)
    writer.write(conn, DEFAULT_START_TIME_NS, ts.serialize_cdr(msg, msgtype))
    writer.close()
    return path


def test_a_known_topic_stored_as_another_type_is_refused_whole(ros_context, tmp_path):
    from mixture_ip_ros.io.bags import typestore
    T = typestore().types
    point = T['geometry_msgs/msg/PointStamped'](
        header=T['std_msgs/msg/Header'](stamp=T['builtin_interfaces/msg/Time'](sec=1, nanosec=0),
                                        frame_id='world'),
        point=T['geometry_msgs/msg/Point'](x=0.0, y=0.0, z=0.0))
    path = _bag_with(tmp_path / 'b', '/mocap/wrist', 'geometry_msgs/msg/PointStamped', point)
    with pytest.raises(BagError, match='/mocap/wrist is stored as geometry_msgs/msg/'
                                       'PointStamped, expected geometry_msgs/msg/PoseStamped'):
        BagPlayer(context=ros_context, parameter_overrides=[Parameter('bag', value=str(path))])


def test_message_types_come_from_the_type_store_only():
    from mixture_ip_ros.nodes.bag_player import message_class
    assert message_class('sensor_msgs/msg/JointState') is JointState
    for bad in ('os/path/join', 'evil/msg/Thing', 'sensor_msgs/msg/NoSuchType', 'nonsense'):
        with pytest.raises(ValueError, match='not a ROS 2 Jazzy message type'):
            message_class(bad)


def test_waiting_for_a_clock_that_never_comes_is_warned_about(harness, bag, capfd):
    pb = Playback(harness, bag[0], use_sim_time=True, clock_warning_period=0.05)
    pb.player.resume()
    seen = []

    def warned():
        seen.append(capfd.readouterr().err)
        return 'no /clock has come' in ''.join(seen)
    harness.spin_until(warned, what='the warning')
    assert pb.player.published == 0


def test_waiting_for_a_subscriber_plays_the_bag_from_its_first_message_once_one_matches(
        harness, bag):
    """Messages published before a subscriber matches are lost to it: the player waits (and
    says so) until every played topic has one, then plays from the bag's first message."""
    path, t, xyz, _ = bag
    player = harness.add(BagPlayer(context=harness.context, parameter_overrides=[
        Parameter('bag', value=str(path)), Parameter('topics', value=['/mocap/wrist']),
        Parameter('remap', value=['/mocap/wrist:=/unheard_wrist']),
        Parameter('wait_for_subscribers', value=1), Parameter('clock_warning_period', value=0.05)]))
    harness.spin_until(lambda: player._unheard() == ['/mocap/wrist'] and player.published == 0,
                       what='the player waiting')
    wrist = harness.subscribe(PoseStamped, '/unheard_wrist', DEEP_BEST_EFFORT)
    harness.spin_until(lambda: player.finished, what='the end of the bag')
    present = ~np.isnan(xyz).any(axis=1)
    harness.spin_until(lambda: len(wrist) == present.sum(), what='every wrist message')
    assert stamp_to_ns(wrist[0].header.stamp) == DEFAULT_START_TIME_NS
