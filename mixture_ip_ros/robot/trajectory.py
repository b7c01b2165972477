"""Joint trajectory acceptance and interpolation with the semantics of ros2_controllers' JTC.

Acceptance (validate_trajectory) follows JointTrajectoryController::validate_trajectory_msg with
the default parameters (allow_partial_joints_goal=false, allow_nonzero_velocity_at_trajectory_end=
false, allow_integration_in_goal_trajectories=false) plus checks JTC lacks: every value finite, no
duplicate joint names, the joint limits (positions, speeds, accelerations, the mean speed between
points) and a cap on the number of points. Given the state the arm will be blended from, it also
does what a controller's safety layer does with a late command: a first point due before the arm
can reach it within its speed and acceleration limits (late, or due in the past) is not refused
but re-timed, the whole trajectory starting later by the shortfall; only a first point due more
than ``max_delay`` before the command arrived is refused, as stale.

Interpolation (TrajectoryFollower) follows JTC's Trajectory::sample: per segment linear when
either end lacks velocities, cubic with velocities, quintic with velocities and accelerations;
before the first point, a segment from the state measured when the trajectory is first sampled;
after the last point, hold it. Times are seconds on the caller's clock; None as a
start time means "when first sampled".
No ROS types here: the node converts messages into TrajectoryPoint lists.
"""

from __future__ import annotations

from bisect import bisect_right
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from mixture_ip_ros.estimation.blending import (MAX_REACH_TIME, blend_kind, earliest_reach,
                                                segment_coefficients, segment_kind)
from mixture_ip_ros.estimation.plans import JointLimits

# Control steps whose references are evaluated at once (TrajectoryFollower.references).
REFERENCE_BLOCK = 256


@dataclass
class TrajectoryPoint:
    """One waypoint as received (joint order of the message). Empty sequences mean 'not given'."""

    time_from_start: float
    positions: Sequence[float] = ()
    velocities: Sequence[float] = ()
    accelerations: Sequence[float] = ()


@dataclass
class JointTrajectory:
    """An accepted trajectory, remapped to the controller's joint order.

    velocities/accelerations rows of points that did not give them are NaN-free zeros with the
    matching has_velocities/has_accelerations entry False.
    """

    start_time: float | None
    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray
    has_velocities: np.ndarray
    has_accelerations: np.ndarray
    # s the start was moved later than stamped because the first point came too late to reach
    # (0: on time).
    delay: float = 0.0

    @property
    def end_time(self) -> float | None:
        return None if self.start_time is None else self.start_time + float(self.times[-1])


def points_from_arrays(times, positions, velocities=None,
                       accelerations=None) -> list[TrajectoryPoint]:
    """TrajectoryPoints from times (n,), positions (n, dof) and optional (n, dof) derivatives."""
    times = np.asarray(times, dtype=float)
    positions = np.asarray(positions, dtype=float)
    if positions.ndim != 2 or times.shape != (positions.shape[0],):
        raise ValueError(f'times {times.shape} and positions {positions.shape} do not match')
    out = []
    for i, t in enumerate(times):
        out.append(TrajectoryPoint(
            float(t), positions[i].tolist(),
            [] if velocities is None else np.asarray(velocities[i], dtype=float).tolist(),
            [] if accelerations is None else np.asarray(accelerations[i], dtype=float).tolist()))
    return out


# A minute and a half at 100 Hz: far more than any plan, and validated in milliseconds.
DEFAULT_MAX_POINTS = 10_000


def too_many_points(n_points: int, max_points: int | None) -> str | None:
    """Why a trajectory of ``n_points`` is refused by the ``max_points`` rule, or None. Apart so
    that a node can apply it before converting a huge message point by point."""
    if max_points is not None and n_points > max_points:
        return f'{n_points} points, more than the {max_points} allowed (max_trajectory_points)'
    return None


def _beyond(values, low, high, index, names, what: str, unit: str) -> str | None:
    """The first point and joint whose value lies outside [low, high], said in one line."""
    bad = (values < low[index]) | (values > high[index])
    if not bad.any():
        return None
    i, j = (int(x) for x in np.argwhere(bad)[0])
    return (f'point {i}: {names[j]} {what} {values[i, j]:.6g} {unit} beyond its limits '
            f'[{low[index[j]]:.6g}, {high[index[j]]:.6g}]')


