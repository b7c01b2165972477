"""Rigid frame transforms (a fixed mocap-to-robot-base calibration), without ROS or tf."""

from typing import Sequence, Tuple

import numpy as np

# |q| may differ from 1 by this much (rounding in a YAML file or a message); renormalised.
QUATERNION_TOLERANCE = 1e-3


def quaternion_to_matrix(q_xyzw: Sequence[float],
                         tolerance: float = QUATERNION_TOLERANCE) -> np.ndarray:
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

    ``translation`` and ``quaternion`` (x, y, z, w) are the source frame's origin and
    orientation expressed in the target frame (for the observer and the dataset loader: the
    mocap world in the robot base). The default is the identity.
    """

    def __init__(self, translation: Sequence[float] = (0.0, 0.0, 0.0),
                 quaternion: Sequence[float] = (0.0, 0.0, 0.0, 1.0)):
        t = np.asarray(translation, dtype=float)
        if t.shape != (3,) or not np.all(np.isfinite(t)):
            raise ValueError(f'translation must be 3 finite numbers (x, y, z), '
                             f'got {translation!r}')
        self.rotation = quaternion_to_matrix(quaternion)
        self.translation = t
        q = np.asarray(quaternion, dtype=float)
        self.quaternion = tuple(float(v) for v in q / np.linalg.norm(q))
        # Plain floats: the per-message path does scalar arithmetic, numpy's per-call overhead
        # on 3-vectors would cost more than the math.
        self._r = tuple(tuple(float(v) for v in row) for row in self.rotation)
        self._t = tuple(float(v) for v in t)

    @classmethod
    def from_any(cls, transform) -> 'FrameTransform':
        """None (identity), a FrameTransform, or a pair (translation, quaternion_xyzw)."""
        if transform is None:
            return cls()
        if isinstance(transform, cls):
            return transform
        try:
            translation, quaternion = transform
        except (TypeError, ValueError):
            raise ValueError('transform must be None, a FrameTransform or (translation, '
                             f'quaternion_xyzw), got {transform!r}') from None
        return cls(np.ravel(translation), np.ravel(quaternion))

    def apply(self, x: float, y: float, z: float) -> Tuple[float, float, float]:
        """One point, as floats (the per-message path)."""
        (a, b, c), (d, e, f), (g, h, i) = self._r
        tx, ty, tz = self._t
        return (a * x + b * y + c * z + tx, d * x + e * y + f * z + ty, g * x + h * y + i * z + tz)

    def apply_array(self, points) -> np.ndarray:
        """(N, 3) points at once; NaN rows stay NaN."""
        p = np.asarray(points, dtype=float)
        return p @ self.rotation.T + self.translation
