"""Trajectory acceptance (JTC rules + finiteness) and interpolation, alone and in the sim.

The acceptance rules and the simulation's handling of rejections run for every shipped robot
(the controller's joints are the robot's)."""

import numpy as np
import pytest

from mixture_ip_ros.estimation.blending import (REACH_RESOLUTION, earliest_reach,
                                                segment_coefficients)
from mixture_ip_ros.robot.description import JOINT_NAMES, load_description, shipped_robots
from mixture_ip_ros.robot.sim import RobotSimulation
from mixture_ip_ros.robot.trajectory import (JointTrajectory, TrajectoryFollower,
                                             TrajectoryPoint, points_from_arrays,
                                             validate_trajectory)

J7 = list(JOINT_NAMES)   # the interpolation tests' joints (the default robot's)


@pytest.fixture(params=shipped_robots())
def J(request):
    """The controller's joints: one shipped robot's."""
    return list(load_description(request.param).joint_names)


def _points(n=3, dof=7, dt=0.5, vel=True):
    return [TrajectoryPoint((i + 1) * dt, [0.1 * i] * dof, [0.0] * dof if vel else [])
            for i in range(n)]


def _validate(J, names=None, points=None, start=None, now=0.0, **kw):
    return validate_trajectory(J if names is None else names,
                               _points(dof=len(J)) if points is None else points, start, now, J,
                               **kw)


def test_a_good_trajectory_is_accepted(J):
    result = _validate(J)
    assert isinstance(result, JointTrajectory)
    np.testing.assert_allclose(result.times, [0.5, 1.0, 1.5])
    assert result.positions.shape == (3, len(J))
    assert result.has_velocities.all() and not result.has_accelerations.any()


def test_reject_empty_joint_names(J):
    assert 'empty joint_names' in _validate(J, names=[])


def test_reject_empty_points(J):
    assert 'no points' in _validate(J, points=[])


def test_reject_unknown_joint(J):
    assert 'unknown joint' in _validate(J, names=J[:-1] + ['elbow'])


def test_reject_duplicate_joint(J):
    assert 'duplicate' in _validate(J, names=J[:-1] + [J[0]])


def test_reject_wrong_joint_count(J):
    n = len(J)
    assert 'partial goals are off' in _validate(J, names=J[:-1], points=_points(dof=n - 1))


def test_reject_another_robots_joints():
    panda, ur5 = (list(load_description(r).joint_names) for r in ('panda', 'ur5'))
    assert 'unknown joint' in _validate(panda, names=J7, points=_points(dof=7))
    assert 'partial goals are off' in _validate(ur5, names=panda, points=_points(dof=7))


def test_partial_goal_when_allowed_fills_the_missing_joints(J):
    fill = np.arange(len(J)) * 0.1
    result = _validate(J, names=[J[2], J[0]], points=[TrajectoryPoint(1.0, [5.0, 6.0])],
                       allow_partial_joints_goal=True, fill_positions=fill)
    expected = fill.copy()
    expected[[2, 0]] = [5.0, 6.0]
    np.testing.assert_allclose(result.positions[0], expected)


def test_other_joint_order_is_remapped(J):
    order = np.random.default_rng(len(J)).permutation(len(J))
    names = [J[i] for i in order]
    values = 10.0 * np.arange(1, len(J) + 1)
    result = _validate(J, names=names, points=[TrajectoryPoint(1.0, values.tolist())])
    expected = np.empty(len(J))
    expected[order] = values
    np.testing.assert_allclose(result.positions[0], expected)


@pytest.mark.parametrize('field', ['positions', 'velocities', 'accelerations'])
def test_reject_size_mismatch(J, field):
    points = _points(dof=len(J))
    setattr(points[1], field, [0.0] * (len(J) - 1))
    assert f'{field} has {len(J) - 1} values' in _validate(J, points=points)


def test_reject_missing_positions(J):
    points = _points(dof=len(J))
    points[2].positions = []
    assert 'positions has 0 values' in _validate(J, points=points)


