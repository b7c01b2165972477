"""Checks of mocap wrist poses, without ROS (the observer node calls these).

Per-message work is plain float arithmetic: at 500 Hz numpy's per-call overhead on 3-vectors
would cost more than the math.
"""

import math
from typing import Optional, Sequence

# Why a pose was dropped; the observer node counts each.
POSE_REJECT_REASONS = ('non_finite', 'bad_quaternion', 'wrong_frame', 'duplicate_stamp',
                  'stamp_backwards', 'exception')


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
