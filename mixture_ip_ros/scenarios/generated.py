"""Seeded, reproducible demonstration sets that mirror the thesis's experiments.

Scene (the world frame of robot/scene.py, metres): the table top is z = 0; the default robot, the
KUKA iiwa 14, stands at the origin facing +x, and any other arm stands where its description's
mount puts its base. The human stands across the table, about 1.35 m away in +x, facing the robot
(so the human's right hand is at +y). The human's right wrist rests on the table edge near
HUMAN_REST = (1.22, 0.24, 0.08) between interactions. The human side (wrist streams) is given in
this world frame, the mocap frame 'world' of the bags; the robot side (joints, flange targets) in
the robot's base frame, which for the iiwa is the world frame itself.

The robot is configuration (robot/description.py): every robot-specific number (seed postures,
tool orientation, clearance frames and link radius, limits) comes from the description or the
model. The human side is drawn before and independently of the robot, from a random stream per
demonstration and attempt, so two arms given the same seed get the same human movements, except
where an arm cannot follow one (too fast for its joint speeds, out of reach): that attempt is
redrawn for that arm only. In the pole scenario a movement an arm cannot follow in the drawn time
is slowed to 1.03 times its fastest instead (so its human duration differs).

- Box assembly (thesis 3.4.2), 48 unlabeled demonstrations, labels kept for evaluation only:
    plate (15):       the human extends the hand forward to receive a plate anywhere in a
                      15 x 45 x 20 cm region in front of them; the robot lifts the plate off its
                      stand (the fixed first 15 % of the movement) and carries it gripper-down so
                      the flange ends 12 cm in front of (robot side) and 4 cm above the wrist.
    screw (20):       the human fetches the screwdriver lying on the table to their right; the
                      robot lifts a screw from its stand and offers it at one fixed place
                      (+- 8 mm of teaching noise), not correlated with the human.
    screwdriver (13): the human raises the hand (50-66 cm above the table, to their left) to
                      take/give the screwdriver; the robot, holding it pointed at the human, goes
                      straight to the hand (flange 9 cm in front of and 3 cm below the wrist).
  Stands are robot/scene.py's. Durations (stratified, so each pattern spans >= 1.5x): plate
  2.0-3.4 s, screw 1.7-2.8 s, screwdriver 1.2-2.1 s; fetching from a stand 70 deg to the side
  takes the iiwa (85 deg/s on joint 1) about 2 s, and a target the robot cannot reach in time is
  redrawn.
- Pole (thesis 3.4.1), 28 demonstrations: the human points with a wand at a spot on the table beyond
  a vertical pole in front of the robot (POLE_XY from robot/scene.py); the wrist ends 22 cm behind
  and 14 cm above the spot. The robot goes from a home posture behind the pole, via a posture beside
  the pole, to point at the same spot (flange 5 cm from it along a pointing axis tilted in from
  its side), passing left (+y) or right (-y) of the pole with every link >= 11 cm from the pole's
  axis; spots with |y| > 4 cm are reachable on their own side only, and 6 spots near the middle are
  demonstrated on both sides (very different arm postures). Labels 'left' / 'right'. The arm
  swings ~2 rad, so these take 2.6-4.6 s.
- Phase (thesis 4.3.1) and missing data (4.3.2): 2-D letter-"a" trajectories drawn from Gaussian
  weights of normalized Gaussian basis functions and a Gaussian phase speed alpha; missing-data
  training trajectories lose one random block of 180 samples.

Human reaches are minimum-jerk with shape and speed variability (``data.human``); mocap adds white
noise; an optional occlusion removes 0.1-0.3 s of wrist samples. Robot motions are joint-space
minimum-jerk-like (quintic) paths through IK waypoints (``robot.kinematics.RobotKinematics``, warm
started from a per-pattern nominal posture so postures are consistent within a pattern), spanning
exactly the human's movement (onset..end), within joint position and velocity limits. Both streams
are sampled at 100 Hz with 0.3-0.5 s of stillness before the onset and 0.4-0.6 s after the end.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple, Optional

import numpy as np

from mixture_ip_ros.core.demonstration import Demonstration
from mixture_ip_ros.scenarios import human_motion as human
from mixture_ip_ros.io.dataset import resample_wrist
from mixture_ip_ros.robot.description import DEFAULT_ROBOT, RobotDescription, load_description

LABEL_FILE = 'labels.json'
HUMAN_REST = np.array([1.22, 0.24, 0.08])
REST_JITTER = 0.015          # m, rest position differs between demonstrations
MOCAP_NOISE = 0.001          # m, white noise per axis
# Letter units (letter height ~2): the online observation noise of a hand-drawn letter
# (MixtureIProMP's observation_noise), the pen's departure from a smooth ProMP path.
LETTER_OBSERVATION_NOISE = 0.01
RATE = 100.0                 # Hz, mocap and joint_states
REST_BEFORE = (0.3, 0.5)     # s of stillness before the onset
REST_AFTER = (0.4, 0.6)      # s after the end (the end detector needs ~0.3 s of rest)
JOINT_CLOCK_OFFSET = 0.004   # s, joint_states are not sampled in phase with the mocap

# Tool orientations in the robot's base frame (the tool frame's z axis is the approach direction;
# a description's tool_rpy maps it onto its flange frame): pointing down, and pointing
# horizontally at the human (+x); both get turned by the yaw toward the target.
R_DOWN = np.array([[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]])
R_FORWARD = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])

# Box assembly geometry (see module docstring).
PLATE_GOAL = ((0.80, 0.95), (-0.25, 0.20), (0.22, 0.42))      # human wrist x, y, z ranges
SCREWDRIVER_FETCH = ((1.00, 1.12), (0.45, 0.60), (0.05, 0.14))
SCREWDRIVER_GOAL = ((0.82, 0.95), (-0.30, 0.05), (0.50, 0.66))
PLATE_OFFSET = np.array([-0.12, 0.0, 0.04])                  # flange end - wrist end
SCREWDRIVER_OFFSET = np.array([-0.09, 0.0, -0.03])
SCREW_HANDOVER = np.array([0.70, -0.12, 0.30])
# The robot holds the screwdriver here at the onset, pointing at the human, at the middle height of
# the handover region (flange 47-63 cm): lower, a Panda's wrist (joint 6 <= 215 deg) could not
# point it horizontally this close to its base.
SCREWDRIVER_HOLD = np.array([0.60, 0.0, 0.55])
SCREW_HANDOVER_NOISE = 0.008
LIFT = 0.12                  # m the robot lifts an object off its stand
LIFT_FRACTION = 0.15        # of the movement spent lifting (the deterministic part)
# Handing over an object from a stand 70 deg to the side takes the iiwa (85 deg/s on joint 1) ~2 s.
BOX_DURATION = {'plate': (2.0, 3.4), 'screw': (1.7, 2.8), 'screwdriver': (1.2, 2.1)}
BOX_COUNTS = {'plate': 15, 'screw': 20, 'screwdriver': 13}
MAX_ATTEMPTS = 50            # per demonstration (box) or spot (pole) before giving up
TABLE_CLEARANCE = 0.01       # m the arm (past its shoulder) keeps above the table top (z = 0)

# Pole geometry.
WAND_OFFSET = np.array([0.22, 0.0, 0.14])     # wrist end - pointed spot
POLE_TARGET_X = (0.64, 0.80)
POLE_TARGET_Y = (-0.36, 0.36)
POLE_BOTH_SIDES_Y = 0.04     # |y| below this: reachable on both sides
FLANGE_FROM_SPOT = 0.05     # m between the flange and the spot, along the pointing axis
POLE_POINT_TILT = (0.25, 0.6)  # pointing axis (x, side) components per unit down
# The arm swings ~2 rad around the pole, which the iiwa's joint speed limits allow in no less than
# 2.4-3.5 s depending on the spot: durations are drawn (stratified) from this range but never
# below 1.03 times the shortest feasible one.
POLE_DURATION = (2.6, 4.6)
POLE_MARGIN = 0.015
POLE_VIA_FRACTION = 0.4
APPROACH = 0.1               # m back along the pointing axis: the posture above the spot ...
APPROACH_FRACTION = 0.9      # ... passed at this fraction of the movement, when one is needed

BOX_LABELS = ('plate', 'screw', 'screwdriver')
POLE_LABELS = ('left', 'right')


@dataclass
class GeneratedDemo:
    """One generated demonstration as recorded (before segmentation), with its ground truth.

    Times are seconds since the recording start. ``wrist_xyz`` and ``wrist_goal`` are in the
    scene's world frame (the mocap frame), NaN rows are occluded (not written to a bag);
    ``joint_*`` and ``flange_goal`` are the robot's (``robot``), in its base frame.
    ``onset``/``end`` are the true movement interval.
    """

    name: str
    label: str
    wrist_t: np.ndarray
    wrist_xyz: np.ndarray
    joint_t: np.ndarray
    joint_q: np.ndarray
    joint_qd: np.ndarray
    onset: float
    end: float
    wrist_goal: np.ndarray
    flange_goal: np.ndarray
    robot: RobotDescription = field(default_factory=load_description)
    extra: dict = field(default_factory=dict)

    @property
    def duration(self) -> float:
        return self.end - self.onset

    def to_demonstration(self, dt: float = 0.01, gap_tolerance: float = 1.25) -> Demonstration:
        """The Demonstration with the *true* onset/end (no detector), resampled like a loaded bag
        (the wrist moved into the robot's base frame)."""
        n = int(np.floor(self.duration / dt + 1e-9)) + 1
        rel = dt * np.arange(n)
        grid = self.onset + rel
        period = max(dt, float(np.median(np.diff(self.wrist_t))))
        observed = resample_wrist(self.wrist_t, self.robot.world_to_base().apply_array(
            self.wrist_xyz), grid, gap_tolerance * period)
        controlled = np.column_stack([np.interp(grid, self.joint_t, self.joint_q[:, j])
                                      for j in range(self.joint_q.shape[1])])
        return Demonstration(t=rel, observed=observed, controlled=controlled, label=self.label,
                             name=self.name)


# --------------------------------------------------------------------------------- robot paths

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


class _Arm:
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


ROTATION_TOL = 0.2  # rad; a handover or pointing only needs the gripper roughly facing its target
# rad demonstrated postures keep from every joint limit: a prediction around them then stays
# inside the limits (MuJoCo stops a joint at its limit; the controller's model does not know it).
LIMIT_MARGIN = 0.1


def _ik(kin, position, q0, rotation, tol=2e-3):
    """IK of the flange to ``position`` (base frame) with the soft flange ``rotation``."""
    # Tight position, soft orientation (within ROTATION_TOL), no random restarts: a restart could
    # land in another arm configuration and break the consistency of a pattern's postures.
    return kin.ik(np.asarray(position, dtype=float), q0, rotation=rotation, tol=tol,
                  orientation_weight=0.3, rotation_tol=ROTATION_TOL, restarts=0,
                  limit_margin=LIMIT_MARGIN)


def _ik_turning(kin, position, q0, R_from, R_to, steps: int = 6):
    """IK at ``position`` with the flange orientation turned from R_from to R_to in ``steps``
    (each solve warm-started at the last): a local solver then follows one arm configuration
    from the seed's to a pose far from it (pointing forward instead of down)."""
    from scipy.spatial.transform import Rotation, Slerp
    turn = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([R_from, R_to])))
    q = q0
    for s in np.linspace(0.0, 1.0, steps + 1):
        q = _ik(kin, position, q, turn([s]).as_matrix()[0])
    return q