def validate_trajectory(joint_names: Sequence[str], points: Sequence[TrajectoryPoint],
                        start_time: float | None, now: float, controller_joints: Sequence[str], *,
                        allow_partial_joints_goal: bool = False,
                        allow_nonzero_velocity_at_trajectory_end: bool = False,
                        fill_positions=None, limits: JointLimits | None = None,
                        positions_now=None, velocities_now=None, control_period: float = 0.0,
                        max_delay: float | None = None,
                        max_points: int | None = None) -> JointTrajectory | str:
    """The accepted trajectory in controller joint order, or the reason for rejecting it.

    start_time: when time_from_start = 0 happens, on the same clock as `now` (None: start now).
    fill_positions: positions (controller order) used for joints a partial goal leaves out.
    With ``limits`` (controller order), as a controller that enforces joint limits: every
    point's positions, velocities and accelerations within them, and no mean speed between two
    points above the speed limit. ``max_points`` caps the length. Every check is on arrays: a
    long trajectory is refused or accepted without a Python loop per value.

    With ``limits`` and ``positions_now`` (the state the follower will blend from, controller
    order; ``velocities_now`` zero if not given), lateness is handled, never refused: the first
    point must be reachable from that state by the follower's blending segment within the speed
    and acceleration limits by the time it is due (:func:`earliest_reach`; a first point due
    within ``control_period`` of now counts as due then). If it is not, or it was due in the
    past, the whole trajectory starts later by the shortfall (``delay`` of the result), as a
    controller's safety layer scales a command it cannot follow on time; this covers a
    trajectory whose end is already past. A first point due more than ``max_delay`` s before
    ``now`` is refused as stale (None: no bound).
    """
    dof = len(controller_joints)
    names = list(joint_names)
    if not names:
        return 'empty joint_names'
    if not allow_partial_joints_goal and len(names) != dof:
        return (f'trajectory has {len(names)} joints, the controller has {dof} '
                '(partial goals are off)')
    for name in names:
        if name not in controller_joints:
            return f'unknown joint {name!r}'
    if len(set(names)) != len(names):
        return 'duplicate joint names'
    m, n = len(points), len(names)
    if m == 0:
        return 'empty trajectory: no points'
    why = too_many_points(m, max_points)
    if why:
        return why
    arrays = {}
    for field_name, allow_empty in (('positions', False), ('velocities', True),
                                    ('accelerations', True)):
        lengths = np.array([len(getattr(p, field_name)) for p in points])
        given = lengths > 0 if allow_empty else np.ones(m, dtype=bool)
        wrong = np.flatnonzero(given & (lengths != n))
        if wrong.size:
            i = int(wrong[0])
            return f'point {i}: {field_name} has {lengths[i]} values for {n} joint names'
        values = np.zeros((m, n))
        if given.any():
            values[given] = np.array([getattr(p, field_name) for p, g in zip(points, given) if g],
                                     dtype=float).reshape(-1, n)
        finite = np.isfinite(values).all(axis=1)
        if not finite.all():
            return f'point {int(np.argmin(finite))}: non-finite value in {field_name}'
        arrays[field_name] = (values, given)
    times = np.array([p.time_from_start for p in points], dtype=float)
    if not np.isfinite(times).all():
        return f'point {int(np.argmin(np.isfinite(times)))}: non-finite time_from_start'
    steps = np.diff(times)
    if (steps <= 0).any():
        i = int(np.argmax(steps <= 0)) + 1
        return (f'time_from_start not strictly increasing at point {i} '
                f'({times[i - 1]} then {times[i]})')
    retime = limits is not None and positions_now is not None
    if start_time is not None:
        if not np.isfinite(start_time):
            return 'non-finite start time'
        end = start_time + times[-1]
        if end < now and not retime:
            return f'trajectory ends in the past (ends at {end:.6f}, now {now:.6f})'
    pos, _ = arrays['positions']
    vel, has_v = arrays['velocities']
    acc, has_a = arrays['accelerations']
    if not allow_nonzero_velocity_at_trajectory_end:
        # Same threshold as JTC: float epsilon.
        if has_v[-1] and np.any(np.abs(vel[-1]) > np.finfo(np.float32).eps):
            return 'velocity of the last point is not zero'

    index = np.array([list(controller_joints).index(name) for name in names])
    if limits is not None:
        why = (_beyond(pos, limits.lower, limits.upper, index, names, 'position', 'rad')
               or _beyond(vel, -limits.velocity, limits.velocity, index, names, 'velocity',
                          'rad/s')
               or _beyond(acc, -limits.acceleration, limits.acceleration, index, names,
                          'acceleration', 'rad/s^2'))
        if why:
            return why
        speed = np.abs(np.diff(pos, axis=0)) / steps[:, None]
        over = speed > limits.velocity[index]
        if over.any():
            i, j = (int(x) for x in np.argwhere(over)[0])
            return (f'points {i} to {i + 1}: {names[j]} moves {speed[i, j]:.3g} rad/s on '
                    f'average, above its limit {limits.velocity[index[j]]:.3g} rad/s')
    delay = 0.0
    if retime:
        due = (now if start_time is None else start_time) + times[0] - now
        if max_delay is not None and due < -max_delay:
            return (f'stale: the first point was due {-due:.3g} s before the trajectory '
                    f'arrived, more than max_delay {max_delay:.3g} s')
        q = np.asarray(positions_now, dtype=float)[index]
        qd = (np.zeros(n) if velocities_now is None
              else np.asarray(velocities_now, dtype=float)[index])
        kind = blend_kind(bool(has_v[0]), bool(has_a[0]))
        shortest = max(due, control_period)
        reach = earliest_reach(q, qd, pos[0], vel[0], kind, limits.velocity[index],
                               limits.acceleration[index], shortest)
        if reach is None:
            return (f'the first point cannot be reached from the present state within the '
                    f'joint limits in {MAX_REACH_TIME:.0f} s')
        if due < 0 or reach > shortest:
            delay = reach - due
            start_time = (now if start_time is None else start_time) + delay

    out_pos = np.zeros((m, dof))
    out_vel = np.zeros((m, dof))
    out_acc = np.zeros((m, dof))
    if n < dof:
        if fill_positions is None:
            return 'partial goal but no positions to fill the missing joints'
        fill = np.asarray(fill_positions, dtype=float)
        if fill.shape != (dof,) or not np.all(np.isfinite(fill)):
            return 'partial goal but fill positions are not finite'
        out_pos[:] = fill
    out_pos[:, index] = pos
    out_vel[:, index] = vel
    out_acc[:, index] = acc
    return JointTrajectory(start_time=None if start_time is None else float(start_time),
                           times=times, positions=out_pos, velocities=out_vel,
                           accelerations=out_acc, has_velocities=has_v, has_accelerations=has_a,
                           delay=float(delay))



