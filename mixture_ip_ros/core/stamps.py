"""Time stamps as integer nanoseconds: the one conversion between ROS-style stamps (an object
with ``sec`` and ``nanosec``, e.g. builtin_interfaces/Time or a rosbags Time) and ns.

Integers, not float seconds: an epoch stamp in float seconds keeps only ~0.2 us, and two
samples 1 ns apart must still compare as ordered.
"""

from typing import Tuple

NS_PER_S = 1_000_000_000


def stamp_to_ns(stamp) -> int:
    """Nanoseconds of a stamp with ``sec`` and ``nanosec`` fields."""
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def ns_to_parts(ns: int) -> Tuple[int, int]:
    """(sec, nanosec) with 0 <= nanosec < 1e9, as builtin_interfaces/Time wants."""
    sec, nanosec = divmod(int(ns), NS_PER_S)
    return sec, nanosec


def seconds_to_ns(seconds: float) -> int:
    """Nearest nanosecond of a time in float seconds."""
    return int(round(float(seconds) * NS_PER_S))