@pytest.mark.parametrize('field,bad', [('positions', np.nan), ('velocities', np.inf),
                                       ('accelerations', -np.inf)])
def test_reject_non_finite_values(J, field, bad):
    points = _points(dof=len(J))
    values = [0.0] * len(J)
    values[3] = bad
    setattr(points[1], field, values)
    assert f'non-finite value in {field}' in _validate(J, points=points)


@pytest.mark.parametrize('times', [[0.5, 0.5, 1.0], [0.5, 1.0, 0.9]])
def test_reject_time_not_strictly_increasing(J, times):
    points = _points(dof=len(J))
    for p, t in zip(points, times):
        p.time_from_start = t
    assert 'not strictly increasing' in _validate(J, points=points)


def test_reject_trajectory_that_ends_in_the_past(J):
    # Starts at t=10 and lasts 1.5 s: at now=12 it is over.
    assert 'ends in the past' in _validate(J, start=10.0, now=12.0)
    # Still running at now=11: accepted (sampled from now).
    assert isinstance(_validate(J, start=10.0, now=11.0), JointTrajectory)
    # No start time (header.stamp 0) is never in the past.
    assert isinstance(_validate(J, start=None, now=1e6), JointTrajectory)


def test_reject_nonzero_final_velocity_unless_allowed(J):
    points = _points(dof=len(J))
    points[-1].velocities = [0.1] + [0.0] * (len(J) - 1)
    assert 'last point is not zero' in _validate(J, points=points)
    assert isinstance(_validate(J, points=points, allow_nonzero_velocity_at_trajectory_end=True),
                      JointTrajectory)


# ---------------------------------------------------------------------- interpolation

def _anchored(points, t=0.0, q=None, qd=None, start=None):
    traj = validate_trajectory(J7, points, start, t, J7,
                               allow_nonzero_velocity_at_trajectory_end=True)
    assert isinstance(traj, JointTrajectory), traj
    follower = TrajectoryFollower(7)
    follower.set(traj)
    q = np.zeros(7) if q is None else q
    qd = np.zeros(7) if qd is None else qd
    follower.sample(t, q, qd)
    return follower


def test_quintic_segment_matches_a_quintic_polynomial():
    # A quintic sampled with exact derivatives must be reproduced everywhere.
    coeffs = np.random.default_rng(0).normal(size=(6, 7))

    def poly(t, d=0):
        c = coeffs
        if d == 0:
            return sum(c[k] * t**k for k in range(6))
        if d == 1:
            return sum(k * c[k] * t**(k - 1) for k in range(1, 6))
        return sum(k * (k - 1) * c[k] * t**(k - 2) for k in range(2, 6))
    times = [0.0, 0.7, 1.3]
    points = [TrajectoryPoint(t, poly(t).tolist(), poly(t, 1).tolist(), poly(t, 2).tolist())
              for t in times]
    follower = _anchored(points, q=poly(0.0), qd=poly(0.0, 1))
    for t in np.linspace(0, 1.3, 27)[:-1]:
        q, qd, qdd = follower.sample(t, None, None)
        np.testing.assert_allclose(q, poly(t), atol=1e-9)
        np.testing.assert_allclose(qd, poly(t, 1), atol=1e-8)
        np.testing.assert_allclose(qdd, poly(t, 2), atol=1e-7)
    np.testing.assert_allclose(follower.sample(1.3, None, None)[0], poly(1.3), atol=1e-9)


def test_cubic_segment_hits_positions_and_velocities():
    p0, p1 = np.zeros(7), np.arange(7.0)
    v0, v1 = np.ones(7), -np.ones(7)
    follower = _anchored([TrajectoryPoint(0.0, p0.tolist(), v0.tolist()),
                          TrajectoryPoint(2.0, p1.tolist(), v1.tolist())])
    q, qd, _ = follower.sample(0.0, None, None)
    np.testing.assert_allclose(q, p0, atol=1e-12)
    np.testing.assert_allclose(qd, v0, atol=1e-12)
    q, qd, _ = follower.sample(2.0 - 1e-9, None, None)
    np.testing.assert_allclose(q, p1, atol=1e-7)
    np.testing.assert_allclose(qd, v1, atol=1e-7)
    # The cubic's acceleration is linear in time: midpoint = mean of the ends.
    a_start = follower.sample(0.0, None, None)[2]
    a_end = follower.sample(2.0 - 1e-12, None, None)[2]
    np.testing.assert_allclose(follower.sample(1.0, None, None)[2], (a_start + a_end) / 2,
                               atol=1e-9)