def stopping_trajectory(q, qd, acceleration, control_period: float) -> JointTrajectory:
    """To rest from the state (``q``, ``qd``) at constant deceleration, within the joint
    acceleration limits, along the present direction of motion: every joint stops at the same
    time T = max_j |qd_j| / acceleration_j (at least one ``control_period``), so the joint that
    needs longest brakes at its limit and the others less, and the arm stops on the path it was
    on. One point, (q + qd T / 2, at rest) at T, starting when first sampled: the follower's
    cubic blend from (q, qd) into it is exactly that deceleration (its cubic term vanishes).
    To be sampled from the state it was computed from (the next control step)."""
    q = np.asarray(q, dtype=float)
    qd = np.asarray(qd, dtype=float)
    T = max(float(np.max(np.abs(qd) / np.asarray(acceleration, dtype=float))),
            float(control_period), 1e-9)
    dof = len(q)
    zero = np.zeros((1, dof))
    return JointTrajectory(start_time=None, times=np.array([T]),
                           positions=(q + 0.5 * T * qd)[None, :], velocities=zero,
                           accelerations=zero.copy(), has_velocities=np.array([True]),
                           has_accelerations=np.array([False]))

@dataclass
class _Plan:
    t0: list                           # segment start times (absolute)
    duration: list                     # segment durations
    coeffs: np.ndarray                 # (nseg, 6, dof)
    final: np.ndarray                  # last positions
    end_time: float
    kinds: list = field(default_factory=list)


