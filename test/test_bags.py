"""rosbag2 demonstration bags: round trip, independent readers, and every bad-bag case."""

import json
import sqlite3
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from mixture_ip_ros.robot.description import JOINT_NAMES
from mixture_ip_ros.io.bags import (DEFAULT_START_TIME_NS, LABEL_KEY, BagError,
                                      bag_topics, read_bag, read_messages, typestore,
                                      write_demonstration_bag)


def _arrays(seed=0, n=150, gap=(40, 70)):
    rng = np.random.default_rng(seed)
    t = 0.01 * np.arange(n)
    xyz = np.column_stack([0.5 + 0.1 * np.sin(t), 0.2 * np.cos(t), 1.0 + t]) + rng.normal(0, 1e-3, (n, 3))
    xyz[gap[0]:gap[1]] = np.nan
    quat = rng.normal(size=(n, 4))
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    jt = 0.01 * np.arange(n + 20)  # joints run a bit longer than the wrist
    q = rng.uniform(-2, 2, (jt.size, 7))
    qd = rng.uniform(-1, 1, (jt.size, 7))
    return t, xyz, quat, jt, q, qd


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_round_trip_gives_back_the_arrays(tmp_path, storage):
    t, xyz, quat, jt, q, qd = _arrays()
    bag = write_demonstration_bag(tmp_path / 'demo', t, xyz, jt, q, storage=storage, label='plate',
                                  wrist_quat=quat, joint_qd=qd, frame_id='mocap')
    rec = read_bag(bag)
    present = ~np.isnan(xyz).any(axis=1)
    assert rec.start_time_ns == DEFAULT_START_TIME_NS
    np.testing.assert_allclose(rec.wrist_t, t[present], atol=1e-9)
    np.testing.assert_array_equal(rec.wrist_xyz, xyz[present])
    np.testing.assert_array_equal(rec.wrist_quat, quat[present])
    np.testing.assert_allclose(rec.joint_t, jt, atol=1e-9)
    np.testing.assert_array_equal(rec.joint_q, q)
    np.testing.assert_array_equal(rec.joint_qd, qd)
    assert rec.joint_names == JOINT_NAMES
    assert rec.wrist_frame == 'mocap'
    assert rec.label == 'plate'
    # The occlusion is absent messages, not NaN messages.
    assert len(rec.wrist_t) == present.sum() == 120


def test_custom_topics_no_label_and_joint_reordering(tmp_path):
    t, xyz, _, jt, q, _ = _arrays(gap=(0, 0))
    names = list(reversed(JOINT_NAMES)) + ['gripper']
    q8 = np.column_stack([q[:, ::-1], np.zeros(len(jt))])
    bag = write_demonstration_bag(tmp_path / 'b', t, xyz, jt, q8, joint_names=names,
                                  wrist_topic='/vicon/hand', joint_topic='/robot/joints')
    assert set(bag_topics(bag)) == {'/vicon/hand', '/robot/joints'}
    rec = read_bag(bag, wrist_topic='/vicon/hand', joint_topic='/robot/joints')
    np.testing.assert_array_equal(rec.joint_q, q)  # picked by name, in iiwa_joint_1..7 order
    assert rec.label is None and rec.joint_qd is None
    with pytest.raises(BagError, match="topic '/mocap/wrist' not in bag"):
        read_bag(bag)


def _share(pkg_type):
    path = Path(sys.prefix) / 'share' / f'{pkg_type}.json'
    if not path.is_file():
        pytest.skip(f'no ROS type description {path}')
    return json.loads(path.read_text())['type_hashes'][0]['hash_string']


