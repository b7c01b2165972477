"""The executables' entry points. Ctrl-C (or SIGTERM) is a clean exit at any moment, also in the
first second, while a node's module (numpy, rclpy, Pinocchio, MuJoCo, numba) is still being
imported: an interrupt there is kept until the import is complete (an exception raised inside a
C extension's initialisation would leave a half-imported module and a traceback), then the
executable exits. Nothing here is imported until it is needed.

Each executable first sets its own process's environment (:func:`set_process_defaults`), before
numpy and numba are imported: both read it once, when they load. Importing the package changes
no environment."""

import importlib
import os
import signal

from mixture_ip_ros.io.cache import cache_dir


def set_process_defaults() -> None:
    """The environment the executables run in; a value the user set is kept. To be called
    before numpy (BLAS) and numba are imported.

    - One BLAS / OpenMP thread: every matrix here is small (at most a few hundred rows), so more
      threads only add overhead and contend with the nodes' own threads.
    - numba's compiled kernels cached in the user's cache folder (io.cache.cache_dir()/numba):
      by default numba writes them next to their source, which for an installed package is a
      system folder (unwritable, or shared between users)."""
    for name in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
        os.environ.setdefault(name, '1')
    os.environ.setdefault('NUMBA_CACHE_DIR', str(cache_dir() / 'numba'))


def _run(module: str) -> int:
    set_process_defaults()
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
