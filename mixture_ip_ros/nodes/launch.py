"""The executables' entry points. Ctrl-C (or SIGTERM) is a clean exit at any moment, also in the
first second, while a node's module (numpy, rclpy, Pinocchio, MuJoCo, numba) is still being
imported: an interrupt there is kept until the import is complete (an exception raised inside a
C extension's initialisation would leave a half-imported module and a traceback), then the
executable exits. Nothing here is imported until it is needed."""

import importlib
import signal


def _run(module: str) -> int:
    requested = []

    def keep(signum, frame):
        requested.append(signum)
    previous = {sig: signal.signal(sig, keep) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        node_main = importlib.import_module(f'mixture_ip_ros.nodes.{module}').main
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if requested:
        return 0
    try:
        return node_main()
    except KeyboardInterrupt:
        return 0


def observer_node() -> int:
    return _run('observer_node')


def estimator_node() -> int:
    return _run('estimator_node')


def sim_node() -> int:
    return _run('sim_node')


def bag_player() -> int:
    return _run('bag_player')
