"""Movement onset/end detection on a 3-D wrist position stream (streaming and offline).

The phase of a demonstration runs from the human's movement onset to its end, so the
same detector must define time zero for training data (``segment_motion``) and online
(``MotionSegmenter`` inside the observer node). ``segment_motion`` therefore runs the
streaming detector sample by sample: both agree exactly on the same samples.

Detection: speed is the norm of a least-squares velocity over a sliding time window
(running sums, O(1) per sample). Noise of sigma_p per coordinate gives a per-axis velocity
noise of about sigma_p * sqrt(12 / (n w^2)) for n samples in a window of w seconds, which
``speed_window`` and the thresholds must stay above.

Thresholds relative to the recording's own rest: a real hand never holds perfectly still (a
person's wrist drifts before a reach and hovers after a handover, faster than a fixed floor
for motion-capture jitter), so fixed speeds would fire the onset at once and never see the
end. The speed while at rest is tracked (its median and scaled median absolute deviation over
the last ``rest_window`` seconds of rest, lagging ``speed_window`` behind so that a starting
movement does not count as rest), and the thresholds are the fixed floors ``onset_speed`` /
``end_speed`` or that rest level plus ``onset_noise_factor`` / ``end_noise_factor`` spreads,
whichever is higher. No onset is confirmed before ``rest_min`` seconds of rest have been
measured (0: the fixed floors alone until then, so a recording that starts mid-movement has its
onset at the first sample).

Dating: by the time speed has stayed above threshold the hand has moved for a while (slow
reaches longest). Once an onset is confirmed, it is dated back to when the hand left rest by a
cubic fit to the positions of the last ``max_backdate`` seconds up to the first threshold
crossing (core.cubic_onset); the end likewise, in reversed time, over the slowing down and
the rest that confirmed it. The dating is the same offline and online.
"""

from collections import deque
import math
from typing import List, NamedTuple, Optional, Tuple

import numpy as np

from .cubic_onset import fit_cubic_onset

# Time comparisons get 1 us of slack: durations are often whole numbers of sample periods
# and round-off (e.g. of epoch stamps) must not decide them at random.
_SLACK = 1e-6


