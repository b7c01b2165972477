"""Checks and frame change for mocap wrist poses, without ROS (the observer node calls these).

Per-message work is plain float arithmetic: at 500 Hz numpy's per-call overhead on 3-vectors
would cost more than the math.
"""

import math
from typing import Optional, Sequence, Tuple

import numpy as np

# Why a pose was dropped; the observer node counts each.
REJECT_REASONS = ('non_finite', 'bad_quaternion', 'wrong_frame', 'duplicate_stamp',
                  'stamp_backwards', 'exception')


def check_pose(stamp_ns: int, frame_id: str, position: Sequence[float],
               orientation_xyzw: Sequence[float], last_stamp_ns: Optional[int],
               expected_frame: str = '', quaternion_tolerance: float = 0.01) -> Optional[str]:
    """The reason (one of ``REJECT_REASONS``) to drop a pose, or None if it is usable.

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


def quaternion_to_matrix(q_xyzw: Sequence[float], tolerance: float = 1e-3) -> np.ndarray:
    """Rotation matrix of a unit quaternion (x, y, z, w); renormalised if within ``tolerance``."""
    q = np.asarray(q_xyzw, dtype=float)
    if q.shape != (4,) or not np.all(np.isfinite(q)):
        raise ValueError(f'quaternion must be 4 finite numbers (x, y, z, w), got {q_xyzw!r}')
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > tolerance:
        raise ValueError(f'quaternion (x, y, z, w) = {list(q)} is not unit length '
                         f'(norm {norm:.6g})')
    x, y, z, w = q / norm
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


class FrameTransform:
    """Fixed rigid transform p_target = R p_source + t.

    ``translation`` and ``rotation_xyzw`` are the source frame's origin and orientation
    expressed in the target frame (for the observer: the mocap frame in the robot base).
    """

    def __init__(self, translation: Sequence[float], rotation_xyzw: Sequence[float]):
        t = np.asarray(translation, dtype=float)
        if t.shape != (3,) or not np.all(np.isfinite(t)):
            raise ValueError(f'translation must be 3 finite numbers (x, y, z), '
                             f'got {translation!r}')
        self.rotation = quaternion_to_matrix(rotation_xyzw)
        self.translation = t
        self._r = tuple(tuple(float(v) for v in row) for row in self.rotation)
        self._t = tuple(float(v) for v in t)

    def apply(self, x: float, y: float, z: float) -> Tuple[float, float, float]:
        """One point, as floats (the per-message path)."""
        (a, b, c), (d, e, f), (g, h, i) = self._r
        tx, ty, tz = self._t
        return (a * x + b * y + c * z + tx, d * x + e * y + f * z + ty, g * x + h * y + i * z + tz)

    def apply_array(self, points) -> np.ndarray:
        """(N, 3) points at once."""
        p = np.asarray(points, dtype=float)
        return p @ self.rotation.T + self.translation


def stamp_to_ns(sec: int, nanosec: int) -> int:
    return int(sec) * 1_000_000_000 + int(nanosec)


def ns_to_stamp(ns: int) -> Tuple[int, int]:
    """(sec, nanosec) with 0 <= nanosec < 1e9, as builtin_interfaces/Time wants."""
    sec, nanosec = divmod(int(ns), 1_000_000_000)
    return sec, nanosec
