"""core.parallel: pieces of work side by side on threads, their results in order."""

import threading

import pytest

from mixture_ip_ros.core.parallel import ProgressCount, checked_jobs, map_threads


def test_results_come_back_in_the_items_order_whatever_the_threads():
    items = list(range(23))
    for jobs in (1, 2, 5, 40):
        assert map_threads(lambda x: x * x, items, jobs) == [x * x for x in items]
    assert map_threads(str, [], 4) == []


def test_an_exception_in_a_piece_is_raised_to_the_caller():
    def piece(x):
        if x == 3:
            raise ValueError('piece 3 failed')
        return x
    with pytest.raises(ValueError, match='piece 3 failed'):
        map_threads(piece, range(6), 2)


@pytest.mark.parametrize('bad', [0, -1, 1.5, '2', True])
def test_a_number_of_threads_is_a_positive_integer_or_none(bad):
    with pytest.raises(ValueError, match='n_jobs must be a positive integer'):
        checked_jobs(bad)
    assert checked_jobs(None) >= 1 and checked_jobs(3) == 3


def test_progress_counts_every_piece_once_from_any_thread():
    seen, lock = [], threading.Lock()

    def progress(done, total, K):
        with lock:
            seen.append((done, total, K))
    count = ProgressCount(progress, 30)
    map_threads(lambda i: count.step(i % 3), range(30), 4)
    assert [d for d, _, _ in seen] == list(range(1, 31)) and {t for _, t, _ in seen} == {30}


def test_the_cores_available_are_the_affinity_or_fewer_under_a_cgroup_quota(tmp_path):
    import os
    from mixture_ip_ros.core.parallel import available_cores
    affinity = len(os.sched_getaffinity(0))
    quota = tmp_path / 'cpu.max'
    quota.write_text('max 100000\n')
    assert available_cores(quota) == affinity
    quota.write_text('150000 100000\n')             # one and a half CPUs: one thread
    assert available_cores(quota) == 1
    quota.write_text(f'{(affinity + 8) * 100000} 100000\n')
    assert available_cores(quota) == affinity
    assert available_cores(tmp_path / 'none') == affinity
    assert checked_jobs(__import__('numpy').int64(2)) == 2
