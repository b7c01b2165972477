"""Checks of mocap wrist poses, without ROS (the observer node calls these): is the message
well formed, and is it a person's wrist at all. Offline, the same checks over a recorded stream
(:func:`accepted_online`) and, with hindsight, over a whole track (:func:`plausible_track`).

Per-message work is plain float arithmetic: at 500 Hz numpy's per-call overhead on 3-vectors
would cost more than the math.
"""

from bisect import bisect_right
from collections import deque
from dataclasses import dataclass
import math
from typing import Optional, Sequence

import numpy as np

# Why a pose was dropped; the observer node counts each.
POSE_REJECT_REASONS = ('non_finite', 'bad_quaternion', 'wrong_frame', 'off_clock',
                       'duplicate_stamp', 'stamp_backwards', 'outside_workspace',
                       'implausible_speed', 'implausible_acceleration', 'exception')


def check_pose(stamp_ns: int, frame_id: str, position: Sequence[float],
               orientation_xyzw: Sequence[float], last_stamp_ns: Optional[int],
               expected_frame: str = '', quaternion_tolerance: float = 0.01) -> Optional[str]:
    """The reason (one of ``POSE_REJECT_REASONS``) to drop a pose, or None if it is usable.

    ``last_stamp_ns`` is the stamp of the last accepted pose (None: first pose); stamps must
    strictly increase. An empty ``expected_frame`` accepts any frame. The orientation must
    be a unit quaternion within ``quaternion_tolerance`` on its norm: a wrong norm means
    a broken or uninitialised message, even though only the position is used.
    """
    x, y, z = position
    qx, qy, qz, qw = orientation_xyzw
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z) and math.isfinite(qx)
            and math.isfinite(qy) and math.isfinite(qz) and math.isfinite(qw)):
        return 'non_finite'
    if abs(math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw) - 1.0) > quaternion_tolerance:
        return 'bad_quaternion'
    if expected_frame and frame_id != expected_frame:
        return 'wrong_frame'
    if last_stamp_ns is not None:
        if stamp_ns == last_stamp_ns:
            return 'duplicate_stamp'
        if stamp_ns < last_stamp_ns:
            return 'stamp_backwards'
    return None


@dataclass(frozen=True)
class HumanLimits:
    """What a person's wrist can do, in the robot base frame.

    People hand objects over and reach at peak wrist speeds of about 1-2 m/s and accelerations
    of about 10-30 m/s^2 (Flash & Hogan 1985; fast aimed movements a few times more); the
    defaults, 5 m/s and 100 m/s^2, are far beyond both, so only what no hand does is refused: a
    marker swapped or lost, a reflection, a corrupt message. ``noise`` is the sensor's position
    noise per axis (m), allowed for on top; ``window`` the span (s) of the velocities whose
    change is the acceleration; the workspace is a box in the base frame (m).
    """

    max_speed: float = 5.0
    max_acceleration: float = 100.0
    noise: float = 0.002
    window: float = 0.05
    workspace_min: tuple = (-3.0, -3.0, -3.0)
    workspace_max: tuple = (3.0, 3.0, 3.0)

    def __post_init__(self):
        for name in ('max_speed', 'max_acceleration', 'window'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f'{name} must be a positive number, got {value}')
        if not (math.isfinite(self.noise) and self.noise >= 0):
            raise ValueError(f'noise must be >= 0 m, got {self.noise}')
        lo, hi = tuple(self.workspace_min), tuple(self.workspace_max)
        if len(lo) != 3 or len(hi) != 3 or not all(
                math.isfinite(a) and math.isfinite(b) and a < b for a, b in zip(lo, hi)):
            raise ValueError(f'the workspace must be a box: 3 finite minima below 3 maxima, got '
                             f'{list(lo)} .. {list(hi)}')


