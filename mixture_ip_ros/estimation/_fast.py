"""The estimation layer's fast paths: the phases and the checks of every plan, compiled.

The node plans in callbacks that follow a wait, where each distinct numpy call costs tens of
microseconds: each of these is one compiled call in place of a handful of numpy statements,
and must give their values bit for bit (test_estimation compares each with the numpy it
replaces on random inputs):

- linspace: np.linspace (plans.build_plan's phases);
- plan_problem: plans.check_plan's checks as numpy statements (test_estimation's
  _check_plan_numpy);
- limit_ratios: plans.within_limits' positions and ratios as numpy statements (test_estimation's
  _limit_numbers_numpy).
"""

import numba
import numpy as np

_F1, _F2 = numba.float64[:], numba.float64[:, :]


@numba.njit(_F1(numba.float64, numba.float64, numba.int64), cache=True)
def linspace(start, stop, num):
    """np.linspace(start, stop, num) for num >= 2, its operations elementwise (i step + start,
    or (i / (num - 1)) delta + start when the step underflows to zero; the last one is stop)."""
    div = num - 1
    delta = stop - start
    step = delta / div
    y = np.empty(num)
    for i in range(num):
        y[i] = (i / div * delta if step == 0 else i * step) + start
    y[num - 1] = stop
    return y


# What check_plan reports for each of plan_problem's codes.
PLAN_PROBLEMS = (None, 'non-finite times', 'non-finite positions', 'non-finite velocities',
                 'non-finite accelerations', 'times not strictly increasing (or negative)',
                 'last point not at rest')


@numba.njit(numba.int64(_F1, _F2, _F2, _F2), cache=True)
def plan_problem(times, positions, velocities, accelerations):
    """Index into PLAN_PROBLEMS of the first problem, in check_plan's order (0: none)."""
    for x in times:
        if not np.isfinite(x):
            return 1
    for code, a in ((2, positions), (3, velocities), (4, accelerations)):
        for x in a.ravel():
            if not np.isfinite(x):
                return code
    previous = 0.0
    for i in range(times.shape[0]):
        ns = np.rint(times[i] * 1e9)          # np.round: half to even
        if (i == 0 and ns < 0) or (i > 0 and ns <= previous):
            return 5
        previous = ns
    last = times.shape[0] - 1
    for j in range(velocities.shape[1]):
        if velocities[last, j] != 0 or accelerations[last, j] != 0:
            return 6
    return 0


@numba.njit(numba.types.Tuple((numba.int64, numba.float64, numba.float64, numba.float64))(
    _F1, _F2, _F2, _F2, _F1, _F1, _F1, _F1), cache=True)
def limit_ratios(times, positions, velocities, accelerations, lower, upper, velocity,
                 acceleration):
    """(the first joint with a position beyond its limits, or -1; its lowest position if one is
    below the lower limit, else its highest; the largest speed over its limit, of a point's
    velocity or the mean between two points, |v| / v_limit; max |a| / a_limit), each ratio a
    division then a maximum, as numpy's."""
    n, q = positions.shape
    for j in range(q):
        low = high = False
        lowest, highest = np.inf, -np.inf
        for i in range(n):
            p = positions[i, j]
            low |= p < lower[j]
            high |= p > upper[j]
            lowest = min(lowest, p)
            highest = max(highest, p)
        if low or high:
            return j, lowest if low else highest, 0.0, 0.0
    v = a = -np.inf
    for i in range(n):
        for j in range(q):
            v = max(v, abs(velocities[i, j]) / velocity[j])
            a = max(a, abs(accelerations[i, j]) / acceleration[j])
    for i in range(n - 1):
        for j in range(q):
            v = max(v, abs(positions[i + 1, j] - positions[i, j]) / (times[i + 1] - times[i])
                    / velocity[j])
    return -1, 0.0, v, a
