"""The robot's plan under one component (its phase speed marginalised, or one given), and the
posterior summary that goes with every replan.

Time is seconds since the interaction's onset on the observations' clock (their stamps).

Plan (:func:`build_plan`): under the MAP component k* (or, hedged, every likely component
weighted by its probability), the robot's expected trajectory with the phase speed
marginalised (OnlineEstimator.expected_controlled: each speed hypothesis's conditioned
trajectory, eq. 13, weighted by its tempered posterior), at ``n_points`` times evenly spaced
from ``t_now + lookahead`` to the end of the slowest speed hypothesis that holds the
posterior, ``1 / min alpha_m``; or, for a given phase speed alpha (the end known), phases
evenly spaced from ``alpha (t_now + lookahead)`` to 1 at ``times = z / alpha``. The first point
lies ``lookahead`` ahead of the present (later where the arm cannot reach the path sooner: see
build_plan's ``robot``), and the last
point's velocity and acceleration are zero (the human holds still past z = 1, and
joint_trajectory_controller rejects a trajectory ending in motion). When ``t_now + lookahead``
is past that end (the human is at rest) the plan is a single point: the predicted final
posture, reached ``max(lookahead, settle_time)`` after ``t_now``; later final plans of the same
interaction keep that time (while it is still ahead) so that the arrival does not recede with
every replan.

The phases (np.linspace) and the checks of a plan run as compiled kernels (estimation._fast),
one call each with the values of the numpy statements they stand for.
"""

from dataclasses import dataclass, replace
import math
from typing import Optional, Tuple

import numpy as np

from mixture_ip_ros.estimation._fast import PLAN_PROBLEMS, limit_ratios, linspace, plan_problem
from mixture_ip_ros.estimation.blending import blend_kind, blend_within_limits, earliest_reach

PHASE_EPS = 1e-6
# A plan would have to be slowed down more than this to respect the joint speed limits: it is
# not the movement that was learned any more, and is refused.
MAX_TIME_SCALE = 4.0
# A plan slowed down to its limits is slowed this much more (relative): times sent as whole
# nanoseconds and rounded divisions would put one exactly at a limit just beyond it.
SLOWDOWN_MARGIN = 1e-6
# An arm behind its plan rejoins the path at the earliest time it can reach, found to within
# this (s): the plan's points are spread over the whole movement (0.5 s apart in a 13 s wave),
# far coarser than the arm's reach changes.
CATCH_UP_RESOLUTION = 0.01
# The controller blends from the arm's state (positions and velocities) into a first point that
# has velocities and accelerations, as the plans' points do.
BLEND = blend_kind(True, True)


@dataclass(frozen=True)
class PosteriorSummary:
    """What the estimator believes after an update: p(k | D) for every component, the MAP
    component k* and its MAP phase speed alpha* (1/s), the phase z = alpha* t in [0, 1] at the
    latest observation, and the confidence p(k* | D)."""

    probabilities: np.ndarray
    component: int
    alpha: float
    phase: float

    @property
    def confidence(self) -> float:
        return float(self.probabilities[self.component])

    @staticmethod
    def labels(n_components: int) -> list:
        """Field names of :meth:`as_array` (the posterior topic's layout)."""
        return [f'p{k}' for k in range(n_components)] + ['alpha', 'phase', 'confidence',
                                                         'component']

    def as_array(self) -> np.ndarray:
        """[p(k=0 | D) .. p(k=K-1 | D), alpha*, phase, confidence, k*]."""
        return np.concatenate([self.probabilities, [self.alpha, self.phase, self.confidence,
                                                    self.component]]).astype(float)


def posterior_summary(estimator, t_now: float) -> PosteriorSummary:
    """The summary of an OnlineEstimator's posterior, the phase taken at ``t_now`` (s since
    onset)."""
    k, alpha = estimator.map_hypothesis()
    return PosteriorSummary(probabilities=estimator.component_posterior(), component=int(k),
                            alpha=float(alpha), phase=float(min(max(alpha * t_now, 0.0), 1.0)))