def median_sorted(v) -> float:
    """The median of the sorted list ``v`` as np.median computes it."""
    n = len(v)
    return v[n // 2] if n % 2 else (v[n // 2 - 1] + v[n // 2]) / 2


class Event(NamedTuple):
    """A segmentation event; ``time`` is in the stream's time base (seconds)."""

    kind: str  # 'onset' | 'end' | 'gap'
    time: float


class MotionSegmenter:
    """Streaming detector of movement onset, end and stream gaps for one wrist.

    ``update(t, position)`` returns the events the new sample settles, in time order:

    - 'gap' at the last sample time when the stream was silent for more than ``gap_timeout``
      (also announced early by ``gap(t_now)``). The velocity window restarts after a gap,
      an interaction in progress continues; after more than ``max_gap`` of silence it is
      closed with an 'end' at the last sample time (tracking is lost). A silence of
      ``end_hold`` that falls once the hand has come to rest confirms the end, dated from the
      samples as a recording that stops there is (a tracker losing the hand at the end of a
      reach); at speed, or after a shorter silence, the interaction goes on.
    - 'onset' once speed has stayed >= ``onset_speed`` for ``onset_hold`` seconds; its time
      is back-dated to when the hand left rest (cubic fit, see the module notes), never
      more than ``max_backdate`` before the sample that confirmed it, nor before the
      stream's first sample or the previous end.
    - 'end' once speed has stayed < ``end_speed`` for ``end_hold`` seconds; its time is
      when the hand came to rest, not when the detector was sure.
    ``onset_speed`` and ``end_speed`` are floors: the thresholds rise with the measured rest
    level and spread (``rest_window``, ``onset_noise_factor``, ``end_noise_factor``,
    ``rest_min``; see the module notes). ``onset_threshold`` / ``end_threshold`` are the
    ones in force.

    Speeds are in m/s and times in seconds; times must strictly increase. Per sample the
    work is O(1) (amortised); the dating fit runs once per onset and once per end.
    """

    def __init__(self, onset_speed: float = 0.06, onset_hold: float = 0.06,
                 end_speed: float = 0.03, end_hold: float = 0.3, speed_window: float = 0.15,
                 gap_timeout: float = 0.1, max_gap: float = 2.0, max_backdate: float = 2.0,
                 min_window_samples: int = 4, rest_window: float = 1.0,
                 onset_noise_factor: float = 5.0, end_noise_factor: float = 3.0,
                 rest_min: float = 0.1):
        checks = {'onset_speed': onset_speed, 'end_speed': end_speed, 'end_hold': end_hold,
                  'speed_window': speed_window, 'gap_timeout': gap_timeout, 'max_gap': max_gap,
                  'max_backdate': max_backdate, 'rest_window': rest_window,
                  'onset_noise_factor': onset_noise_factor, 'end_noise_factor': end_noise_factor}
        for name, value in checks.items():
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f'MotionSegmenter: {name} must be a positive finite number, '
                                 f'got {value!r}')
        if not (math.isfinite(onset_hold) and onset_hold >= 0):
            raise ValueError(f'MotionSegmenter: onset_hold must be >= 0, got {onset_hold!r}')
        if not (isinstance(rest_min, (int, float)) and math.isfinite(rest_min)
                and 0 <= rest_min <= rest_window):
            raise ValueError(f'MotionSegmenter: rest_min must be in [0, rest_window], got '
                             f'{rest_min!r}')
        if end_noise_factor >= onset_noise_factor:
            raise ValueError(f'MotionSegmenter: end_noise_factor ({end_noise_factor}) must be '
                             f'below onset_noise_factor ({onset_noise_factor}) to give hysteresis')
        if end_speed >= onset_speed:
            raise ValueError(f'MotionSegmenter: end_speed ({end_speed}) must be below '
                             f'onset_speed ({onset_speed}) to give hysteresis')
        if max_gap < gap_timeout:
            raise ValueError(f'MotionSegmenter: max_gap ({max_gap}) must be >= gap_timeout '
                             f'({gap_timeout})')
        if int(min_window_samples) != min_window_samples or min_window_samples < 3:
            raise ValueError(f'MotionSegmenter: min_window_samples must be an integer >= 3, '
                             f'got {min_window_samples!r}')
        self.onset_speed = float(onset_speed)
        self.onset_hold = float(onset_hold)
        self.end_speed = float(end_speed)
        self.end_hold = float(end_hold)
        self.speed_window = float(speed_window)
        self.gap_timeout = float(gap_timeout)
        self.max_gap = float(max_gap)
        self.max_backdate = float(max_backdate)
        self.min_window_samples = int(min_window_samples)
        self.rest_window = float(rest_window)
        self.onset_noise_factor = float(onset_noise_factor)
        self.end_noise_factor = float(end_noise_factor)
        self.rest_min = float(rest_min)
        self._win = deque()    # velocity window (t, x, y, z)
        self._hist = deque()   # last max_backdate seconds of samples, for dating
        self._pending = deque()  # (t, speed) at rest, not yet speed_window old
        self._rest = deque()     # (t, speed) of the rest statistics
        self.reset()

    # -- public state -------------------------------------------------------------------
    @property
    def moving(self) -> bool:
        """True between an 'onset' and its 'end'."""
        return self._moving

    @property
    def last_time(self) -> Optional[float]:
        """Time of the last sample given to ``update`` (None before the first)."""
        return self._last_t

    @property
    def onset_threshold(self) -> float:
        """The onset speed in force: onset_speed or the rest level + onset_noise_factor spreads."""
        return self._on_thr

    @property
    def end_threshold(self) -> float:
        """The end speed in force: end_speed or the rest level + end_noise_factor spreads."""
        return self._end_thr

    def reset(self):
        """Forget everything: as if no sample had been seen."""
        self._last_t = None
        self._stream_start = None
        self._gap_reported = False
        self._moving = False
        self._last_end = -math.inf
        self._onset_time = -math.inf
        self._hist.clear()
        self._pending.clear()
        self._rest.clear()
        self._on_thr, self._end_thr = self.onset_speed, self.end_speed
        self._calm_c = None      # centre time of the last speed under the end threshold
        self._restart_window()
        self._reset_onset_search()
        self._reset_end_search()

    # -- streaming ----------------------------------------------------------------------
    def update(self, t: float, position) -> List[Event]:
        """Feed one sample; returns the events it settles (possibly none)."""
        t = float(t)
        try:
            x, y, z = (float(v) for v in position)
        except (TypeError, ValueError):
            raise ValueError(f'MotionSegmenter.update: position must be 3 numbers (x, y, z), '
                             f'got {position!r}') from None
        if not (math.isfinite(t) and math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
            raise ValueError(f'MotionSegmenter.update: non-finite sample t={t}, '
                             f'position=({x}, {y}, {z})')
        events = []
        if self._last_t is None:
            self._stream_start = t
        else:
            if t <= self._last_t:
                raise ValueError(f'MotionSegmenter.update: time must strictly increase, got {t} '
                                 f'after {self._last_t}')
            if t - self._last_t > self.gap_timeout + _SLACK:
                events.extend(self._silence(t - self._last_t))
                self._restart_window()
                # A rise interrupted by an occlusion keeps its samples for the dating fit;
                # only the 'sustained' streak and a rest period must start again.
                self._hold_start = None
                self._rest_start_t = None
        self._last_t = t
        self._gap_reported = False
        hist = self._hist
        hist.append((t, x, y, z))
        horizon = t - self.max_backdate - _SLACK
        while hist[0][0] < horizon:
            hist.popleft()
        speed, center = self._push(t, x, y, z)
        if not self._moving:
            self._track_rest(t, speed)
        if speed == speed:  # not NaN: the window is long enough
            if self._moving:
                events.extend(self._search_end(t, speed, center))
            else:
                events.extend(self._search_onset(t, speed, center))
        return events

    def gap(self, t_now: float) -> List[Event]:
        """Report a silence seen at stream time ``t_now`` without waiting for the next sample.

        Gives the same 'gap' (and, past ``max_gap``, 'end') events ``update`` would give
        when the next sample arrives, once per silence; ``update`` then does not repeat them.
        """
        if self._last_t is None or t_now - self._last_t <= self.gap_timeout + _SLACK:
            return []
        return self._silence(t_now - self._last_t)

    def finish(self) -> List[Event]:
        """The stream is over: close an open interaction.

        If the hand was at rest at the end (not yet long enough to confirm), the end is dated
        from the data as usual, else it is the last sample (the recording stopped mid-move).
        """
        if not self._moving:
            return []
        if self._rest_start_t is None:
            return [self._close(self._last_t)]
        return [self._close(self._date_end(self._last_t))]

    # -- internals ----------------------------------------------------------------------
    def _track_rest(self, t, speed):
        """Rest statistics of the speed (see the module notes) and the thresholds from them.

        A speed counts as rest if it was under the end threshold when measured (a rise never
        does; until five rest speeds are known every speed counts, since a drifting rest can be
        above the floors) and once it is ``speed_window`` old; level and spread are the median
        and the scaled median absolute deviation, so the slow start of a movement that slips in
        before the onset is confirmed hardly moves them."""
        if speed == speed and (speed < self._end_thr or len(self._rest) < 5):
            self._pending.append((t, speed))
        mature = t - self.speed_window + _SLACK
        while self._pending and self._pending[0][0] <= mature:
            self._rest.append(self._pending.popleft())
        horizon = mature - self.rest_window
        while self._rest and self._rest[0][0] < horizon:
            self._rest.popleft()
        if len(self._rest) >= 5:
            # np.median's values (the middle one, or the mean of the two middle ones) from a
            # sorted list, without numpy's per-call overhead at every sample.
            v = sorted([r[1] for r in self._rest])
            level = median_sorted(v)
            spread = 1.4826 * median_sorted(sorted([abs(x - level) for x in v]))
            self._on_thr = max(self.onset_speed, level + self.onset_noise_factor * spread)
            self._end_thr = max(self.end_speed, level + self.end_noise_factor * spread)

    def _rest_known(self) -> bool:
        if self.rest_min == 0:
            return True
        return (len(self._rest) >= 5
                and self._rest[-1][0] - self._rest[0][0] >= self.rest_min - _SLACK)

    def _silence(self, duration):
        events = []
        if not self._gap_reported:
            events.append(Event('gap', self._last_t))
            self._gap_reported = True
        if not self._moving:
            return events
        if self._rest_start_t is not None and duration >= self.end_hold - _SLACK:
            events.append(self._close(self._date_end(self._last_t)))
        elif duration > self.max_gap + _SLACK:
            events.append(self._close(self._last_t))
        return events

    def _close(self, t_end):
        self._moving = False
        self._last_end = t_end
        self._reset_onset_search()
        return Event('end', t_end)

    def _restart_window(self):
        """Empty the velocity window (start, gap): never difference across missing data."""
        self._win.clear()
        self._t_ref = 0.0
        self._p_ref = (0.0, 0.0, 0.0)
        self._n = 0
        self._st = self._stt = 0.0
        self._sx = self._sy = self._sz = 0.0
        self._stx = self._sty = self._stz = 0.0

    def _rebase(self, t, x, y, z):
        """Recompute the running sums around a fresh origin to stop round-off drift."""
        self._t_ref, self._p_ref = t, (x, y, z)
        self._n = 0
        self._st = self._stt = 0.0
        self._sx = self._sy = self._sz = 0.0
        self._stx = self._sty = self._stz = 0.0
        for s in self._win:
            self._accumulate(s, 1.0)

    def _accumulate(self, s, sign):
        dt = s[0] - self._t_ref
        dx = s[1] - self._p_ref[0]
        dy = s[2] - self._p_ref[1]
        dz = s[3] - self._p_ref[2]
        self._n += int(sign)
        self._st += sign * dt
        self._stt += sign * dt * dt
        self._sx += sign * dx
        self._sy += sign * dy
        self._sz += sign * dz
        self._stx += sign * dt * dx
        self._sty += sign * dt * dy
        self._stz += sign * dt * dz

    def _push(self, t, x, y, z):
        """Add a sample to the window; returns (speed, time it refers to) or (NaN, NaN)."""
        win = self._win
        if not win:
            self._t_ref, self._p_ref = t, (x, y, z)
        s = (t, x, y, z)
        win.append(s)
        self._accumulate(s, 1.0)
        horizon = t - self.speed_window + _SLACK
        while win[0][0] <= horizon:
            self._accumulate(win.popleft(), -1.0)
        if t - self._t_ref > 1.0:  # amortised O(1): once a second, O(window) work
            first = win[0]
            self._rebase(*first)
        n = self._n
        if n < self.min_window_samples or t - win[0][0] < 0.5 * self.speed_window - _SLACK:
            return math.nan, math.nan
        st = self._st
        ctt = self._stt - st * st / n
        if ctt <= 0.0:
            return math.nan, math.nan
        vx = (self._stx - st * self._sx / n) / ctt
        vy = (self._sty - st * self._sy / n) / ctt
        vz = (self._stz - st * self._sz / n) / ctt
        return math.sqrt(vx * vx + vy * vy + vz * vz), self._t_ref + st / n

    def _reset_onset_search(self):
        self._cross_t = None     # first sample of this rise with speed >= onset_speed
        self._hold_start = None  # first sample of the current streak >= onset_speed

    def _reset_end_search(self):
        self._fast_c = None      # last time speed was >= onset_speed (window centre)
        self._rest_start_t = None

    def _search_onset(self, t, speed, center):
        if speed < self._end_thr:  # at rest: no rise in progress
            self._reset_onset_search()
            self._calm_c = center
            return []
        if speed < self._on_thr:
            self._hold_start = None
            return []
        if self._cross_t is None:
            self._cross_t = t
        if self._hold_start is None:
            self._hold_start = t
        if t - self._hold_start < self.onset_hold - _SLACK or not self._rest_known():
            return []
        # Confirmed. The hand left rest before the speed first crossed onset_speed.
        lo = max(self._stream_start, self._last_end, t - self.max_backdate)
        if self._on_thr > self.onset_speed and self._calm_c is not None:
            # A drifting rest: the hand left it after it was last as slow as at rest.
            lo = max(lo, self._calm_c - self.speed_window)
        hi = max(lo, self._cross_t)
        t0 = self._fit_between(lo, hi, hi, reverse=False)
        self._moving = True
        self._pending.clear()           # the rise, not rest
        self._reset_onset_search()
        self._reset_end_search()
        self._fast_c = center
        self._onset_time = t0
        return [Event('onset', t0)]

    def _search_end(self, t, speed, center):
        if speed >= self._on_thr:
            self._fast_c = center
            self._rest_start_t = None
            return []
        if speed >= self._end_thr:
            self._rest_start_t = None
            return []
        if self._rest_start_t is None:
            self._rest_start_t = t
        if t - self._rest_start_t < self.end_hold - _SLACK:
            return []
        return [self._close(self._date_end(t))]

    def _date_end(self, t):
        """End time from the slowing down (since speed was last >= onset_speed) and the rest."""
        # Mirror of the onset window, which ends half a velocity window after the crossing.
        lo = max(self._fast_c - 0.5 * self.speed_window, self._onset_time, t - self.max_backdate)
        return self._fit_between(lo, t, lo, reverse=True)

    def _fit_between(self, lo, hi, fallback, reverse):
        """Fit the cubic onset (or, reversed, end) to the stored samples in [lo, hi]."""
        rows = [s for s in self._hist if lo - _SLACK <= s[0] <= hi + _SLACK]
        if len(rows) < 4:
            return fallback
        a = np.array(rows)
        # A rest that moves (the rest level, not the floor, sets the threshold) is a drift.
        drift = self._on_thr > self.onset_speed
        if not reverse:
            return fit_cubic_onset(a[:, 0], a[:, 1:], lo, hi, drift=drift)
        return -fit_cubic_onset(-a[::-1, 0], a[::-1, 1:], -hi, -lo, drift=drift)


def segment_motion(t, positions, **params) -> Tuple[float, float]:
    """Onset and end time of the first movement in a recorded stream.

    ``t``: (T,) strictly increasing seconds; ``positions``: (T, 3), rows with NaN are
    missing samples and are skipped. ``params`` are ``MotionSegmenter``'s. The stream is
    fed through the streaming detector, so the times equal what the observer node finds
    online on the same samples. If the recording stops before the end is confirmed, the end
    is dated from the data when the hand was already at rest, else it is the last sample.
    Later movements in the stream are ignored. Raises ValueError if no movement onset is
    found or the input is malformed.
    """
    t = np.asarray(t, dtype=float)
    p = np.asarray(positions, dtype=float)
    if t.ndim != 1:
        raise ValueError(f'segment_motion: t must be 1-D, got shape {t.shape}')
    if p.ndim != 2 or p.shape != (t.size, 3):
        raise ValueError(f'segment_motion: positions must have shape (len(t), 3) = ({t.size}, 3), '
                         f'got {p.shape}')
    if not np.all(np.isfinite(t)):
        raise ValueError('segment_motion: t contains NaN or Inf')
    if np.any(np.isinf(p)):
        raise ValueError('segment_motion: positions contain Inf')
    valid = ~np.isnan(p).any(axis=1)
    tv, pv = t[valid], p[valid]
    if np.any(np.diff(tv) <= 0):
        raise ValueError('segment_motion: t must be strictly increasing')
    seg = MotionSegmenter(**params)
    onset = None
    for ti, row in zip(tv.tolist(), pv.tolist()):
        for ev in seg.update(ti, row):
            if ev.kind == 'onset':
                onset = ev.time
            elif ev.kind == 'end' and onset is not None:
                return onset, ev.time
    if onset is None:
        raise ValueError(f'segment_motion: no movement found in {tv.size} valid samples '
                         f'(speed never stayed >= {seg.onset_threshold:.3g} m/s for '
                         f'{seg.onset_hold} s after {seg.rest_min} s of rest)')
    return onset, seg.finish()[0].time

