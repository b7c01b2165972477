"""rosbag2 demonstration bags, written and read with the pure-Python `rosbags` library.

One bag is one demonstration: the human wrist as ``geometry_msgs/msg/PoseStamped`` (default
``/mocap/wrist``, frame ``world``) and the robot as ``sensor_msgs/msg/JointState`` (default
``/joint_states``, joints ``iiwa_joint_1`` .. ``iiwa_joint_7``). Bags are rosbag2 format version 9
(what ``ros2 bag`` on Jazzy writes), mcap storage by default or sqlite3, with the Jazzy type store so
message definitions and type hashes match the installed ROS 2 message packages.

Times are header stamps (the sensor's acquisition time); a message whose stamp is zero falls back to
the bag's receive (log) time. An occlusion is a stretch without wrist messages, exactly like a mocap
driver that stops publishing while the marker is hidden.

The pattern label (evaluation only, no learner may read it) is stored in the bag's metadata
``custom_data`` under the key ``mixture_ip_ros.label``, not on a topic: a player replaying the bag then
cannot leak it to the estimator, and ``ros2 bag`` keeps it when it rewrites metadata. Where the
demonstration's movement interval is known (an annotated data set, a generated scenario), its
onset and end stamps (ns) are kept there too (``mixture_ip_ros.onset_ns`` / ``end_ns``), for
training to cut the demonstration where its annotator did (io.dataset, ``cut='recorded'``).

Every problem with a bag (not a bag, missing topic, empty topic, wrong message type, unreadable or
truncated storage, undecodable message, joints missing from the JointState) raises :class:`BagError`
(a ``ValueError``) that names the bag and the problem.
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Optional, Sequence

import numpy as np
import yaml

from mixture_ip_ros.core.stamps import ns_to_parts, stamp_to_ns
from mixture_ip_ros.io import cdr
from mixture_ip_ros.robot.description import JOINT_NAMES

WRIST_TOPIC = '/mocap/wrist'
JOINT_TOPIC = '/joint_states'
WRIST_TYPE = 'geometry_msgs/msg/PoseStamped'
JOINT_TYPE = 'sensor_msgs/msg/JointState'
LABEL_KEY = 'mixture_ip_ros.label'
ONSET_KEY = 'mixture_ip_ros.onset_ns'
END_KEY = 'mixture_ip_ros.end_ns'
STORAGES = ('mcap', 'sqlite3')
BAG_VERSION = 9
# Deterministic default start (2023-11-14T22:13:20Z) so a seeded scenario gives byte-identical bags.
DEFAULT_START_TIME_NS = 1_700_000_000 * 10**9


class BagError(ValueError):
    """A bag that cannot be used, with the bag path and what is wrong with it."""

    def __init__(self, bag, problem: str):
        self.bag = str(bag)
        self.problem = problem
        super().__init__(f'bag {self.bag}: {problem}')


@dataclass
class RawRecording:
    """The two streams of one bag as recorded (no resampling, no frame change).

    Times are seconds since ``start_time_ns`` (the earliest stamp of either stream), so
    ``start_time_ns + round(t * 1e9)`` is the original stamp. Wrist quaternions are (x, y, z, w).
    """

    wrist_t: np.ndarray
    wrist_xyz: np.ndarray
    wrist_quat: np.ndarray
    wrist_frame: str
    joint_t: np.ndarray
    joint_q: np.ndarray
    joint_names: tuple
    label: Optional[str]
    start_time_ns: int = 0
    joint_qd: Optional[np.ndarray] = None
    custom_data: Optional[dict] = None


@dataclass(frozen=True)
class BagMessage:
    """One serialized (CDR) message as stored in a bag."""

    topic: str
    msgtype: str
    log_time_ns: int
    data: bytes


def typestore():
    """The ROS 2 Jazzy type store (cached): message definitions and RIHS01 hashes of Jazzy."""
    global _TYPESTORE
    if _TYPESTORE is None:
        from rosbags.typesys import Stores, get_typestore
        _TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
    return _TYPESTORE


_TYPESTORE = None


def sensor_data_qos():
    """rosbags QoS equal to rclpy's qos_profile_sensor_data (best effort, keep last 5, volatile)."""
    from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness,
                                    QosReliability, QosTime)
    return Qos(QosHistory.KEEP_LAST, 5, QosReliability.BEST_EFFORT, QosDurability.VOLATILE,
               QosTime(0, 0), QosTime(0, 0), QosLiveliness.SYSTEM_DEFAULT, QosTime(0, 0), False)


