"""io.cdr: the bytes it builds are the messages rclpy builds (oracle: rclpy's deserializer
and message equality), and the arrays it reads from messages rclpy serialized are their fields,
for every length and alignment the layouts meet."""

from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path
import numpy as np
import pytest
from rclpy.serialization import deserialize_message
from std_msgs.msg import Float64MultiArray, MultiArrayDimension
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from mixture_ip_ros.io.bags import typestore
from mixture_ip_ros.io.cdr import (Float64MultiArrayEncoder, JointTrajectoryEncoder, PathEncoder,
                                   joint_state_rows, pose_stamped_rows)

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


def _rosbags_cdr(msgtype, **fields):
    """A message serialized by rosbags (the bags' serialiser: padding bytes are zero, where
    rmw leaves whatever was in its buffer, so that only rosbags' messages of one layout are
    byte for byte alike outside their values)."""
    ts = typestore()
    T = ts.types
    stamp = fields.pop('stamp_ns')
    header = T['std_msgs/msg/Header'](stamp=T['builtin_interfaces/msg/Time'](
        sec=stamp // NS, nanosec=stamp % NS), frame_id=fields.pop('frame'))
    return ts.serialize_cdr(T[msgtype](header=header, **fields), msgtype)


@pytest.mark.parametrize('frame', ['', 'w', 'world', 'camera_link'])
def test_pose_stamped_rows_are_the_messages_fields(frame):
    ts = typestore().types
    rng = np.random.default_rng(len(frame))
    stamps = [0, 5, NS - 1, 1_700_000_000 * NS + 3]
    values = rng.normal(size=(len(stamps), 7))
    messages = [_rosbags_cdr('geometry_msgs/msg/PoseStamped', stamp_ns=ns, frame=frame,
                             pose=ts['geometry_msgs/msg/Pose'](
                                 position=ts['geometry_msgs/msg/Point'](*v[:3]),
                                 orientation=ts['geometry_msgs/msg/Quaternion'](*v[3:])))
                for ns, v in zip(stamps, values)]
    ns, xyz, quat, got_frame = pose_stamped_rows(messages)
    assert ns.tolist() == stamps and got_frame == frame
    assert np.array_equal(xyz, values[:, :3]) and np.array_equal(quat, values[:, 3:])
    other = bytes(messages[0][:12]) + b'\xff' + bytes(messages[0][13:])   # not one layout
    assert pose_stamped_rows(messages + [other]) is None
    assert pose_stamped_rows([messages[0][:-8]]) is None         # too short for its layout


@pytest.mark.parametrize('names,frame', [(['a', 'bc', 'def', 'g'], ''),
                                         ([f'iiwa_joint_{i}' for i in range(1, 8)], 'base')])
@pytest.mark.parametrize('with_velocity', [True, False])
def test_joint_state_rows_are_the_messages_fields(names, frame, with_velocity):
    rng = np.random.default_rng(len(names))
    stamps = [3, 2 * NS + 1, 0]
    pos, vel = rng.normal(size=(2, len(stamps), len(names)))
    messages = [_rosbags_cdr('sensor_msgs/msg/JointState', stamp_ns=ns, frame=frame, name=names,
                             position=pos[i], velocity=vel[i] if with_velocity else np.zeros(0),
                             effort=np.zeros(0))
                for i, ns in enumerate(stamps)]
    wanted = names[::-2]
    ns, q, qd = joint_state_rows(messages, wanted)
    index = [names.index(n) for n in wanted]
    assert ns.tolist() == stamps and np.array_equal(q, pos[:, index])
    assert np.array_equal(qd, vel[:, index]) if with_velocity else qd is None
    assert joint_state_rows(messages, ['not_a_joint']) is None
    renamed = _rosbags_cdr('sensor_msgs/msg/JointState', stamp_ns=0, frame=frame,
                           name=[n.upper() for n in names], position=pos[0],
                           velocity=vel[0] if with_velocity else np.zeros(0), effort=np.zeros(0))
    assert joint_state_rows(messages + [renamed], wanted) is None