def test_position_only_is_linear_and_holds_the_last_point():
    follower = _anchored([TrajectoryPoint(0.0, [0.0] * 7), TrajectoryPoint(2.0, [1.0] * 7)])
    q, qd, qdd = follower.sample(0.5, None, None)
    np.testing.assert_allclose(q, 0.25)
    np.testing.assert_allclose(qd, 0.5)
    np.testing.assert_allclose(qdd, 0.0)
    for t in (2.0, 3.0, 100.0):
        q, qd, qdd = follower.sample(t, None, None)
        np.testing.assert_allclose(q, 1.0)
        np.testing.assert_allclose(qd, 0.0)
        np.testing.assert_allclose(qdd, 0.0)


def test_first_point_in_the_future_is_reached_from_the_current_state():
    q_now = np.full(7, 0.3)
    qd_now = np.full(7, -0.2)
    points = [TrajectoryPoint(1.0, [1.0] * 7, [0.0] * 7)]
    follower = _anchored(points, t=5.0, q=q_now, qd=qd_now)
    q, qd, _ = follower.sample(5.0, None, None)
    np.testing.assert_allclose(q, q_now)
    np.testing.assert_allclose(qd, qd_now)
    np.testing.assert_allclose(follower.sample(6.0, None, None)[0], 1.0)


def test_start_in_the_past_is_sampled_from_now():
    # The trajectory started at t=10; at t=11 it is sampled 1 s in, not from its beginning.
    points = [TrajectoryPoint(0.0, [0.0] * 7), TrajectoryPoint(2.0, [2.0] * 7)]
    follower = _anchored(points, t=11.0, start=10.0, q=np.full(7, 5.0))
    np.testing.assert_allclose(follower.sample(11.0, None, None)[0], 1.0)
    np.testing.assert_allclose(follower.sample(11.5, None, None)[0], 1.5)


def test_header_stamp_zero_starts_now():
    points = [TrajectoryPoint(0.0, [0.0] * 7), TrajectoryPoint(2.0, [2.0] * 7)]
    follower = _anchored(points, t=7.0, start=None)
    np.testing.assert_allclose(follower.sample(7.5, None, None)[0], 0.5)


def test_references_equal_sample_bit_for_bit():
    """References of a stepping clock, asked for in chunks across the evaluation blocks: every
    segment kind, the segment from the state before the first point, and the hold after the
    last, equal to sample() at the same times."""
    rng = np.random.default_rng(3)
    t = [0.3, 0.5, 0.9, 1.0, 1.2]
    points = [TrajectoryPoint(t[0], *(rng.normal(size=(3, 7)).tolist())),
              TrajectoryPoint(t[1], *(rng.normal(size=(3, 7)).tolist())),
              TrajectoryPoint(t[2], *(rng.normal(size=(2, 7)).tolist())),   # quintic, cubic
              TrajectoryPoint(t[3], rng.normal(size=7).tolist()),           # linear
              TrajectoryPoint(t[4], rng.normal(size=7).tolist(), [0.0] * 7)]
    q, qd = rng.normal(size=7), rng.normal(size=7)
    fast, plain = TrajectoryFollower(7), TrajectoryFollower(7)
    for f in (fast, plain):
        f.set(validate_trajectory(J7, points, None, 0.0, J7))
    clock, dt = 0.0123, 0.001
    chunks = [1, 2, 250, 7, 600, 1, 400] * 3
    while clock < 0.0123 + t[-1] + 0.1:       # on into the hold after the last point
        n = chunks.pop(0)
        refs = fast.references(clock, dt, n, q, qd)
        assert 1 <= len(refs) <= n and refs.shape[1:] == (3, 7)
        for row in refs:
            assert np.array_equal(row, np.array(plain.sample(clock, q, qd)))
            clock += dt
    assert TrajectoryFollower(7).references(0.0, dt, 5, q, qd) is None