def reliable_qos(depth: int = 10):
    """rosbags QoS of a default rclpy publisher (reliable, keep last, volatile)."""
    from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness,
                                    QosReliability, QosTime)
    return Qos(QosHistory.KEEP_LAST, depth, QosReliability.RELIABLE, QosDurability.VOLATILE,
               QosTime(0, 0), QosTime(0, 0), QosLiveliness.SYSTEM_DEFAULT, QosTime(0, 0), False)


# ----------------------------------------------------------------------------------------- writing

def _stamp_ns(start_time_ns: int, t: np.ndarray) -> np.ndarray:
    return start_time_ns + np.round(np.asarray(t, dtype=float) * 1e9).astype(np.int64)


def _check_times(name: str, t: np.ndarray) -> np.ndarray:
    t = np.asarray(t, dtype=float)
    if t.ndim != 1:
        raise ValueError(f'{name} must be 1-D, got shape {t.shape}')
    if not np.all(np.isfinite(t)):
        raise ValueError(f'{name} contains NaN or Inf')
    if t.size and np.any(np.diff(t) <= 0):
        raise ValueError(f'{name} must be strictly increasing')
    if t.size and t[0] < 0:
        raise ValueError(f'{name} must be >= 0 (seconds since start_time_ns), got {t[0]}')
    return t


