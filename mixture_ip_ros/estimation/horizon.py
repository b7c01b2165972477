"""A plan cut short: the controller gets the plan up to a horizon, then a stop at rest, so that an
arm whose planner is gone stops soon (ROS-free).

A joint_trajectory_controller runs a trajectory to its end whatever happens to the node that
sent it. If every trajectory sent follows the plan only ``horizon`` seconds past the present and
then brakes to rest within the joint acceleration limits, and each replan (they come with the
wrist observations, several per horizon) sends the next one, the arm moves as the plan says
while its planner and the person's stream are alive, and stops on its own when either goes:
a killed estimator, a killed observer, a tracker that loses the person. Nothing in the
controller needs to know the nodes.

The stop is one quintic segment, as the controller follows it, from the plan's state at the
cut (positions, speeds and accelerations on the plan's own quintic between its points) to
rest: from speed v at zero acceleration its speed falls as v (1 - 3 s^2 + 2 s^3), s = t / T,
peak deceleration 1.5 v / T, so T = 1.5 |qd| / a puts the joint that needs longest at its
limit; T is lengthened until every joint keeps within its speed and acceleration limits from
the state it has. It carries on along the present direction for qd T / 2 (0.75 v^2 / a from
zero acceleration: 2.4 cm of a 0.8 m arm at 1.4 rad/s and the iiwa's 62 rad/s^2), which may be
past where the plan curves or slows; a plan that comes to rest by the stop's end anyway is sent
whole. A single-point plan (the final posture, or an arm catching up to one point) is not cut:
it ends at rest already. The sim's own stop when its commander is gone
(robot.trajectory.stopping_trajectory) starts from the measured positions and speeds, which
the controller blends from with a cubic (constant deceleration); this one starts from the
plan's state, acceleration included, hence a quintic.
"""

from dataclasses import replace
from typing import Optional, Tuple

import numpy as np

from mixture_ip_ros.estimation.blending import segment_coefficients, segment_state
from mixture_ip_ros.estimation.plans import JointLimits, Plan, check_plan

# Peak deceleration of the quintic stop from speed v over T, at zero acceleration at both ends:
# 1.5 v / T (at s = 1/2).
STOP_PEAK = 1.5
# Samples per stop at which its speeds and accelerations are checked, and the factor its
# duration grows by until they keep within the limits.
STOP_SAMPLES = 64
STOP_GROWTH = 1.05
# The shortest stop (s): a plan already at rest at the cut still gets a last segment.
MIN_STOP = 0.02
# The stop keeps this far (relative) within the speed and acceleration limits at its samples,
# so that it is within them between the samples too.
STOP_MARGIN = 1e-3
# A point of the plan this close before the cut gives way to the cut's (times are sent in whole
# nanoseconds and must increase).
CUT_GAP = 1e-6


def plan_state(plan: Plan, t: float):
    """(positions, velocities, accelerations) of the plan at time ``t`` (s since onset, within
    its points): its quintic between the two points around ``t``, as the controller follows
    it."""
    times = plan.times
    i = int(np.clip(np.searchsorted(times, t, side='right') - 1, 0, len(times) - 2))
    T = times[i + 1] - times[i]
    c = segment_coefficients(T, plan.positions[i], plan.velocities[i], plan.accelerations[i],
                             plan.positions[i + 1], plan.velocities[i + 1],
                             plan.accelerations[i + 1], 'quintic')
    return segment_state(c, float(np.clip(t - times[i], 0.0, T)))


def stop_segment(q, qd, qdd, limits: JointLimits):
    """(duration, positions at rest) of the quintic stop from (``q``, ``qd``, ``qdd``): the
    shortest of durations growing by STOP_GROWTH from ``STOP_PEAK |qd| / a`` whose speeds and
    accelerations, sampled after its start, keep within ``limits`` less STOP_MARGIN (the
    samples' margin for the peaks between them); it comes to rest at
    ``q + qd T / 2 + qdd T^2 / 12``, where the speed's profile above (with the starting
    acceleration's own share) ends. ValueError when no duration does (a start beyond the
    limits: the plan's quintic between two points can exceed what its points respect), or the
    stop's positions leave the position limits."""
    q, qd, qdd = (np.asarray(x, dtype=float) for x in (q, qd, qdd))
    velocity = limits.velocity * (1.0 - STOP_MARGIN)
    acceleration = limits.acceleration * (1.0 - STOP_MARGIN)
    if np.any(np.abs(qdd) > acceleration) or np.any(np.abs(qd) > velocity):
        raise ValueError('the stop starts beyond the joint speed or acceleration limits')
    T = max(MIN_STOP, float(np.max(STOP_PEAK * np.abs(qd) / acceleration)))
    s = np.linspace(0.0, 1.0, STOP_SAMPLES)[1:, None]
    zero = np.zeros_like(q)
    for _ in range(200):
        end = q + qd * T / 2 + qdd * T * T / 12
        c = segment_coefficients(T, q, qd, qdd, end, zero, zero, 'quintic')
        pos, vel, acc = segment_state(c, s * T)
        if np.all(np.abs(acc) <= acceleration) and np.all(np.abs(vel) <= velocity):
            if np.any(pos < limits.lower) or np.any(pos > limits.upper):
                raise ValueError('the stop leaves the joint position limits')
            return T, end
        T *= STOP_GROWTH
    raise ValueError('no stop within the joint limits from this state')


def within_horizon(plan: Plan, t_cut: float, limits: Optional[JointLimits]) -> Tuple[Plan, bool]:
    """(what the controller gets, whether the plan had to go whole): the plan's points before
    the cut, its state at the cut and a stop to rest within ``limits``. The cut is at ``t_cut``
    (s since onset), or where no stop within the limits starts there (the plan's quintic
    between two points can exceed what its points respect), at its latest point before. The
    plan itself when it has a single point, it ends by ``t_cut`` or comes to rest by the end
    of the stop anyway (no stop then carries on past its path), or there are no limits; also,
    reported, when no stop keeps within the joint limits (the arm runs on to its end unless a
    replan comes). A cut before the plan's first point is made at that point (the arm is still
    blending into it)."""
    if limits is None or len(plan.times) < 2 or plan.times[-1] <= t_cut:
        return plan, False
    t_cut = max(float(t_cut), float(plan.times[0]))
    before = plan.times[plan.times < t_cut - CUT_GAP][-1:]     # the plan's point before it
    for at in (t_cut, *before):
        q, qd, qdd = plan_state(plan, at)
        try:
            T, rest = stop_segment(q, qd, qdd, limits)
        except ValueError:
            continue
        if plan.times[-1] <= at + T:
            return plan, False
        keep = plan.times < at - CUT_GAP
        zero = np.zeros((1, len(q)))
        phase = float(np.interp(at, plan.times, plan.phases))
        cut = replace(
            plan, times=np.r_[plan.times[keep], at, at + T],
            phases=np.r_[plan.phases[keep], phase, phase],
            positions=np.vstack([plan.positions[keep], q, rest]),
            velocities=np.vstack([plan.velocities[keep], qd, zero]),
            accelerations=np.vstack([plan.accelerations[keep], qdd, zero]))
        if check_plan(cut) is None:
            return cut, False
    return plan, True
