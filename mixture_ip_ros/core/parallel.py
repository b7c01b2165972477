"""Independent pieces of training's work (cross-validation folds) side by side on the cores
this process may use.

Threads, not processes: the work is the estimator's compiled kernels (numba, nogil) and
LAPACK, which run without the interpreter lock, and a thread shares the recordings and the
compiled kernels where a worker process would import the package and be sent the data first
(most of a fold's second). A process forked from one that ran ROS nodes can also crash in
their threads' objects (app.evaluation.interactions._run forks from a server instead). Each
piece writes only its own results and they come back in the order of the items, so the
result is the same whatever the number of threads.
"""

import os
import threading
from concurrent.futures import ThreadPoolExecutor


def available_cores() -> int:
    """The number of cores this process may run on (its CPU affinity, not the machine's)."""
    if hasattr(os, 'sched_getaffinity'):
        return max(1, len(os.sched_getaffinity(0)))
    return os.cpu_count() or 1


def checked_jobs(n_jobs) -> int:
    """``n_jobs`` as a number of threads: None for every available core, else a positive
    integer (a clear error otherwise)."""
    if n_jobs is None:
        return available_cores()
    if isinstance(n_jobs, bool) or not isinstance(n_jobs, int) or n_jobs < 1:
        raise ValueError(f'n_jobs must be a positive integer or None (every core), '
                         f'got {n_jobs!r}')
    return n_jobs


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