def end_summary(estimator, t_end: float) -> PosteriorSummary:
    """The summary once the movement's end is known (``t_end`` s after onset): the component
    posterior with the phase 1 there (OnlineEstimator.end_posterior: the batch posterior with
    the phase known, each component at its own warp where the model has them),
    alpha = 1 / t_end."""
    p = estimator.end_posterior(t_end)
    return PosteriorSummary(probabilities=p, component=int(np.argmax(p)), alpha=1.0 / t_end,
                            phase=1.0)


@dataclass(frozen=True)
class Plan:
    """Robot plan under one component.

    times (n,) s since onset; phases (n,) at those times under the phase speed ``alpha`` (the
    MAP one when the plan marginalises the speed); positions, velocities, accelerations (n, Q)
    in joint order of the model. final: the human is at rest (single point at the final
    posture).
    """

    times: np.ndarray
    phases: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray
    component: int
    alpha: float
    final: bool


def build_plan(estimator, t_now: float, *, n_points: int = 25, lookahead: float = 0.1,
               settle_time: float = 0.5, component: Optional[int] = None,
               alpha: Optional[float] = None, final_time: Optional[float] = None,
               robot=None, limits=None, final_position=None,
               hedged: bool = False, margin: float = 0.0) -> Plan:
    """The plan from ``t_now`` (s since onset) on, for ``component`` (default: the MAP one),
    the phase speed marginalised, or at phase speed ``alpha`` if given.

    ``final_time``: when the human is at rest, the time of the final point if it is at least
    ``lookahead`` ahead of ``t_now`` (else ``t_now + max(lookahead, settle_time)``).
    ``robot``/``limits``: the arm's present joints and joint speeds (q, qd) and its
    JointLimits. The points it cannot reach in time are dropped: those into which the
    controller's blend from (q, qd) would exceed the speed or acceleration limits (the
    controller's own rule, estimation.blending.blend_within_limits). The plan then starts at the
    earliest time on the path that the blend reaches within them (to CATCH_UP_RESOLUTION), so
    the arm rejoins the path as soon as it can. If no point is reachable, the plan is the last
    point, timed when the blend can reach it. Without them, every point is kept.
    ``margin`` (s): the controller takes the plan up to this long after ``t_now`` (its
    delivery), so where the arm catches up the point it rejoins the path at, and a final
    plan's point, is one that a blend starting that late, from the arm's state carried on at
    its present speed, reaches within the limits too (else the final point is timed when it
    does): a point at the very edge of reach would be re-timed by the controller for the few
    ms the plan took to arrive.
    ``final_position``: the human's movement has ended here (the observer's 'end'): the plan is
    the single final posture conditioned on this final position at z = 1
    (``OnlineEstimator.predict_at_rest``).
    ``hedged``: the component marginalised too (OnlineEstimator.predictive_controlled: every
    likely component's expected path weighted by p(k | D)), up to the end of the slowest
    speed of any of them; ``component`` is then only the one the plan is recorded under. A
    plan before the robot is confident of the interaction (PlannerSettings.hedge).
    """
    if n_points < 2:
        raise ValueError(f'n_points must be >= 2, got {n_points}')
    if not np.isfinite(t_now) or t_now < 0:
        raise ValueError(f't_now must be finite and >= 0, got {t_now}')
    if hedged and (alpha is not None or final_position is not None):
        raise ValueError('a hedged plan marginalises the phase speed and the component: no '
                         'alpha or final position')
    if component is None:
        component = estimator.map_hypothesis()[0]
    marginal = alpha is None
    if marginal:
        speeds, p = estimator.speed_hypotheses(component)
        t_end = (estimator.latest_end(estimator.likely_components()[0]) if hedged
                 else 1.0 / float(estimator.alphas[speeds].min()))
        a = float(estimator.alphas[speeds[int(np.argmax(p))]])
    else:
        a = float(alpha)
        t_end = 1.0 / a
    final = final_position is not None or t_now + lookahead >= t_end * (1.0 - PHASE_EPS)
    if final:
        if final_time is None or not final_time >= t_now + lookahead:
            final_time = t_now + max(lookahead, settle_time)
        times = np.array([float(final_time)])
        phases = np.array([1.0])
    elif marginal:
        times = linspace(t_now + lookahead, t_end, n_points)
        phases = np.minimum(a * times, 1.0)
    else:
        phases = linspace(a * (t_now + lookahead), 1.0, n_points)
        times = phases / a
    speed = a

    def path(at):
        """The plan's positions, velocities and accelerations at times ``at``."""
        if hedged:
            return estimator.predictive_controlled(at)
        if marginal:
            return estimator.expected_controlled(at, component=component)[1:]
        return estimator.mean_trajectories(speed * at, component=component, alpha=speed)[2]
    if marginal:
        # past every hypothesis's end (a final plan) each one holds its final posture
        k = int(component)
        pos, vel, acc = path(np.maximum(times, t_end) if final else times)
    else:
        # a: the grid value actually used (identical when it came from the grid)
        k, a, (pos, vel, acc), _ = estimator.mean_trajectories(phases, component=component,
                                                               alpha=a)
    vel[-1] = 0.0
    acc[-1] = 0.0
    if final_position is not None:
        pos[-1] = estimator.predict_at_rest(final_position, component=k)[0]
    if robot is not None and limits is not None:
        q, qd = (np.asarray(x, dtype=float) for x in robot)

        def reachable(at, p, v, late=(0.0,)):
            # The plan's own speed is within_limits' to check (it slows a plan down); here only
            # whether the arm gets onto the path. A point due now or earlier is not reachable.
            # ``late``: the blend starts this long after t_now (each of them) from the arm's
            # state carried on; feasibility is not monotonic in the duration, hence several.
            T = np.asarray(at, dtype=float) - t_now
            ok = T > max(late)
            for d in late:
                with np.errstate(divide='ignore', invalid='ignore'):
                    ok[ok] = blend_within_limits(T[ok] - d, q + qd * d, qd, p[ok], np.clip(
                        v[ok], -limits.velocity, limits.velocity), BLEND, limits.velocity,
                        limits.acceleration)
            return ok
        delivery = (0.0, 0.5 * margin, margin) if margin > 0 else (0.0,)
        ok = np.flatnonzero(reachable(times, pos, vel))
        if margin > 0 and ok.size and (ok[0] > 0 or final):
            # catching up, or the single final point: reached also when the plan comes late
            late = np.flatnonzero(reachable(times, pos, vel, delivery))
            ok = late if late.size or final else ok
        first = ok[0] if ok.size else len(times) - 1
        if first > 0:
            # The earliest time on the path the arm reaches in time, before that point; the
            # plan's points after it are kept (the arm follows the path from there).
            probe = np.arange(times[0], times[first] - 0.5 * CATCH_UP_RESOLUTION,
                              CATCH_UP_RESOLUTION)
            at = path(probe) if probe.size else None
            hit = (np.flatnonzero(reachable(probe, at[0], at[1], delivery)) if probe.size
                   else probe)
            if hit.size:
                i = hit[0]
                keep = np.flatnonzero(times > probe[i] + 0.5 * CATCH_UP_RESOLUTION)
                pos, vel, acc = (np.concatenate([x[i:i + 1], y[keep]])
                                 for x, y in zip(at, (pos, vel, acc)))
                phases = np.r_[min(speed * probe[i], 1.0), phases[keep]]
                times = np.r_[probe[i], times[keep]]
                ok = np.array([0])
                first = 0
        phases, times, pos, vel, acc = (x[first:] for x in (phases, times, pos, vel, acc))
        if not ok.size:
            reach = earliest_reach(q + qd * margin, qd, pos[0], np.clip(
                vel[0], -limits.velocity, limits.velocity), BLEND, limits.velocity,
                limits.acceleration, max(times[0] - t_now - margin, 0.0))
            if reach is not None:
                times = np.r_[max(times[0], t_now + margin + reach)]
    return Plan(times=times, phases=phases, positions=pos, velocities=vel, accelerations=acc,
                component=k, alpha=a, final=bool(final))


