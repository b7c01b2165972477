"""The robot side of the generated scenarios: the arm in the scene, its IK and its joint paths.

The robot is configuration (robot/description.py): every robot-specific number (seed postures,
tool orientation, clearance frames and link radius, limits) comes from the description or the
model. Robot motions are joint-space minimum-jerk-like (quintic) paths through IK waypoints
(``robot.kinematics.RobotKinematics``, warm started from a per-pattern nominal posture so postures
are consistent within a pattern), spanning exactly the human's movement (onset..end), within joint
position and velocity limits.
"""

from __future__ import annotations

import numpy as np

# Tool orientations in the robot's base frame (the tool frame's z axis is the approach direction;
# a description's tool_rpy maps it onto its flange frame): pointing down, and pointing
# horizontally at the human (+x); both get turned by the yaw toward the target.
R_DOWN = np.array([[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]])
R_FORWARD = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
TABLE_CLEARANCE = 0.01       # m the arm (past its shoulder) keeps above the table top (z = 0)
ROTATION_TOL = 0.2  # rad; a handover or pointing only needs the gripper roughly facing its target
# rad demonstrated postures keep from every joint limit: a prediction around them then stays
# inside the limits (MuJoCo stops a joint at its limit; the controller's model does not know it).
LIMIT_MARGIN = 0.1


def quintic_path(t, knot_times, knots, stops=None):
    """Joint path through ``knots`` (K, J) at ``knot_times`` (K,), held outside; (q, qd) at t.

    Each segment is a quintic with zero acceleration at its knots (minimum jerk between rests).
    Interior knots pass with a velocity that keeps each joint monotone between knots (zero where a
    joint turns back, else the harmonic mean of the neighbouring slopes, as in PCHIP); ``stops``
    (K,) bool forces a rest at a knot (e.g. a grasp).
    """
    t = np.asarray(t, dtype=float)
    T = np.asarray(knot_times, dtype=float)
    Q = np.asarray(knots, dtype=float)
    if Q.ndim != 2 or Q.shape[0] != T.size or T.size < 2 or np.any(np.diff(T) <= 0):
        raise ValueError('knots must be (K, J) with K >= 2 strictly increasing knot times')
    K = T.size
    stops = np.zeros(K, dtype=bool) if stops is None else np.asarray(stops, dtype=bool)
    slopes = np.diff(Q, axis=0) / np.diff(T)[:, None]
    V = np.zeros_like(Q)
    for k in range(1, K - 1):
        if stops[k]:
            continue
        a, b = slopes[k - 1], slopes[k]
        same = a * b > 0
        V[k, same] = 2 * a[same] * b[same] / (a[same] + b[same])
    q = np.empty((t.size, Q.shape[1]))
    qd = np.zeros_like(q)
    q[t <= T[0]] = Q[0]
    q[t >= T[-1]] = Q[-1]
    for k in range(K - 1):
        sel = (t > T[k]) & (t < T[k + 1])
        if not np.any(sel):
            continue
        h = T[k + 1] - T[k]
        s = ((t[sel] - T[k]) / h)[:, None]
        # Quintic Hermite basis with zero end accelerations.
        h00 = 1 - 10 * s**3 + 15 * s**4 - 6 * s**5
        h01 = 10 * s**3 - 15 * s**4 + 6 * s**5
        h10 = s - 6 * s**3 + 8 * s**4 - 3 * s**5
        h11 = -4 * s**3 + 7 * s**4 - 3 * s**5
        d00 = -30 * s**2 + 60 * s**3 - 30 * s**4
        d10 = 1 - 18 * s**2 + 32 * s**3 - 15 * s**4
        d11 = -12 * s**2 + 28 * s**3 - 15 * s**4
        q[sel] = h00 * Q[k] + h01 * Q[k + 1] + h * (h10 * V[k] + h11 * V[k + 1])
        qd[sel] = (d00 * Q[k] - d00 * Q[k + 1]) / h + d10 * V[k] + d11 * V[k + 1]
    return q, qd


def _yaw_rotation(yaw: float, R: np.ndarray) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ R


def _yaw(position) -> float:
    """Direction of ``position`` (base frame) seen from the robot's vertical axis."""
    return float(np.arctan2(position[1], position[0]))


