"""Observer node: pose checks and frame change (pure), then the node over real DDS."""

import math
import time

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mixture_ip_ros.core.frames import FrameTransform, quaternion_to_matrix
from mixture_ip_ros.core.stamps import ns_to_parts as ns_to_stamp
from mixture_ip_ros.estimation.pose_check import POSE_REJECT_REASONS as REJECT_REASONS, check_pose


def stamp_to_ns(sec, nanosec):
    return sec * 1_000_000_000 + nanosec
from mixture_ip_ros.core.segmentation import segment_motion

T0_NS = 1_700_000_000_123_456_789  # an epoch stamp with nanoseconds, like real mocap
XYZ = [0.5, -0.2, 0.1]
XYZW = [0.0, 0.0, math.sin(math.pi / 8), math.cos(math.pi / 8)]  # 45 deg about z


# -- pure helpers --------------------------------------------------------------------------

def test_check_pose_reasons():
    good = dict(stamp_ns=10, frame_id='world', position=(0.1, 0.2, 0.3),
                orientation_xyzw=(0.0, 0.0, 0.0, 1.0), last_stamp_ns=5,
                expected_frame='world', quaternion_tolerance=0.01)
    assert check_pose(**good) is None
    assert check_pose(**{**good, 'last_stamp_ns': None}) is None
    assert check_pose(**{**good, 'position': (0.1, math.nan, 0.3)}) == 'non_finite'
    assert check_pose(**{**good, 'orientation_xyzw': (0, 0, math.inf, 1)}) == 'non_finite'
    assert check_pose(**{**good, 'orientation_xyzw': (0, 0, 0, 0)}) == 'bad_quaternion'
    assert check_pose(**{**good, 'orientation_xyzw': (0, 0, 0, 1.02)}) == 'bad_quaternion'
    assert check_pose(**{**good, 'orientation_xyzw': (0, 0, 0, 1.005)}) is None
    assert check_pose(**{**good, 'frame_id': 'map'}) == 'wrong_frame'
    assert check_pose(**{**good, 'frame_id': 'map', 'expected_frame': ''}) is None
    assert check_pose(**{**good, 'stamp_ns': 5}) == 'duplicate_stamp'
    assert check_pose(**{**good, 'stamp_ns': 4}) == 'stamp_backwards'
    assert set(REJECT_REASONS) >= {'non_finite', 'bad_quaternion', 'wrong_frame',
                                   'duplicate_stamp', 'stamp_backwards', 'exception'}


def test_frame_transform_matches_scipy():
    rng = np.random.default_rng(0)
    for _ in range(5):
        q = Rotation.random(random_state=rng).as_quat()  # (x, y, z, w)
        t = rng.normal(size=3)
        tf = FrameTransform(t, q)
        pts = rng.normal(size=(20, 3))
        expected = Rotation.from_quat(q).apply(pts) + t
        np.testing.assert_allclose(tf.apply_array(pts), expected, atol=1e-12)
        for p, e in zip(pts, expected):
            np.testing.assert_allclose(tf.apply(*p), e, atol=1e-12)