class TrajectoryFollower:
    """The active trajectory and its reference samples (JTC's Trajectory::sample semantics).

    set() replaces the active trajectory; the next sample() anchors it: start_time None becomes
    the sample time, and if the first point lies in the future a segment from the state given to
    sample() (measured positions and velocities, as JTC in closed loop; with open_loop, the old
    trajectory's reference at that time) leads to it. A start in
    the past is sampled at the current time on the trajectory's own time axis.
    """

    def __init__(self, dof: int = 7, open_loop: bool = False):
        self.dof = dof
        # JTC's open_loop_control: blend a replacement from the old trajectory's reference at
        # the switch time instead of the measured state.
        self.open_loop = open_loop
        self._basis = np.zeros((3, 6))
        self._basis[0, 0] = 1.0
        self._basis[1, 1] = 1.0
        self._basis[2, 2] = 2.0
        self._pending: JointTrajectory | None = None
        self._plan: _Plan | None = None
        self._block = None    # (plan, times, references, next row) of references()

    @property
    def active(self) -> bool:
        return self._plan is not None or self._pending is not None

    def following(self, t: float) -> bool:
        """Whether a trajectory is set and not yet at its end at ``t`` (after it, the arm
        holds its last point)."""
        return self._pending is not None or (self._plan is not None
                                             and t < self._plan.end_time)

    def set(self, trajectory: JointTrajectory) -> None:
        self._pending = trajectory

    def clear(self) -> None:
        self._pending = None
        self._plan = None

    def _anchor(self, traj: JointTrajectory, t: float, q, qd) -> _Plan:
        start = t if traj.start_time is None else traj.start_time
        abs_times = start + traj.times
        t0, dur, coeffs, kinds = [], [], [], []
        if t < abs_times[0]:
            # From the current state (positions and velocities, no accelerations, like JTC).
            kind = blend_kind(traj.has_velocities[0], traj.has_accelerations[0])
            T = abs_times[0] - t
            coeffs.append(segment_coefficients(T, np.asarray(q, float), np.asarray(qd, float),
                                               np.zeros(self.dof), traj.positions[0],
                                               traj.velocities[0], traj.accelerations[0], kind))
            t0.append(t)
            dur.append(T)
            kinds.append(kind)
        for i in range(len(traj.times) - 1):
            kind = segment_kind(traj.has_velocities[i], traj.has_accelerations[i],
                                traj.has_velocities[i + 1], traj.has_accelerations[i + 1])
            T = abs_times[i + 1] - abs_times[i]
            coeffs.append(segment_coefficients(
                T, traj.positions[i], traj.velocities[i], traj.accelerations[i],
                traj.positions[i + 1], traj.velocities[i + 1], traj.accelerations[i + 1], kind))
            t0.append(abs_times[i])
            dur.append(T)
            kinds.append(kind)
        # Plain float lists: bisect and scalar arithmetic on them are much faster than on arrays.
        return _Plan(t0=[float(x) for x in t0], duration=[float(x) for x in dur],
                     coeffs=np.array(coeffs).reshape(len(coeffs), 6, self.dof),
                     final=traj.positions[-1].copy(), end_time=float(abs_times[-1]), kinds=kinds)

    def sample(self, t: float, q, qd):
        """(q_ref, qd_ref, qdd_ref) at time t, or None when there is no trajectory."""
        self._take_pending(t, q, qd)
        if self._plan is None:
            return None
        return self._sample_plan(self._plan, t)

    def references(self, t: float, dt: float, n: int, q, qd):
        """The references of the next control steps of a clock that starts at ``t`` and
        advances by ``t += dt`` (as MuJoCo's): an array (m, 3, dof), 1 <= m <= n, row k =
        (q_ref, qd_ref, qdd_ref) at the k-th time, equal bit for bit to :meth:`sample` there;
        None when there is no trajectory. ``q``, ``qd``: the state at ``t`` (anchoring).

        Evaluated for REFERENCE_BLOCK steps at a time and kept: a caller stepping on that
        clock, whatever its n, pays one vectorised evaluation per block instead of one small
        matrix product per step (at 1 kHz numpy's per-call overhead is most of the cost).
        """
        self._take_pending(t, q, qd)
        plan = self._plan
        if plan is None:
            return None
        block = self._block
        if block is not None and block[0] is plan:
            _, times, refs, k = block
            if k < len(times) and times[k] == t:
                m = min(int(n), len(times) - k)
                self._block = (plan, times, refs, k + m)
                return refs[k:k + m]
        steps = REFERENCE_BLOCK
        times = np.empty(steps)
        times[0] = t
        times[1:] = dt
        np.add.accumulate(times, out=times)      # sequential: t, t + dt, (t + dt) + dt, ...
        refs = self._sample_plan_at(plan, times)
        m = min(int(n), steps)
        self._block = (plan, times, refs, m)
        return refs[:m]

    def blend_state(self, t: float, q, qd):
        """The state a trajectory anchored at ``t`` is blended from: the measured (q, qd), or
        with open_loop the anchored trajectory's reference there (if there is one)."""
        if self.open_loop and self._plan is not None:
            q, qd, _ = self._sample_plan(self._plan, t)
        return q, qd

    def _take_pending(self, t, q, qd):
        """Anchor a trajectory set since the last sample at ``t``."""
        if self._pending is not None:
            self._plan = self._anchor(self._pending, t, *self.blend_state(t, q, qd))
            self._pending = None

    def _sample_plan(self, plan: _Plan, t: float):
        if t >= plan.end_time or len(plan.t0) == 0:
            zero = np.zeros(self.dof)
            return plan.final.copy(), zero, zero.copy()
        i = bisect_right(plan.t0, t) - 1
        if i < 0:
            i = 0
        s = min(max(t - plan.t0[i], 0.0), plan.duration[i])
        s2 = s * s
        s3 = s2 * s
        # Position, velocity and acceleration rows of the power basis, one small matrix product
        # (filled in place: this runs at 1 kHz and numpy call overhead dominates).
        b = self._basis
        b[0, 1] = s
        b[0, 2] = s2
        b[0, 3] = s3
        b[0, 4] = s3 * s
        b[0, 5] = s3 * s2
        b[1, 2] = 2 * s
        b[1, 3] = 3 * s2
        b[1, 4] = 4 * s3
        b[1, 5] = 5 * s3 * s
        b[2, 3] = 6 * s
        b[2, 4] = 12 * s2
        b[2, 5] = 20 * s3
        out = b @ plan.coeffs[i]
        return out[0], out[1], out[2]

    def _sample_plan_at(self, plan: _Plan, times: np.ndarray) -> np.ndarray:
        """:meth:`_sample_plan` at every time of ``times``, as an array (len(times), 3, dof):
        the same operations elementwise, and the same 3 x 6 by 6 x dof product per time (a
        stacked matmul multiplies each pair as the single one does), so the values are the
        same bit for bit."""
        out = np.empty((len(times), 3, self.dof))
        live = times < plan.end_time if len(plan.t0) else np.zeros(len(times), dtype=bool)
        done = ~live
        out[done, 0] = plan.final
        out[done, 1:] = 0.0
        t = times[live]
        if t.size:
            t0 = np.asarray(plan.t0)
            i = np.maximum(np.searchsorted(t0, t, side='right') - 1, 0)
            s = np.minimum(np.maximum(t - t0[i], 0.0), np.asarray(plan.duration)[i])
            s2 = s * s
            s3 = s2 * s
            b = np.zeros((t.size, 3, 6))
            b[:, 0, 0] = 1.0
            b[:, 1, 1] = 1.0
            b[:, 2, 2] = 2.0
            b[:, 0, 1] = s
            b[:, 0, 2] = s2
            b[:, 0, 3] = s3
            b[:, 0, 4] = s3 * s
            b[:, 0, 5] = s3 * s2
            b[:, 1, 2] = 2 * s
            b[:, 1, 3] = 3 * s2
            b[:, 1, 4] = 4 * s3
            b[:, 1, 5] = 5 * s3 * s
            b[:, 2, 3] = 6 * s
            b[:, 2, 4] = 12 * s2
            b[:, 2, 5] = 20 * s3
            out[live] = b @ plan.coeffs[i]
        return out
