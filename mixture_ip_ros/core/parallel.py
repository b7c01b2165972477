"""Independent pieces of training's work (cross-validation folds) side by side on the cores
this process may use.

Threads, not processes: the work is the estimator's compiled kernels (numba, nogil) and
LAPACK, which run without the interpreter lock, and a thread shares the recordings and the
compiled kernels where a worker process would import the package and be sent the data first
(most of a fold's second). A process forked from one that ran ROS nodes can also crash in
their threads' objects (app.evaluation.interactions._run forks from a server instead). Each
piece writes only its own results and they come back in the order of the items, so the
result is the same whatever the number of threads. A piece that draws random numbers seeds
its own generator (an integer random_state), never a generator shared with the others.
"""

import operator
import os
import threading
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path


def available_cores(cgroup: Path = Path('/sys/fs/cgroup/cpu.max')) -> int:
    """The number of cores this process may run on: its CPU affinity, or fewer where its
    control group's CPU quota allows less (a container given 2 CPUs of a 64-core host sees 64
    in its affinity)."""
    n = len(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity') else os.cpu_count()
    n = max(1, n or 1)
    try:
        quota, period = cgroup.read_text().split()[:2]
        if quota != 'max':
            n = min(n, max(1, int(float(quota) // float(period))))
    except (OSError, ValueError):
        pass                            # no cgroup v2 quota: the affinity is the limit
    return n


def checked_jobs(n_jobs) -> int:
    """``n_jobs`` as a number of threads: None for every available core, else a positive
    integer (a clear error otherwise)."""
    if n_jobs is None:
        return available_cores()
    try:
        n = operator.index(n_jobs)
    except TypeError:
        n = 0
    if isinstance(n_jobs, bool) or n < 1:
        raise ValueError(f'n_jobs must be a positive integer or None (every core), '
                         f'got {n_jobs!r}')
    return n


def map_threads(fn, items, n_jobs=None) -> list:
    """[fn(item) for item in items], with up to ``n_jobs`` (:func:`checked_jobs`) of them at
    a time; an exception in any is raised here."""
    items = list(items)
    n = min(checked_jobs(n_jobs), len(items))
    if n <= 1:
        return [fn(item) for item in items]
    with ThreadPoolExecutor(n) as pool:
        return list(pool.map(fn, items))


class ProgressCount:
    """``progress(done, total, K)`` after each of ``total`` fits, whichever thread made it
    (None: nothing is called); the count and the call under one lock, so ``done`` rises by one
    each call."""

    def __init__(self, progress, total: int):
        self.progress, self.total, self.done = progress, total, 0
        self._lock = threading.Lock()

    def step(self, K):
        with self._lock:
            self.done += 1
            if self.progress:
                self.progress(self.done, self.total, K)