def _uniform_box(rng, box) -> np.ndarray:
    return np.array([rng.uniform(lo, hi) for lo, hi in box])


def _recording_times(rng, duration):
    onset = rng.uniform(*REST_BEFORE)
    end = onset + duration
    total = end + rng.uniform(*REST_AFTER)
    wrist_t = np.arange(0.0, total, 1.0 / RATE)
    joint_t = np.arange(JOINT_CLOCK_OFFSET, total, 1.0 / RATE)
    return onset, end, wrist_t, joint_t


def _human_wrist(rng, t, onset, duration, start, goal, via_scale, occlusion, noise):
    via = rng.normal(0.0, 1.0, 3) * via_scale
    skew = rng.uniform(-0.3, 0.3)
    xyz = human.reach(t, onset, duration, start, goal, via, skew)
    xyz = human.mocap(xyz, rng, noise)
    return human.occlude(t, xyz, rng, occlusion, onset, onset + duration), via, skew


def check_velocity_limits(kin, qd, slack: float = 1.0) -> bool:
    return bool(np.all(np.abs(qd) <= slack * kin.velocity_limit))


# --------------------------------------------------------------------------------- box assembly

class _BoxPostures:
    """Nominal postures per pattern, solved once so every demonstration warm-starts the same way.

    Orientation targets per pattern: plate and screw are carried gripper-down (lifted off a stand,
    handed over from above); the screwdriver is held gripper-forward, pointing at the human.
    """

    def __init__(self, arm: _Arm):
        from mixture_ip_ros.robot.scene import plate_position, screw_position
        kin = arm.kin
        lift = np.array([0.0, 0.0, LIFT])
        self.plate_grasp_pos = arm.base(plate_position() + np.array([0.0, 0.0, 0.03]))
        self.screw_grasp_pos = arm.base(screw_position() + np.array([0.0, 0.0, 0.03]))
        p, s = self.plate_grasp_pos, self.screw_grasp_pos
        up = arm.base(lift) - arm.base(np.zeros(3))
        self.plate_grasp = _ik(kin, p, arm.seed(p), arm.down(p))
        self.plate_lift = _ik(kin, p + up, self.plate_grasp, arm.down(p))
        self.screw_grasp = _ik(kin, s, arm.seed(s), arm.down(s))
        self.screw_lift = _ik(kin, s + up, self.screw_grasp, arm.down(s))
        centre = lambda box: np.array([(lo + hi) / 2 for lo, hi in box])  # noqa: E731
        plate_c = arm.base(centre(PLATE_GOAL) + PLATE_OFFSET)
        self.plate_hand = _ik(kin, plate_c, arm.seed(plate_c), arm.down(plate_c))
        screw = arm.base(SCREW_HANDOVER)
        self.screw_hand = _ik(kin, screw, arm.seed(screw), arm.down(screw))
        hold = arm.base(SCREWDRIVER_HOLD)
        self.screwdriver_start = _ik_turning(kin, hold, arm.seed(hold), arm.down(hold),
                                             arm.toward(hold))
        sd_c = arm.base(centre(SCREWDRIVER_GOAL) + SCREWDRIVER_OFFSET)
        self.screwdriver_hand = _ik(kin, sd_c, self.screwdriver_start, arm.toward(sd_c))


