"""A person's hand path made an arm's joint path: the person's body frame placed on the arm,
a reach scale where the arm's reach differs, and inverse kinematics along the path with
continuity within the arm's position and speed limits.

- Placement: the person's shoulder goes where the arm's shoulder is (:func:`shoulder`: the
  second joint's origin seen on the first joint's axis), the body frame turned by a stated yaw,
  and the hand's offsets from the shoulder scaled by ``scale``:
  p_base = shoulder_arm + scale Rz(yaw) (p_body - shoulder_body).
- Reach: one scale of the hand's offsets from the shoulder (:func:`reach_scale`), 1 unless
  some positions are out of reach: below 1 for positions beyond the arm's reach, above 1 (as
  far as the farthest position allows) for positions nearer the shoulder than the arm's elbow
  and wrist can fold; what no scale brings in is reached as closely as the joint limits allow
  and the residual is reported.
- Following a path (:func:`joint_path`): each target is solved from the previous solution
  within what the joints cover in the meantime at their speed limits, pulled toward a posture
  (the arm's home) so that a redundant arm keeps to one branch. The path is therefore
  continuous (no branch flip) and within the position and speed limits; where the person's
  hand is faster than the arm, or out of its reach, the flange lags or stays as close as it
  gets and catches up, and the time axis stays the person's.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

def shoulder(kin) -> np.ndarray:
    """The arm's shoulder in its base frame (3,): the second joint's origin projected onto the
    first joint's axis at the home posture (the iiwa's and the Panda's joint 2, the point on the
    UR5's base axis at its shoulder-lift height)."""
    q = kin.description.home_array()
    pin.forwardKinematics(kin.model, kin.data, q)
    pin.computeJointJacobians(kin.model, kin.data, q)
    first = kin.data.oMi[1].translation
    axis = pin.getJointJacobian(kin.model, kin.data, 1, pin.LOCAL_WORLD_ALIGNED)[3:, 0]
    axis = axis / np.linalg.norm(axis)
    second = kin.data.oMi[2].translation
    return first + axis * float((second - first) @ axis)


@functools.lru_cache(maxsize=8)
def _reach(robot_source: str) -> tuple:
    from mixture_ip_ros.robot.kinematics import RobotKinematics
    kin = RobotKinematics(robot_source)
    rng = np.random.default_rng(0)
    Q = rng.uniform(kin.lower, kin.upper, (20000, kin.dof))
    d = np.linalg.norm(kin.fk_positions(Q) - shoulder(kin), axis=1)
    return float(d.min()), float(d.max())


def reach(kin) -> tuple:
    """(nearest, farthest) the flange gets to and from the shoulder (m), over 20000 postures
    drawn uniformly inside the joint limits (seeded: the same every time). The nearest is where
    the elbow and wrist fold as far as their limits allow (the iiwa's about 0.32 m, the Panda's
    and the UR5's a few cm)."""
    return _reach(kin.description.source)


def reach_scale(kin, offsets, margin: float) -> float:
    """The scale of hand offsets from the shoulder (n, 3) that fits their distances into the
    arm's reach, [nearest / margin, margin farthest]: 1 when they fit; below 1 when some are
    too far; when some are too near (an elbow that folds less than a person's), above 1 as far
    as the farthest offset stays within reach (never both: enlarging for the near ones is
    bounded by the far ones)."""
    if not 0 < margin <= 1:
        raise ValueError(f'reach margin must be in (0, 1], got {margin}')
    d = np.linalg.norm(np.asarray(offsets, dtype=float), axis=1)
    d = d[np.isfinite(d)]
    if d.size == 0 or d.max() <= 0:
        raise ValueError('no hand position to scale')
    near, far = reach(kin)
    if d.max() > margin * far:
        return float(margin * far / d.max())
    if d.min() < near / margin:
        return float(max(1.0, min(near / (margin * max(d.min(), 1e-9)),
                                  margin * far / d.max())))
    return 1.0