def predicted_paths(estimator, n_points: int, components=None):
    """The whole predicted human movement (phases evenly spaced over 0..1) of each component
    under its MAP alpha: a list of (component, alpha, times (s since onset), positions
    (n_points, P)) for ``components`` (default: all)."""
    phases = linspace(0.0, 1.0, n_points)
    out = []
    for k in (range(estimator.n_components) if components is None else components):
        alpha = float(estimator.alphas[int(np.argmax(estimator.speed_posterior(k)))])
        _, a, _, positions = estimator.mean_trajectories((), phases, component=k, alpha=alpha)
        out.append((int(k), a, phases / a, positions))
    return out


def predicted_wrist(estimator, plan: Plan, n_points: int):
    """The whole predicted human movement under the plan's hypothesis: times (s since onset)
    and positions (n_points, P) at phases evenly spaced over 0..1."""
    phases = linspace(0.0, 1.0, n_points)
    _, a, _, positions = estimator.mean_trajectories((), phases, component=plan.component,
                                                     alpha=plan.alpha)
    return phases / a, positions


def check_plan(plan: Plan) -> Optional[str]:
    """Why the plan must not be published (None if it may): non-finite values, times not
    strictly increasing at nanosecond resolution, motion at the last point."""
    return PLAN_PROBLEMS[plan_problem(plan.times, plan.positions, plan.velocities,
                                      plan.accelerations)]


