"""Observer node: pose checks, frame change and stamps (pure), then the node over real DDS."""

import math
from types import SimpleNamespace

from geometry_msgs.msg import PointStamped, PoseStamped
import numpy as np
import pytest
from rclpy.parameter import Parameter
from scipy.spatial.transform import Rotation
from std_msgs.msg import Header

from mixture_ip_ros.core.frames import FrameTransform, quaternion_to_matrix
from mixture_ip_ros.core.segmentation import segment_motion
from mixture_ip_ros.core.stamps import ns_to_parts, seconds_to_ns, stamp_to_ns
from mixture_ip_ros.estimation.pose_check import POSE_REJECT_REASONS, check_pose
from mixture_ip_ros.nodes import qos
from mixture_ip_ros.nodes.observer_node import ObserverNode

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
    assert set(POSE_REJECT_REASONS) >= {'non_finite', 'bad_quaternion', 'wrong_frame',
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
    assert ns_to_parts(T0_NS) == (1_700_000_000, 123_456_789)
    sec, nanosec = ns_to_parts(T0_NS)
    assert stamp_to_ns(SimpleNamespace(sec=sec, nanosec=nanosec)) == T0_NS
    assert ns_to_parts(-1) == (-1, 999_999_999)
    assert seconds_to_ns(1.5e-9) == 2 and seconds_to_ns(-0.25) == -250_000_000


# -- the node -----------------------------------------------------------------------------

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
    msg = PoseStamped()
    msg.header.frame_id = frame
    msg.header.stamp.sec, msg.header.stamp.nanosec = ns_to_parts(int(stamp_ns))
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (float(v) for v in pos)
    (msg.pose.orientation.x, msg.pose.orientation.y, msg.pose.orientation.z,
     msg.pose.orientation.w) = (float(v) for v in quat)
    return msg


class Observer:
    """The observer in the harness, with a mocap publisher and recorders of its outputs."""

    def __init__(self, harness, **params):
        params.setdefault('max_clock_offset', 0.0)   # T0_NS is not the node's clock
        overrides = [Parameter(k, value=v) for k, v in params.items()]
        self.h = harness
        self.node = harness.add(ObserverNode(context=harness.context,
                                             parameter_overrides=overrides))
        self.pose_pub = harness.publisher(PoseStamped, '/mocap/wrist', qos.sensor_data(100))
        self.points = harness.subscribe(PointStamped, '/observer/wrist', qos.reliable(5000))
        self.events = harness.subscribe(Header, '/observer/event', qos.reliable(5000))
        harness.matched(self.pose_pub, self.node.observation_pub, self.node.event_pub)

    def handled(self):
        return self.node.accepted + sum(self.node.drop_counts.values())

    def send(self, msg):
        """Publish one pose and spin until the observer has handled it (none lost)."""
        before = self.handled()
        self.pose_pub.publish(msg)
        self.h.spin_until(lambda: self.handled() > before, what='pose delivery')


def _nonzero(counts):
    return {k: v for k, v in counts.items() if v}


UNCLOCKED = Parameter('max_clock_offset', value=0.0)    # T0_NS is not the node's clock


def test_bad_poses_are_dropped_counted_and_the_node_keeps_working(harness):
    node = harness.add(ObserverNode(context=harness.context, parameter_overrides=[UNCLOCKED]))
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
    assert _nonzero(node.drop_counts) == {'non_finite': 1, 'bad_quaternion': 1, 'wrong_frame': 1,
                                          'duplicate_stamp': 1, 'stamp_backwards': 1,
                                          'exception': 1}
    assert node.accepted == 2
    for s, x in zip(stamps[2:], p[2:]):
        node.on_pose(pose_msg(s, x))
    assert node.accepted == len(stamps)
    assert node.published['onset'] == 1 and node.published['end'] == 1
    assert node.published['observations'] > 100


def test_stream_restart_after_consistent_backwards_stamps(harness):
    node = harness.add(ObserverNode(context=harness.context, parameter_overrides=[
        Parameter('restart_after_backwards', value=5), UNCLOCKED]))
    for k in range(10):
        node.on_pose(pose_msg(T0_NS + k * 10_000_000, (0, 0, 1)))
    # Stamps from 20 ms on again, less than new_stream_jump_back (0.1 s) before the last one:
    # the first few are dropped ...
    for k in range(4):
        node.on_pose(pose_msg(T0_NS + 20_000_000 + k * 10_000_000, (0, 0, 1)))
    assert node.drop_counts['stamp_backwards'] == 4 and node.observer.counts.stream_restarts == 0
    node.on_pose(pose_msg(T0_NS + 20_000_000 + 4 * 10_000_000, (0, 0, 1)))
    assert node.observer.counts.stream_restarts == 1 and node.accepted == 11   # a new stream
    node.on_pose(pose_msg(T0_NS + 20_000_000 + 5 * 10_000_000, (0, 0, 1)))
    assert node.accepted == 12


def test_reach_end_to_end_over_dds(harness):
    o = Observer(harness, mocap_to_base_xyz=XYZ, mocap_to_base_xyzw=XYZW)
    rate = 200
    stamps, p, true_on, true_end = min_jerk_reach(rate, seed=3)
    for k, (s, x) in enumerate(zip(stamps, p)):
        o.send(pose_msg(s, x))
        if k == 50:  # at rest: one of each bad input, all dropped
            o.send(pose_msg(s + 1000, (0, math.nan, 0)))
            o.send(pose_msg(s + 1000, x, quat=(0, 0, 0.5, 0.5)))
            o.send(pose_msg(s + 1000, x, frame='map'))
            o.send(pose_msg(s, x))
            o.send(pose_msg(s - 5_000_000, x))
    harness.spin_until(lambda: [e.frame_id for e in o.events].count('end') == 1,
                       what="the 'end' event")
    harness.spin_until(lambda: len(o.points) == o.node.published['observations'],
                       what='all observations')
    assert _nonzero(o.node.drop_counts) == {
        'non_finite': 1, 'bad_quaternion': 1, 'wrong_frame': 1, 'duplicate_stamp': 1,
        'stamp_backwards': 1}
    assert o.node.accepted == len(stamps)

    # A 'gap' could only come from a >0.1 s stall of this process, never from the data.
    events = [e for e in o.events if e.frame_id != 'gap']
    assert [e.frame_id for e in events] == ['onset', 'end']
    onset_ns, end_ns = stamp_to_ns(events[0].stamp), stamp_to_ns(events[1].stamp)
    assert abs((onset_ns - T0_NS) * 1e-9 - true_on) < 0.03
    assert abs((end_ns - T0_NS) * 1e-9 - true_end) < 0.15

    # Observations: every accepted pose as it came, in order, original stamps, in the
    # base frame (checked against scipy's rotation).
    got = np.array([stamp_to_ns(m.header.stamp) for m in o.points])
    np.testing.assert_array_equal(got, stamps)
    assert all(m.header.frame_id == 'iiwa_link_0' for m in o.points)
    xyz = np.array([[m.point.x, m.point.y, m.point.z] for m in o.points])
    expected = Rotation.from_quat(XYZW).apply(p) + XYZ
    np.testing.assert_allclose(xyz, expected, atol=1e-12)
    assert not o.node.moving

    # Online and offline segmentation agree to the nanosecond on the same samples.
    t_rel = (stamps - stamps[0]) * 1e-9
    base = FrameTransform(XYZ, XYZW).apply_array(p)
    on, end = segment_motion(t_rel, base)
    assert abs(stamps[0] + round(on * 1e9) - onset_ns) <= 1
    assert abs(stamps[0] + round(end * 1e9) - end_ns) <= 1


def test_pause_in_stream_gives_a_gap_event_on_simulated_time(harness):
    """On simulated time the gap is found when the simulated clock passes gap_timeout after
    the last sample, however long the wall clock took."""
    o = Observer(harness, use_sim_time=True, gap_timeout=0.1)
    period = 10_000_000  # 100 Hz
    k = 0
    for k in range(60):  # 0.6 s at rest
        harness.set_clock(T0_NS + k * period)
        o.send(pose_msg(T0_NS + k * period, (0.2, 0.1, 1.0)))
    last_ns = T0_NS + k * period
    j = 1
    while not o.events:  # the clock runs on, no mocap
        harness.set_clock(last_ns + j * period)
        j += 1
        assert j < 100, 'no gap event'
    assert [e.frame_id for e in o.events] == ['gap']
    assert stamp_to_ns(o.events[0].stamp) == last_ns  # the gap starts after the last sample
    # found within one timer period (gap_timeout / 4) of simulated time after the timeout
    assert 0.1 < (j - 1) * period * 1e-9 <= 0.1 + 0.025 + 0.03   # (+ delivery steps)


def test_inactive_observer_does_not_subscribe(harness):
    node = harness.add(ObserverNode(context=harness.context), start=False)
    assert node.lifecycle_state == 'unconfigured'
    node.trigger_configure()
    assert harness.probe.count_subscribers('/mocap/wrist') == 0
    node.trigger_activate()
    harness.spin_until(lambda: harness.probe.count_subscribers('/mocap/wrist') == 1,
                       what='the subscription')
    node.trigger_deactivate()
    harness.spin_until(lambda: harness.probe.count_subscribers('/mocap/wrist') == 0,
                       what='the subscription gone')
    assert node.lifecycle_state == 'inactive'


@pytest.mark.parametrize('params, match', [
    ({'mocap_to_base_xyzw': [0.0, 0.0, 0.0, 2.0]}, 'mocap_to_base_xyzw'),
    ({'mocap_to_base_xyz': [0.0, float('nan'), 0.0]}, 'mocap_to_base_xyz'),
    ({'quaternion_tolerance': float('nan')}, 'quaternion_tolerance'),
    ({'onset_speed': -1.0}, 'onset_speed'),
])
def test_invalid_parameters_are_refused_naming_the_parameter(ros_context, params, match):
    with pytest.raises(ValueError, match=match):
        ObserverNode(context=ros_context,
                     parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])


def test_inconsistent_segmentation_is_refused_at_configure(harness):
    node = harness.add(ObserverNode(context=harness.context, parameter_overrides=[
        Parameter('end_speed', value=0.5)]), start=False)
    assert node.trigger_configure().to_label() == 'transition_failure'
    assert 'end_speed' in node.refusal and 'onset_speed' in node.refusal
