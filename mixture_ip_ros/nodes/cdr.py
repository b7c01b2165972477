"""Serialized JointTrajectory and Path messages, filled from numpy arrays.

Built as rclpy message objects, a JointTrajectory is one Python object per point and field, each
checked by its setter: most of the estimator's time before the robot gets its plan
(bench/replan.py measures both ways). Publisher.publish also takes a serialized message, so the
estimator fills a byte template instead, cached per number of points, where only stamps, times
and numbers change.

Encoding: CDR little endian as rmw_fastrtps writes it (encapsulation header 00 01 00 00, each
primitive aligned to its size from the start of the payload, strings as uint32 length with the
terminating NUL). test_cdr checks every layout against rclpy's own deserializer.

The numbers go into the template in one compiled call per message: in the node every callback
follows a wait, and a thread woken from a wait runs each distinct numpy function several times
slower than in a loop (bench/replan.py, 'after_sleep'); a handful of numpy calls per field cost
more than the message.
"""

import struct

import numba
import numpy as np

_ENCAPSULATION = b'\x00\x01\x00\x00'
_NS = 1_000_000_000
_INT32_MIN, _INT32_MAX = -2**31, 2**31 - 1


class _Template:
    """Writes a message's constant bytes and records where the variable fields go."""

    def __init__(self):
        self.buf = bytearray()

    def _at(self, align: int, size: int) -> int:
        start = -len(self.buf) % align + len(self.buf)
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


@numba.njit(cache=True)
def _put_time(u32, i, ns):
    """builtin_interfaces Time at u32[i], u32[i + 1]: int32 sec (floor) and uint32 nanosec;
    False if the seconds are outside int32."""
    sec = ns // _NS
    if sec < _INT32_MIN or sec > _INT32_MAX:
        return False
    u32[i] = sec & 0xFFFFFFFF
    u32[i + 1] = ns - sec * _NS
    return True


@numba.njit(cache=True)
def _fill(u32, f64, value_index, values, stamp_index, stamp_ns, time_index, times_ns):
    """f64[value_index[f, i, j]] = values[f][i, j] for each array f of the tuple ``values``, the
    header stamp at stamp_index and times_ns[i] at time_index[i]; False if a time is outside
    int32 seconds (the buffer is then partly written)."""
    for k in range(len(values)):
        a = values[k]
        for i in range(a.shape[0]):
            for j in range(a.shape[1]):
                f64[value_index[k, i, j]] = a[i, j]
    if not _put_time(u32, stamp_index, stamp_ns):
        return False
    for i in range(times_ns.shape[0]):
        if not _put_time(u32, time_index[i], times_ns[i]):
            return False
    return True


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
        return _ENCAPSULATION + payload.tobytes()

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
        if not _fill(u32, f64, values, values_in, stamp, stamp_ns, times, times_ns):
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
        if not _fill(u32, f64, xyz, (positions,), stamp, stamp_ns, stamps, stamps_ns):
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
