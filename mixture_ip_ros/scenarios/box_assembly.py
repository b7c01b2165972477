"""Box assembly (thesis 3.4.2): 48 unlabeled demonstrations, labels kept for evaluation only.

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
2.0-3.4 s, screw 1.7-2.8 s, screwdriver 1.2-2.1 s; fetching from a stand 70 deg to the side takes
the iiwa (85 deg/s on joint 1) about 2 s, and a target the robot cannot reach in time is redrawn.
"""

from __future__ import annotations

from typing import Optional

import numpy as np

from mixture_ip_ros.scenarios.arm import Arm, ik, ik_turning, quintic_path
from mixture_ip_ros.scenarios.recording import (HUMAN_REST, MAX_ATTEMPTS, MOCAP_NOISE, REST_JITTER,
                                                GeneratedDemo, human_wrist, recording_times)

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
BOX_LABELS = ('plate', 'screw', 'screwdriver')


def _uniform_box(rng, box) -> np.ndarray:
    return np.array([rng.uniform(lo, hi) for lo, hi in box])


class _BoxPostures:
    """Nominal postures per pattern, solved once so every demonstration warm-starts the same way.

    Orientation targets per pattern: plate and screw are carried gripper-down (lifted off a stand,
    handed over from above); the screwdriver is held gripper-forward, pointing at the human.
    """

    def __init__(self, arm: Arm):
        from mixture_ip_ros.robot.scene import plate_position, screw_position
        kin = arm.kin
        lift = np.array([0.0, 0.0, LIFT])
        self.plate_grasp_pos = arm.base(plate_position() + np.array([0.0, 0.0, 0.03]))
        self.screw_grasp_pos = arm.base(screw_position() + np.array([0.0, 0.0, 0.03]))
        p, s = self.plate_grasp_pos, self.screw_grasp_pos
        up = arm.base(lift) - arm.base(np.zeros(3))
        self.plate_grasp = ik(kin, p, arm.seed(p), arm.down(p))
        self.plate_lift = ik(kin, p + up, self.plate_grasp, arm.down(p))
        self.screw_grasp = ik(kin, s, arm.seed(s), arm.down(s))
        self.screw_lift = ik(kin, s + up, self.screw_grasp, arm.down(s))
        centre = lambda box: np.array([(lo + hi) / 2 for lo, hi in box])  # noqa: E731
        plate_c = arm.base(centre(PLATE_GOAL) + PLATE_OFFSET)
        self.plate_hand = ik(kin, plate_c, arm.seed(plate_c), arm.down(plate_c))
        screw = arm.base(SCREW_HANDOVER)
        self.screw_hand = ik(kin, screw, arm.seed(screw), arm.down(screw))
        hold = arm.base(SCREWDRIVER_HOLD)
        self.screwdriver_start = ik_turning(kin, hold, arm.seed(hold), arm.down(hold),
                                            arm.toward(hold))
        sd_c = arm.base(centre(SCREWDRIVER_GOAL) + SCREWDRIVER_OFFSET)
        self.screwdriver_hand = ik(kin, sd_c, self.screwdriver_start, arm.toward(sd_c))


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
        onset, end, wrist_t, joint_t = recording_times(rng, duration)
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
        xyz, via, skew = human_wrist(rng, wrist_t, onset, duration, start, goal,
                                     np.asarray(via_scale), occlusion, noise)
        flange = arm.base(flange)
        try:
            q_end = ik(kin, flange, warm,
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
    arm = Arm(kinematics)
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
