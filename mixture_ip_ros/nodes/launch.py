"""The executables' entry points. Ctrl-C is a clean exit at any moment, also in the first second,
while a node's module (numpy, rclpy, Pinocchio, MuJoCo, numba) is still being imported and before
rclpy's own signal handling is in place: nothing here is imported until it is needed."""

import importlib


def _run(module: str) -> int:
    try:
        return importlib.import_module(f'mixture_ip_ros.nodes.{module}').main()
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