class MotionPlausibility:
    """Refuses points no person's wrist reaches: outside the workspace, or implied by the last
    accepted points to move or accelerate beyond :class:`HumanLimits`. Judged against accepted
    points only, so one outlier never poisons the next; after a silence longer than the window
    the acceleration is not judged (there is no velocity to compare with)."""

    def __init__(self, limits: HumanLimits = HumanLimits()):
        self.limits = limits
        self._recent = deque()   # accepted (t, x, y, z) of the last 3 windows
        self._times = deque()    # their times, for bisection

    def reset(self) -> None:
        self._recent.clear()
        self._times.clear()

    def check(self, t: float, point) -> Optional[str]:
        """The reason to refuse ``point`` (x, y, z) at ``t`` s, or None; call :meth:`accept`
        with the points that pass every other check too."""
        lim = self.limits
        x, y, z = point
        (lo_x, lo_y, lo_z), (hi_x, hi_y, hi_z) = lim.workspace_min, lim.workspace_max
        if not (lo_x <= x <= hi_x and lo_y <= y <= hi_y and lo_z <= z <= hi_z):
            return 'outside_workspace'
        if not self._recent:
            return None
        t1, x1, y1, z1 = self._recent[-1]
        dt = t - t1
        if dt <= 0:
            return None          # the stamp checks refuse it
        step = math.sqrt((x - x1) ** 2 + (y - y1) ** 2 + (z - z1) ** 2)
        if step > lim.max_speed * dt + 6.0 * lim.noise:      # 3 sigma of both points
            return 'implausible_speed'
        w = lim.window
        mid = self._before(t - w) if dt <= w else None
        first = self._before(mid[0] - w) if mid is not None else None
        if first is not None:
            tm, xm, ym, zm = mid
            tf, xf, yf, zf = first
            d2, d1 = t - tm, tm - tf
            # v2 - v1: the velocity over the last window minus the one over the window before
            dx = (x - xm) / d2 - (xm - xf) / d1
            dy = (y - ym) / d2 - (ym - yf) / d1
            dz = (z - zm) / d2 - (zm - zf) / d1
            dv = math.sqrt(dx ** 2 + dy ** 2 + dz ** 2)
            span = 0.5 * (t - tf)
            noise = 4.0 * lim.noise / (w * w)          # of a difference of two velocities
            if dv / span > lim.max_acceleration + noise:
                return 'implausible_acceleration'
        return None

    def accept(self, t: float, point) -> None:
        recent, times = self._recent, self._times
        if times and t - times[-1] > self.limits.window:
            self.reset()         # a silence: velocities start again
        recent.append((t, *point))
        times.append(t)
        while times[0] < t - 3 * self.limits.window - 1e-9:
            recent.popleft()
            times.popleft()

    def _before(self, t0):
        """The last accepted sample at or before ``t0`` (None if none is kept)."""
        i = bisect_right(self._times, t0 + 1e-9)
        return self._recent[i - 1] if i else None


def accepted_online(t, points, limits: HumanLimits = HumanLimits()):
    """Which samples of a recorded stream (times (n,), points (n, 3) in the base frame) the
    observer's check accepts, fed in order as the observer is (a bool mask (n,)): the training
    data of a replayed stream then holds exactly what the nodes will see."""
    check = MotionPlausibility(limits)
    out = []
    for ti, p in zip(map(float, t), map(tuple, points)):
        ok = check.check(ti, p) is None
        if ok:
            check.accept(ti, p)
        out.append(ok)
    return np.array(out, dtype=bool)


def plausible_track(t, points, limits: HumanLimits = HumanLimits(), max_glitch: float = 0.5):
    """The samples of a whole recorded track a hand can have made (a bool mask (n,)), judged
    with hindsight, for data that is never streamed (a partner whose hand becomes the robot's
    demonstration). A tracker that loses the hand jumps somewhere else for a few samples and
    back; online, :class:`MotionPlausibility` takes such a run once it lasts longer than the
    jump takes at ``max_speed``. Here the track is cut at every jump no hand makes between two
    samples (the speed test). A piece lasting ``max_glitch`` s or more is the hand (the
    tracker found it again somewhere else); a shorter one joins them only when it is reachable
    at ``max_speed`` from the kept samples on both sides (longest first, until none joins).
    NaN rows are not samples. The tracker of the NuiSI recordings loses the hand for up to
    0.37 s at a time."""
    t = np.asarray(t, dtype=float)
    p = np.asarray(points, dtype=float)
    present = np.flatnonzero(~np.isnan(p).any(axis=1))
    ok = np.zeros(len(t), dtype=bool)
    if present.size == 0:
        return ok
    tp, pp = t[present], p[present]
    slack = 6.0 * limits.noise

    def reachable(i, j):
        return (np.linalg.norm(pp[j] - pp[i]) <= limits.max_speed * abs(tp[j] - tp[i]) + slack)

    cuts = [k + 1 for k in range(len(tp) - 1) if not reachable(k, k + 1)]
    pieces = [range(a, b) for a, b in zip([0] + cuts, cuts + [len(tp)])]
    pieces.sort(key=lambda r: (-len(r), r.start))
    kept = np.zeros(len(tp), dtype=bool)
    kept[pieces[0]] = True
    for r in pieces:
        if tp[r.stop - 1] - tp[r.start] >= max_glitch:
            kept[r] = True
    joined = True
    while joined:
        joined = False
        for r in pieces:
            if kept[r.start]:
                continue
            before = np.flatnonzero(kept[:r.start])
            after = np.flatnonzero(kept[r.stop:]) + r.stop
            if ((before.size == 0 or reachable(before[-1], r.start))
                    and (after.size == 0 or reachable(r.stop - 1, after[0]))):
                kept[r] = True
                joined = True
    ok[present[kept]] = True
    return ok
