"""Plans cut at a horizon (estimation.horizon): the controller's own following of the cut plan
(robot.trajectory.TrajectoryFollower, JTC's semantics) is the oracle. Up to the cut it is the
whole plan's; after it the arm comes to rest within the joint limits."""

import numpy as np
import pytest

from mixture_ip_ros.estimation.horizon import (STOP_MARGIN, STOP_PEAK, MIN_STOP, plan_state,
                                               stop_segment, within_horizon)
from mixture_ip_ros.estimation.planner import OnlinePlanner, PlannerSettings
from mixture_ip_ros.estimation.plans import JointLimits, Plan
from mixture_ip_ros.robot.trajectory import JointTrajectory, TrajectoryFollower

DOF = 3
LIMITS = JointLimits(lower=np.full(DOF, -3.0), upper=np.full(DOF, 3.0),
                     velocity=np.array([1.5, 2.0, 1.0]), acceleration=np.array([8.0, 5.0, 3.0]))


def _plan(seed=0, t0=0.2, t1=3.0, n=25):
    """A smooth plan within LIMITS: sums of sines, exact velocities and accelerations, at rest
    at its last point as every plan is."""
    rng = np.random.default_rng(seed)
    t = np.linspace(t0, t1, n)
    f = np.array([1.0, 1.3, 0.7])
    w = rng.normal(size=(3, DOF)) * 0.25
    pos = np.sin(np.outer(t, f)) @ w
    vel = (np.cos(np.outer(t, f)) * f) @ w
    acc = (-np.sin(np.outer(t, f)) * f ** 2) @ w
    vel[-1] = acc[-1] = 0.0
    return Plan(times=t, phases=t / t1, positions=pos, velocities=vel, accelerations=acc,
                component=0, alpha=1.0 / t1, final=False)


def _followed(plan, times):
    """The controller's reference (q, qd, qdd) at ``times`` along ``plan``."""
    follower = TrajectoryFollower(dof=DOF)
    n = len(plan.times)
    follower.set(JointTrajectory(start_time=0.0, times=plan.times, positions=plan.positions,
                                 velocities=plan.velocities, accelerations=plan.accelerations,
                                 has_velocities=np.ones(n, bool),
                                 has_accelerations=np.ones(n, bool), delay=0.0))
    return np.array([np.stack(follower.sample(t, plan.positions[0], plan.velocities[0]))
                     for t in times])


@pytest.mark.parametrize('seed,cut', [(0, 0.95), (1, 1.7), (2, 0.2), (3, 2.7), (4, 0.51),
                                      (5, 2.2), (6, 1.234)])
def test_the_controller_follows_the_plan_to_the_cut_then_stops_within_the_limits(seed, cut):
    plan = _plan(seed)
    sent, whole = within_horizon(plan, cut, LIMITS)
    assert not whole
    times = np.arange(plan.times[0], plan.times[-1] + 0.5, 1e-3)
    full, short = _followed(plan, times), _followed(sent, times)
    upto = times <= cut
    np.testing.assert_allclose(short[upto], full[upto], atol=1e-10)
    after = short[~upto]
    assert np.all(np.abs(after[:, 1]) <= LIMITS.velocity * (1 + 1e-9))
    assert np.all(np.abs(after[:, 2]) <= LIMITS.acceleration * (1 + 1e-9))
    rest = times >= sent.times[-1]
    assert rest.any() and not np.any(short[rest, 1:])
    # positions stay where the stop ended, and the cut's state is the plan's there
    assert np.abs(short[rest, 0] - sent.positions[-1]).max() <= 1e-12
    np.testing.assert_allclose(np.stack(plan_state(plan, cut)),
                               _followed(plan, [cut])[0], atol=1e-10)


