"""How a joint trajectory controller moves between points and blends into a new trajectory
(the semantics of ros2_controllers' JTC): the segment polynomials, and whether the blend from
the arm's present state into a first point keeps within the joint limits.

In the estimation layer because the planner needs the controller's own rule to know which
points of a plan the arm can still reach in time (plans.build_plan); robot.trajectory's
acceptance and follower use the same functions.
"""

import numpy as np

# The blending segment's duration is found to this resolution (s).
REACH_RESOLUTION = 1e-4
# Longer than any blend a plan needs: a first point not reachable in this time is refused.
MAX_REACH_TIME = 3600.0
# Durations tried per doubling when a first point cannot be reached in time (2 % apart).
REACH_STEPS_PER_OCTAVE = 32


def segment_coefficients(T, p0, v0, a0, p1, v1, a1, kind: str) -> np.ndarray:
    """Polynomial coefficients c (6, dof), p(s) = sum_k c_k s^k for s in [0, T]; for an array T
    (m, 1) of durations, c (6, m, dof)."""
    dof = len(p0)
    c = np.zeros((6,) + np.broadcast_shapes(np.shape(T), (dof,)))
    c[0] = p0
    if kind == 'linear':
        c[1] = (p1 - p0) / T
    elif kind == 'cubic':
        c[1] = v0
        c[2] = (3 * (p1 - p0) - (2 * v0 + v1) * T) / T**2
        c[3] = (2 * (p0 - p1) + (v0 + v1) * T) / T**3
    elif kind == 'quintic':
        c[1] = v0
        c[2] = a0 / 2
        c[3] = (20 * (p1 - p0) - (8 * v1 + 12 * v0) * T - (3 * a0 - a1) * T**2) / (2 * T**3)
        c[4] = (30 * (p0 - p1) + (14 * v1 + 16 * v0) * T + (3 * a0 - 2 * a1) * T**2) / (2 * T**4)
        c[5] = (12 * (p1 - p0) - 6 * (v1 + v0) * T - (a0 - a1) * T**2) / (2 * T**5)
    else:
        raise ValueError(f'unknown segment kind {kind!r}')
    return c


def segment_state(c: np.ndarray, s):
    """(positions, velocities, accelerations) of the segment with coefficients ``c`` (6, dof)
    at ``s`` s from its start: a scalar gives rows (dof,), an array (m, 1) rows (m, dof)."""
    s = np.asarray(s, dtype=float)
    pos = c[0] + s * (c[1] + s * (c[2] + s * (c[3] + s * (c[4] + s * c[5]))))
    vel = c[1] + s * (2 * c[2] + s * (3 * c[3] + s * (4 * c[4] + s * 5 * c[5])))
    acc = 2 * c[2] + s * (6 * c[3] + s * (12 * c[4] + s * 20 * c[5]))
    return pos, vel, acc


def segment_kind(has_v0, has_a0, has_v1, has_a1) -> str:
    """JTC's segment between two points: quintic with velocities and accelerations at both
    ends, cubic with velocities, else linear."""
    if has_v0 and has_v1:
        return 'quintic' if (has_a0 and has_a1) else 'cubic'
    return 'linear'


def blend_kind(has_velocities: bool, has_accelerations: bool) -> str:
    """The kind of segment the follower blends from the measured state (positions and
    velocities, no accelerations, as JTC) into a first point that has these fields."""
    return segment_kind(True, False, has_velocities, has_accelerations)


def blend_within_limits(T, q, qd, p1, v1, kind, velocity, acceleration) -> np.ndarray:
    """Whether the follower's blending segment of duration T from (q, qd) into (p1, v1) keeps
    every joint within its speed and acceleration limits, for each duration of ``T`` (an array
    (m,) of them; bool (m,)). A present speed at or over a joint's limit is the arm's, not the
    plan's: that joint's speed bound is then its present speed.

    Exact, not sampled: the blend is of degree <= 3, so its speed is extreme at the ends (qd and
    v1, taken as given: a plan may run at exactly its limit) or at the vertex of its parabola
    inside the segment, and its acceleration (linear) at the ends. The linear blend of a first
    point without velocities has a constant speed and no acceleration within it (JTC's)."""
    T = np.asarray(T, dtype=float)[:, None]
    zero = np.zeros_like(q)
    c = segment_coefficients(T, q, qd, zero, p1, v1, zero, kind)
    if kind == 'linear':
        return np.all(np.abs(c[1]) <= velocity, axis=1)
    if kind != 'cubic':
        raise ValueError(f'the follower never blends with a {kind!r} segment')
    c1, c2, c3 = c[1], c[2], c[3]
    with np.errstate(divide='ignore', invalid='ignore'):
        vertex = -c2 / (3.0 * c3)
    inside = (c3 != 0.0) & (vertex > 0.0) & (vertex < T)
    s = np.where(inside, vertex, 0.0)
    speed = np.maximum(np.abs(v1), np.where(inside, np.abs(c1 + 2 * c2 * s + 3 * c3 * s * s),
                                            0.0))
    accel = np.maximum(np.abs(2 * c2), np.abs(2 * c2 + 6 * c3 * T))
    return (np.all(speed <= np.maximum(velocity, np.abs(qd)), axis=1)
            & np.all(accel <= acceleration, axis=1))


def earliest_reach(q, qd, p1, v1, kind, velocity, acceleration, shortest: float,
                   resolution: float = REACH_RESOLUTION,
                   longest: float = MAX_REACH_TIME) -> float | None:
    """The shortest duration >= ``shortest`` of the follower's blending segment from (q, qd)
    into (p1, v1) within the limits (:func:`blend_within_limits`), or None if no duration up to
    ``longest`` s is.

    ``shortest`` itself if that is within them. Otherwise the first of the durations from
    ``shortest`` to ``longest`` in steps of 2^(1/REACH_STEPS_PER_OCTAVE) that is within them,
    then bisection to ``resolution`` between it and the step before. Feasibility is not
    monotonic in the duration when the arm is moving (arriving with its momentum can be within
    the limits where a longer blend that must brake and accelerate again is not), so the steps
    are all evaluated, in one vectorised call, rather than doubled until one fits. The end of
    the last bracket that is within the limits is returned: the result always is. A bounded
    number of evaluations: it always terminates."""
    shortest = max(float(shortest), resolution)

    def ok(T):
        return blend_within_limits(np.atleast_1d(T), q, qd, p1, v1, kind, velocity,
                                   acceleration)
    if ok(shortest)[0]:
        return shortest
    steps = int(np.ceil(REACH_STEPS_PER_OCTAVE * np.log2(max(longest / shortest, 2.0))))
    grid = np.minimum(shortest * 2.0 ** (np.arange(1, steps + 1) / REACH_STEPS_PER_OCTAVE),
                      longest)
    feasible = ok(grid)
    if not feasible.any():
        return None
    i = int(np.argmax(feasible))
    low, high = (shortest if i == 0 else float(grid[i - 1])), float(grid[i])
    while high - low > resolution:
        middle = 0.5 * (low + high)
        if ok(middle)[0]:
            high = middle
        else:
            low = middle
    return high
