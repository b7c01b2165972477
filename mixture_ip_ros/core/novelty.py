"""Is the observed movement one the model knows? A calibrated "none of these" test.

A confident p(k* | D) says one component explains the observations better than the others, not
that any explains them: a person returning the hand to rest, or starting a second reach without
resting, is confidently assigned to some component. The model's own evidence says more: the
log marginal likelihood of the observations, log p(D_1:n) = log sum_(k, m) p(k, alpha_m)
p(D_1:n | k, alpha_m) (eqs. 16-18), is high for movements like the training ones and collapses
for others. Two statistics, per observation used (so they do not grow with n):

- the whole interaction so far, log p(D_1:n) / n;
- the latest ``window`` observations, (log p(D_1:n) - log p(D_1:n-window)) / window: the log
  predictive density of what was just seen, which falls as soon as the movement stops being
  explained (the second reach of two without a rest, an unseen movement after a good start).

Their thresholds are calibrated on training demonstrations held out of the model (cross
validation), fed through the online estimator exactly as the node feeds it (the same alpha grid
and decimation): the lowest value any held-out demonstration reached, lowered by a margin of
the spread between that lowest and the median value, so that a new person's reach, a little
further from the training set than held-out ones, is still explained. The prefix threshold is
per number of observations (it starts noisy and settles). Movements it refuses (returns to rest,
transitions between reaches) are tested in the test suite and measured by bench/soak.py.

An observation that follows a gap in the stream (a tracker's dropped frames, an occlusion) is
conditioned on but not judged (GapWatch): after a silence the phase has spread, so the first
sample is predicted far less sharply than one taken at the stream's own spacing (on the box
assembly with bursts of up to 0.8 s dropped: log p about 7 on median, down to -0.6, against
10.3 within the stream), and the thresholds come from streams without gaps. The sample after
it is predicted as sharply as any (median 9.8), so only the one is left out, in the
calibration as online.
"""

import bisect
from collections import deque
from dataclasses import dataclass
from typing import Optional

import numpy as np

from .parallel import map_threads
from .segmentation import median_sorted

WINDOW = 5           # observations: 0.25 s at the node's 20 Hz
MAX_PREFIX = 40      # per-n prefix thresholds up to here, then one for every larger n
# A spacing longer than this many of the stream's own (the median so far, at least the
# decimation) is a gap: a 20 Hz tracker's sample skipped by the decimation (twice its spacing,
# give or take its jitter) stays within it.
GAP = 2.5


@dataclass(frozen=True)
class NoveltyThresholds:
    """``prefix[n - 1]``: the lowest acceptable log p(D_1:n) / n for n observations (the last
    entry for every larger n); ``window``: the lowest acceptable mean of the latest
    ``window_size`` observations' log predictive densities; ``min_interval``: the decimation it
    was calibrated with (s)."""

    prefix: np.ndarray
    window: float
    window_size: int = WINDOW
    min_interval: float = 0.05

    def __post_init__(self):
        prefix = np.asarray(self.prefix, dtype=float)
        if prefix.ndim != 1 or prefix.size < 1 or not np.all(np.isfinite(prefix)):
            raise ValueError('novelty prefix thresholds must be a non-empty finite 1-D array')
        if not np.isfinite(self.window):
            raise ValueError('the novelty window threshold must be finite')
        if int(self.window_size) != self.window_size or self.window_size < 1:
            raise ValueError(f'window_size must be an integer >= 1, got {self.window_size}')
        object.__setattr__(self, 'prefix', prefix)
        object.__setattr__(self, 'window_size', int(self.window_size))

    def prefix_threshold(self, n: int) -> float:
        return float(self.prefix[min(n, self.prefix.size) - 1])


class GapWatch:
    """Says which observations, in time order, follow a gap in the stream (GAP)."""

    def __init__(self, min_interval: float):
        self.min_interval = float(min_interval)
        self.reset()

    def reset(self) -> None:
        self._last = None
        self._spacings = []

    def after_gap(self, t: float) -> bool:
        """Whether the observation at ``t`` (later than every one before) follows a gap."""
        last, self._last = self._last, float(t)
        if last is None:
            return False
        spacing = float(t) - last
        # the first spacing is the stream's own: there is none to compare it with
        gap = bool(self._spacings) and spacing > GAP * max(self.min_interval,
                                                           median_sorted(self._spacings))
        bisect.insort(self._spacings, spacing)     # kept sorted: the median per sample is O(1)
        return gap