# ---------------------------------------------------------------------- in the simulation

# The probe of issue 13: what sim_node accepted before it enforced the joint limits. Each case
# is a trajectory from the arm's home posture; the reason names the rule and the joint.
def _probe_cases(sim):
    """(name, points, start, expected words in the reason) for the arm of ``sim``."""
    k, home, n = sim.kinematics, sim.description.home_array(), sim.dof
    beyond = home.copy()
    beyond[0] = k.upper[0] + 0.5              # e.g. 10 rad on joint 1 (iiwa limit 2.97)
    far = np.full(n, 1e6)
    sudden = home + np.eye(n)[0]              # 1 rad in 25 ms: as fast as 2 rad in 50 ms
    fast = [0.0] * n
    fast[0] = 10.0                            # 10 rad/s
    acc = [0.0] * n
    acc[0] = 2.0 * float(k.acceleration_limit[0])
    rest = [0.0] * n
    return [
        ('position beyond', [TrajectoryPoint(2.0, beyond.tolist(), rest)], None,
         ['point 0', sim.joint_names[0], 'position', 'beyond its limits']),
        ('1e6 rad', [TrajectoryPoint(2.0, far.tolist(), rest)], None, ['position', 'beyond']),
        ('40 rad/s between points', [TrajectoryPoint(1.0, home.tolist(), rest),
                                     TrajectoryPoint(1.025, sudden.tolist(), rest)], None,
         ['points 0 to 1', sim.joint_names[0], 'moves 40 rad/s on average, above its limit']),
        ('10 rad/s', [TrajectoryPoint(1.0, home.tolist(), fast),
                      TrajectoryPoint(3.0, home.tolist(), rest)], None,
         ['velocity 10 rad/s beyond']),
        ('acceleration', [TrajectoryPoint(1.0, home.tolist(), rest, acc),
                          TrajectoryPoint(3.0, home.tolist(), rest, [0.0] * n)], None,
         ['acceleration', 'beyond']),
        ('first point due 2 s before it arrived',
         [TrajectoryPoint(-2.0, (home + 0.3).tolist(), rest),
          TrajectoryPoint(2.0, home.tolist(), rest)], None,
         ['stale', 'due 2 s before', 'max_delay 1 s']),
        ('stamped 3 s ago, first point 1 s in', [TrajectoryPoint(1.0, home.tolist(), rest)],
         sim.time - 3.0, ['stale', 'due 2 s before']),
        ('100,000 points', points_from_arrays(np.arange(1, 100_001) * 0.01,
                                              np.tile(home, (100_000, 1))), None,
         ['100000 points, more than the 10000 allowed']),
    ]


@pytest.mark.parametrize('robot', shipped_robots())
def test_the_simulation_refuses_what_a_controller_with_joint_limits_refuses(robot):
    logged = []
    sim = RobotSimulation(robot=robot, logger=logged.append)
    home = sim.description.home_array()
    cases = _probe_cases(sim)
    for name, points, start, words in cases:
        why = sim.set_trajectory(sim.joint_names, points, start)
        assert why is not None, name
        assert all(w in why for w in words), (name, why)
    assert sim.rejection_count == len(cases) and sim.accepted_count == 0
    assert len(logged) == len(cases)                          # one warning each
    assert all(m.startswith('trajectory rejected: ') and '\n' not in m for m in logged)
    sim.step(200)                                            # the arm holds where it was
    np.testing.assert_allclose(sim.q, home, atol=1e-5)
    assert np.abs(sim.qd).max() < 1e-3


# ---------------------------------------------------------------------- late trajectories

