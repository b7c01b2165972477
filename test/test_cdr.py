"""nodes.cdr: the bytes it builds are the messages rclpy builds (oracle: rclpy's deserializer
and message equality), for every length and alignment the templates meet."""

from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path
import numpy as np
import pytest
from rclpy.serialization import deserialize_message
from std_msgs.msg import Float64MultiArray, MultiArrayDimension
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from mixture_ip_ros.nodes.cdr import (Float64MultiArrayEncoder, JointTrajectoryEncoder,
                                      PathEncoder)

NS = 1_000_000_000


def _time(ns):
    return Time(sec=int(ns) // NS, nanosec=int(ns) % NS)


def _reference_trajectory(names, frame, stamp_ns, times_ns, pos, vel, acc):
    msg = JointTrajectory()
    msg.header.stamp = _time(stamp_ns)
    msg.header.frame_id = frame
    msg.joint_names = names
    msg.points = [JointTrajectoryPoint(
        positions=pos[i].tolist(), velocities=vel[i].tolist(), accelerations=acc[i].tolist(),
        time_from_start=Duration(sec=int(t) // NS, nanosec=int(t) % NS))
        for i, t in enumerate(times_ns)]
    return msg


# Odd name and frame lengths shift every later field off 8-byte alignment.
@pytest.mark.parametrize('names,frame', [
    ([f'iiwa_joint_{i}' for i in range(1, 8)], ''),
    (['a', 'bc', 'def'], 'base'),
    (['shoulder'], 'x'),
])
@pytest.mark.parametrize('n', [1, 2, 3, 25])
def test_joint_trajectory_matches_rclpy(names, frame, n):
    rng = np.random.default_rng(n)
    q = len(names)
    pos, vel, acc = rng.normal(size=(3, n, q)) * [[[1.0]], [[1e-300]], [[1e300]]]
    times_ns = np.cumsum(rng.integers(1, 3 * NS, n))
    stamp_ns = 1_795_000_000 * NS + 123_456_789
    enc = JointTrajectoryEncoder(names, frame)
    data = enc.encode(stamp_ns, times_ns, pos, vel, acc)
    ref = _reference_trajectory(names, frame, stamp_ns, times_ns, pos, vel, acc)
    assert deserialize_message(data, JointTrajectory) == ref
    # The cached template is reused, not stale.
    assert enc.encode(stamp_ns, times_ns, pos, vel, acc) == data
    again = enc.encode(stamp_ns + 1, times_ns + 7, -pos, vel, acc)
    assert deserialize_message(again, JointTrajectory) == _reference_trajectory(
        names, frame, stamp_ns + 1, times_ns + 7, -pos, vel, acc)


def test_joint_trajectory_values_exact():
    """Bit-exact doubles (NaN is never encoded: check_plan refuses it upstream)."""
    enc = JointTrajectoryEncoder(['j'])
    values = np.array([[0.1], [-0.0], [5e-324]])
    msg = deserialize_message(enc.encode(0, [1, 2, NS + 3], values, 2 * values, 3 * values),
                              JointTrajectory)
    assert [p.positions[0] for p in msg.points] == values[:, 0].tolist()
    assert np.signbit(msg.points[1].positions[0])
    assert [(p.time_from_start.sec, p.time_from_start.nanosec) for p in msg.points] == [
        (0, 1), (0, 2), (1, 3)]


@pytest.mark.parametrize('frame', ['iiwa_link_0', 'w', ''])
@pytest.mark.parametrize('n', [1, 2, 25])
def test_path_matches_rclpy(frame, n):
    rng = np.random.default_rng(n)
    xyz = rng.normal(size=(n, 3))
    stamp_ns = 1000 * NS + 5
    stamps = stamp_ns + np.cumsum(rng.integers(1, NS, n))
    ref = Path()
    ref.header.stamp = _time(stamp_ns)
    ref.header.frame_id = frame
    for t, (x, y, z) in zip(stamps, xyz):
        pose = PoseStamped()
        pose.header.stamp = _time(t)
        pose.header.frame_id = frame
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = x, y, z
        pose.pose.orientation.w = 1.0
        ref.poses.append(pose)
    enc = PathEncoder(frame)
    assert deserialize_message(enc.encode(stamp_ns, stamps, xyz), Path) == ref
    assert deserialize_message(enc.encode(stamp_ns, stamps, xyz), Path) == ref


def test_negative_and_extreme_times_and_bad_shapes():
    enc = JointTrajectoryEncoder(['a', 'b'])
    v = np.zeros((2, 2))
    msg = deserialize_message(enc.encode(-1, [0, (2**31 - 1) * NS], v, v, v), JointTrajectory)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (-1, NS - 1)
    assert msg.points[1].time_from_start.sec == 2**31 - 1
    with pytest.raises(ValueError, match='int32'):
        enc.encode(2**31 * NS, [0, 1], v, v, v)
    with pytest.raises(ValueError, match='int32'):
        enc.encode(0, [0, -(2**31 + 1) * NS], v, v, v)
    with pytest.raises(ValueError, match='shape'):
        enc.encode(0, [0, 1], np.zeros((2, 1)), v, v)     # would broadcast
    with pytest.raises(ValueError, match='shape'):
        PathEncoder('w').encode(0, [0, 1], np.zeros((1, 3)))


@pytest.mark.parametrize('label', ['p0,p1,p2,alpha,phase,confidence,component', 'ab', ''])
@pytest.mark.parametrize('n', [0, 1, 2, 7, 16])
def test_float64_multi_array_matches_rclpy(label, n):
    data = np.random.default_rng(n).normal(size=n) * 1e5
    ref = Float64MultiArray()
    ref.layout.dim = [MultiArrayDimension(label=label, size=n, stride=n)]
    ref.data = data.tolist()
    enc = Float64MultiArrayEncoder(label)
    assert deserialize_message(enc.encode(data), Float64MultiArray) == ref
    assert deserialize_message(enc.encode(-data), Float64MultiArray).data.tolist() == \
        (-data).tolist()
    with pytest.raises(ValueError, match='one-dimensional'):
        enc.encode(data.reshape(1, -1))