def test_mcap_bag_reads_with_the_independent_mcap_reader(tmp_path):
    from mcap.reader import make_reader
    from rclpy.serialization import deserialize_message
    from geometry_msgs.msg import PoseStamped
    from sensor_msgs.msg import JointState

    t, xyz, quat, jt, q, _ = _arrays()
    bag = write_demonstration_bag(tmp_path / 'demo', t, xyz, jt, q, wrist_quat=quat, label='screw')
    meta = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert meta['version'] == 9 and meta['storage_identifier'] == 'mcap'
    assert meta['custom_data'] == {LABEL_KEY: 'screw'}
    hashes = {x['topic_metadata']['name']: x['topic_metadata']['type_description_hash']
              for x in meta['topics_with_message_count']}
    # Type hashes equal the ones the installed ROS 2 Jazzy message packages generated.
    assert hashes['/mocap/wrist'] == _share('geometry_msgs/msg/PoseStamped')
    assert hashes['/joint_states'] == _share('sensor_msgs/msg/JointState')
    qos = {x['topic_metadata']['name']: x['topic_metadata']['offered_qos_profiles'][0]['reliability']
           for x in meta['topics_with_message_count']}
    assert qos == {'/mocap/wrist': 'best_effort', '/joint_states': 'reliable'}

    present = ~np.isnan(xyz).any(axis=1)
    with open(bag / meta['relative_file_paths'][0], 'rb') as f:
        reader = make_reader(f)
        assert reader.get_header().profile == 'ros2'
        summary = reader.get_summary()
        channels = {c.id: c for c in summary.channels.values()}
        by_topic = {c.topic: c for c in channels.values()}
        assert set(by_topic) == {'/mocap/wrist', '/joint_states'}
        for topic, typ in [('/mocap/wrist', 'geometry_msgs/msg/PoseStamped'),
                           ('/joint_states', 'sensor_msgs/msg/JointState')]:
            schema = summary.schemas[by_topic[topic].schema_id]
            assert schema.name == typ and schema.encoding == 'ros2msg'
            assert by_topic[topic].message_encoding == 'cdr'
        counts = summary.statistics.channel_message_counts
        assert counts[by_topic['/mocap/wrist'].id] == present.sum()
        assert counts[by_topic['/joint_states'].id] == jt.size
        wrist_times, wrist_msgs, joint_times, joint_msgs = [], [], [], []
        for _, channel, message in reader.iter_messages(log_time_order=True):
            if channel.topic == '/mocap/wrist':
                wrist_times.append(message.log_time)
                wrist_msgs.append(message.data)
            else:
                joint_times.append(message.log_time)
                joint_msgs.append(message.data)
    expected_w = DEFAULT_START_TIME_NS + np.round(t[present] * 1e9).astype(np.int64)
    expected_j = DEFAULT_START_TIME_NS + np.round(jt * 1e9).astype(np.int64)
    np.testing.assert_array_equal(wrist_times, expected_w)
    np.testing.assert_array_equal(joint_times, expected_j)

    k = 50  # first sample after the gap
    msg = deserialize_message(wrist_msgs[40], PoseStamped)
    assert msg.header.frame_id == 'world'
    assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == expected_w[40]
    p = msg.pose.position
    np.testing.assert_array_equal([p.x, p.y, p.z], xyz[present][40])
    o = msg.pose.orientation
    np.testing.assert_array_equal([o.x, o.y, o.z, o.w], quat[present][40])
    js = deserialize_message(joint_msgs[k], JointState)
    assert list(js.name) == list(JOINT_NAMES)
    np.testing.assert_array_equal(js.position, q[k])


def test_sqlite3_bag_reads_with_plain_sqlite(tmp_path):
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import JointState

    t, xyz, _, jt, q, _ = _arrays()
    bag = write_demonstration_bag(tmp_path / 'demo', t, xyz, jt, q, storage='sqlite3')
    dbs = list(bag.glob('*.db3'))
    assert len(dbs) == 1
    con = sqlite3.connect(dbs[0])
    try:
        topics = {name: (tid, typ) for tid, name, typ in
                  con.execute('SELECT id, name, type FROM topics')}
        assert topics['/joint_states'][1] == 'sensor_msgs/msg/JointState'
        assert topics['/mocap/wrist'][1] == 'geometry_msgs/msg/PoseStamped'
        rows = con.execute('SELECT timestamp, data FROM messages WHERE topic_id = ? ORDER BY timestamp',
                           (topics['/joint_states'][0],)).fetchall()
        n_wrist = con.execute('SELECT COUNT(*) FROM messages WHERE topic_id = ?',
                              (topics['/mocap/wrist'][0],)).fetchone()[0]
    finally:
        con.close()
    assert n_wrist == (~np.isnan(xyz).any(axis=1)).sum()
    np.testing.assert_array_equal([r[0] for r in rows],
                                  DEFAULT_START_TIME_NS + np.round(jt * 1e9).astype(np.int64))
    js = deserialize_message(bytes(rows[7][1]), JointState)
    np.testing.assert_array_equal(js.position, q[7])