def test_a_stop_from_speed_at_zero_acceleration_in_closed_form():
    qd = np.array([0.9, -1.2, 0.3])
    T, end = stop_segment(np.zeros(DOF), qd, np.zeros(DOF), LIMITS)
    acceleration = LIMITS.acceleration * (1 - STOP_MARGIN)
    assert T == pytest.approx(max(MIN_STOP, np.max(STOP_PEAK * np.abs(qd) / acceleration)))
    np.testing.assert_allclose(end, qd * T / 2)
    # the quintic with zero acceleration at both ends: speed v (1 - 3 s^2 + 2 s^3)
    plan = Plan(times=np.array([0.0, T]), phases=np.zeros(2),
                positions=np.vstack([np.zeros(DOF), end]),
                velocities=np.vstack([qd, np.zeros(DOF)]), accelerations=np.zeros((2, DOF)),
                component=0, alpha=1.0, final=False)
    for s in (0.1, 0.5, 0.8):
        v = plan_state(plan, s * T)[1]
        np.testing.assert_allclose(v, qd * (1 - 3 * s ** 2 + 2 * s ** 3),
                                   atol=1e-12)
    # the joint that needs longest brakes at its acceleration limit, at s = 1/2
    j = int(np.argmax(np.abs(qd) / LIMITS.acceleration))
    assert abs(plan_state(plan, T / 2)[2][j]) == pytest.approx(acceleration[j])


def test_what_is_not_cut():
    plan = _plan(0)
    assert within_horizon(plan, plan.times[-1], LIMITS) == (plan, False)      # ends by the cut
    assert within_horizon(plan, 1.0, None) == (plan, False)                  # no limits
    single = Plan(times=plan.times[-1:], phases=plan.phases[-1:],
                  positions=plan.positions[-1:], velocities=plan.velocities[-1:],
                  accelerations=plan.accelerations[-1:], component=0, alpha=1.0, final=True)
    assert within_horizon(single, 0.0, LIMITS) == (single, False)            # at rest already
    # a cut before the first point is made at it: the arm still blends into it
    sent, _ = within_horizon(plan, 0.0, LIMITS)
    assert sent.times[0] == plan.times[0] and len(sent.times) == 2


def test_where_no_stop_keeps_within_the_limits_the_cut_moves_back_or_the_plan_goes_whole():
    t = np.linspace(0.0, 1.0, 5)
    up = np.outer(t, np.full(DOF, 0.2))            # every joint up at 0.2 rad/s
    vel = np.full((5, DOF), 0.2)
    vel[-1] = 0.0
    plan = Plan(times=t, phases=t, positions=up, velocities=vel,
                accelerations=np.zeros((5, DOF)), component=0, alpha=1.0, final=False)

    def limited(upper_1):
        upper = LIMITS.upper.copy()
        upper[1] = upper_1
        return JointLimits(LIMITS.lower, upper, LIMITS.velocity, LIMITS.acceleration)
    q, qd, qdd = plan_state(plan, 0.5)
    _, rest = stop_segment(q, qd, qdd, LIMITS)
    # the stop from 0.5 would come to rest beyond joint 1's limit: cut at the point before
    tight = limited(0.5 * (q[1] + rest[1]))
    sent, whole = within_horizon(plan, 0.5, tight)
    assert not whole and sent.times[-2] == 0.25 and sent.positions[-1, 1] < tight.upper[1]
    assert within_horizon(plan, 0.5, LIMITS)[0].times[-2] == 0.5
    # from there too: the whole plan, reported
    q, qd, qdd = plan_state(plan, 0.25)
    _, rest = stop_segment(q, qd, qdd, LIMITS)
    assert within_horizon(plan, 0.5, limited(0.5 * (q[1] + rest[1]))) == (plan, True)
    # a plan that comes to rest by the stop's end anyway goes whole, and is no failure
    assert within_horizon(plan, 1.0 - 1e-3, LIMITS) == (plan, False)
    # where the plan's quintic between two points is beyond the acceleration limits (into its
    # last point, at rest) no stop starts there: the cut moves to the point before
    q, qd, qdd = plan_state(plan, 0.95)
    assert np.abs(qdd).max() > 3.0
    slow = JointLimits(LIMITS.lower, LIMITS.upper, LIMITS.velocity, np.full(DOF, 3.0))
    sent, whole = within_horizon(plan, 0.95, slow)
    assert not whole and sent.times[-2] == 0.75


class _Estimator:
    """What the planner reads of an estimator for a test of its sending: never called."""
    n_components = 1


def test_the_planner_sends_the_plan_within_its_horizon_and_counts_whole_ones():
    planner = OnlinePlanner(_Estimator(), PlannerSettings(horizon=0.3), limits=LIMITS)
    plan = _plan(0)
    sent = planner._command(plan, 1.0)
    assert sent.times[-2] == pytest.approx(1.3) and planner.counts.plans_uncut == 0
    planner.update_settings(horizon=0.0)
    assert planner._command(plan, 1.0) is plan
    with pytest.raises(ValueError, match='horizon'):
        PlannerSettings(horizon=-1.0)
