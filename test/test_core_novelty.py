"""The "none of these" test (core.novelty): calibrated on held-out training demonstrations, it
explains new movements of the learned patterns and refuses the others (returns to rest, an
unseen pattern, a second reach without a rest)."""

import numpy as np
import pytest

from mixture_ip_ros.core.demonstration import Demonstration
from mixture_ip_ros.core.mixture import MixtureIProMP
from mixture_ip_ros.core.novelty import (GapWatch, NoveltyMonitor, NoveltyThresholds,
                                         calibrate)
from mixture_ip_ros.core.online import OnlineEstimator
from mixture_ip_ros.scenarios.synthetic import mixture_demos


def _fit(demos):
    return MixtureIProMP(len({d.label for d in demos}), n_basis=8,
                         observation_noise=0.005).fit(demos)


@pytest.fixture(scope='module')
def patterns():
    demos = mixture_demos(seed=0, n_obs=3, n_ctrl=2, n_basis=8)[0]
    test = demos[::3]                              # a third never seen in training
    train = [d for i, d in enumerate(demos) if i % 3]
    return train, test, calibrate(train, lambda i: _fit([train[j] for j in i])), _fit(train)


def _first_flag(model, thresholds, t, Y):
    """The number of observations after which the monitor first refuses the stream (None)."""
    est = OnlineEstimator(model)
    monitor = NoveltyMonitor(thresholds)
    for ti, y in zip(t, Y):
        if est.update(float(ti), y):
            monitor.record(est.n_observations, est.log_marginal())
            if monitor.unexplained():
                return est.n_observations
    return None


def test_new_movements_of_the_learned_patterns_are_explained(patterns):
    train, test, thresholds, model = patterns
    assert [_first_flag(model, thresholds, d.t, d.observed) for d in test] == [None] * len(test)


def test_a_return_to_rest_is_refused_within_three_observations(patterns):
    _, test, thresholds, model = patterns
    flags = [_first_flag(model, thresholds, d.t, d.observed[::-1]) for d in test]
    assert all(f is not None and f <= 3 for f in flags), flags


def test_a_pattern_never_learned_is_refused():
    demos = mixture_demos(seed=0, n_obs=3, n_ctrl=2, n_basis=8)[0]
    known = [d for d in demos if d.label != '2']
    thresholds, model = calibrate(known, lambda i: _fit([known[j] for j in i])), _fit(known)
    flags = [_first_flag(model, thresholds, d.t, d.observed) for d in demos if d.label == '2']
    assert all(f is not None and f <= 5 for f in flags), flags


def test_a_second_reach_without_a_rest_is_refused_soon_after_it_starts(patterns):
    """A movement explained to its end, then another pattern's from where it ended: the
    latest observations stop being explained within a window of the change."""
    _, test, thresholds, model = patterns
    first = next(d for d in test if d.label == '0')
    second = next(d for d in test if d.label == '1')
    t = np.concatenate([first.t, first.t[-1] + 0.01 + second.t])
    Y = np.vstack([first.observed, second.observed - second.observed[0] + first.observed[-1]])
    n_first = int(np.floor(first.duration / 0.05)) + 1            # observations at 20 Hz
    flag = _first_flag(model, thresholds, t, Y)
    assert flag is not None and n_first < flag <= n_first + 2 * thresholds.window_size


def test_thresholds_are_validated_and_read_per_number_of_observations():
    th = NoveltyThresholds(np.array([1.0, 2.0, 3.0]), 0.5)
    assert [th.prefix_threshold(n) for n in (1, 3, 40)] == [1.0, 3.0, 3.0]
    for bad in ({'prefix': np.array([])}, {'prefix': np.array([np.nan])},
                {'window': np.inf}, {'window_size': 0}):
        with pytest.raises(ValueError):
            NoveltyThresholds(**{'prefix': np.ones(2), 'window': 0.0, **bad})


def test_calibration_bounds_every_held_out_statistic_with_a_margin(patterns):
    """By construction each threshold is below every held-out value by the spread between the
    lowest and the median: recomputed here from the same folds."""
    from mixture_ip_ros.core.crossval import cv_folds
    from mixture_ip_ros.core.novelty import held_out_statistics
    train, _, thresholds, _ = patterns
    folds = cv_folds(len(train), 5, 0)
    lowest = np.inf
    for f in range(5):
        part = [d for d, g in zip(train, folds) if g != f]
        held = [d for d, g in zip(train, folds) if g == f]
        by_n, windows = held_out_statistics(_fit(part), held, n_alpha=50, min_interval=0.05)
        for n, values in enumerate(by_n, start=1):
            assert values.min() >= thresholds.prefix_threshold(n)
        lowest = min(lowest, windows.min())
    assert thresholds.window < lowest


