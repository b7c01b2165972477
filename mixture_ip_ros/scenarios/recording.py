"""A generated demonstration as recorded, and what every generated scenario draws the same way.

Scene (the world frame of robot/scene.py, metres): the table top is z = 0; the default robot, the
KUKA iiwa 14, stands at the origin facing +x, and any other arm stands where its description's
mount puts its base. The human stands across the table, about 1.35 m away in +x, facing the robot
(so the human's right hand is at +y). The human's right wrist rests on the table edge near
HUMAN_REST = (1.22, 0.24, 0.08) between interactions. The human side (wrist streams) is given in
this world frame, the mocap frame 'world' of the bags; the robot side (joints, flange targets) in
the robot's base frame, which for the iiwa is the world frame itself.

The human side is drawn before and independently of the robot, from a random stream per
demonstration and attempt, so two arms given the same seed get the same human movements, except
where an arm cannot follow one (too fast for its joint speeds, out of reach): that attempt is
redrawn for that arm only (at most MAX_ATTEMPTS times).

Human reaches are minimum-jerk with shape and speed variability (``scenarios.human_motion``);
mocap adds white noise; an optional occlusion removes 0.1-0.3 s of wrist samples. Both streams
are sampled at 100 Hz with 0.3-0.5 s of stillness before the onset and 0.4-0.6 s after the end.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mixture_ip_ros.core.demonstration import Demonstration
from mixture_ip_ros.io.dataset import resample_wrist
from mixture_ip_ros.robot.description import RobotDescription, load_description
from mixture_ip_ros.scenarios import human_motion as human

HUMAN_REST = np.array([1.22, 0.24, 0.08])
REST_JITTER = 0.015          # m, rest position differs between demonstrations
MOCAP_NOISE = 0.001          # m, white noise per axis
RATE = 100.0                 # Hz, mocap and joint_states
REST_BEFORE = (0.3, 0.5)     # s of stillness before the onset
REST_AFTER = (0.4, 0.6)      # s after the end (the end detector needs ~0.3 s of rest)
JOINT_CLOCK_OFFSET = 0.004   # s, joint_states are not sampled in phase with the mocap
MAX_ATTEMPTS = 50            # per demonstration (box) or spot (pole) before giving up


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


def recording_times(rng, duration):
    """(onset, end, wrist_t, joint_t) of a movement of ``duration`` s with rest either side."""
    onset = rng.uniform(*REST_BEFORE)
    end = onset + duration
    total = end + rng.uniform(*REST_AFTER)
    wrist_t = np.arange(0.0, total, 1.0 / RATE)
    joint_t = np.arange(JOINT_CLOCK_OFFSET, total, 1.0 / RATE)
    return onset, end, wrist_t, joint_t


def human_wrist(rng, t, onset, duration, start, goal, via_scale, occlusion, noise):
    """(wrist (len(t), 3) as the mocap saw it, via offset, skew): a reach from ``start`` to
    ``goal`` with a random via offset (``via_scale`` std per axis) and speed skew."""
    via = rng.normal(0.0, 1.0, 3) * via_scale
    skew = rng.uniform(-0.3, 0.3)
    xyz = human.reach(t, onset, duration, start, goal, via, skew)
    xyz = human.mocap(xyz, rng, noise)
    return human.occlude(t, xyz, rng, occlusion, onset, onset + duration), via, skew
