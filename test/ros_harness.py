"""The one harness of the node tests: the nodes under test and a probe node on one executor.

The probe publishes the nodes' inputs and records their outputs; ``spin_until`` spins everything
until a condition holds (it fails after a generous timeout, which no test's outcome depends on).
Simulated time is driven by ``set_clock``: a test never waits on the wall clock to see that
something did not happen.
"""

import time

from builtin_interfaces.msg import Time
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.lifecycle import TransitionCallbackReturn
from rosgraph_msgs.msg import Clock

from mixture_ip_ros.core.stamps import ns_to_parts
from mixture_ip_ros.nodes import qos
from mixture_ip_ros.nodes.managed import ManagedNode


def time_msg(ns: int) -> Time:
    sec, nanosec = ns_to_parts(ns)
    return Time(sec=sec, nanosec=nanosec)


class RosHarness:

    def __init__(self, context):
        self.context = context
        self.executor = SingleThreadedExecutor(context=context)
        self.probe = rclpy.create_node('test_probe', context=context)
        self.executor.add_node(self.probe)
        self.nodes = []
        self._clock_pub = None

    def add(self, node, start: bool = True):
        """Spin ``node`` too; a managed node is configured and activated unless ``start`` is
        False."""
        self.executor.add_node(node)
        self.nodes.append(node)
        if start and isinstance(node, ManagedNode):
            for transition in (node.trigger_configure, node.trigger_activate):
                assert transition() == TransitionCallbackReturn.SUCCESS, node.refusal
        return node

    def publisher(self, msg_type, topic: str, profile=None):
        return self.probe.create_publisher(msg_type, topic, profile or qos.reliable(1000))

    def subscribe(self, msg_type, topic: str, profile=None) -> list:
        """A list that receives every message on ``topic``."""
        got = []
        self.probe.create_subscription(msg_type, topic, got.append,
                                       profile or qos.reliable(1000))
        return got

    def spin_until(self, predicate, timeout: float = 30.0, what: str = 'condition'):
        deadline = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > deadline:
                raise AssertionError(f'timed out waiting for {what}')
            self.executor.spin_once(timeout_sec=0.01)

    def matched(self, *publishers):
        """Spin until every publisher has a subscriber."""
        self.spin_until(lambda: all(p.get_subscription_count() > 0 for p in publishers),
                        what='discovery')

    def result(self, future, what: str = 'a service response'):
        self.spin_until(future.done, what=what)
        return future.result()

    def set_clock(self, ns: int, nodes=None):
        """Publish /clock = ``ns`` and spin until every node in ``nodes`` (default: all nodes
        using simulated time) reads at least that time."""
        if self._clock_pub is None:
            self._clock_pub = self.probe.create_publisher(Clock, '/clock', qos.reliable(10))
        watched = [n for n in (self.nodes if nodes is None else nodes)
                   if n.get_parameter('use_sim_time').value]
        self._clock_pub.publish(Clock(clock=time_msg(ns)))
        self.spin_until(lambda: all(n.get_clock().now().nanoseconds >= ns for n in watched),
                        what=f'/clock {ns}')

    def close(self):
        self.executor.shutdown()
        for node in self.nodes:
            node.destroy_node()
        self.probe.destroy_node()