def _box_demo(arm, postures, seed, index, label, occlusion, noise, stratum):
    """Demonstration ``index``; ``stratum`` = (k, n): its duration is drawn from the k-th of n
    equal slices of the pattern's range, so every pattern spans its whole range of speeds.

    Attempt a draws the human's movement from the stream (seed, index, a) and the robot's
    teaching noise from (seed, index, a, 1), so the human side does not depend on the robot.
    """
    kin = arm.kin
    lo, hi = BOX_DURATION[label]
    k, n = stratum
    for attempt in range(MAX_ATTEMPTS):
        rng = np.random.default_rng([seed, index, attempt])
        teacher = np.random.default_rng([seed, index, attempt, 1])
        # A target the robot cannot reach in time within its velocity limits is redrawn; after
        # every 5 failures the movement gets 5 % slower (as a teacher would slow down).
        u = (k + rng.uniform(0.25, 0.75)) / n
        duration = (lo + (hi - lo) * u) * 1.05 ** (attempt // 5)
        onset, end, wrist_t, joint_t = _recording_times(rng, duration)
        start = HUMAN_REST + rng.normal(0.0, REST_JITTER, 3)
        if label == 'plate':
            goal = _uniform_box(rng, PLATE_GOAL)
            flange = goal + PLATE_OFFSET
            warm = postures.plate_hand
            first = [postures.plate_grasp, postures.plate_lift]
        elif label == 'screw':
            goal = _uniform_box(rng, SCREWDRIVER_FETCH)
            flange = SCREW_HANDOVER + teacher.normal(0.0, SCREW_HANDOVER_NOISE, 3)
            warm = postures.screw_hand
            first = [postures.screw_grasp, postures.screw_lift]
        else:
            goal = _uniform_box(rng, SCREWDRIVER_GOAL)
            flange = goal + SCREWDRIVER_OFFSET
            warm = postures.screwdriver_hand
            first = [postures.screwdriver_start]
        via_scale = {'plate': (0.03, 0.04, 0.05), 'screw': (0.03, 0.03, 0.05),
                     'screwdriver': (0.04, 0.04, 0.04)}[label]
        xyz, via, skew = _human_wrist(rng, wrist_t, onset, duration, start, goal,
                                      np.asarray(via_scale), occlusion, noise)
        flange = arm.base(flange)
        try:
            q_end = _ik(kin, flange, warm,
                        arm.toward(flange) if label == 'screwdriver' else arm.down(flange))
        except ValueError:
            continue
        if len(first) == 2:
            times = [onset, onset + LIFT_FRACTION * duration, end]
            stops = [True, True, True]
        else:
            times, stops = [onset, end], [True, True]
        q, qd = quintic_path(joint_t, times, np.vstack(first + [q_end]), stops)
        if not arm.feasible(q, qd):
            continue
        return GeneratedDemo(name=f'demo_{index:03d}', label=label, wrist_t=wrist_t,
                             wrist_xyz=xyz, joint_t=joint_t, joint_q=q, joint_qd=qd, onset=onset,
                             end=end, wrist_goal=goal, flange_goal=flange, robot=arm.description,
                             extra={'via': via, 'skew': skew, 'wrist_start': start,
                                    'attempt': attempt})
    raise RuntimeError(f'{arm.description.name}: could not generate a feasible {label} '
                       f'demonstration in {MAX_ATTEMPTS} tries (is the task within its reach? '
                       'see its mount)')


def box_assembly(seed: int = 0, *, occlusion: float = 0.0, noise: float = MOCAP_NOISE,
                 counts: Optional[dict] = None, kinematics=None) -> list:
    """The 48 box-assembly demonstrations (thesis 3.4.2), in a seeded random order.

    ``occlusion`` is the probability that a demonstration has one 0.1-0.3 s wrist gap. Names are
    demo_000.. in that shuffled order, so a folder listing does not reveal the pattern.
    ``kinematics``: the robot's RobotKinematics (None: the default iiwa 14).
    """
    counts = dict(BOX_COUNTS if counts is None else counts)
    unknown = set(counts) - set(BOX_LABELS)
    if unknown:
        raise ValueError(f'unknown box-assembly patterns {sorted(unknown)}; known: {BOX_LABELS}')
    arm = _Arm(kinematics)
    try:
        postures = _BoxPostures(arm)
    except ValueError as exc:
        raise ValueError(f'{arm.description.name} cannot reach the box-assembly postures from '
                         f'its mount and box_seed: {exc}') from exc
    rng = np.random.default_rng(seed)
    jobs = []
    for label in BOX_LABELS:
        n = int(counts.get(label, 0))
        jobs += [(label, (int(k), n)) for k in rng.permutation(n)]
    jobs = [jobs[i] for i in rng.permutation(len(jobs))]
    return [_box_demo(arm, postures, seed, i, label, occlusion, noise, stratum)
            for i, (label, stratum) in enumerate(jobs)]


# --------------------------------------------------------------------------------- pole

def pole_geometry():
    """(pole xy (2,), radius, height) of robot/scene.py's pole, metres in the world frame."""
    from mixture_ip_ros.robot.scene import POLE_HEIGHT, POLE_RADIUS, POLE_XY
    return np.asarray(POLE_XY, dtype=float), float(POLE_RADIUS), float(POLE_HEIGHT)


_pole_geometry = pole_geometry  # older name, used by evaluation.py


def link_points(kin, q) -> np.ndarray:
    """The arm as a polyline at q: the origins of the description's clearance frames (e.g.
    shoulder, elbow, wrist, flange), (m, 3), in the world frame (where the pole stands)."""
    return _Arm(kin).link_points(q)


def pole_clearance(points: np.ndarray, pole_xy=None, pole_height=None, samples: int = 12) -> float:
    """Smallest distance between the pole's axis segment and the polyline through ``points``
    (world frame)."""
    if pole_xy is None or pole_height is None:
        xy, _, height = pole_geometry()
        pole_xy = xy if pole_xy is None else np.asarray(pole_xy, dtype=float)
        pole_height = height if pole_height is None else pole_height
    points = np.asarray(points, dtype=float)
    s = np.linspace(0.0, 1.0, samples)[:, None]
    line = np.vstack([a + s * (b - a) for a, b in zip(points[:-1], points[1:])])
    dz = np.clip(line[:, 2], 0.0, pole_height) - line[:, 2]
    dxy = np.linalg.norm(line[:, :2] - pole_xy, axis=1)
    return float(np.min(np.hypot(dxy, dz)))


def pole_clearance_required(link_radius: float) -> float:
    """Distance every link segment keeps from the pole's axis: pole + link radius + margin."""
    _, pole_radius, _ = pole_geometry()
    return pole_radius + link_radius + POLE_MARGIN


def _path_clearance(arm, Q) -> float:
    return min(pole_clearance(arm.link_points(q)) for q in Q)


def _pointing_rotation(side: int) -> np.ndarray:
    """Tool axis pointing down at the spot, tilted to come from the robot's side ``side`` (world
    frame).

    Tilting moves the wrist out to that side of the pole, where the arm passes.
    """
    z = np.array([POLE_POINT_TILT[0], -side * POLE_POINT_TILT[1], -1.0])
    z /= np.linalg.norm(z)
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def _clear_the_pole(arm, q, required: float, steps: int = 60, step: float = 0.04):
    """Move the arm in the null space of its flange pose (the elbow around the shoulder-wrist line
    of a 7-joint arm; nothing moves for an arm without spare joints) until every link is
    ``required`` metres from the pole axis, or no further gain is possible."""
    kin = arm.kin
    q = np.array(q, dtype=float)
    lo, hi = kin.lower + 0.03, kin.upper - 0.03
    n = kin.dof
    for _ in range(steps):
        c = pole_clearance(arm.link_points(q))
        if c >= required:
            break
        grad = np.zeros(n)
        for j in range(n):
            dq = np.zeros(n)
            dq[j] = 1e-4
            grad[j] = (pole_clearance(arm.link_points(q + dq)) - c) / 1e-4
        J = kin.jacobian(q)
        N = np.eye(n) - np.linalg.pinv(J) @ J
        d = N @ grad
        norm = np.linalg.norm(d)
        if norm < 1e-9:
            break
        q_new = np.clip(q + step * d / norm, lo, hi)
        if pole_clearance(arm.link_points(q_new)) <= c:
            break
        q = q_new
    return q


class _PolePostures:
    """Per side: the via posture beside the pole and a nominal pointing posture (at a spot just
    beyond the pole), both with the elbow swung out; every demonstration warm-starts from them."""

    def __init__(self, arm, clearance):
        kin = arm.kin
        pole_xy, _, _ = pole_geometry()
        self.via, self.nominal = {}, {}
        for side in (1, -1):
            R_world = _pointing_rotation(side)
            R = arm.flange_from_world(R_world)
            seed = arm.pole_home.copy()
            seed[0] += side * 0.7
            via_pos = arm.base([pole_xy[0] - 0.08, pole_xy[1] + side * 0.30, 0.40])
            q = _ik(kin, via_pos, seed, R)
            q = _ik(kin, via_pos, _clear_the_pole(arm, q, 2 * clearance), R)
            spot = np.array([pole_xy[0] + 0.22, pole_xy[1] + side * 0.05, 0.0])
            flange = arm.base(spot - FLANGE_FROM_SPOT * R_world[:, 2])
            n = _ik(kin, flange, q, R)
            n = _ik(kin, flange, _clear_the_pole(arm, n, 2 * clearance, steps=100), R)
            self.via[side], self.nominal[side] = q, n


def _pole_demo(arm, postures, rng, side, spot, name, occlusion, noise, clearance, stratum):
    """One demonstration pointing at ``spot`` (world frame) from ``side``, or None if the robot
    cannot do it; the human's movement comes from ``rng`` only."""
    kin = arm.kin
    k, n = stratum
    lo, hi = POLE_DURATION
    drawn = lo + (hi - lo) * (k + rng.uniform(0.25, 0.75)) / n
    start = HUMAN_REST + rng.normal(0.0, REST_JITTER, 3)
    goal = spot + WAND_OFFSET + rng.normal(0.0, 0.01, 3)
    R_world = _pointing_rotation(side)
    R = arm.flange_from_world(R_world)
    flange = arm.base(spot - FLANGE_FROM_SPOT * R_world[:, 2])
    q_via = postures.via[side]
    try:
        q_end = _ik(kin, flange, postures.nominal[side], R)
        if pole_clearance(arm.link_points(q_end)) < clearance + 0.02:
            q_end = _ik(kin, flange, _clear_the_pole(arm, q_end, clearance + 0.03, steps=100), R)
    except ValueError:
        return None
    knots = [arm.pole_home, q_via, q_end]
    fractions = [0.0, POLE_VIA_FRACTION, 1.0]
    unit = np.linspace(0.0, 1.0, 400)
    q_unit, qd_unit = quintic_path(unit, fractions, knots)
    if min(arm.link_points(x)[1:, 2].min(initial=np.inf) for x in q_unit[::10]) <= TABLE_CLEARANCE:
        # The joint-space path from the via posture swings the hand through the table (it does
        # for the Panda's long hand): come down to the spot from a posture above it instead.
        try:
            q_above = _ik(kin, flange - APPROACH * (R @ arm.tool_axis), q_end, R)
        except ValueError:
            return None
        knots.insert(2, q_above)
        fractions.insert(2, APPROACH_FRACTION)
        q_unit, qd_unit = quintic_path(unit, fractions, knots)
    # The fastest the arm can follow this path: joint speeds scale with 1 / duration.
    fastest = float(np.max(np.abs(qd_unit) / kin.velocity_limit))
    duration = max(drawn, 1.03 * fastest)
    onset, end, wrist_t, joint_t = _recording_times(rng, duration)
    q, qd = quintic_path(joint_t, [onset + f * duration for f in fractions], knots)
    if not arm.feasible(q, qd) or _path_clearance(arm, q) < clearance:
        return None
    xyz, via, skew = _human_wrist(rng, wrist_t, onset, duration, start, goal,
                                  np.array([0.03, 0.03, 0.05]), occlusion, noise)
    return GeneratedDemo(name=name, label='left' if side > 0 else 'right', wrist_t=wrist_t,
                         wrist_xyz=xyz, joint_t=joint_t, joint_q=q, joint_qd=qd, onset=onset,
                         end=end, wrist_goal=goal, flange_goal=flange, robot=arm.description,
                         extra={'spot': spot, 'via': via, 'skew': skew, 'wrist_start': start,
                                'drawn_duration': drawn})


def pole(seed: int = 0, *, n: int = 28, both_sides: int = 6, occlusion: float = 0.0,
         noise: float = MOCAP_NOISE, kinematics=None) -> list:
    """The pole-pointing demonstrations (thesis 3.4.1), ``n`` in all, in a seeded random order.

    ``both_sides`` spots near the middle are demonstrated once on each side (first), then every
    other spot once, on a side from which it is reachable (spots with |y| > POLE_BOTH_SIDES_Y only
    on their own side). Spot s, attempt a is drawn from the stream (seed, s, a), so the human side
    does not depend on the robot (``kinematics``; None: the iiwa 14).
    """
    if n < 2 * both_sides:
        raise ValueError(f'n ({n}) must be at least 2 * both_sides ({2 * both_sides})')
    arm = _Arm(kinematics)
    clearance = pole_clearance_required(arm.description.link_radius)
    try:
        postures = _PolePostures(arm, clearance)
    except ValueError as exc:
        raise ValueError(f'{arm.description.name} cannot reach the pole postures from its mount '
                         f'and pole_home: {exc}') from exc
    rng = np.random.default_rng(seed)
    strata = rng.permutation(n)
    demos = []
    slot = 0
    while len(demos) < n:
        pair = slot < both_sides
        for attempt in range(MAX_ATTEMPTS):
            human = np.random.default_rng([seed, slot, attempt])
            y_range = (-POLE_BOTH_SIDES_Y, POLE_BOTH_SIDES_Y) if pair else POLE_TARGET_Y
            spot = np.array([human.uniform(*POLE_TARGET_X), human.uniform(*y_range), 0.0])
            if pair:
                sides = [1, -1]
            elif abs(spot[1]) > POLE_BOTH_SIDES_Y:
                sides = [1 if spot[1] > 0 else -1]
            else:
                sides = [1 if human.uniform() < 0.5 else -1]
            made = []
            for i, s in enumerate(sides):
                made.append(_pole_demo(arm, postures, human, s, spot, '', occlusion, noise,
                                       clearance, (int(strata[len(demos) + i]), n)))
                if made[-1] is None:
                    break
            if all(d is not None for d in made):
                break
        else:
            raise RuntimeError(
                f'{arm.description.name}: could not generate a collision-free pole demonstration '
                f'{"pair " if pair else ""}in {MAX_ATTEMPTS} tries'
                + (' (an arm without a spare joint may not pass the pole on both sides of the '
                   'same spot: try both_sides=0)' if pair and arm.kin.dof < 7 else ''))
        for d in made:
            d.extra['attempt'] = attempt
        demos.extend(made)
        slot += 1
    order = rng.permutation(len(demos))
    demos = [demos[i] for i in order]
    for i, d in enumerate(demos):
        d.name = f'demo_{i:03d}'
    return demos


SCENARIOS = {'box_assembly': box_assembly, 'pole': pole}


def generate(scenario: str, seed: int = 0, robot=None, **kwargs) -> list:
    """Demonstrations of a named scenario ('box_assembly' or 'pole') for ``robot`` (a shipped
    name, a description file or a RobotDescription; None: the iiwa 14)."""
    if scenario not in SCENARIOS:
        raise ValueError(f'unknown scenario {scenario!r}; known: {sorted(SCENARIOS)}')
    if kwargs.get('kinematics') is None:
        from mixture_ip_ros.robot.kinematics import RobotKinematics
        kwargs['kinematics'] = RobotKinematics(robot)
    return SCENARIOS[scenario](seed, **kwargs)


def write_scenario_bags(scenario: str, out_dir, seed: int = 0, occlusion: float = 0.0,
                        storage: str = 'mcap', demos: Optional[list] = None,
                        robot=None) -> list:
    """Write one rosbag2 bag per demonstration into ``out_dir`` plus labels.json (evaluation only).

    ``out_dir`` must not exist or be empty. Returns the bag paths. labels.json maps bag name to
    label and records the scenario, seed and robot; the label, scenario, seed and robot are also
    in each bag's metadata custom_data. Wrist poses are in the frame 'world', joint states carry
    the robot's joint names. ``robot`` is used when ``demos`` is None (else the demos' own).
    """
    from mixture_ip_ros.io.bags import write_demonstration_bag
    out = Path(out_dir)
    if out.exists() and any(out.iterdir()):
        raise ValueError(f'{out} is not empty; refusing to mix demonstration sets')
    if demos is None:
        demos = generate(scenario, seed, robot=robot, occlusion=occlusion)
    robots = {d.robot.name for d in demos}
    if len(robots) != 1:
        raise ValueError(f'demonstrations of several robots {sorted(robots)}; one folder, '
                         'one robot')
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for d in demos:
        paths.append(write_demonstration_bag(
            out / d.name, d.wrist_t, d.wrist_xyz, d.joint_t, d.joint_q, joint_qd=d.joint_qd,
            storage=storage, label=d.label, joint_names=d.robot.joint_names,
            custom_data={'mixture_ip_ros.scenario': scenario, 'mixture_ip_ros.seed': str(seed),
                         'mixture_ip_ros.robot': d.robot.name}))
    labels = {'scenario': scenario, 'seed': seed, 'occlusion': occlusion,
              'robot': robots.pop(), 'labels': {d.name: d.label for d in demos}}
    (out / LABEL_FILE).write_text(json.dumps(labels, indent=2, sort_keys=True) + '\n')
    return paths


def read_scenario_robot(folder) -> str:
    """The name of the robot a scenario folder was generated for (labels.json; a folder that does
    not say is the default robot's)."""
    path = Path(folder) / LABEL_FILE
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise ValueError(f'cannot read {path}: {exc}') from exc
    return str(data.get('robot', DEFAULT_ROBOT)) if isinstance(data, dict) else DEFAULT_ROBOT


def read_labels(folder) -> dict:
    """{bag name: label} from a scenario folder's labels.json (evaluation only)."""
    path = Path(folder) / LABEL_FILE
    try:
        data = json.loads(path.read_text())
        labels = data['labels']
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ValueError(f'cannot read labels from {path}: {exc}') from exc
    if not isinstance(labels, dict):
        raise ValueError(f'{path}: "labels" must map bag names to labels')
    return {str(k): str(v) for k, v in labels.items()}


# --------------------------------------------------------------------------------- letters

class LetterData(NamedTuple):
    """Letter trajectories for the phase (4.3.1) and missing-data (4.3.2) experiments.

    ``train``/``test``: Demonstrations with 2-D ``observed`` (letter units, 1 = letter height / 2)
    and no controlled DOFs; ``train_complete``: the training trajectories before any removal;
    ``train_alpha``/``test_alpha``: the true phase speeds (1/s).
    """

    train: list
    test: list
    train_complete: list
    train_alpha: np.ndarray
    test_alpha: np.ndarray


# One handwritten "a": the bowl drawn counter-clockwise from its top right, up the stem, down, tail.
LETTER_A = np.array([[1.0, 1.7], [0.6, 2.0], [0.15, 1.75], [0.0, 1.1], [0.25, 0.55], [0.75, 0.6],
                     [1.0, 1.2], [1.02, 1.95], [1.0, 0.9], [1.05, 0.25], [1.35, 0.0]])
LETTER_BASIS = 15
LETTER_DT = 0.01
LETTER_ALPHA = (0.16, 0.04)               # mean, std of the phase speed (1/s)
LETTER_ALPHA_RANGE = (1 / 11.3, 1 / 3.5)  # durations of 3.5-11.3 s: 355-1130 samples at 100 Hz


def _rbf(z, n=LETTER_BASIS):
    centers = np.linspace(0.0, 1.0, n)
    width = 1.0 / (n - 1)
    b = np.exp(-0.5 * ((np.asarray(z)[:, None] - centers) / width) ** 2)
    return b / b.sum(axis=1, keepdims=True)


def letter_prior():
    """Mean (2, B) and covariance (2B, 2B) of the letter weights (x weights then y weights)."""
    from scipy.interpolate import CubicSpline
    chord = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(LETTER_A, axis=0), axis=1))]
    spline = CubicSpline(chord / chord[-1], LETTER_A, bc_type='natural')
    z = np.linspace(0.0, 1.0, 400)
    Phi = _rbf(z)
    W = np.linalg.solve(Phi.T @ Phi + 1e-6 * np.eye(LETTER_BASIS), Phi.T @ spline(z))  # (B, 2)
    mean = W.T
    centroid = mean.mean(axis=1, keepdims=True)
    B = LETTER_BASIS
    modes = [
        ((mean - centroid) * 0.08).ravel(),                        # size
        (np.vstack([mean[1] - centroid[1], np.zeros(B)]) * 0.12).ravel(),  # slant
        (np.vstack([np.ones(B), np.zeros(B)]) * 0.1).ravel(),      # position
        (np.vstack([np.zeros(B), np.ones(B)]) * 0.1).ravel(),
        (np.vstack([np.zeros(B), mean[1] - centroid[1]]) * 0.06).ravel(),  # height only
    ]
    A = np.column_stack(modes)
    cov = A @ A.T + 0.04**2 * np.eye(2 * B)                         # local shape wobble
    return mean, cov


