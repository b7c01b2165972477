"""Human wrist motion for generated demonstrations: reaches that look like a person's.

A reach from a rest position to a goal follows the minimum-jerk profile (Flash & Hogan 1985): the
straight-line min-jerk path plus a smooth bump through a via-point offset (the hand lifts and curves,
differently every time), on a mildly warped time axis (peak speed earlier or later), so no two
reaches share shape or speed. Mocap adds white noise; an occlusion removes a stretch of samples.
"""

from __future__ import annotations

import numpy as np


def minimum_jerk(s):
    """Min-jerk position profile h(s) = 10 s^3 - 15 s^4 + 6 s^5, s clipped to [0, 1]."""
    s = np.clip(np.asarray(s, dtype=float), 0.0, 1.0)
    return s**3 * (10 - 15 * s + 6 * s * s)


def via_bump(s):
    """64 s^3 (1 - s)^3: 1 at s = 1/2, zero position/velocity/acceleration at both ends."""
    s = np.clip(np.asarray(s, dtype=float), 0.0, 1.0)
    return 64 * s**3 * (1 - s) ** 3


def warp(tau, skew: float):
    """Monotone time warp tau + skew tau (1 - tau) of [0, 1] onto itself (|skew| < 1).

    skew > 0 moves the speed peak earlier, as in fast, ballistic reaches.
    """
    if not abs(skew) < 1:
        raise ValueError(f'skew must be in (-1, 1), got {skew}')
    tau = np.clip(np.asarray(tau, dtype=float), 0.0, 1.0)
    return tau + skew * tau * (1 - tau)


def reach(t, onset: float, duration: float, start, goal, via_offset=(0.0, 0.0, 0.0),
          skew: float = 0.0) -> np.ndarray:
    """Wrist positions (len(t), 3): at ``start`` until ``onset``, reaching ``goal`` at
    ``onset + duration`` and resting there after; ``via_offset`` is the mid-reach deviation."""
    if not duration > 0:
        raise ValueError(f'duration must be > 0, got {duration}')
    start = np.asarray(start, dtype=float)
    goal = np.asarray(goal, dtype=float)
    s = warp((np.asarray(t, dtype=float) - onset) / duration, skew)
    return (start + minimum_jerk(s)[:, None] * (goal - start)
            + via_bump(s)[:, None] * np.asarray(via_offset, dtype=float))


def mocap(xyz, rng: np.random.Generator, noise: float) -> np.ndarray:
    """Add white position noise of standard deviation ``noise`` metres per axis."""
    xyz = np.asarray(xyz, dtype=float)
    return xyz + rng.normal(0.0, noise, xyz.shape) if noise > 0 else xyz.copy()


def occlude(t, xyz, rng: np.random.Generator, probability: float, onset: float, end: float,
            min_gap: float = 0.1, max_gap: float = 0.3) -> np.ndarray:
    """With ``probability``, blank (NaN) one stretch of min_gap..max_gap seconds inside the movement."""
    xyz = np.array(xyz, dtype=float)
    if probability <= 0 or rng.uniform() >= probability:
        return xyz
    length = rng.uniform(min_gap, max_gap)
    lo, hi = onset + 0.1 * (end - onset), end - 0.1 * (end - onset) - length
    if hi <= lo:
        return xyz
    begin = rng.uniform(lo, hi)
    t = np.asarray(t)
    xyz[(t >= begin) & (t < begin + length)] = np.nan
    return xyz