class Arm:
    """The robot side of the scenarios: its kinematics and description, and the map from the
    scene's world frame (the human, the stands, the pole) to its base frame (its targets).

    Rotations it returns are flange orientations in the base frame: a tool orientation times the
    description's tool rotation.
    """

    def __init__(self, kinematics=None):
        if kinematics is None:
            from mixture_ip_ros.robot.kinematics import RobotKinematics
            kinematics = RobotKinematics()
        self.kin = kinematics
        self.description = d = kinematics.description
        self._to_base = d.world_to_base()
        self._to_world = d.base_to_world()
        self._tool = d.tool_rotation()
        self.box_seed = np.array(d.box_seed if d.box_seed is not None else d.home, dtype=float)
        self.pole_home = np.array(d.pole_home if d.pole_home is not None else d.home,
                                  dtype=float)
        if not d.clearance_frames:
            self.clearance_frames = [d.flange_frame]
        else:
            self.clearance_frames = list(d.clearance_frames)

    def base(self, p_world) -> np.ndarray:
        return self._to_base.apply_array(np.asarray(p_world, dtype=float))

    @property
    def tool_axis(self) -> np.ndarray:
        """The tool's approach axis in the flange frame."""
        return self._tool.T[:, 2]

    def flange(self, R_tool_base) -> np.ndarray:
        """Flange orientation (base frame) for a tool orientation given in the base frame."""
        return R_tool_base @ self._tool

    def flange_from_world(self, R_tool_world) -> np.ndarray:
        """Flange orientation (base frame) for a tool orientation given in the world frame."""
        return self._to_base.rotation @ R_tool_world @ self._tool

    def down(self, p_base) -> np.ndarray:
        """Tool pointing down, turned with the robot's axis toward ``p_base`` (no wrist roll)."""
        return self.flange(_yaw_rotation(_yaw(p_base), R_DOWN))

    def toward(self, p_base) -> np.ndarray:
        """Tool pointing horizontally from the robot's axis toward ``p_base``."""
        return self.flange(_yaw_rotation(_yaw(p_base), R_FORWARD))

    def seed(self, p_base) -> np.ndarray:
        """The box seed posture turned toward ``p_base`` by the first (vertical) joint."""
        return np.r_[self.box_seed[0] + _yaw(p_base), self.box_seed[1:]]

    def link_points(self, q) -> np.ndarray:
        """The clearance frames' origins at q, (m, 3), world frame."""
        return self._to_world.apply_array(self.kin.frame_positions(q, self.clearance_frames))

    def feasible(self, q, qd) -> bool:
        """A joint path (samples, dof) within the position and velocity limits, with the arm
        (its clearance polyline after the first point, every 5th sample) above the table."""
        kin = self.kin
        if not (check_velocity_limits(kin, qd) and np.all(q >= kin.lower)
                and np.all(q <= kin.upper)):
            return False
        lowest = min(self.link_points(x)[1:, 2].min(initial=np.inf) for x in q[::5])
        return bool(lowest > TABLE_CLEARANCE)


def ik(kin, position, q0, rotation, tol=2e-3):
    """IK of the flange to ``position`` (base frame) with the soft flange ``rotation``."""
    # Tight position, soft orientation (within ROTATION_TOL), no random restarts: a restart could
    # land in another arm configuration and break the consistency of a pattern's postures.
    return kin.ik(np.asarray(position, dtype=float), q0, rotation=rotation, tol=tol,
                  orientation_weight=0.3, rotation_tol=ROTATION_TOL, restarts=0,
                  limit_margin=LIMIT_MARGIN)


def ik_turning(kin, position, q0, R_from, R_to, steps: int = 6):
    """IK at ``position`` with the flange orientation turned from R_from to R_to in ``steps``
    (each solve warm-started at the last): a local solver then follows one arm configuration
    from the seed's to a pose far from it (pointing forward instead of down)."""
    from scipy.spatial.transform import Rotation, Slerp
    turn = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([R_from, R_to])))
    q = q0
    for s in np.linspace(0.0, 1.0, steps + 1):
        q = ik(kin, position, q, turn([s]).as_matrix()[0])
    return q


def check_velocity_limits(kin, qd, slack: float = 1.0) -> bool:
    return bool(np.all(np.abs(qd) <= slack * kin.velocity_limit))
