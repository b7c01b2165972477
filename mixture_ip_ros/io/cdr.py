"""CDR, the serialisation of ROS 2 messages, as rmw_fastrtps writes it and rosbag2 stores it:
an encapsulation header (00 01 00 00: little endian), then the payload, each primitive
aligned to its size from the start of the payload, strings as a uint32 length (with the
terminating NUL) and the bytes, sequences as a uint32 count and the elements. One codec for
the nodes (encoding) and the bags (decoding); test_cdr checks every layout against rclpy's own
serialisation, test_bags against rosbags'.

Encoding: JointTrajectory, Path and Float64MultiArray messages filled from numpy arrays.
Built as rclpy message objects, a JointTrajectory is one Python object per point and field,
each checked by its setter: most of the estimator's time before the robot gets its plan.
Publisher.publish also takes a serialized message, so the estimator fills a byte template
instead, cached per number of points, where only stamps, times and numbers change. The numbers
go into the template in one compiled call per message (io._fast.fill): in the node every
callback follows a wait, and a thread woken from a wait runs each distinct numpy function
several times slower than in a loop; a handful of numpy calls per field cost more than the
message.

Decoding: PoseStamped and JointState streams whose messages share one layout (the same size,
frame id and joint names, as a recorder writes them), read as arrays: every field is then at
the same offset of every message (pose_stamped_rows, joint_state_rows); None for any other
stream, which the caller decodes message by message.
"""

import struct
from typing import Optional, Sequence

import numpy as np

from mixture_ip_ros.io._fast import fill

ENCAPSULATION = b'\x00\x01\x00\x00'