@dataclass(frozen=True)
class Placement:
    """A person's body frame on the arm: p_base = arm_shoulder + scale Rz(yaw) (p - body_shoulder)."""

    body_shoulder: tuple
    arm_shoulder: tuple
    yaw: float = 0.0
    scale: float = 1.0

    def __post_init__(self):
        for name in ('body_shoulder', 'arm_shoulder'):
            v = np.asarray(getattr(self, name), dtype=float)
            if v.shape != (3,) or not np.all(np.isfinite(v)):
                raise ValueError(f'{name} must be 3 finite numbers, got {getattr(self, name)!r}')
        if not (np.isfinite(self.yaw) and np.isfinite(self.scale) and self.scale > 0):
            raise ValueError(f'yaw must be finite and scale positive, got {self.yaw}, '
                             f'{self.scale}')

    @property
    def rotation(self) -> np.ndarray:
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

    def offsets(self, points) -> np.ndarray:
        """Points (n, 3) of the body frame as offsets from the shoulder, turned into the base's
        axes, not yet scaled."""
        p = np.asarray(points, dtype=float) - np.asarray(self.body_shoulder, dtype=float)
        return p @ self.rotation.T

    def apply(self, points) -> np.ndarray:
        """Points (n, 3) of the body frame in the base frame; NaN rows stay NaN."""
        return np.asarray(self.arm_shoulder, dtype=float) + self.scale * self.offsets(points)


@dataclass
class JointPath:
    """``q`` (n, dof) joints along a path; ``error`` (n,) m from each target (NaN where the
    target was missing); ``max_step`` the largest change of a joint between two samples."""

    q: np.ndarray
    error: np.ndarray

    @property
    def max_step(self) -> float:
        return float(np.abs(np.diff(self.q, axis=0)).max()) if len(self.q) > 1 else 0.0


def joint_path(kin, targets, dt: float, q_start, *, speed_limit=None, posture=None,
               posture_weight: float = 0.05, limit_margin: float = 0.1,
               tol: float = 1e-3) -> JointPath:
    """The arm following flange targets (n, 3) in the base frame, one every ``dt`` s.

    The first target is solved from ``q_start`` without a bound (the arm placed at its start);
    every later one from the previous solution within what the joints cover meanwhile at
    ``speed_limit`` (rad/s per joint, default the arm's limits): the least-squares closest
    configuration in that box, pulled toward ``posture`` (default the arm's home) with
    ``posture_weight`` m/rad, the position then polished alone. So the path never jumps to
    another configuration (a branch flip) and stays within the joint limits less
    ``limit_margin`` and within the speed limits; where the hand moves faster than the arm
    can, or out of its reach, the flange lags or stays as close as it gets and catches up as
    the hand slows down; the time axis stays the person's. A NaN target is a missing sample:
    the arm holds (before the first target, it is where the first target puts it)."""
    targets = np.asarray(targets, dtype=float)
    if targets.ndim != 2 or targets.shape[1] != 3 or len(targets) == 0:
        raise ValueError(f'targets must have shape (n, 3), got {targets.shape}')
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f'dt must be a positive number of seconds, got {dt!r}')
    speed = kin.velocity_limit if speed_limit is None else np.asarray(speed_limit, float)
    posture = kin.description.home_array() if posture is None else np.asarray(posture, float)
    have = np.flatnonzero(~np.isnan(targets).any(axis=1))
    if have.size == 0:
        raise ValueError('no target to follow: every row is missing')
    Q = np.empty((len(targets), kin.dof))
    err = np.full(len(targets), np.nan)
    q = np.asarray(q_start, dtype=float)
    last = None
    for i in have:
        bound = None if last is None else speed * dt * (i - last)
        q, err[i] = kin.closest(targets[i], q, posture=posture, max_change=bound,
                                posture_weight=posture_weight, tol=tol,
                                limit_margin=limit_margin)
        Q[i] = q
        last = i
    held = have[np.maximum(np.searchsorted(have, np.arange(len(targets)), side='right') - 1, 0)]
    return JointPath(Q[held], err)