def write_demonstration_bag(path, wrist_t, wrist_xyz, joint_t, joint_q, *,
                            storage: str = 'mcap',
                            label: Optional[str] = None,
                            wrist_topic: str = WRIST_TOPIC,
                            joint_topic: str = JOINT_TOPIC,
                            frame_id: str = 'world',
                            joint_names: Sequence[str] = JOINT_NAMES,
                            wrist_quat=None,
                            joint_qd=None,
                            start_time_ns: int = DEFAULT_START_TIME_NS,
                            custom_data: Optional[Mapping[str, str]] = None,
                            segment: Optional[tuple] = None) -> Path:
    """Write one demonstration as a rosbag2 (version 9) directory at ``path`` and return it.

    ``wrist_t`` (N,) and ``joint_t`` (M,) are seconds since ``start_time_ns``; ``wrist_xyz`` (N, 3)
    metres in ``frame_id``; wrist rows that are NaN are not written (occlusion = no message).
    ``joint_q`` (M, J) radians, optional ``joint_qd`` (M, J) rad/s. ``segment``: the movement's
    (onset, end), seconds on the same time base, where it is known. ``path`` must not exist.
    """
    from rosbags.rosbag2 import StoragePlugin, Writer, WriterError

    path = Path(path)
    if storage not in STORAGES:
        raise ValueError(f'storage must be one of {STORAGES}, got {storage!r}')
    if path.exists():
        raise FileExistsError(f'{path} exists already; not overwriting a bag')
    wrist_t = _check_times('wrist_t', wrist_t)
    joint_t = _check_times('joint_t', joint_t)
    wrist_xyz = np.asarray(wrist_xyz, dtype=float)
    if wrist_xyz.shape != (wrist_t.size, 3):
        raise ValueError(f'wrist_xyz must have shape ({wrist_t.size}, 3), got {wrist_xyz.shape}')
    if wrist_quat is None:
        wrist_quat = np.tile([0.0, 0.0, 0.0, 1.0], (wrist_t.size, 1))
    wrist_quat = np.asarray(wrist_quat, dtype=float)
    if wrist_quat.shape != (wrist_t.size, 4):
        raise ValueError(f'wrist_quat must have shape ({wrist_t.size}, 4) as (x, y, z, w), '
                         f'got {wrist_quat.shape}')
    joint_names = tuple(str(n) for n in joint_names)
    joint_q = np.asarray(joint_q, dtype=float)
    if joint_q.shape != (joint_t.size, len(joint_names)):
        raise ValueError(f'joint_q must have shape ({joint_t.size}, {len(joint_names)}), '
                         f'got {joint_q.shape}')
    if not np.all(np.isfinite(joint_q)):
        raise ValueError('joint_q contains NaN or Inf')
    if joint_qd is not None:
        joint_qd = np.asarray(joint_qd, dtype=float)
        if joint_qd.shape != joint_q.shape or not np.all(np.isfinite(joint_qd)):
            raise ValueError(f'joint_qd must be finite with the shape of joint_q {joint_q.shape}')
    present = ~np.isnan(wrist_xyz).any(axis=1)
    if np.any(np.isinf(wrist_xyz)):
        raise ValueError('wrist_xyz contains Inf (use NaN rows for occlusion)')
    if not present.any():
        raise ValueError('wrist_xyz has no observed sample')
    if joint_t.size == 0:
        raise ValueError('joint_t is empty')
    if wrist_topic == joint_topic:
        raise ValueError(f'wrist and joint topics must differ, both are {wrist_topic!r}')
    custom_data = dict(custom_data or {})
    if segment is not None:
        onset, end = (float(x) for x in segment)
        if not (np.isfinite(onset) and np.isfinite(end) and onset < end):
            raise ValueError(f'segment must be a finite (onset, end) with onset < end, '
                             f'got {segment!r}')
        onset_ns, end_ns = _stamp_ns(start_time_ns, [onset, end])
        custom_data.update({ONSET_KEY: str(int(onset_ns)), END_KEY: str(int(end_ns))})

    ts = typestore()
    Time = ts.types['builtin_interfaces/msg/Time']
    Header = ts.types['std_msgs/msg/Header']
    PoseStamped = ts.types[WRIST_TYPE]
    Pose = ts.types['geometry_msgs/msg/Pose']
    Point = ts.types['geometry_msgs/msg/Point']
    Quaternion = ts.types['geometry_msgs/msg/Quaternion']
    JointState = ts.types[JOINT_TYPE]
    empty = np.zeros(0, dtype=np.float64)

    records = []  # (stamp_ns, order, topic, cdr)
    for k, ns in zip(np.flatnonzero(present), _stamp_ns(start_time_ns, wrist_t[present])):
        ns = int(ns)
        p, q = wrist_xyz[k], wrist_quat[k]
        msg = PoseStamped(
            header=Header(stamp=Time(*ns_to_parts(ns)), frame_id=frame_id),
            pose=Pose(position=Point(x=float(p[0]), y=float(p[1]), z=float(p[2])),
                      orientation=Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]),
                                             w=float(q[3]))))
        records.append((ns, 0, 'wrist', ts.serialize_cdr(msg, WRIST_TYPE)))
    for k, ns in enumerate(_stamp_ns(start_time_ns, joint_t)):
        ns = int(ns)
        msg = JointState(
            header=Header(stamp=Time(*ns_to_parts(ns)), frame_id=''),
            name=list(joint_names), position=joint_q[k].copy(),
            velocity=joint_qd[k].copy() if joint_qd is not None else empty, effort=empty)
        records.append((ns, 1, 'joint', ts.serialize_cdr(msg, JOINT_TYPE)))
    records.sort(key=lambda r: (r[0], r[1]))  # a recorder writes in arrival order

    plugin = StoragePlugin.MCAP if storage == 'mcap' else StoragePlugin.SQLITE3
    writer = Writer(path, version=BAG_VERSION, storage_plugin=plugin)
    try:
        for key, value in custom_data.items():
            writer.set_custom_data(str(key), str(value))
        if label is not None:
            writer.set_custom_data(LABEL_KEY, str(label))
        writer.open()
        conns = {
            'wrist': writer.add_connection(wrist_topic, WRIST_TYPE, typestore=ts,
                                           offered_qos_profiles=[sensor_data_qos()]),
            'joint': writer.add_connection(joint_topic, JOINT_TYPE, typestore=ts,
                                           offered_qos_profiles=[reliable_qos()]),
        }
        for ns, _, which, data in records:
            writer.write(conns[which], ns, data)
        writer.close()
    except WriterError as exc:
        raise ValueError(f'cannot write bag {path}: {exc}') from exc
    return path


# ----------------------------------------------------------------------------------------- reading

def _open_reader(path: Path):
    from rosbags.rosbag2 import Reader
    if not path.exists():
        raise BagError(path, 'does not exist')
    if path.is_dir() and not (path / 'metadata.yaml').is_file():
        if any(path.glob('*.mcap')) or any(path.glob('*.db3')):
            raise BagError(path, 'metadata.yaml is missing (recording not closed cleanly? '
                                 '`ros2 bag reindex` can rebuild it)')
        raise BagError(path, 'not a rosbag2 bag directory (no metadata.yaml)')
    try:
        reader = Reader(path)
        reader.open()
    except BagError:
        raise
    except Exception as exc:  # rosbags raises many types on damaged files
        raise BagError(path, f'cannot open bag: {type(exc).__name__}: {exc}') from exc
    return reader


@contextmanager
def _reading(path: Path):
    """An open reader of ``path``; any failure while reading becomes a BagError naming it."""
    reader = _open_reader(path)
    try:
        yield reader
    except BagError:
        raise
    except Exception as exc:  # rosbags raises many types on truncated or corrupt storage
        raise BagError(path, f'cannot read messages (truncated or corrupt storage?): '
                             f'{type(exc).__name__}: {exc}') from exc
    finally:
        reader.close()


