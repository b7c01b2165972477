"""Pole (thesis 3.4.1): 28 demonstrations of pointing past a pole, labels 'left' / 'right'.

The human points with a wand at a spot on the table beyond a vertical pole in front of the robot
(POLE_XY from robot/scene.py); the wrist ends 22 cm behind and 14 cm above the spot. The robot goes
from a home posture behind the pole, via a posture beside the pole, to point at the same spot
(flange 5 cm from it along a pointing axis tilted in from its side), passing left (+y) or right
(-y) of the pole with every link >= 11 cm from the pole's axis; spots with |y| > 4 cm are
reachable on their own side only, and 6 spots near the middle are demonstrated on both sides (very
different arm postures). The arm swings ~2 rad, so these take 2.6-4.6 s; a movement an arm cannot
follow in the drawn time is slowed to 1.03 times its fastest instead (so its human duration
differs).
"""

from __future__ import annotations

import numpy as np

from mixture_ip_ros.scenarios.arm import TABLE_CLEARANCE, Arm, ik, quintic_path
from mixture_ip_ros.scenarios.recording import (HUMAN_REST, MAX_ATTEMPTS, MOCAP_NOISE, REST_JITTER,
                                                GeneratedDemo, human_wrist, recording_times)

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


def pole_geometry():
    """(pole xy (2,), radius, height) of robot/scene.py's pole, metres in the world frame."""
    from mixture_ip_ros.robot.scene import POLE_HEIGHT, POLE_RADIUS, POLE_XY
    return np.asarray(POLE_XY, dtype=float), float(POLE_RADIUS), float(POLE_HEIGHT)


def link_points(kin, q) -> np.ndarray:
    """The arm as a polyline at q: the origins of the description's clearance frames (e.g.
    shoulder, elbow, wrist, flange), (m, 3), in the world frame (where the pole stands)."""
    return Arm(kin).link_points(q)


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
            q = ik(kin, via_pos, seed, R)
            q = ik(kin, via_pos, _clear_the_pole(arm, q, 2 * clearance), R)
            spot = np.array([pole_xy[0] + 0.22, pole_xy[1] + side * 0.05, 0.0])
            flange = arm.base(spot - FLANGE_FROM_SPOT * R_world[:, 2])
            n = ik(kin, flange, q, R)
            n = ik(kin, flange, _clear_the_pole(arm, n, 2 * clearance, steps=100), R)
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
        q_end = ik(kin, flange, postures.nominal[side], R)
        if pole_clearance(arm.link_points(q_end)) < clearance + 0.02:
            q_end = ik(kin, flange, _clear_the_pole(arm, q_end, clearance + 0.03, steps=100), R)
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
            q_above = ik(kin, flange - APPROACH * (R @ arm.tool_axis), q_end, R)
        except ValueError:
            return None
        knots.insert(2, q_above)
        fractions.insert(2, APPROACH_FRACTION)
        q_unit, qd_unit = quintic_path(unit, fractions, knots)
    # The fastest the arm can follow this path: joint speeds scale with 1 / duration.
    fastest = float(np.max(np.abs(qd_unit) / kin.velocity_limit))
    duration = max(drawn, 1.03 * fastest)
    onset, end, wrist_t, joint_t = recording_times(rng, duration)
    q, qd = quintic_path(joint_t, [onset + f * duration for f in fractions], knots)
    if not arm.feasible(q, qd) or _path_clearance(arm, q) < clearance:
        return None
    xyz, via, skew = human_wrist(rng, wrist_t, onset, duration, start, goal,
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
    arm = Arm(kinematics)
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
