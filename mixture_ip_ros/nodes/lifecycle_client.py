"""Drive a managed node through its lifecycle services (what ``ros2 lifecycle set`` does; ros2cli
is not installable from PyPI): ``<node>/get_state`` and ``<node>/change_state`` of
lifecycle_msgs."""

from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
import rclpy
from rclpy.executors import SingleThreadedExecutor

TRANSITIONS = ('configure', 'activate', 'deactivate', 'cleanup', 'shutdown')


class LifecycleClient:
    """Service clients of one managed node, on a node of the caller's. ``state`` and ``change``
    block and spin their own executor (the caller's node must not be spun elsewhere at the same
    time); the ``*_async`` ones return futures for a caller that spins its own executor."""

    def __init__(self, node, target: str):
        self.node = node
        self.target = target.rstrip('/')
        if not self.target.startswith('/'):
            self.target = '/' + self.target
        self._get = node.create_client(GetState, f'{self.target}/get_state')
        self._change = node.create_client(ChangeState, f'{self.target}/change_state')
        self._executor = SingleThreadedExecutor(context=node.context)

    def destroy(self) -> None:
        self.node.destroy_client(self._get)
        self.node.destroy_client(self._change)
        self._executor.shutdown(timeout_sec=0)

    def state_async(self):
        """A future of the GetState response (the caller spins until it is done)."""
        return self._get.call_async(GetState.Request())

    def change_async(self, transition: str):
        """A future of the ChangeState response for ``transition`` (one of TRANSITIONS)."""
        if transition not in TRANSITIONS:
            raise ValueError(f'unknown transition {transition!r}; one of {TRANSITIONS}')
        return self._change.call_async(ChangeState.Request(transition=Transition(
            label=transition)))

    def _wait(self, client, future, timeout: float):
        self._executor.add_node(self.node)
        try:
            rclpy.spin_until_future_complete(self.node, future, executor=self._executor,
                                             timeout_sec=timeout)
        finally:
            self._executor.remove_node(self.node)
        if not future.done():
            raise TimeoutError(f'{client.srv_name} did not answer within {timeout} s')
        return future.result()

    def _ready(self, client, timeout):
        if not client.wait_for_service(timeout_sec=timeout):
            raise TimeoutError(f'{client.srv_name} is not available (is {self.target} running?)')

    def state(self, timeout: float = 10.0) -> str:
        """The node's current state label ('unconfigured', 'inactive', 'active', ...)."""
        self._ready(self._get, timeout)
        return self._wait(self._get, self.state_async(), timeout).current_state.label

    def change(self, transition: str, timeout: float = 10.0) -> bool:
        """Trigger ``transition``; True if the node performed it."""
        self._ready(self._change, timeout)
        return bool(self._wait(self._change, self.change_async(transition), timeout).success)