def _dense_references(follower, t0, t1, q, qd, step=1e-4):
    """The anchored follower's (q, qd, qdd) references every ``step`` s over [t0, t1]."""
    times = np.arange(t0, t1 + step / 2, step)
    return times, np.array([follower.sample(t, q, qd) for t in times])


def _within(refs, limits, qd_now, margin=1e-9):
    """Oracle: every sampled reference speed within the limit (or the present speed, which the
    arm already has) and every acceleration within its limit."""
    speed_bound = np.maximum(limits.velocity, np.abs(qd_now)) * (1 + margin)
    return (np.abs(refs[:, 1]).max(axis=0) <= speed_bound).all() and \
        (np.abs(refs[:, 2]).max(axis=0) <= limits.acceleration * (1 + margin)).all()


def _late_cases(sim):
    """(name, points, start) of trajectories that come too late for the arm of ``sim`` to
    follow them as stamped: each is re-timed, none is refused."""
    home, n = sim.description.home_array(), sim.dof
    rest = [0.0] * n
    away = (home + 0.1).tolist()         # a posture clear of the scene for every arm
    return [
        ('first point due 1 s before it arrived', [TrajectoryPoint(-1.0, away, rest),
                                                   TrajectoryPoint(2.0, home.tolist(), rest)],
         None),
        ('first point due now, elsewhere', [TrajectoryPoint(0.0, away, rest)], None),
        ('first point too soon', [TrajectoryPoint(0.05, away, rest)], None),
        ('stamped so the first point is due now', [TrajectoryPoint(1.0, away, rest)],
         sim.time - 1.0),
        ('ends in the past', [TrajectoryPoint(0.1, away, rest),
                              TrajectoryPoint(0.7, home.tolist(), rest)], sim.time - 0.9),
        ('first point without velocities, too soon', [TrajectoryPoint(0.02, away)], None),
    ]


@pytest.mark.parametrize('robot', shipped_robots())
def test_a_late_trajectory_is_retimed_from_the_present_state_not_refused(robot):
    """Each late case is accepted and starts later; oracle: the anchored follower's references,
    sampled every 0.1 ms from now to the first point, stay within the speed and acceleration
    limits and reach the first point at its shifted time, then the trajectory's own points come
    at their shifted times; the shift is the least that does (0.5 ms less breaks a limit); the
    arm gets there."""
    for name, points, start in _late_cases(RobotSimulation(robot=robot)):
        logged = []
        sim = RobotSimulation(robot=robot, logger=logged.append)
        sim.step(50)
        now, q, qd = sim.time, sim.q, sim.qd
        assert sim.set_trajectory(sim.joint_names, points, start) is None, name
        assert sim.retimed_count == 1 and sim.rejection_count == 0, name
        assert len(logged) == 1 and 'trajectory late: re-timed to start' in logged[0]
        delay = sim.last_delay
        stamped = (now if start is None else start)
        due = stamped + points[0].time_from_start
        first = due + delay                              # the first point's shifted time
        assert delay > 0 and first > now, name
        traj = sim.follower._pending
        assert traj.start_time == pytest.approx(stamped + delay, abs=1e-12)
        # The follower, anchored now from the state now, as the next step anchors it.
        follower = TrajectoryFollower(sim.dof)
        follower.set(traj)
        times, refs = _dense_references(follower, now, first, q, qd)
        assert _within(refs, sim.limits, qd), name
        np.testing.assert_allclose(follower.sample(first, q, qd)[0], points[0].positions,
                                   atol=1e-9)
        for p in points[1:]:
            np.testing.assert_allclose(follower.sample(first + p.time_from_start
                                                       - points[0].time_from_start, q, qd)[0],
                                       p.positions, atol=1e-9)
        # Least: the same blend 0.5 ms shorter breaks a limit.
        if first - now > 1e-3:
            shorter = JointTrajectory(**{**traj.__dict__, 'start_time': traj.start_time - 5e-4})
            follower = TrajectoryFollower(sim.dof)
            follower.set(shorter)
            _, refs = _dense_references(follower, now, first - 5e-4, q, qd)
            assert not _within(refs, sim.limits, qd), name
        sim.step(int((first + points[-1].time_from_start - points[0].time_from_start
                      - sim.time) / sim.dt) + 1000)
        np.testing.assert_allclose(sim.q, points[-1].positions, atol=1e-3)