# libyaml's safe loader where PyYAML was built with it (the same documents, parsed in C).
_YAML_LOADER = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)


def bag_custom_data(path) -> dict:
    """The ``custom_data`` map of a bag directory's metadata.yaml ({} if none)."""
    path = Path(path)
    meta = path / 'metadata.yaml'
    if not meta.is_file():
        return {}
    try:
        info = yaml.load(meta.read_text(), Loader=_YAML_LOADER)['rosbag2_bagfile_information']
    except Exception as exc:
        raise BagError(path, f'unreadable metadata.yaml: {exc}') from exc
    custom = info.get('custom_data') or {}
    if not isinstance(custom, dict):
        raise BagError(path, f'custom_data in metadata.yaml is not a map: {custom!r}')
    return {str(k): str(v) for k, v in custom.items()}


def bag_topics(path) -> dict:
    """{topic: (msgtype, message count)} of a bag."""
    path = Path(path)
    reader = _open_reader(path)
    try:
        return {c.topic: (c.msgtype, c.msgcount) for c in reader.connections}
    finally:
        reader.close()


def read_messages(path, topics: Optional[Sequence[str]] = None) -> list:
    """All messages of a bag (optionally only ``topics``) as :class:`BagMessage`, in log-time order."""
    path = Path(path)
    with _reading(path) as reader:
        conns = reader.connections
        if topics is not None:
            missing = sorted(set(topics) - {c.topic for c in conns})
            if missing:
                raise BagError(path, f'topics {missing} not in bag (has {_topic_list(conns)})')
            conns = [c for c in conns if c.topic in set(topics)]
        out = [BagMessage(c.topic, c.msgtype, int(ns), bytes(data))
               for c, ns, data in reader.messages(connections=conns)]
    out.sort(key=lambda m: m.log_time_ns)
    return out


def _topic_list(conns) -> str:
    return ', '.join(sorted(f'{c.topic} [{c.msgtype}]' for c in conns)) or 'no topics'


def _find_connection(path, conns, topic, msgtype):
    matching = [c for c in conns if c.topic == topic]
    if not matching:
        raise BagError(path, f'topic {topic!r} not in bag (has {_topic_list(conns)})')
    wrong = [c.msgtype for c in matching if c.msgtype != msgtype]
    if wrong:
        raise BagError(path, f'topic {topic!r} has message type {wrong[0]}, expected {msgtype}')
    return matching


def _stamp_or_log(stamp, log_ns: int) -> int:
    ns = stamp_to_ns(stamp)
    return ns if ns > 0 else log_ns


def _stamps_or_log(ns: np.ndarray, msgs) -> np.ndarray:
    """:func:`_stamp_or_log` of every message: header stamps ``ns`` (n,), the log time of the
    message (conn, log_ns, data) where a stamp is 0."""
    return np.where(ns > 0, ns, np.asarray([log_ns for _, log_ns, _ in msgs], dtype=np.int64))


