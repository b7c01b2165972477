"""Spinning nodes: an executable until Ctrl-C or shutdown, or a node in a thread of its own."""

import threading

from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy


def spin_until_shutdown(node, done=None) -> None:
    """Spin ``node`` until Ctrl-C, an external shutdown or ``done()`` returns True.

    On SIGINT rclpy's signal handler shuts the context down: a callback publishing at that
    moment, or the next wait, raises RCLError ('context is invalid'). That is the shutdown,
    not a failure; an RCLError while the context is still valid is re-raised.
    """
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    try:
        while node.context.ok() and not (done is not None and done()):
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except _rclpy.RCLError:
        if node.context.ok():
            raise
    finally:
        executor.shutdown(timeout_sec=0)


def spin_in_thread(node):
    """Spin ``node`` with its own SingleThreadedExecutor in a daemon thread; returns (executor,
    thread). One executor per node: a MultiThreadedExecutor shared by several nodes lets their
    callbacks contend for the GIL and the executor's own bookkeeping, which on a small machine
    slows an in-process simulation far below real time."""
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    thread = threading.Thread(target=executor.spin, daemon=True)
    thread.start()
    return executor, thread