def test_write_rejects_bad_input(tmp_path):
    t, xyz, _, jt, q, _ = _arrays()
    with pytest.raises(ValueError, match='wrist_xyz must have shape'):
        write_demonstration_bag(tmp_path / 'a', t, xyz[:, :2], jt, q)
    with pytest.raises(ValueError, match='joint_q must have shape'):
        write_demonstration_bag(tmp_path / 'a', t, xyz, jt, q[:, :6])
    with pytest.raises(ValueError, match='strictly increasing'):
        write_demonstration_bag(tmp_path / 'a', t[::-1], xyz, jt, q)
    with pytest.raises(ValueError, match='storage'):
        write_demonstration_bag(tmp_path / 'a', t, xyz, jt, q, storage='rosbag1')
    with pytest.raises(ValueError, match='no observed sample'):
        write_demonstration_bag(tmp_path / 'a', t, np.full_like(xyz, np.nan), jt, q)
    write_demonstration_bag(tmp_path / 'a', t, xyz, jt, q)
    with pytest.raises(FileExistsError):
        write_demonstration_bag(tmp_path / 'a', t, xyz, jt, q)


# ------------------------------------------------------------------------------------ bad bags

def _raw_bag(path, topics, storage='mcap'):
    """A bag with arbitrary (topic, msgtype, [(ns, cdr bytes)]) connections, for broken cases."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    writer = Writer(path, version=9,
                    storage_plugin=StoragePlugin.MCAP if storage == 'mcap' else StoragePlugin.SQLITE3)
    writer.open()
    for topic, msgtype, msgs in topics:
        conn = writer.add_connection(topic, msgtype, typestore=typestore())
        for ns, data in msgs:
            writer.write(conn, ns, data)
    writer.close()
    return path


def _pose_cdr(ns, x=0.0, frame='world'):
    ts = typestore()
    T = ts.types
    msg = T['geometry_msgs/msg/PoseStamped'](
        header=T['std_msgs/msg/Header'](stamp=T['builtin_interfaces/msg/Time'](sec=ns // 10**9,
                                                                               nanosec=ns % 10**9),
                                        frame_id=frame),
        pose=T['geometry_msgs/msg/Pose'](position=T['geometry_msgs/msg/Point'](x=x, y=0.0, z=0.0),
                                         orientation=T['geometry_msgs/msg/Quaternion'](
                                             x=0.0, y=0.0, z=0.0, w=1.0)))
    return ts.serialize_cdr(msg, 'geometry_msgs/msg/PoseStamped')


def _joint_cdr(ns, names=JOINT_NAMES):
    ts = typestore()
    T = ts.types
    msg = T['sensor_msgs/msg/JointState'](
        header=T['std_msgs/msg/Header'](stamp=T['builtin_interfaces/msg/Time'](sec=ns // 10**9,
                                                                               nanosec=ns % 10**9),
                                        frame_id=''),
        name=list(names), position=np.zeros(len(names)), velocity=np.zeros(0), effort=np.zeros(0))
    return ts.serialize_cdr(msg, 'sensor_msgs/msg/JointState')


def _string_cdr(text):
    ts = typestore()
    return ts.serialize_cdr(ts.types['std_msgs/msg/String'](data=text), 'std_msgs/msg/String')


NS = [DEFAULT_START_TIME_NS + k * 10**7 for k in range(5)]
WRIST_OK = ('/mocap/wrist', 'geometry_msgs/msg/PoseStamped', [(n, _pose_cdr(n)) for n in NS])
JOINT_OK = ('/joint_states', 'sensor_msgs/msg/JointState', [(n, _joint_cdr(n)) for n in NS])


def test_raw_bag_helper_makes_a_good_bag(tmp_path):
    # The broken-bag cases below differ from this one in exactly one respect.
    rec = read_bag(_raw_bag(tmp_path / 'ok', [WRIST_OK, JOINT_OK]))
    assert rec.wrist_t.size == rec.joint_t.size == 5


def test_missing_path_and_not_a_bag(tmp_path):
    with pytest.raises(BagError, match='does not exist') as err:
        read_bag(tmp_path / 'nope')
    assert err.value.bag == str(tmp_path / 'nope')
    (tmp_path / 'empty_dir').mkdir()
    with pytest.raises(BagError, match='not a rosbag2 bag directory'):
        read_bag(tmp_path / 'empty_dir')
    (tmp_path / 'labels.json').write_text('{}')
    with pytest.raises(BagError, match='cannot open bag'):
        read_bag(tmp_path / 'labels.json')


def test_missing_metadata_yaml(tmp_path):
    bag = _raw_bag(tmp_path / 'b', [WRIST_OK, JOINT_OK])
    (bag / 'metadata.yaml').unlink()
    with pytest.raises(BagError, match='metadata.yaml is missing'):
        read_bag(bag)


def test_corrupt_metadata_yaml(tmp_path):
    bag = _raw_bag(tmp_path / 'b', [WRIST_OK, JOINT_OK])
    (bag / 'metadata.yaml').write_text('rosbag2_bagfile_information: [unclosed\n')
    with pytest.raises(BagError, match='metadata.yaml'):
        read_bag(bag)


def test_missing_topic(tmp_path):
    bag = _raw_bag(tmp_path / 'b', [JOINT_OK])
    with pytest.raises(BagError, match=r"topic '/mocap/wrist' not in bag \(has /joint_states"):
        read_bag(bag)


def test_empty_bag_and_empty_topic(tmp_path):
    with pytest.raises(BagError, match="not in bag .*no topics"):
        read_bag(_raw_bag(tmp_path / 'empty', []))
    bag = _raw_bag(tmp_path / 'b', [('/mocap/wrist', 'geometry_msgs/msg/PoseStamped', []), JOINT_OK])
    with pytest.raises(BagError, match="topic '/mocap/wrist' has no messages"):
        read_bag(bag)


def test_wrong_message_type(tmp_path):
    bag = _raw_bag(tmp_path / 'b', [('/mocap/wrist', 'std_msgs/msg/String',
                                     [(NS[0], _string_cdr('hi'))]), JOINT_OK])
    with pytest.raises(BagError, match="'/mocap/wrist' has message type std_msgs/msg/String, "
                                       "expected geometry_msgs/msg/PoseStamped"):
        read_bag(bag)


def test_undecodable_message(tmp_path):
    broken = ('/mocap/wrist', 'geometry_msgs/msg/PoseStamped', [(NS[0], b'\x00\x01\x00\x00\x07')])
    bag = _raw_bag(tmp_path / 'b', [broken, JOINT_OK])
    with pytest.raises(BagError, match='cannot decode a geometry_msgs/msg/PoseStamped message'):
        read_bag(bag)


def test_joints_missing_from_joint_state(tmp_path):
    short = ('/joint_states', 'sensor_msgs/msg/JointState',
             [(n, _joint_cdr(n, JOINT_NAMES[:6])) for n in NS])
    with pytest.raises(BagError, match=r"lacks joints \['iiwa_joint_7'\]"):
        read_bag(_raw_bag(tmp_path / 'b', [WRIST_OK, short]))


def test_wrist_in_several_frames(tmp_path):
    mixed = ('/mocap/wrist', 'geometry_msgs/msg/PoseStamped',
             [(n, _pose_cdr(n, frame='world' if i % 2 else 'camera')) for i, n in enumerate(NS)])
    with pytest.raises(BagError, match='several frames'):
        read_bag(_raw_bag(tmp_path / 'b', [mixed, JOINT_OK]))


def test_truncated_mcap(tmp_path):
    t, xyz, _, jt, q, _ = _arrays()
    bag = write_demonstration_bag(tmp_path / 'b', t, xyz, jt, q)
    f = next(bag.glob('*.mcap'))
    f.write_bytes(f.read_bytes()[: f.stat().st_size // 2])
    with pytest.raises(BagError, match=str(bag)):
        read_bag(bag)
    with pytest.raises(BagError):
        read_messages(bag)


def test_corrupt_mcap_payload(tmp_path):
    t, xyz, _, jt, q, _ = _arrays()
    bag = write_demonstration_bag(tmp_path / 'b', t, xyz, jt, q)
    f = next(bag.glob('*.mcap'))
    data = bytearray(f.read_bytes())
    for i in range(2000, len(data) - 2000, 7):
        data[i] = (data[i] * 31 + 7) % 256
    f.write_bytes(bytes(data))
    with pytest.raises(BagError, match='truncated or corrupt|cannot open bag|cannot decode'):
        read_bag(bag)


def test_corrupt_sqlite3(tmp_path):
    t, xyz, _, jt, q, _ = _arrays()
    bag = write_demonstration_bag(tmp_path / 'b', t, xyz, jt, q, storage='sqlite3')
    f = next(bag.glob('*.db3'))
    f.write_bytes(f.read_bytes()[: f.stat().st_size // 3])
    with pytest.raises(BagError, match='cannot open bag: .*malformed'):
        read_bag(bag)


def test_read_messages_in_time_order(tmp_path):
    t, xyz, _, jt, q, _ = _arrays()
    bag = write_demonstration_bag(tmp_path / 'b', t, xyz, jt, q)
    msgs = read_messages(bag)
    assert len(msgs) == (~np.isnan(xyz).any(axis=1)).sum() + jt.size
    times = [m.log_time_ns for m in msgs]
    assert times == sorted(times)
    assert {m.topic for m in read_messages(bag, topics=['/joint_states'])} == {'/joint_states'}
    with pytest.raises(BagError, match="not in bag"):
        read_messages(bag, topics=['/nope'])


def _joint_msg(ns, names, pos, vel, frame=''):
    ts = typestore()
    T = ts.types
    return ts.serialize_cdr(T['sensor_msgs/msg/JointState'](
        header=T['std_msgs/msg/Header'](stamp=T['builtin_interfaces/msg/Time'](
            sec=ns // 10**9, nanosec=ns % 10**9), frame_id=frame),
        name=list(names), position=np.asarray(pos, dtype=float),
        velocity=np.asarray(vel, dtype=float), effort=np.zeros(0)), 'sensor_msgs/msg/JointState')


def _decoded_by_rosbags(bag, joint_names=JOINT_NAMES):
    """The streams decoded message by message with rosbags (the reference of read_bag): stamps
    (ns) and values of each, in stamp order."""
    ts = typestore()
    wrist, joints = {}, {}
    for m in read_messages(bag):
        msg = ts.deserialize_cdr(m.data, m.msgtype)
        ns = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec or m.log_time_ns
        if m.topic == '/mocap/wrist':
            p, q = msg.pose.position, msg.pose.orientation
            wrist[ns] = (p.x, p.y, p.z, q.x, q.y, q.z, q.w)
        else:
            names = list(msg.name)
            joints[ns] = [msg.position[names.index(n)] for n in joint_names]
    return ((np.array(sorted(wrist)), np.array([wrist[k] for k in sorted(wrist)])),
            (np.array(sorted(joints)), np.array([joints[k] for k in sorted(joints)])))


@pytest.mark.parametrize('layout', ['uniform', 'names_change', 'velocity_sometimes',
                                    'zero_stamps'])
def test_streams_read_as_one_array_equal_the_message_by_message_decode(tmp_path, layout,
                                                                      monkeypatch):
    """read_bag reads a stream whose messages share one layout as one array, and any other
    message by message: both give what rosbags decodes from each message."""
    from mixture_ip_ros.io import bags
    if layout in ('uniform', 'zero_stamps'):            # no message decoded one by one
        monkeypatch.setattr(bags, '_deserialize', None)
    rng = np.random.default_rng(9)
    ns = [DEFAULT_START_TIME_NS + k * 10**7 for k in range(1, 41)]
    gripper = list(JOINT_NAMES) + ['gripper']
    poses, joints = [], []
    for i, n in enumerate(ns):
        stamp = 0 if layout == 'zero_stamps' and i % 3 == 0 else n
        poses.append((n, _pose_cdr(stamp, x=float(rng.normal()))))
        names = gripper[::-1] if layout == 'names_change' and i >= 20 else gripper
        vel = (rng.normal(size=8) if layout != 'velocity_sometimes' or i % 2 else [])
        joints.append((n, _joint_msg(stamp, names, rng.normal(size=8), vel, frame='base')))
    bag = _raw_bag(tmp_path / 'b', [('/mocap/wrist', 'geometry_msgs/msg/PoseStamped', poses),
                                    ('/joint_states', 'sensor_msgs/msg/JointState', joints)])
    rec = read_bag(bag)
    (w_ns, wrist), (j_ns, joint) = _decoded_by_rosbags(bag)
    assert rec.start_time_ns == min(w_ns[0], j_ns[0]) and rec.wrist_frame == 'world'
    np.testing.assert_array_equal(rec.start_time_ns + np.round(rec.wrist_t * 1e9).astype(int),
                                  w_ns)
    np.testing.assert_array_equal(rec.start_time_ns + np.round(rec.joint_t * 1e9).astype(int),
                                  j_ns)
    np.testing.assert_array_equal(rec.wrist_xyz, wrist[:, :3])
    np.testing.assert_array_equal(rec.wrist_quat, wrist[:, 3:])
    np.testing.assert_array_equal(rec.joint_q, joint)
    assert (rec.joint_qd is None) == (layout == 'velocity_sometimes')