@pytest.mark.parametrize('robot', shipped_robots())
def test_a_trajectory_on_time_is_unchanged(robot):
    """A first point the arm reaches in time within its limits: no shift, and the references
    are those of the trajectory validated without the arm's state, bit for bit."""
    sim = RobotSimulation(robot=robot)
    home, n = sim.description.home_array(), sim.dof
    points = [TrajectoryPoint(0.5, (home + 0.05).tolist(), [0.0] * n),
              TrajectoryPoint(1.5, (home + 0.1).tolist(), [0.0] * n)]
    assert sim.set_trajectory(sim.joint_names, points, sim.time) is None
    assert sim.retimed_count == 0 and sim.follower._pending.delay == 0.0
    plain = TrajectoryFollower(n)
    plain.set(validate_trajectory(sim.joint_names, points, sim.time, sim.time, sim.joint_names))
    q, qd = sim.q, sim.qd
    for k in range(1600):
        t = sim.time
        expected = plain.sample(t, q, qd)
        sim.step(1)
        assert all(np.array_equal(a, b) for a, b in zip(sim.reference, expected))
        q, qd = sim.q, sim.qd


def test_earliest_reach_is_within_the_limits_and_nearly_least_on_random_states():
    """Random present states (some moving faster than their limit), first points and limits:
    the blend found is within the limits by dense sampling (the arm's own excess speed
    tolerated), and no duration between the shortest asked for and 3 % less than it is (dense
    sampling on a grid of durations; feasibility is not monotonic in the duration)."""
    rng = np.random.default_rng(19)
    for trial in range(100):
        n = int(rng.integers(1, 8))
        velocity = rng.uniform(0.5, 3.0, n)
        acceleration = rng.uniform(5.0, 200.0, n)
        q = rng.uniform(-2, 2, n)
        qd = rng.uniform(-1.5, 1.5, n) * velocity
        p1 = q + rng.normal(0, 0.3, n)
        v1 = rng.uniform(-1, 1, n) * velocity
        kind = 'cubic' if trial % 4 else 'linear'
        shortest = float(rng.choice([0.001, 0.02, 0.1]))
        T = earliest_reach(q, qd, p1, v1, kind, velocity, acceleration, shortest)
        assert T is not None and T >= shortest

        def dense_ok(T, samples=2001):
            s = np.linspace(0.0, T, samples)[:, None]
            c = segment_coefficients(T, q, qd, 0 * q, p1, v1, 0 * q, kind)
            v = c[1] + 2 * c[2] * s + 3 * c[3] * s ** 2
            a = 2 * c[2] + 6 * c[3] * s
            bound = velocity if kind == 'linear' else np.maximum(velocity, np.abs(qd))
            return (np.abs(v) <= bound * (1 + 1e-9)).all() and \
                (np.abs(a) <= acceleration * (1 + 1e-9)).all()
        assert dense_ok(T), trial
        if T > 1.03 * shortest:
            shorter = np.geomspace(shortest, T / 1.03, 60)
            assert not any(dense_ok(t, 501) for t in shorter), trial


@pytest.mark.parametrize('robot', shipped_robots())
def test_moves_at_the_limits_are_accepted(robot):
    """The rules refuse nothing a careful plan does: a first point at the present position now,
    a minimum-jerk move whose peak speed is 95 % of a joint's limit, positions at the limits."""
    sim = RobotSimulation(robot=robot)
    k, home, n = sim.kinematics, sim.description.home_array(), sim.dof
    T = 2.0
    goal = home.copy()
    goal[0] = home[0] + 0.95 * k.velocity_limit[0] * T / 1.875
    assert goal[0] < k.upper[0]
    t = np.linspace(0.0, T, 41)
    s = t / T
    pos = home + np.outer(10 * s**3 - 15 * s**4 + 6 * s**5, goal - home)
    vel = np.outer((30 * s**2 - 60 * s**3 + 30 * s**4) / T, goal - home)
    assert sim.set_trajectory(sim.joint_names, points_from_arrays(t, pos, vel)) is None
    at_limits = np.where(np.arange(n) % 2, k.upper, k.lower)
    assert isinstance(validate_trajectory(sim.joint_names, points_from_arrays([60.0], [at_limits]),
                                          None, 0.0, sim.joint_names, limits=sim.limits,
                                          positions_now=home), JointTrajectory)