def test_the_gap_watch_flags_the_observation_after_a_silence_and_only_it():
    rng = np.random.default_rng(0)
    t = np.cumsum(0.05 + 0.01 * rng.random(40))          # 20 Hz, decimation's jitter
    t[20:] += 0.3                                          # a 0.3 s silence before the 21st
    watch = GapWatch(0.05)
    assert [i for i, ti in enumerate(t) if watch.after_gap(ti)] == [20]
    watch.reset()                                          # a slow tracker: its own spacing
    assert not any(watch.after_gap(ti) for ti in 0.125 * np.arange(30))


def test_observations_left_out_leave_the_statistics_of_those_judged():
    """Against the sums written out: the left-out observations' log predictive densities are
    removed from both statistics, which count only the judged ones."""
    rng = np.random.default_rng(1)
    increments = 10 + rng.normal(size=30)
    left_out = {7, 8, 19}
    th = NoveltyThresholds(np.full(3, -1e9), -1e9, window_size=5)
    monitor = NoveltyMonitor(th)
    for n, log_p in enumerate(np.cumsum(increments), start=1):
        monitor.record(n, log_p, judged=n - 1 not in left_out)
        kept = [x for i, x in enumerate(increments[:n]) if i not in left_out]
        prefix, window = monitor.statistics()
        assert monitor.n_judged == len(kept)
        assert prefix == pytest.approx(np.mean(kept), rel=1e-12)
        if n - 1 not in left_out and len(kept) > 5:
            assert window == pytest.approx(np.mean(kept[-5:]), rel=1e-12)
    monitor.record(1, increments[0])                       # a new interaction
    assert monitor.n_judged == 1 and monitor.statistics()[0] == increments[0]


def test_a_gap_in_the_stream_is_not_taken_for_a_movement_the_model_does_not_know(patterns):
    """0.45 s of a held-out movement lost at a quarter of it: the first sample after the gap is
    predicted far less sharply than the ones within the stream; it is left out, and every such
    movement is still explained."""
    _, test, thresholds, model = patterns
    after, within = [], []
    for d in test:
        start = 0.25 * d.duration
        keep = ~((d.t > start) & (d.t < start + 0.45))
        est, monitor, watch = OnlineEstimator(model), NoveltyMonitor(thresholds), GapWatch(0.05)
        before = 0.0
        for ti, y in zip(d.t[keep], d.observed[keep]):
            if est.update(float(ti), y):
                gap = watch.after_gap(ti)
                monitor.record(est.n_observations, est.log_marginal(), judged=not gap)
                (after if gap else within).append(est.log_marginal() - before)
                before = est.log_marginal()
                assert monitor.unexplained() is None, d.label
    assert len(after) == len(test)
    assert np.median(after) < np.median(within) - 2


def test_calibration_leaves_out_the_sample_after_a_gap_as_the_monitor_does(patterns):
    """held_out_statistics on a demonstration with 0.45 s of missing rows (NaN): the prefix
    statistics per number of samples judged, against the log predictive densities summed by
    hand in time order without the first sample after the gap."""
    from mixture_ip_ros.core.novelty import held_out_statistics
    _, test, _, model = patterns
    d = test[0]
    observed = d.observed.copy()
    start = 0.25 * d.duration
    observed[(d.t > start) & (d.t < start + 0.45)] = np.nan
    demo = Demonstration(d.t, observed, d.controlled, d.label)
    by_n, windows = held_out_statistics(model, [demo], n_alpha=50, min_interval=0.05)
    est, before, kept, after_gap = OnlineEstimator(model), 0.0, [], False
    last = None
    for ti, y in zip(demo.t, demo.observed):
        if np.isnan(y).any() or not est.update(float(ti), y):
            continue
        after_gap = last is not None and ti - last > 0.2
        last = ti
        if not after_gap:
            kept.append(est.log_marginal() - before)
        before = est.log_marginal()
    assert len(by_n) == len(kept) == est.n_observations - 1       # one left out
    for n, values in enumerate(by_n, start=1):
        assert values[0] == pytest.approx(np.mean(kept[:n]), rel=1e-9)
    assert windows[-1] == pytest.approx(np.mean(kept[-5:]), rel=1e-9)