def read_bag(path, *, wrist_topic: str = WRIST_TOPIC, joint_topic: str = JOINT_TOPIC,
             joint_names: Sequence[str] = JOINT_NAMES) -> RawRecording:
    """Read one demonstration bag (directory, or a bare .mcap/.db3 file) into a :class:`RawRecording`.

    Joints are picked by name from each JointState, in the order of ``joint_names`` (extra joints,
    e.g. a gripper, are ignored). Raises :class:`BagError` for any unusable bag.
    """
    path = Path(path)
    joint_names = tuple(joint_names)
    custom = bag_custom_data(path) if path.is_dir() else {}
    with _reading(path) as reader:
        conns = reader.connections
        wrist_conns = _find_connection(path, conns, wrist_topic, WRIST_TYPE)
        joint_conns = _find_connection(path, conns, joint_topic, JOINT_TYPE)
        wrist_ids = {c.id for c in wrist_conns}
        wrist_msgs, joint_msgs = [], []
        for conn, log_ns, data in reader.messages(connections=wrist_conns + joint_conns):
            (wrist_msgs if conn.id in wrist_ids else joint_msgs).append((conn, log_ns, data))
    if not wrist_msgs:
        raise BagError(path, f'topic {wrist_topic!r} has no messages')
    if not joint_msgs:
        raise BagError(path, f'topic {joint_topic!r} has no messages')
    # A recorder writes one topic's messages with one layout (the same frame id and joint
    # names): then every field is at the same offset of every message and the whole stream is
    # read as one array; any other stream is decoded message by message.
    wrist = cdr.pose_stamped_rows([data for _, _, data in wrist_msgs])
    if wrist is None:
        w_ns, w_xyz, w_quat, frames = _decode_poses(path, wrist_msgs)
    else:
        w_ns, w_xyz, w_quat, frame = wrist
        w_ns, frames = _stamps_or_log(w_ns, wrist_msgs), {frame}
    joints = cdr.joint_state_rows([data for _, _, data in joint_msgs], joint_names)
    if joints is None:
        j_ns, j_q, qd = _decode_joint_states(path, joint_msgs, joint_names, joint_topic)
    else:
        j_ns, j_q, qd = joints
        j_ns = _stamps_or_log(j_ns, joint_msgs)
    if len(frames) > 1:
        raise BagError(path, f'wrist messages on {wrist_topic!r} use several frames {sorted(frames)}')
    if not np.all(np.isfinite(j_q)):
        raise BagError(path, f'joint positions on {joint_topic!r} contain NaN or Inf')
    # Sort by stamp (stamps can arrive out of order) and drop repeated stamps.
    w_order = _unique_sorted(w_ns)
    j_order = _unique_sorted(j_ns)
    w_ns, w_xyz, w_quat = w_ns[w_order], w_xyz[w_order], w_quat[w_order]
    j_ns, j_q = j_ns[j_order], j_q[j_order]
    if qd is not None:
        qd = qd[j_order]
    start = int(min(w_ns[0], j_ns[0]))
    return RawRecording(
        wrist_t=(w_ns - start) / 1e9, wrist_xyz=w_xyz, wrist_quat=w_quat,
        wrist_frame=frames.pop(), joint_t=(j_ns - start) / 1e9, joint_q=j_q,
        joint_names=joint_names, label=custom.get(LABEL_KEY), start_time_ns=start,
        joint_qd=qd, custom_data=custom)


def _deserialize(path, conn, log_ns, data):
    try:
        return typestore().deserialize_cdr(data, conn.msgtype)
    except Exception as exc:
        raise BagError(path, f'cannot decode a {conn.msgtype} message on {conn.topic} at '
                             f'log time {log_ns} ns: {type(exc).__name__}: {exc}') from exc


def _decode_poses(path, msgs):
    """(stamps ns, xyz, quaternions, set of frames) of PoseStamped messages, one by one."""
    ns, xyz, quat, frames = [], [], [], set()
    for conn, log_ns, data in msgs:
        msg = _deserialize(path, conn, log_ns, data)
        p, q = msg.pose.position, msg.pose.orientation
        ns.append(_stamp_or_log(msg.header.stamp, log_ns))
        xyz.append((p.x, p.y, p.z))
        quat.append((q.x, q.y, q.z, q.w))
        frames.add(msg.header.frame_id)
    return (np.asarray(ns, dtype=np.int64), np.asarray(xyz, dtype=float),
            np.asarray(quat, dtype=float), frames)


def _decode_joint_states(path, msgs, joint_names, joint_topic):
    """(stamps ns, positions of ``joint_names``, their velocities or None) of JointState
    messages, one by one."""
    ns, qs, qds = [], [], []
    index = last_names = None
    for conn, log_ns, data in msgs:
        msg = _deserialize(path, conn, log_ns, data)
        names = list(msg.name)
        if names != last_names:
            missing = [n for n in joint_names if n not in names]
            if missing:
                raise BagError(path, f'JointState on {joint_topic!r} lacks joints {missing} '
                                     f'(has {names})')
            index = [names.index(n) for n in joint_names]
            last_names = names
        pos = np.asarray(msg.position, dtype=float)
        if pos.size != len(names):
            raise BagError(path, f'JointState on {joint_topic!r} at log time {log_ns} ns has '
                                 f'{pos.size} positions for {len(names)} names')
        vel = np.asarray(msg.velocity, dtype=float)
        ns.append(_stamp_or_log(msg.header.stamp, log_ns))
        qs.append(pos[index])
        qds.append(vel[index] if vel.size == len(names) else None)
    qd = np.asarray(qds, dtype=float) if all(v is not None for v in qds) else None
    return np.asarray(ns, dtype=np.int64), np.asarray(qs, dtype=float), qd


def _unique_sorted(ns: np.ndarray) -> np.ndarray:
    order = np.argsort(ns, kind='stable')
    keep = np.ones(order.size, dtype=bool)
    keep[1:] = np.diff(ns[order]) > 0
    return order[keep]
