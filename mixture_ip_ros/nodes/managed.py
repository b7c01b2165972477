"""Managed (lifecycle) nodes of the package, and the one ``main`` every executable uses.

A managed node declares its parameter schema at construction (so ``describe_parameters`` and
``ros2 param`` work in every state), and then follows the ROS 2 node lifecycle:

- configure: read the parameters, load and check what the node needs (model, scene); a problem
  is logged in one line and the node stays unconfigured;
- activate: subscribe, publish, start timers;
- deactivate: stop at once (no more commands; the node stays configured);
- cleanup: free what configure made; shutdown: clean up from any state.

With the parameter ``autostart`` (default true) :func:`run_node` configures and activates the node
itself, so ``ros2 run``-style use is one command; with false it waits for the lifecycle services
(``mixture-ip lifecycle NODE TRANSITION``).
"""

import signal

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.logging import get_logger
from rclpy.signals import SignalHandlerOptions

from mixture_ip_ros.nodes.params import declare
from mixture_ip_ros.nodes.spinning import spin_until_shutdown

SUCCESS = TransitionCallbackReturn.SUCCESS
FAILURE = TransitionCallbackReturn.FAILURE


class ManagedNode(LifecycleNode):
    """Subclasses set ``SCHEMA`` (a params dataclass with an ``autostart`` field) and implement
    ``configure`` / ``activate`` / ``deactivate`` / ``cleanup``; a ValueError from ``configure``
    or ``activate`` refuses the transition with its message."""

    SCHEMA = None

    def __init__(self, name: str, **kwargs):
        super().__init__(name, **kwargs)
        self.refusal = None         # why the last configure or activate failed
        self.params = declare(self, self.SCHEMA, self.apply_parameters, self.robot_defaults)
        self.add_post_set_parameters_callback(self._log_parameter_change)

    # -- to implement -----------------------------------------------------------------
    def configure(self) -> None:
        pass

    def activate(self) -> None:
        pass

    def deactivate(self) -> None:
        pass

    def cleanup(self) -> None:
        pass

    @staticmethod
    def robot_defaults(robot: str) -> dict:
        """Defaults of the schema's ``from_robot`` fields for the ``robot`` parameter."""
        return {}

    def apply_parameters(self, changes: dict) -> None:
        """Apply accepted run-time parameter changes {name: value}; ValueError refuses them."""
        for name, value in changes.items():
            setattr(self.params, name, value)

    # -- lifecycle ----------------------------------------------------------------------
    @property
    def lifecycle_state(self) -> str:
        return self._state_machine.current_state[1]

    def on_configure(self, state):
        return self._run('configure', self.configure, undo=self.cleanup)

    def on_activate(self, state):
        super().on_activate(state)          # enables the lifecycle publishers
        result = self._run('activate', self.activate, undo=self.deactivate)
        if result != SUCCESS:
            super().on_deactivate(state)
        return result

    def on_deactivate(self, state):
        self.deactivate()
        return super().on_deactivate(state)

    def on_cleanup(self, state):
        self.cleanup()
        return SUCCESS

    def on_shutdown(self, state):
        if state.label == 'active':
            self.on_deactivate(state)
        if state.label in ('active', 'inactive'):
            self.cleanup()
        return SUCCESS

    def on_error(self, state):
        self.get_logger().error(f'error while {state.label}: cleaning up')
        self.cleanup()
        return SUCCESS

    def _run(self, what, step, undo):
        try:
            step()
        except (ValueError, ParameterException) as exc:
            self.refusal = str(exc)
            self.get_logger().error(f'cannot {what}: {exc}')
            undo()
            return FAILURE
        self.refusal = None
        return SUCCESS

    def start(self) -> bool:
        """Configure and activate if ``autostart``; False if a transition failed."""
        if not self.params.autostart:
            self.get_logger().info('autostart is off: waiting for lifecycle transitions '
                                   '(configure, activate)')
            return True
        return (self.trigger_configure() == SUCCESS and self.trigger_activate() == SUCCESS)

    def _log_parameter_change(self, parameters):
        names = {p.name for p in parameters}
        if names & {n for n in vars(self.params)}:
            self.get_logger().info('parameters changed: ' + ', '.join(
                f'{p.name} = {p.value}' for p in parameters))


class _Interrupts:
    """SIGINT and SIGTERM for a node executable: a request, seen by :func:`run_node` once
    start-up is complete and by the spin loop after the callback in progress. Never an
    exception raised wherever the process happens to be: one raised inside rclpy's
    create_subscription (the subscription registered, its event handlers not yet) leaves a node
    whose destroy_node raises. Nor is rclpy's own handler used: it shuts the context down from
    another thread, at any point of a callback, and can leave a node spinning on (SIGINT
    ignored at start, as for a shell's background job) or crash it while it publishes."""

    def __init__(self):
        self.requested = False

    def __call__(self, signum, frame):
        self.requested = True


def run_node(node_class, args=None, done=None) -> int:
    """The ``main`` of every executable: start the node (and its lifecycle, for a managed node
    with ``autostart``), spin until Ctrl-C, SIGTERM, an external shutdown or ``done(node)``,
    and exit 0 (Ctrl-C while it starts: once start-up is complete, without spinning). A node
    that cannot start (bad parameter, missing or invalid file) logs one line and exits 1,
    without a traceback."""
    name = getattr(node_class, 'NODE_NAME', node_class.__name__)
    interrupts = _Interrupts()
    previous = {sig: signal.signal(sig, interrupts) for sig in (signal.SIGINT, signal.SIGTERM)}
    node = None
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
        node = node_class()
        if isinstance(node, ManagedNode) and not node.start():
            get_logger(name).fatal(f'refusing to start: {node.refusal}')
            return 1
        if not interrupts.requested:
            spin_until_shutdown(node, lambda: interrupts.requested or (
                done is not None and done(node)))
        return 0
    except (ValueError, ParameterException) as exc:
        get_logger(name).fatal(f'refusing to start: {exc}')
        return 1
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