def test_limit_checks_are_independent_of_the_message_joint_order():
    """A permuted message is checked against each joint's own limits (oracle: the limits looked
    up by name)."""
    sim = RobotSimulation()
    names = sim.joint_names[::-1]
    home = sim.description.home_array()[::-1]
    j = sim.joint_names.index('iiwa_joint_4')              # the narrowest speed limit
    limit = sim.kinematics.velocity_limit[j]
    for speed, ok in ((0.99 * limit, True), (1.01 * limit, False)):
        v = np.zeros(7)
        v[names.index('iiwa_joint_4')] = speed
        why = sim.set_trajectory(names, [TrajectoryPoint(1.0, home.tolist(), v.tolist()),
                                         TrajectoryPoint(10.0, home.tolist(), [0.0] * 7)])
        assert (why is None) == ok, why
        if not ok:
            assert 'iiwa_joint_4 velocity' in why



@pytest.mark.parametrize('robot', shipped_robots())
def test_simulation_counts_and_logs_rejections(robot):
    logged = []
    sim = RobotSimulation(robot=robot, logger=logged.append)
    J, n = sim.joint_names, sim.dof
    assert sim.set_trajectory(J[:-1], _points(dof=n - 1)) is not None
    assert sim.set_trajectory(J, []) is not None
    bad = _points(dof=n)
    bad[0].positions = [np.nan] * n
    assert 'non-finite' in sim.set_trajectory(J, bad)
    assert sim.rejection_count == 3
    assert sum('trajectory rejected' in m for m in logged) == 3
    assert 'non-finite' in logged[-1]
    # A rejected trajectory changes nothing: the arm keeps holding its home posture.
    sim.step(100)
    np.testing.assert_allclose(sim.q, sim.description.home, atol=1e-6)


@pytest.mark.parametrize('open_loop', [False, True])
def test_replacement_mid_trajectory_has_no_jump(open_loop):
    sim = RobotSimulation(open_loop_control=open_loop)
    J = sim.joint_names
    HOME = sim.description.home_array()
    q_a = HOME + np.array([0.6, 0.3, -0.4, 0.5, 0.3, -0.3, 0.8])
    t = np.linspace(0.0, 2.0, 11)
    s = t / 2.0
    shape = 10 * s**3 - 15 * s**4 + 6 * s**5
    dshape = (30 * s**2 - 60 * s**3 + 30 * s**4) / 2.0
    P = HOME + np.outer(shape, q_a - HOME)
    V = np.outer(dshape, q_a - HOME)
    assert sim.set_trajectory(J, points_from_arrays(t, P, V)) is None
    refs = []
    for k in range(2500):
        if k == 1000:
            # Mid-motion (fastest point): a new goal somewhere else, first point 0.5 s ahead.
            q_b = HOME - 0.3
            assert sim.set_trajectory(J, points_from_arrays([0.5, 1.5], [q_b, q_b],
                                                            [np.zeros(7)] * 2)) is None
        sim.step(1)
        refs.append(sim.reference[0])
    refs = np.array(refs)
    steps = np.abs(np.diff(refs, axis=0)).max(axis=1)
    # The largest per-step reference motion at the switch is no larger than elsewhere.
    before = steps[900:998].max()
    at_switch = steps[997:1003].max()
    assert at_switch <= 1.05 * before
    np.testing.assert_allclose(sim.q, HOME - 0.3, atol=1e-4)
