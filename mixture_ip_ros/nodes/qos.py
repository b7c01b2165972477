"""The QoS profiles of the package's topics, in one place."""

import copy

from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy,
                       qos_profile_sensor_data)


def reliable(depth: int) -> QoSProfile:
    """Commands, observations and events: nothing lost, volatile."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=int(depth),
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)


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