@dataclass(frozen=True)
class JointLimits:
    """The robot's limits per joint (in the model's joint order): positions ``lower``..``upper``
    (rad), speeds ``velocity`` (rad/s) and ``acceleration`` (rad/s^2)."""

    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray

    def __post_init__(self):
        arrays = [np.asarray(getattr(self, n), dtype=float) for n in
                  ('lower', 'upper', 'velocity', 'acceleration')]
        if len({a.shape for a in arrays}) != 1 or arrays[0].ndim != 1:
            raise ValueError('joint limits must be four arrays of one value per joint')
        lower, upper, velocity, acceleration = arrays
        if not (np.all(np.isfinite(arrays)) and np.all(lower < upper)
                and np.all(velocity > 0) and np.all(acceleration > 0)):
            raise ValueError('joint limits must be finite, lower < upper, and positive speeds '
                             'and accelerations')
        for name, a in zip(('lower', 'upper', 'velocity', 'acceleration'), arrays):
            object.__setattr__(self, name, a)


def within_limits(plan: Plan, limits: JointLimits, t_plan: float) -> Tuple[Optional[Plan],
                                                                         Optional[str], float]:
    """The plan made to respect ``limits``: (plan, None, time scale), or (None, why, scale).

    Positions beyond a limit cannot be fixed by timing: the plan is refused. Velocities (of
    the points, and the mean speeds between them, which the controller checks too) and
    accelerations beyond their limits are brought just within them by slowing the whole plan
    down about ``t_plan`` (times stretched by s, velocities divided by s, accelerations by
    s^2); a plan that would need s > MAX_TIME_SCALE is refused.
    """
    if plan.positions.shape[1] != limits.lower.shape[0]:
        raise ValueError(f'{plan.positions.shape[1]} joints in the plan, '
                         f'{limits.lower.shape[0]} in the limits')
    j, worst, v, a = limit_ratios(plan.times, plan.positions, plan.velocities,
                                  plan.accelerations, limits.lower, limits.upper,
                                  limits.velocity, limits.acceleration)
    if j >= 0:
        return None, (f'joint {j + 1} at {worst:.3f} rad, beyond its limits '
                      f'[{limits.lower[j]:.3f}, {limits.upper[j]:.3f}]'), 1.0
    scale = max(1.0, v, math.sqrt(a))
    if scale > 1.0:
        # Exactly at a limit is not within it once the times are whole nanoseconds.
        scale *= 1.0 + SLOWDOWN_MARGIN
    if scale > MAX_TIME_SCALE:
        return None, (f'would have to be {scale:.1f} times slower to respect the joint speed '
                      f'and acceleration limits'), scale
    if scale == 1.0:
        return plan, None, 1.0
    return replace(plan, times=t_plan + (plan.times - t_plan) * scale,
                   velocities=plan.velocities / scale,
                   accelerations=plan.accelerations / scale ** 2), None, scale
