"""The io layer's fast path: the numbers of a serialized message written into its template
(io.cdr's encoders) in one compiled call. It writes what the encoders' layouts say, as
struct.pack_into('<d') / ('<I') would write each value (test_cdr compares the messages with
rclpy's serialisation, bit for bit for the doubles).
"""

import numba

_NS = 1_000_000_000
_INT32_MIN, _INT32_MAX = -2**31, 2**31 - 1


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
def fill(u32, f64, value_index, values, stamp_index, stamp_ns, time_index, times_ns):
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
