"""A recorded interaction resampled at the times of the frames that show it."""

from __future__ import annotations

import numpy as np

from mixture_ip_ros.io.records import InteractionRecord
from mixture_ip_ros.robot.description import load_description

TRAIL_STEP = 0.02          # seconds between trail points
TRAIL_SECONDS = 4.0        # trail length drawn in the scene


def _validate(record: InteractionRecord, dof: int) -> None:
    def arr(name, ndim, cols=None):
        a = np.asarray(getattr(record, name), dtype=float)
        if a.ndim != ndim or (cols is not None and a.shape[1] != cols):
            want = f'(n, {cols})' if cols is not None else '(n,)'
            raise ValueError(f'record.{name} must have shape {want}, got {a.shape}')
        return a
    t, q, flange = arr('t', 1), arr('q', 2, dof), arr('flange', 2, 3)
    if t.size < 1 or q.shape[0] != t.size or flange.shape[0] != t.size:
        raise ValueError(f'record.t {t.shape}, q {q.shape} and flange {flange.shape} '
                         'must have the same, non-zero length')
    if not all(np.all(np.isfinite(a)) for a in (t, q, flange)) or np.any(np.diff(t) <= 0):
        raise ValueError('record.t must be strictly increasing and record.t, q, flange finite')
    wt, w = arr('wrist_t', 1), arr('wrist', 2, 3)
    if wt.size != w.shape[0]:
        raise ValueError(f'record.wrist_t {wt.shape} and record.wrist {w.shape} do not match')
    pt = arr('posterior_t', 1)
    if np.any(np.diff(pt) < 0) or not np.all(np.isfinite(pt)):
        raise ValueError('record.posterior_t must be finite and non-decreasing')
    K = len(record.component_labels)
    post = np.asarray(record.posterior, dtype=float)
    if pt.size and post.shape != (pt.size, K):
        raise ValueError(f'record.posterior must have shape ({pt.size}, {K}) for {pt.size} '
                         f'posterior_t and {K} component_labels, got {post.shape}')
    for name in ('phase', 'alpha'):
        if np.asarray(getattr(record, name)).reshape(-1).size != pt.size:
            raise ValueError(f'record.{name} must have one entry per posterior_t ({pt.size})')
    if record.target is not None and np.asarray(record.target, float).shape != (3,):
        raise ValueError('record.target must be None or 3 numbers')


class Replay:
    """The record resampled at arbitrary times: what each frame shows. Positions are moved from
    the robot's base frame (the record's) to the scene's world frame (the picture's)."""

    def __init__(self, record: InteractionRecord):
        extra = record.extra if isinstance(record.extra, dict) else {}
        self.robot = load_description(extra.get('robot'))
        _validate(record, self.robot.dof)
        to_world = self.robot.base_to_world()
        self.record = record
        self.t = np.asarray(record.t, float)
        self.q = np.asarray(record.q, float)
        self.flange = to_world.apply_array(np.asarray(record.flange, float))
        self.target = (None if record.target is None
                       else to_world.apply_array(np.asarray(record.target, float)))
        wt = np.asarray(record.wrist_t, float)
        w = to_world.apply_array(np.asarray(record.wrist, float).reshape(-1, 3))
        ok = np.all(np.isfinite(w), axis=1) & np.isfinite(wt)
        self.wrist_t, self.wrist = wt[ok], w[ok]
        order = np.argsort(self.wrist_t)
        self.wrist_t, self.wrist = self.wrist_t[order], self.wrist[order]
        steps = np.diff(self.wrist_t)
        self.wrist_period = float(np.median(steps)) if steps.size else 0.01
        self.post_t = np.asarray(record.posterior_t, float)
        self.post = (np.asarray(record.posterior, float).reshape(self.post_t.size, -1)
                     if self.post_t.size else np.zeros((0, len(record.component_labels))))
        self.phase = np.asarray(record.phase, float).reshape(-1)
        self.alpha = np.asarray(record.alpha, float).reshape(-1)
        self.labels = [str(x) for x in record.component_labels]
        # A partner whose part the robot takes (the interactions demo): where their hand was,
        # and where the person the robot answers stood (collar x, y, z and facing, world frame).
        partner = extra.get('partner')
        self.partner_t = self.partner = None
        if partner:
            self.partner_t = np.asarray(partner['t'], float)
            self.partner = to_world.apply_array(np.asarray(partner['xyz'], float).reshape(-1, 3))
        self.person = extra.get('person1')

    @property
    def origin(self) -> float:
        """Times are shown relative to the movement onset when known."""
        return float(self.record.onset_time) if self.record.onset_time is not None else self.t[0]

    def joints(self, time: float) -> np.ndarray:
        return np.array([np.interp(time, self.t, self.q[:, j]) for j in range(self.q.shape[1])])

    def wrist_observed(self, time: float) -> np.ndarray | None:
        """The wrist as last seen, if seen within 2.5 sample periods; None while occluded."""
        if self.wrist_t.size == 0:
            return None
        i = int(np.searchsorted(self.wrist_t, time, side='right')) - 1
        if i < 0 or time - self.wrist_t[i] > 2.5 * self.wrist_period:
            return None
        return self.wrist[i]

    def wrist_path(self, time: float) -> np.ndarray | None:
        """Where the person's wrist is drawn: the observed path, interpolated across gaps."""
        if self.wrist_t.size == 0:
            return None
        return np.array([np.interp(time, self.wrist_t, self.wrist[:, j]) for j in range(3)])

    def partner_at(self, time: float) -> np.ndarray | None:
        """Where the partner's hand was at `time` (its last sample then); None where the tracker
        had lost it or outside the recording."""
        if self.partner is None:
            return None
        i = int(np.searchsorted(self.partner_t, time, side='right')) - 1
        if i < 0 or not np.all(np.isfinite(self.partner[i])):
            return None
        return self.partner[i]

    def belief(self, time: float) -> int | None:
        """Index of the last estimator output at or before `time`."""
        i = int(np.searchsorted(self.post_t, time, side='right')) - 1
        return i if i >= 0 else None

    def trail(self, times: np.ndarray, values: np.ndarray, time: float) -> list[np.ndarray]:
        """The last TRAIL_SECONDS of a path up to `time`, thinned to about one point per
        TRAIL_STEP, as pieces split where samples are missing (an occlusion is not drawn)."""
        sel = (times <= time) & (times >= time - TRAIL_SECONDS)
        ts, pts = times[sel], values[sel]
        if ts.size < 2:
            return []
        period = float(np.median(np.diff(times)))
        step = max(1, int(round(TRAIL_STEP / max(period, 1e-6))))
        keep = np.arange(ts.size - 1, -1, -step)[::-1]          # always keep the newest point
        ts, pts = ts[keep], pts[keep]
        breaks = np.flatnonzero(np.diff(ts) > (step + 1.5) * period) + 1
        return [piece for piece in np.split(pts, breaks) if len(piece) > 1]