def test_transform_parameters_are_validated():
    np.testing.assert_allclose(quaternion_to_matrix([0, 0, 0.7071, 0.7071]),
                               [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    with pytest.raises(ValueError, match='not unit length'):
        FrameTransform([0, 0, 0], [0, 0, 0, 2])
    with pytest.raises(ValueError, match='4 finite'):
        FrameTransform([0, 0, 0], [0, 0, 1])
    with pytest.raises(ValueError, match='translation'):
        FrameTransform([0, math.nan, 0], [0, 0, 0, 1])


def test_stamp_conversions_round_trip():
    assert ns_to_stamp(T0_NS) == (1_700_000_000, 123_456_789)
    assert stamp_to_ns(*ns_to_stamp(T0_NS)) == T0_NS
    assert ns_to_stamp(-1) == (-1, 999_999_999)


# -- ROS helpers ---------------------------------------------------------------------------

def min_jerk_reach(rate, start=0.8, duration=1.0, tail=0.9, distance=0.4, noise=5e-4, seed=0):
    """Stamps (ns) and mocap-frame wrist positions of a reach; true onset/end in seconds."""
    rng = np.random.default_rng(seed)
    n = int((start + duration + tail) * rate)
    stamps = T0_NS + np.arange(n, dtype=np.int64) * (1_000_000_000 // rate)
    t = (stamps - T0_NS) * 1e-9
    s = np.clip((t - start) / duration, 0, 1)
    s = 10 * s**3 - 15 * s**4 + 6 * s**5
    p = np.array([0.3, 0.4, 1.0]) + np.outer(s, [distance * 0.6, -distance * 0.8, 0.05])
    p += rng.normal(scale=noise, size=p.shape)
    return stamps, p, start, start + duration


def pose_msg(stamp_ns, pos, quat=(0.0, 0.0, 0.0, 1.0), frame='world'):
    from geometry_msgs.msg import PoseStamped
    msg = PoseStamped()
    msg.header.frame_id = frame
    msg.header.stamp.sec, msg.header.stamp.nanosec = ns_to_stamp(int(stamp_ns))
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (float(v) for v in pos)
    (msg.pose.orientation.x, msg.pose.orientation.y, msg.pose.orientation.z,
     msg.pose.orientation.w) = (float(v) for v in quat)
    return msg


def spin_until(executor, condition, timeout=5.0, what='condition'):
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f'timed out waiting for {what}')
        executor.spin_once(timeout_sec=0.005)


def stamp_ns_of(header):
    return stamp_to_ns(header.stamp.sec, header.stamp.nanosec)


class Harness:
    """The observer plus a test node publishing mocap (and /clock) and recording outputs."""

    def __init__(self, ctx, **params):
        from geometry_msgs.msg import PointStamped, PoseStamped
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        from rclpy.parameter import Parameter
        from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
        from rosgraph_msgs.msg import Clock
        from std_msgs.msg import Header

        from mixture_ip_ros.nodes.observer_node import ObserverNode

        overrides = [Parameter(k, value=v) for k, v in params.items()]
        self.observer = ObserverNode(context=ctx, parameter_overrides=overrides)
        self.peer = Node('observer_test_peer', context=ctx)
        self.pose_pub = self.peer.create_publisher(PoseStamped, '/mocap/wrist',
                                                   qos_profile_sensor_data)
        self.clock_pub = self.peer.create_publisher(Clock, '/clock', 10)
        reliable = QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE)
        self.points, self.events = [], []
        self.peer.create_subscription(PointStamped, '/observer/wrist', self.points.append,
                                      reliable)
        self.peer.create_subscription(Header, '/observer/event', self.events.append, reliable)
        self.executor = SingleThreadedExecutor(context=ctx)
        self.executor.add_node(self.observer)
        self.executor.add_node(self.peer)
        spin_until(self.executor, lambda: (
            self.pose_pub.get_subscription_count() >= 1
            and self.observer._obs_pub.get_subscription_count() >= 1
            and self.observer._event_pub.get_subscription_count() >= 1), what='discovery')

    def handled(self):
        return self.observer.accepted + sum(self.observer.drop_counts.values())

    def send(self, msg):
        """Publish one pose and wait until the observer has handled it (none lost)."""
        before = self.handled()
        self.pose_pub.publish(msg)
        spin_until(self.executor, lambda: self.handled() > before, what='pose delivery')

    def set_clock(self, ns):
        from rosgraph_msgs.msg import Clock
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = ns_to_stamp(ns)
        self.clock_pub.publish(msg)
        spin_until(self.executor,
                   lambda: self.observer.get_clock().now().nanoseconds >= ns, what='/clock')

    def close(self):
        self.executor.shutdown()
        self.observer.destroy_node()
        self.peer.destroy_node()


# -- node: pure logic through direct callback calls -----------------------------------------

def test_bad_poses_are_dropped_counted_and_node_keeps_working(ros_context):
    from mixture_ip_ros.nodes.observer_node import ObserverNode
    node = ObserverNode(context=ros_context)
    try:
        stamps, p, true_on, _ = min_jerk_reach(200)
        node.on_pose(pose_msg(stamps[0], p[0]))
        bad = [
            pose_msg(stamps[1], (math.nan, 0, 0)),
            pose_msg(stamps[1], p[1], quat=(0, 0, 0, 0)),       # unset orientation
            pose_msg(stamps[1], p[1], quat=(0.1, 0, 0, 1.0)),   # norm 1.005: kept
            pose_msg(stamps[2], p[2], frame='camera'),
            pose_msg(stamps[1], p[1]),                           # same stamp as the last
            pose_msg(stamps[0], p[0]),                           # backwards
            None,                                                # not even a message
        ]
        for msg in bad:
            node.on_pose(msg)
        assert node.drop_counts == {'non_finite': 1, 'bad_quaternion': 1, 'wrong_frame': 1,
                                    'duplicate_stamp': 1, 'stamp_backwards': 1, 'exception': 1}
        assert node.accepted == 2
        for s, x in zip(stamps[2:], p[2:]):
            node.on_pose(pose_msg(s, x))
        assert node.accepted == len(stamps)
        assert node.published['onset'] == 1 and node.published['end'] == 1
        assert node.published['observations'] > 100
    finally:
        node.destroy_node()


def test_stream_restart_after_consistent_backwards_stamps(ros_context):
    from rclpy.parameter import Parameter

    from mixture_ip_ros.nodes.observer_node import ObserverNode
    node = ObserverNode(context=ros_context,
                        parameter_overrides=[Parameter('restart_after_backwards', value=5)])
    try:
        for k in range(10):
            node.on_pose(pose_msg(T0_NS + k * 10_000_000, (0, 0, 1)))
        for k in range(4):  # replay from the start: the first few are dropped ...
            node.on_pose(pose_msg(T0_NS - 10**9 + k * 10_000_000, (0, 0, 1)))
        assert node.drop_counts['stamp_backwards'] == 4 and node.stream_restarts == 0
        node.on_pose(pose_msg(T0_NS - 10**9 + 4 * 10_000_000, (0, 0, 1)))
        assert node.stream_restarts == 1 and node.accepted == 11  # ... then it is a new stream
        node.on_pose(pose_msg(T0_NS - 10**9 + 5 * 10_000_000, (0, 0, 1)))
        assert node.accepted == 12
    finally:
        node.destroy_node()


def test_params_file_matches_declared_defaults(ros_context):
    import yaml

    from mixture_ip_ros.nodes.observer_node import ObserverNode
    from mixture_ip_ros.core.share import config_path
    path = config_path('observer.yaml')
    params = yaml.safe_load(path.read_text())['observer_node']['ros__parameters']
    node = ObserverNode(context=ros_context,
                        cli_args=['--ros-args', '--params-file', str(path)])
    try:
        declared = {n: p.value for n, p in node.get_parameters_by_prefix('').items()
                    if n not in ('use_sim_time', 'start_type_description_service')}
        # Not written in the file: the robot's description gives them (the file says so).
        from mixture_ip_ros.robot.description import load_description
        robot = load_description(params['robot'])
        to_base = robot.world_to_base()
        derived = {'base_frame': robot.base_frame,
                   'mocap_to_base_xyz': to_base.translation.tolist(),
                   'mocap_to_base_xyzw': list(to_base.quaternion)}
        assert set(params) | set(derived) == set(declared)  # every setting documented
        for name, value in {**params, **derived}.items():
            got = declared[name]
            assert (list(got) if isinstance(value, list) else got) == value, name
    finally:
        node.destroy_node()


# -- node over DDS --------------------------------------------------------------------------

def test_reach_end_to_end_over_dds(ros_context):
    h = Harness(ros_context, mocap_to_base_xyz=XYZ, mocap_to_base_xyzw=XYZW)
    try:
        rate = 200
        stamps, p, true_on, true_end = min_jerk_reach(rate, seed=3)
        for k, (s, x) in enumerate(zip(stamps, p)):
            h.send(pose_msg(s, x))
            if k == 50:  # at rest: one of each bad input, all dropped
                h.send(pose_msg(s + 1000, (0, math.nan, 0)))
                h.send(pose_msg(s + 1000, x, quat=(0, 0, 0.5, 0.5)))
                h.send(pose_msg(s + 1000, x, frame='map'))
                h.send(pose_msg(s, x))
                h.send(pose_msg(s - 5_000_000, x))
        spin_until(h.executor, lambda: [e.frame_id for e in h.events].count('end') == 1,
                   what="the 'end' event")
        spin_until(h.executor, lambda: len(h.points) == h.observer.published['observations'],
                   what='all observations')
        assert h.observer.drop_counts == {
            'non_finite': 1, 'bad_quaternion': 1, 'wrong_frame': 1, 'duplicate_stamp': 1,
            'stamp_backwards': 1, 'exception': 0}
        assert h.observer.accepted == len(stamps)

        # A 'gap' could only come from a >0.1 s stall of this process, never from the data.
        events = [e for e in h.events if e.frame_id != 'gap']
        assert [e.frame_id for e in events] == ['onset', 'end']
        onset_ns, end_ns = stamp_ns_of(events[0]), stamp_ns_of(events[1])
        assert abs((onset_ns - T0_NS) * 1e-9 - true_on) < 0.03
        assert abs((end_ns - T0_NS) * 1e-9 - true_end) < 0.15

        # Observations: every accepted pose as it came, in order, original stamps, in the
        # base frame (checked against scipy's rotation).
        got = np.array([stamp_ns_of(m.header) for m in h.points])
        np.testing.assert_array_equal(got, stamps)
        assert all(m.header.frame_id == 'iiwa_link_0' for m in h.points)
        xyz = np.array([[m.point.x, m.point.y, m.point.z] for m in h.points])
        expected = Rotation.from_quat(XYZW).apply(p) + XYZ
        np.testing.assert_allclose(xyz, expected, atol=1e-12)
        assert not h.observer.moving

        # Online and offline segmentation agree to the nanosecond on the same samples.
        t_rel = (stamps - stamps[0]) * 1e-9
        base = FrameTransform(XYZ, XYZW).apply_array(p)
        on, end = segment_motion(t_rel, base)
        assert abs(stamps[0] + round(on * 1e9) - onset_ns) <= 1
        assert abs(stamps[0] + round(end * 1e9) - end_ns) <= 1
    finally:
        h.close()


def test_pause_in_stream_gives_one_gap_event_in_sim_time(ros_context):
    h = Harness(ros_context, use_sim_time=True, gap_timeout=0.1)
    try:
        period = 10_000_000  # 100 Hz
        h.set_clock(T0_NS)
        k = 0
        for k in range(60):  # 0.6 s at rest
            h.set_clock(T0_NS + k * period)
            h.send(pose_msg(T0_NS + k * period, (0.2, 0.1, 1.0)))
        last_ns = T0_NS + k * period
        for j in range(1, 51):  # 0.5 s of sim time with no mocap
            h.set_clock(last_ns + j * period)
        spin_until(h.executor, lambda: len(h.events) >= 1, what="the 'gap' event")
        assert [e.frame_id for e in h.events] == ['gap']
        assert stamp_ns_of(h.events[0]) == last_ns  # the gap starts after the last sample
        for j in range(51, 80):  # the stream resumes: the gap is not reported again
            h.set_clock(last_ns + j * period)
            h.send(pose_msg(last_ns + j * period, (0.2, 0.1, 1.0)))
        for _ in range(20):
            h.executor.spin_once(timeout_sec=0.001)
        assert [e.frame_id for e in h.events] == ['gap']
        assert h.observer.published['gap'] == 1
        spin_until(h.executor, lambda: len(h.points) == 89, what="every pose forwarded")
        assert not h.observer.moving  # nothing moved: no onset
    finally:
        h.close()