def aligned(offset: int, size: int) -> int:
    """The first offset at or after ``offset`` (from the payload start) aligned to ``size``."""
    return -(-offset // size) * size


class _Template:
    """Writes a message's constant bytes and records where the variable fields go."""

    def __init__(self):
        self.buf = bytearray()

    def _at(self, align: int, size: int) -> int:
        start = aligned(len(self.buf), align)
        self.buf.extend(bytes(start + size - len(self.buf)))
        return start

    def u32(self, value: int = 0) -> int:
        o = self._at(4, 4)
        struct.pack_into('<I', self.buf, o, value)
        return o // 4

    def f64(self, value: float = 0.0) -> int:
        o = self._at(8, 8)
        struct.pack_into('<d', self.buf, o, value)
        return o // 8

    def string(self, s: str) -> None:
        data = s.encode() + b'\0'
        self.u32(len(data))
        self.buf[self._at(1, len(data)):] = data

    def time(self) -> int:
        """builtin_interfaces Time/Duration: int32 sec, uint32 nanosec; index of sec (u32)."""
        sec = self.u32()
        self.u32()
        return sec

    def header(self, frame_id: str) -> int:
        stamp = self.time()
        self.string(frame_id)
        return stamp


def _check_shape(name: str, array, shape) -> np.ndarray:
    array = np.ascontiguousarray(array, dtype=float)
    if array.shape != shape:
        raise ValueError(f'{name} must have shape {shape}, got {array.shape}')
    return array


def _int32_error():
    return ValueError('time outside the int32 seconds of builtin_interfaces/Time')


class _Encoder:
    """Layouts cached by message length; ``_layout(n)``: (payload template, index arrays)."""

    def __init__(self):
        self._layouts = {}

    def _buffers(self, n: int):
        """The payload buffer for ``n`` items (the template: every encode writes all of its
        variable fields), its uint32 and float64 views (offsets in the index arrays count from
        the payload start, as CDR's alignment) and the index arrays."""
        layout = self._layouts.get(n)
        if layout is None:
            template, index = self._layout(n)
            payload = np.frombuffer(bytearray(template), dtype=np.uint8)
            size = len(template)
            layout = self._layouts[n] = (
                payload, payload[:size - size % 4].view(np.uint32),
                payload[:size - size % 8].view(np.float64), index)
        return layout

    @staticmethod
    def _message(payload) -> bytes:
        return ENCAPSULATION + payload.tobytes()

    def _layout(self, n: int):
        raise NotImplementedError


class JointTrajectoryEncoder(_Encoder):
    """trajectory_msgs/JointTrajectory with positions, velocities and accelerations per point
    (no efforts), for fixed joint names and header frame_id."""

    def __init__(self, joint_names, frame_id: str = ''):
        super().__init__()
        self.joint_names = [str(name) for name in joint_names]
        self.frame_id = str(frame_id)

    def _layout(self, n: int):
        t = _Template()
        stamp = t.header(self.frame_id)
        t.u32(len(self.joint_names))
        for name in self.joint_names:
            t.string(name)
        t.u32(n)
        q = len(self.joint_names)
        values = np.empty((3, n, q), dtype=np.intp)
        times = np.empty(n, dtype=np.intp)
        for i in range(n):
            for field in range(3):   # positions, velocities, accelerations
                t.u32(q)
                for j in range(q):
                    values[field, i, j] = t.f64()
            t.u32(0)                 # effort: empty
            times[i] = t.time()
        return bytes(t.buf), (stamp, values, times)

    def encode(self, stamp_ns: int, times_ns, positions, velocities, accelerations) -> bytes:
        """The serialized message; ``times_ns`` (n,) time_from_start in integer nanoseconds,
        the others (n, Q) in the order of ``joint_names``."""
        times_ns = np.ascontiguousarray(times_ns, dtype=np.int64)
        n = times_ns.shape[0]
        shape = (n, len(self.joint_names))
        values_in = tuple(_check_shape(name, a, shape) for name, a in (
            ('positions', positions), ('velocities', velocities),
            ('accelerations', accelerations)))
        buf, u32, f64, (stamp, values, times) = self._buffers(n)
        if not fill(u32, f64, values, values_in, stamp, stamp_ns, times, times_ns):
            raise _int32_error()
        return self._message(buf)


class PathEncoder(_Encoder):
    """nav_msgs/Path of positions (orientation identity), every pose in ``frame_id``."""

    def __init__(self, frame_id: str):
        super().__init__()
        self.frame_id = str(frame_id)

    def _layout(self, n: int):
        t = _Template()
        stamp = t.header(self.frame_id)
        t.u32(n)
        stamps = np.empty(n, dtype=np.intp)
        xyz = np.empty((1, n, 3), dtype=np.intp)
        for i in range(n):
            stamps[i] = t.header(self.frame_id)
            for j in range(3):
                xyz[0, i, j] = t.f64()
            for value in (0.0, 0.0, 0.0, 1.0):
                t.f64(value)
        return bytes(t.buf), (stamp, stamps, xyz)

    def encode(self, stamp_ns: int, stamps_ns, positions) -> bytes:
        """The serialized message; ``stamps_ns`` (n,) pose stamps, ``positions`` (n, 3)."""
        stamps_ns = np.ascontiguousarray(stamps_ns, dtype=np.int64)
        positions = _check_shape('positions', positions, (stamps_ns.shape[0], 3))
        buf, u32, f64, (stamp, stamps, xyz) = self._buffers(stamps_ns.shape[0])
        if not fill(u32, f64, xyz, (positions,), stamp, stamp_ns, stamps, stamps_ns):
            raise _int32_error()
        return self._message(buf)


class Float64MultiArrayEncoder(_Encoder):
    """std_msgs/Float64MultiArray of one dimension labelled ``label`` (size = stride = the
    number of values, data_offset 0)."""

    def __init__(self, label: str):
        super().__init__()
        self.label = str(label)

    def _layout(self, n: int):
        t = _Template()
        t.u32(1)                     # layout.dim: one MultiArrayDimension
        t.string(self.label)
        t.u32(n)                     # size
        t.u32(n)                     # stride
        t.u32(0)                     # layout.data_offset
        t.u32(n)
        first = t.f64() if n else 0
        for _ in range(n - 1):
            t.f64()
        return bytes(t.buf), first

    def encode(self, data) -> bytes:
        """The serialized message of ``data`` (n,)."""
        data = np.asarray(data, dtype=float)
        if data.ndim != 1:
            raise ValueError(f'data must be one-dimensional, got shape {data.shape}')
        buf, _, f64, first = self._buffers(data.shape[0])
        f64[first:first + data.shape[0]] = data
        return self._message(buf)


class _Reader:
    """Reads a payload's fields in order, as _Template writes them; offsets from the payload
    start. Raises ValueError past the end of the payload or for a string that is not UTF-8."""

    def __init__(self, payload: bytes):
        self.data = payload
        self.offset = 0

    def _at(self, align: int, size: int) -> int:
        start = aligned(self.offset, align)
        if start + size > len(self.data):
            raise ValueError('past the end of the message')
        self.offset = start + size
        return start

    def u32(self) -> int:
        o = self._at(4, 4)
        return int.from_bytes(self.data[o:o + 4], 'little')

    def string(self) -> str:
        length = self.u32()
        o = self._at(1, length)
        return self.data[o:o + length].rstrip(b'\0').decode()

    def header(self) -> str:
        """std_msgs Header: the stamp (skipped: see header_stamps) and the frame_id."""
        self._at(4, 8)
        return self.string()

    def f64_sequence(self):
        """A float64[]: (offset of its count, offset of its first element, its length)."""
        count = self._at(4, 4)
        n = int.from_bytes(self.data[count:count + 4], 'little')
        first = self._at(8, 8 * n) if n else self.offset
        return count, first, n


def _same_size_rows(messages) -> Optional[np.ndarray]:
    """The messages' payloads as one (n, size) uint8 array, or None unless they are all
    little-endian CDR of one size."""
    size = len(messages[0])
    if (size < len(ENCAPSULATION) or any(len(data) != size for data in messages)
            or bytes(messages[0][:len(ENCAPSULATION)]) != ENCAPSULATION):
        return None
    rows = np.frombuffer(b''.join(bytes(data) for data in messages), dtype=np.uint8)
    return rows.reshape(len(messages), size)[:, len(ENCAPSULATION):]


def _field(rows, offset: int, dtype: str, count: int = 1):
    """``count`` values of ``dtype`` at ``offset`` of every row: (n, count)."""
    width = np.dtype(dtype).itemsize * count
    return np.ascontiguousarray(rows[:, offset:offset + width]).view(dtype)


def _header_stamps(rows) -> np.ndarray:
    """header.stamp of every row in ns (int32 sec, uint32 nanosec: the payload's first field)."""
    return (_field(rows, 0, '<i4')[:, 0].astype(np.int64) * 1_000_000_000
            + _field(rows, 4, '<u4')[:, 0].astype(np.int64))


def _constant(rows, lo: int, hi: int) -> bool:
    return bool((rows[:, lo:hi] == rows[0, lo:hi]).all())


def pose_stamped_rows(messages: Sequence[bytes]):
    """geometry_msgs/PoseStamped messages that share one layout (the same size and frame id)
    as arrays: (header stamps ns (n,), positions (n, 3), orientations (n, 4) x y z w, frame id);
    None for any other messages."""
    rows = _same_size_rows(messages)
    if rows is None:
        return None
    reader = _Reader(bytes(rows[0]))
    try:
        frame = reader.header()
        end_of_frame = reader.offset
        pose = reader._at(8, 56)                 # position x y z, orientation x y z w
    except ValueError:
        return None
    if reader.offset != rows.shape[1] or not _constant(rows, 8, end_of_frame):
        return None
    values = _field(rows, pose, '<f8', 7)
    return _header_stamps(rows), values[:, :3].copy(), values[:, 3:].copy(), frame


def joint_state_rows(messages: Sequence[bytes], joint_names: Sequence[str]):
    """sensor_msgs/JointState messages that share one layout (the same size, frame id and
    names, and as many positions as names) as arrays: (header stamps ns (n,), positions of
    ``joint_names`` (n, len(joint_names)), their velocities or None where the messages have
    none); None for any other messages."""
    rows = _same_size_rows(messages)
    if rows is None:
        return None
    reader = _Reader(bytes(rows[0]))
    try:
        reader.header()
        names = [reader.string() for _ in range(reader.u32())]
        (p_count, p_start, n_pos), (v_count, v_start, n_vel), (e_count, _, _) = (
            reader.f64_sequence() for _ in range(3))          # position, velocity, effort
    except ValueError:
        return None
    if (reader.offset != rows.shape[1] or n_pos != len(names)
            or not set(joint_names) <= set(names) or not _constant(rows, 8, p_start)
            or not _constant(rows, v_count, v_count + 4)
            or not _constant(rows, e_count, e_count + 4)):
        return None
    index = [names.index(n) for n in joint_names]
    q = _field(rows, p_start, '<f8', n_pos)[:, index]
    qd = _field(rows, v_start, '<f8', n_vel)[:, index] if n_vel == len(names) else None
    return _header_stamps(rows), q, qd
