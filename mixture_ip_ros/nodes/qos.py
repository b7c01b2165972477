"""The QoS profiles of the package's topics, in one place."""

import copy

from rclpy.duration import Duration
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, LivelinessPolicy, QoSProfile,
                       ReliabilityPolicy, qos_profile_sensor_data)


def reliable(depth: int) -> QoSProfile:
    """Commands, observations and events: nothing lost, volatile."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=int(depth),
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)


def command(depth: int, lease: float) -> QoSProfile:
    """Commands to the arm: reliable, and with ``lease`` > 0 (s) DDS liveliness AUTOMATIC with
    that lease: offered by a publisher (asserted by its DDS participant while the process
    runs), requested by a subscriber, which then hears when a publisher is gone. A subscriber
    matches only publishers offering a lease at most as long as the one it requests; 0: no lease
    (any publisher matches, and none is watched)."""
    qos = reliable(depth)
    if lease > 0:
        qos.liveliness = LivelinessPolicy.AUTOMATIC
        qos.liveliness_lease_duration = Duration(nanoseconds=round(lease * 1e9))
    return qos


def sensor_data(depth: int = 5) -> QoSProfile:
    """Motion capture and joint states: best effort (a late sample is worthless), ``depth``
    deep so a burst is not dropped before the callback runs."""
    qos = copy.copy(qos_profile_sensor_data)
    qos.depth = int(depth)
    return qos


def clock() -> QoSProfile:
    """/clock as rclcpp's ClockQoS: best effort, keep last 1 (rclpy's TimeSource subscribes
    with it)."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                      reliability=ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.VOLATILE)
