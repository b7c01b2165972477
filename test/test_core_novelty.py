"""The "none of these" test (core.novelty): calibrated on held-out training demonstrations, it
explains new movements of the learned patterns and refuses the others (returns to rest, an
unseen pattern, a second reach without a rest)."""

import numpy as np
import pytest

from mixture_ip_ros.core.mixture import MixtureIProMP
from mixture_ip_ros.core.novelty import NoveltyMonitor, NoveltyThresholds, calibrate
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


def _judged(thresholds, densities):
    """monitor.unexplained() after each observation whose log predictive density is given (the
    log marginal is their running sum)."""
    monitor = NoveltyMonitor(thresholds)
    out = []
    for n, lm in enumerate(np.cumsum(densities), start=1):
        monitor.record(n, lm)
        out.append(monitor.unexplained())
    return out


def test_after_a_turn_what_follows_is_judged_on_its_own():
    """Densities by hand: a movement explained over a window (10 nats each), a turn (-50), then
    explained again (8 each, above the settled prefix threshold 7 and the window threshold 3).
    After the turn the prefix is the mean since the last unexplained window: explained once
    3 observations came after it, whatever the turn cost the whole prefix."""
    th = NoveltyThresholds(np.array([0.0, 0.0, 0.0, 7.0]), 3.0, window_size=3)
    got = _judged(th, [10] * 4 + [-50] * 2 + [8] * 8)
    assert got[:4] == [None] * 4
    assert all(why is not None for why in got[4:9])
    # windows ending at the 6th, 7th and 8th observation hold a -50: the last unexplained
    # window ends at the 8th; three more come after it, their mean 8 >= 7
    assert got[8:10] == ['1 observations explained since the movement turned, fewer than 3',
                         '2 observations explained since the movement turned, fewer than 3']
    assert got[10:] == [None] * 4
    whole = np.cumsum([10] * 4 + [-50] * 2 + [8] * 8)[-1] / 14
    assert whole < 7.0                               # the whole prefix would still refuse it
    # after the turn, a mean below the settled threshold stays refused (per-n ones are looser)
    got = _judged(th, [10] * 4 + [-50] * 2 + [5] * 8)
    assert got[-1].startswith('log p(D)/n = 5 below 7')
    # never explained over a whole window (a return to rest): judged whole, from the onset,
    # still refused where the same densities after a turn are explained
    got = _judged(th, [-50] * 2 + [10] * 12)
    assert all(why is not None for why in got)
    assert got[-1].startswith('log p(D)/n = 1.43 below 7')


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
