"""Shared fixtures. ROS tests run on a private DDS domain, discovery limited to localhost."""

import os

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('MUJOCO_GL', 'osmesa')

import pytest  # noqa: E402


def private_domain_id(offset: int = 0) -> int:
    """A domain id unlikely to collide with another run on this machine: 100-159, plus
    ``offset`` (< 70) for a second domain in the same test. Fast DDS allows 0-232 only."""
    if not 0 <= offset < 70:
        raise ValueError('offset must be in [0, 70)')
    return 100 + os.getpid() % 60 + offset


@pytest.fixture
def ros_context():
    """A fresh rclpy context on a private domain, shut down after the test."""
    import rclpy
    from rclpy.context import Context

    ctx = Context()
    rclpy.init(context=ctx, domain_id=private_domain_id())
    try:
        yield ctx
    finally:
        rclpy.try_shutdown(context=ctx)