class NoveltyMonitor:
    """Follows log p(D_1:n) of one interaction and says whether the model explains it."""

    def __init__(self, thresholds: NoveltyThresholds):
        self.thresholds = thresholds
        self.reset()

    def reset(self) -> None:
        # (observations judged, their log p) at the latest window_size + 1 records
        self._history = deque(maxlen=self.thresholds.window_size + 1)
        self._last = (0, 0.0)               # (n, log p(D_1:n)) at the latest record
        self._left_out = (0, 0.0)           # observations not judged and their log p

    def record(self, n: int, log_marginal: float, judged: bool = True) -> None:
        """log p(D_1:n) after the n-th observation used (in time order, every one); not
        ``judged``: the observations since the latest record are left out of the statistics
        (they follow a gap)."""
        if n <= self._last[0]:
            self.reset()                    # a new interaction, or its samples re-absorbed
        if not judged:
            count, log_p = self._left_out
            self._left_out = (count + n - self._last[0],
                              log_p + float(log_marginal) - self._last[1])
        self._last = (int(n), float(log_marginal))
        if judged:
            self._history.append((int(n) - self._left_out[0],
                                  float(log_marginal) - self._left_out[1]))

    @property
    def n_judged(self) -> int:
        return self._history[-1][0] if self._history else 0

    def statistics(self):
        """(prefix, window) statistics of the latest record (window None until there are
        ``window_size`` observations judged after the first recorded one), over the
        observations judged."""
        if not self._history:
            return None, None
        n, lm = self._history[-1]
        prefix = lm / n
        n0, lm0 = self._history[0]
        window = (lm - lm0) / (n - n0) if n - n0 >= self.thresholds.window_size else None
        return prefix, window

    def unexplained(self) -> Optional[str]:
        """Why the observations so far are not explained by the model, or None."""
        prefix, window = self.statistics()
        if prefix is None:
            return None
        n = self.n_judged
        low = self.thresholds.prefix_threshold(n)
        if prefix < low:
            return (f'log p(D)/n = {prefix:.3g} below {low:.3g}, the lowest of held-out '
                    f'training movements after {n} observations')
        if window is not None and window < self.thresholds.window:
            return (f'the latest {self.thresholds.window_size} observations have log '
                    f'p = {window:.3g} each, below {self.thresholds.window:.3g}')
        return None


def held_out_statistics(model, demos, *, n_alpha: int, min_interval: float,
                        window_size: int = WINDOW):
    """Prefix statistics per n (list of arrays over demonstrations, n = 1.. observations
    judged) and every window statistic, of ``demos`` fed through an OnlineEstimator of
    ``model`` (the online way: an observation after a gap is not judged)."""
    from mixture_ip_ros.core.noise import decimated_rows
    from mixture_ip_ros.core.online import OnlineEstimator
    from mixture_ip_ros.core.playback import observed_rows
    prefix, windows = {}, []
    est = OnlineEstimator(model, n_alpha=n_alpha, min_interval=min_interval)
    for demo in demos:
        est.reset()
        monitor = NoveltyMonitor(NoveltyThresholds(np.zeros(1), 0.0, window_size, min_interval))
        gaps = GapWatch(min_interval)
        rows = observed_rows(demo)
        t = demo.t[rows]
        log_ps = est.offer_many(t, demo.observed[rows])
        for n, (log_p, ti) in enumerate(zip(log_ps, t[decimated_rows(t, min_interval)]),
                                        start=1):
            judged = not gaps.after_gap(ti)
            monitor.record(n, log_p, judged)
            if not judged:
                continue
            p, w = monitor.statistics()
            prefix.setdefault(monitor.n_judged, []).append(p)
            if w is not None:
                windows.append(w)
    return [np.array(prefix[n]) for n in sorted(prefix)], np.array(windows)


def _threshold(values) -> float:
    """The lowest value, lowered by the spread between it and the median."""
    values = np.asarray(values, dtype=float)
    low = float(values.min())
    return low - (float(np.median(values)) - low)


def calibrate(demos, fit, *, n_alpha: int = 50, min_interval: float = 0.05, n_folds: int = 5,
              window_size: int = WINDOW, random_state=0, n_jobs=None) -> NoveltyThresholds:
    """Thresholds from ``demos`` held out in ``n_folds`` folds; ``fit(index)`` returns a
    MixtureIProMP (the same configuration as the model they will guard) fitted to the
    demonstrations ``demos[i] for i in index`` (by index, so that what a caller prepared of
    each demonstration once serves every fold). The folds run on ``n_jobs`` threads
    (core.parallel.map_threads; None: every core), so ``fit`` must not share mutable state
    between calls."""
    from mixture_ip_ros.core.crossval import cv_folds
    demos = list(demos)
    if len(demos) < 2:
        raise ValueError('novelty calibration needs at least 2 demonstrations')
    folds = cv_folds(len(demos), min(n_folds, len(demos)), random_state)

    def one_fold(f):
        test = [d for d, g in zip(demos, folds) if g == f]
        return held_out_statistics(fit(np.flatnonzero(folds != f)), test, n_alpha=n_alpha,
                                   min_interval=min_interval, window_size=window_size)
    prefix, windows = {}, []
    for by_n, w in map_threads(one_fold, range(folds.max() + 1), n_jobs):
        for n, values in enumerate(by_n, start=1):
            prefix.setdefault(n, []).extend(values)
        windows.extend(w)
    ns = sorted(prefix)
    # Beyond MAX_PREFIX (or where few demonstrations are that long) one threshold for all.
    last = [v for n in ns if n >= MAX_PREFIX for v in prefix[n]]
    per_n = [_threshold(prefix[n]) for n in ns if n < MAX_PREFIX]
    if last:
        per_n.append(_threshold(last))
    window = _threshold(windows) if len(windows) else -np.inf
    if not np.isfinite(window):
        raise ValueError('novelty calibration: no demonstration is long enough for a window of '
                         f'{window_size} observations')
    return NoveltyThresholds(np.array(per_n), window, window_size, min_interval)