def _letters(rng, n, dt=LETTER_DT, noise=0.0):
    mean, cov = letter_prior()
    L = np.linalg.cholesky(cov)
    demos, alphas = [], []
    for i in range(n):
        w = mean.ravel() + L @ rng.normal(size=mean.size)
        alpha = float(np.clip(rng.normal(*LETTER_ALPHA), *LETTER_ALPHA_RANGE))
        steps = int(round(1.0 / (alpha * dt))) + 1
        t = dt * np.arange(steps)
        z = np.clip(alpha * t, 0.0, 1.0)
        y = _rbf(z) @ w.reshape(2, -1).T
        if noise > 0:
            y = y + rng.normal(0.0, noise, y.shape)
        demos.append(Demonstration(t=t, observed=y, controlled=np.zeros((steps, 0)), label='a',
                                   name=f'letter_{i:03d}'))
        alphas.append(alpha)
    return demos, np.array(alphas)


def phase_letters(seed: int = 0, n_train: int = 20, n_test: int = 20, noise: float = 0.0) -> LetterData:
    """Thesis 4.3.1: 40 letters from Gaussian weights and alpha, split at random into train/test."""
    rng = np.random.default_rng(seed)
    demos, alphas = _letters(rng, n_train + n_test, noise=noise)
    order = rng.permutation(len(demos))
    tr, te = order[:n_train], order[n_train:]
    train = [demos[i] for i in tr]
    return LetterData(train=train, test=[demos[i] for i in te], train_complete=list(train),
                      train_alpha=alphas[tr], test_alpha=alphas[te])


def missing_data_letters(seed: int = 0, n_train: int = 20, n_test: int = 20, gap_steps: int = 180,
                         noise: float = 0.0) -> LetterData:
    """Thesis 4.3.2: like :func:`phase_letters`, then one random block of ``gap_steps`` samples of
    every training trajectory becomes missing (NaN rows)."""
    data = phase_letters(seed, n_train, n_test, noise)
    rng = np.random.default_rng([seed, 432])
    train = []
    for d in data.train:
        T = d.t.size
        if gap_steps >= T - 1:
            raise ValueError(f'gap of {gap_steps} samples does not fit a {T}-sample trajectory')
        begin = int(rng.integers(0, T - gap_steps + 1))
        observed = d.observed.copy()
        observed[begin:begin + gap_steps] = np.nan
        train.append(Demonstration(t=d.t, observed=observed, controlled=d.controlled,
                                   label=d.label, name=d.name))
    return data._replace(train=train)
