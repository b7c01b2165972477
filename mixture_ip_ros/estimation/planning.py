"""What the estimator node decides, without ROS: one interaction at a time, the online estimate
of (component, phase speed), when to commit the robot, and the plan it is sent.

Time is seconds since the interaction's onset on the observations' clock (their stamps), so a
plan's ``times`` are exactly the ``time_from_start`` of a JointTrajectory stamped with the onset.

Plan (:func:`build_plan`): under the MAP hypothesis (k*, alpha*), ``n_points`` phases evenly
spaced from ``z_start = alpha* (t_now + lookahead)`` to 1, ``times = z / alpha*``, positions,
velocities and accelerations of the conditioned robot trajectory (eq. 13); the first point lies
``lookahead`` ahead of the latest observation so the controller gets a reachable target, and the
last point's velocity and acceleration are zero (the human holds still past z = 1, and
joint_trajectory_controller rejects a trajectory ending in motion). When ``z_start`` >= 1 (the
human is at rest) the plan is a single point: the predicted final posture, reached
``max(lookahead, settle_time)`` after ``t_now``; later final plans of the same interaction keep
that time (while it is still ahead) so that the arrival does not recede with every replan.

Commit (:func:`should_commit`): the first plan is sent once p(k* | D) >= ``confidence_threshold``
with at least ``min_observations`` observations used and none of the samples held before the
onset still waiting to be absorbed; afterwards every replan is sent, also
when k* changes (the controller blends from its current state into the new plan).
"""

from collections import deque
from dataclasses import dataclass
import time
from typing import Optional

import numpy as np

STATES = ('idle', 'observing', 'committed', 'done')
# Why the estimator did not use an observation (beyond 'skipped': within min_interval of the last one used).
OBSERVATION_REJECT_REASONS = ('wrong_frame', 'non_finite', 'before_onset',
                  'time_backwards', 'exception', 'bad_joint_state')
MAX_HELD = 20_000   # held observations at most (2.5 s at 8 kHz), whatever their stamps
PHASE_EPS = 1e-6
MAX_LAG = 1.0   # s; a present further from the latest observation means another clock


def summary_labels(n_components: int) -> list:
    """Field names of :func:`posterior_summary` (the posterior topic's layout)."""
    return [f'p{k}' for k in range(n_components)] + ['alpha', 'phase', 'confidence',
                                                     'component']


def posterior_summary(estimator, t_now: float) -> np.ndarray:
    """[p(k=0 | D) .. p(k=K-1 | D), alpha*, phase, confidence = p(k* | D), k*]."""
    p = estimator.component_posterior()
    k, alpha = estimator.map_hypothesis()
    phase = float(np.clip(alpha * t_now, 0.0, 1.0))
    return np.concatenate([p, [alpha, phase, p[k], k]]).astype(float)


def should_commit(component_posterior, n_observations: int, confidence_threshold: float,
                  min_observations: int) -> bool:
    """Whether the robot may start: enough evidence and a confident most probable component."""
    return (n_observations >= min_observations
            and float(np.max(component_posterior)) >= confidence_threshold)


@dataclass(frozen=True)
class Plan:
    """Robot plan under one hypothesis (component, alpha).

    times (n,) s since onset (time_from_start); phases (n,); positions, velocities,
    accelerations (n, Q) in joint order of the model. final: the human is at rest (single
    point at the final posture).
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
               robot_q=None, catch_up_velocity=None, final_position=None) -> Plan:
    """The plan from ``t_now`` (s since onset) on, for (component, alpha) (default: the MAP).

    ``final_time``: when the human is at rest, the time of the final point if it is at least
    ``lookahead`` ahead of ``t_now`` (else ``t_now + max(lookahead, settle_time)``).
    ``robot_q``/``catch_up_velocity``: the robot's current joints and the joint speeds it may
    use to catch up with the plan. Points it cannot reach in time at those speeds are dropped
    (the controller blends from its state into the first kept point); if none is reachable the
    plan is the last point, timed when it can be reached. Without them, no catch-up limit.
    ``final_position``: the human's movement has ended here (the observer's 'end'): the plan is
    the single final posture conditioned on this final position at z = 1
    (``OnlineEstimator.predict_at_rest``).
    """
    if n_points < 2:
        raise ValueError(f'n_points must be >= 2, got {n_points}')
    if not np.isfinite(t_now) or t_now < 0:
        raise ValueError(f't_now must be finite and >= 0, got {t_now}')
    if component is None or alpha is None:
        k_map, a_map = estimator.map_hypothesis()
        component = k_map if component is None else component
        alpha = a_map if alpha is None else alpha
    a = float(alpha)
    z_start = a * (t_now + lookahead)
    final = final_position is not None or z_start >= 1.0 - PHASE_EPS
    if final:
        phases = np.array([1.0])
        if final_time is None or not final_time >= t_now + lookahead:
            final_time = t_now + max(lookahead, settle_time)
        times = np.array([float(final_time)])
    else:
        phases = np.linspace(z_start, 1.0, n_points)
        times = phases / a
    # a: the grid value actually used (identical when it came from the grid)
    k, a, (pos, vel, acc), _ = estimator.mean_trajectories(phases, component=component, alpha=a)
    vel[-1] = 0.0
    acc[-1] = 0.0
    if final_position is not None:
        pos[-1] = estimator.predict_at_rest(final_position, component=k)[0]
    if robot_q is not None and catch_up_velocity is not None:
        reachable_at = t_now + np.max(np.abs(pos - np.asarray(robot_q))
                                      / np.asarray(catch_up_velocity), axis=1)
        ok = np.flatnonzero(times >= reachable_at)
        first = ok[0] if ok.size else len(times) - 1
        times = times.copy()
        times[first] = max(times[first], reachable_at[first])
        phases, times, pos, vel, acc = (x[first:] for x in (phases, times, pos, vel, acc))
    return Plan(times=times, phases=phases, positions=pos, velocities=vel, accelerations=acc,
                component=k, alpha=a, final=bool(final))


def predicted_wrist(estimator, plan: Plan, n_points: int):
    """The whole predicted human movement under the plan's hypothesis: times (s since onset)
    and positions (n_points, P) at phases evenly spaced over 0..1."""
    phases = np.linspace(0.0, 1.0, n_points)
    _, a, _, positions = estimator.mean_trajectories((), phases, component=plan.component,
                                                     alpha=plan.alpha)
    return phases / a, positions


def check_plan(plan: Plan) -> Optional[str]:
    """Why the plan must not be published (None if it may): non-finite values, times not
    strictly increasing at nanosecond resolution, motion at the last point."""
    for name in ('times', 'positions', 'velocities', 'accelerations'):
        if not np.isfinite(getattr(plan, name)).all():
            return f'non-finite {name}'
    ns = np.round(plan.times * 1e9)
    if ns[0] < 0 or (ns[1:] <= ns[:-1]).any():
        return 'times not strictly increasing (or negative)'
    if plan.velocities[-1].any() or plan.accelerations[-1].any():
        return 'last point not at rest'
    return None


@dataclass
class Step:
    """What one replan produced: always the posterior summary and the plan (the predicted
    path follows its hypothesis); ``send`` says whether the joint trajectory goes out.
    ``problem`` is check_plan's reason."""

    summary: np.ndarray
    plan: Optional[Plan]
    send: bool
    committed_now: bool = False
    switched_from: Optional[int] = None
    problem: Optional[str] = None


class LatencyStats:
    """Last / mean / max of a duration, in microseconds."""

    def __init__(self):
        self.count = 0
        self.last_us = 0.0
        self.max_us = 0.0
        self._sum_us = 0.0

    def add(self, seconds: float) -> None:
        us = seconds * 1e6
        self.count += 1
        self.last_us = us
        self._sum_us += us
        self.max_us = max(self.max_us, us)

    @property
    def mean_us(self) -> float:
        return self._sum_us / self.count if self.count else 0.0


class InteractionPlanner:
    """The estimator node's logic: idle -> observing -> committed -> done per interaction.

    ``onset(stamp_ns)`` resets the estimator; ``observe(stamp_ns, xyz)`` feeds it and returns
    'used', 'skipped', 'held' or the reject reason; ``step()`` (timer) and ``end(stamp_ns)``
    (last plan) return a :class:`Step`.

    Observations that arrive outside an interaction are held for ``hold_window`` seconds (of
    their stamps): the observer forwards every sample as it comes and confirms an onset some
    0.1-1 s after the hand left rest, back-dating it. At the onset the held samples from then on
    are admitted (thinned by min_interval) into a backlog that ``absorb_backlog(budget)``
    conditions on in slices, while live observations are conditioned on at once (the posterior
    does not depend on the order, see OnlineEstimator.absorb): a live sample never waits behind
    the whole backlog. The robot is committed only once the backlog is absorbed: on all the
    evidence, as if every sample had been conditioned on when it came.

    ``interactions`` lists one record (dict) per interaction, the last one is the current one
    (the most recent ``max_records`` are kept). Absolute times (``*_time``) are seconds on the
    stamps' clock, ``*_elapsed`` seconds since the onset:
    onset_stamp_ns, onset_time; state; component, label, confidence, alpha, phase (at the
    latest replan); final_component, final_label (set when the interaction closes);
    commit_phase (phase at the first plan sent = fraction of the human movement seen; None if
    the robot never moved), commit_time, commit_elapsed, commit_component,
    commit_observations; n_observations (used), n_received, n_skipped, n_rejected; plans
    (sent); switches (list of {elapsed, phase, from, to}); gaps; end_reason ('end',
    'new_onset', None while running); end_time, end_elapsed (None for 'new_onset').
    """

    def __init__(self, estimator, *, confidence_threshold: float = 0.9,
                 min_observations: int = 3, n_points: int = 25, lookahead: float = 0.1,
                 settle_time: float = 0.5, labels=None, hold_window: float = 2.5,
                 max_records: int = 1000, catch_up_velocity=None):
        if not 0.0 < confidence_threshold <= 1.0:
            raise ValueError(f'confidence_threshold must be in (0, 1], got {confidence_threshold}')
        if int(min_observations) != min_observations or min_observations < 1:
            raise ValueError(f'min_observations must be an integer >= 1, got {min_observations}')
        if int(n_points) != n_points or n_points < 2:
            raise ValueError(f'n_points must be an integer >= 2, got {n_points}')
        if not (np.isfinite(lookahead) and lookahead >= 0):
            raise ValueError(f'lookahead must be >= 0, got {lookahead}')
        if not (np.isfinite(settle_time) and settle_time > 0):
            raise ValueError(f'settle_time must be > 0, got {settle_time}')
        if not (np.isfinite(hold_window) and hold_window > 0):
            raise ValueError(f'hold_window must be > 0, got {hold_window}')
        if labels is not None and len(labels) != estimator.n_components:
            raise ValueError(f'{len(labels)} component labels for {estimator.n_components} '
                             'components')
        self.estimator = estimator
        self.confidence_threshold = float(confidence_threshold)
        self.min_observations = int(min_observations)
        self.n_points = int(n_points)
        self.lookahead = float(lookahead)
        self.settle_time = float(settle_time)
        self.labels = None if labels is None else list(labels)
        self.catch_up_velocity = (None if catch_up_velocity is None
                                  else np.asarray(catch_up_velocity, dtype=float))
        self.robot_q = None       # latest robot joints (set by the node), for catching up
        self.state = 'idle'
        self.interactions = []
        self.received = 0
        self.used = 0
        self.skipped = 0
        self.rejected = {reason: 0 for reason in OBSERVATION_REJECT_REASONS}
        self.plans_sent = 0
        self.plan_failures = 0
        self._held = deque(maxlen=MAX_HELD)   # (stamp ns, y) outside an interaction
        self._hold_ns = round(float(hold_window) * 1e9)
        self._backlog = deque()   # (t, y) admitted at the onset, not yet absorbed
        self._max_records = max(1, int(max_records))
        self._onset_ns = None
        self._t_latest = None     # latest observation time (s since onset), used or skipped
        self._y_latest = None     # and the observed position then
        self._dirty = False       # something new since the last step
        self._sent_component = None
        self._final_time = None   # time of the last final (at rest) plan's point

    # -- queries ----------------------------------------------------------------------
    @property
    def current(self) -> Optional[dict]:
        return self.interactions[-1] if self.interactions else None

    @property
    def onset_ns(self) -> Optional[int]:
        return self._onset_ns

    @property
    def t_now(self) -> float:
        """Latest observation time of the interaction, s since onset (0 before any)."""
        return 0.0 if self._t_latest is None else self._t_latest

    @property
    def active(self) -> bool:
        return self.state in ('observing', 'committed')

    @property
    def n_held(self) -> int:
        return len(self._held)

    @property
    def n_backlog(self) -> int:
        """Held observations of the interaction not yet absorbed (see absorb_backlog)."""
        return len(self._backlog)

    def label(self, k: Optional[int]):
        return None if (k is None or self.labels is None) else self.labels[k]

    def _absolute(self, elapsed: float) -> float:
        return (self._onset_ns + round(elapsed * 1e9)) * 1e-9

    # -- input ------------------------------------------------------------------------
    def reject(self, reason: str) -> str:
        self.rejected[reason] += 1
        return reason

    def refuse(self, reason: str) -> str:
        """Count an observation received and rejected before ``observe`` (e.g. wrong frame)."""
        self.received += 1
        if self.active:
            self.current['n_received'] += 1
        return self._rejected_in_interaction(reason)

    def onset(self, stamp_ns: int) -> None:
        """Start an interaction at ``stamp_ns``: the held observations from then on are
        admitted into the backlog (older ones were rest before the movement: dropped)."""
        if self.active:
            self._close('new_onset', None)
        self.estimator.reset()
        self._onset_ns = int(stamp_ns)
        self._t_latest = None
        self._y_latest = None
        self._dirty = True
        self._sent_component = None
        self._final_time = None
        self.state = 'observing'
        excess = len(self.interactions) + 1 - self._max_records
        if excess > 0:
            del self.interactions[:excess]
        self.interactions.append({
            'onset_stamp_ns': self._onset_ns, 'onset_time': self._onset_ns * 1e-9,
            'state': 'observing',
            'component': None, 'label': None, 'confidence': None, 'alpha': None,
            'phase': 0.0, 'final_component': None, 'final_label': None,
            'commit_phase': None, 'commit_time': None, 'commit_elapsed': None,
            'commit_component': None, 'commit_observations': None,
            'n_observations': 0, 'n_received': 0, 'n_skipped': 0, 'n_rejected': 0,
            'plans': 0, 'switches': [], 'gaps': 0, 'end_reason': None, 'end_time': None,
            'end_elapsed': None})
        held, self._held = self._held, deque(maxlen=MAX_HELD)
        for ns, y in held:
            if ns >= self._onset_ns:
                self.current['n_received'] += 1
                self._take((ns - self._onset_ns) * 1e-9, y, defer=True)

    def gap(self) -> None:
        if self.active:
            self.current['gaps'] += 1

    def observe(self, stamp_ns: int, xyz) -> str:
        """Feed one observation; 'used', 'skipped', 'held' (no interaction yet) or a reason."""
        self.received += 1
        if self.active:
            self.current['n_received'] += 1
        y = np.asarray(xyz, dtype=float)
        if y.shape != (self.estimator.n_observed,) or not np.isfinite(y).all():
            return self._rejected_in_interaction('non_finite')
        if not self.active:
            self._hold(int(stamp_ns), y)
            return 'held'
        return self._take((int(stamp_ns) - self._onset_ns) * 1e-9, y, defer=False)

    def absorb_backlog(self, budget: float) -> int:
        """Condition on backlog observations for about ``budget`` seconds (at least one);
        returns how many were absorbed."""
        n = 0
        deadline = time.perf_counter() + budget
        while self._backlog:
            self.estimator.absorb(*self._backlog.popleft())
            n += 1
            if time.perf_counter() >= deadline:
                break
        if n:
            self._dirty = True
        return n

    def _hold(self, stamp_ns: int, y) -> None:
        h = self._held
        if h and stamp_ns <= h[-1][0]:
            h.clear()        # the stamps' clock restarted (the observer sends them in order)
        h.append((stamp_ns, y))
        while h[0][0] < stamp_ns - self._hold_ns:
            h.popleft()

    def _take(self, t: float, y, defer: bool) -> str:
        """An observation of the current interaction at t (s since onset): conditioned on now,
        or (``defer``) appended to the backlog."""
        rec = self.current
        if t < 0:
            return self._rejected_in_interaction('before_onset')
        if self._t_latest is not None and t <= self._t_latest:
            return self._rejected_in_interaction('time_backwards')
        try:
            used = self.estimator.admit(t)
            if used and not defer:
                self.estimator.absorb(t, y)
        except ValueError:
            return self._rejected_in_interaction('exception')
        self._t_latest = t
        self._y_latest = y
        self._dirty = True
        if used:
            if defer:
                self._backlog.append((t, y))
            self.used += 1
            rec['n_observations'] += 1
            return 'used'
        self.skipped += 1
        rec['n_skipped'] += 1
        return 'skipped'

    def _rejected_in_interaction(self, reason):
        if self.active:
            self.current['n_rejected'] += 1
        return self.reject(reason)

    # -- planning ---------------------------------------------------------------------
    def step(self, final: bool = False, clock_now: Optional[float] = None) -> Optional[Step]:
        """Replan (timer): None when there is no interaction or nothing new since the last.

        ``clock_now``: the present on the stamps' clock (s since onset), when known. Observations
        reach the planner some milliseconds after their stamps; the plan starts from the present
        (if it is later than the latest observation by less than MAX_LAG s), so its first point
        and its end are never already in the past when the controller receives it."""
        if not self.active or not (self._dirty or final):
            return None
        self._dirty = False
        est = self.estimator
        rec = self.current
        t_now = self.t_now
        summary = posterior_summary(est, t_now)
        K = est.n_components
        k, alpha, phase, confidence = int(summary[-1]), summary[K], summary[K + 1], summary[K + 2]
        rec.update(component=k, label=self.label(k), confidence=float(confidence),
                   alpha=float(alpha), phase=float(phase))
        t_plan = t_now
        if clock_now is not None and t_now < clock_now <= t_now + MAX_LAG:
            t_plan = clock_now
        plan = build_plan(est, t_plan, n_points=self.n_points, lookahead=self.lookahead,
                          settle_time=self.settle_time, component=k, alpha=alpha,
                          final_time=self._final_time, robot_q=self.robot_q,
                          catch_up_velocity=self.catch_up_velocity,
                          final_position=self._y_latest if final else None)
        problem = check_plan(plan)
        if problem is not None:
            self.plan_failures += 1
            return Step(summary, plan, send=False, problem=problem)
        committed_now = False
        if self.state == 'observing':
            if self._backlog or not should_commit(summary[:K], est.n_observations,
                                                  self.confidence_threshold,
                                                  self.min_observations):
                return Step(summary, plan, send=False)
            committed_now = True
            self.state = rec['state'] = 'committed'
            rec.update(commit_phase=float(phase), commit_elapsed=t_now,
                       commit_time=self._absolute(t_now), commit_component=k,
                       commit_observations=est.n_observations)
        switched_from = None
        if self._sent_component is not None and k != self._sent_component:
            switched_from = self._sent_component
            rec['switches'].append({'elapsed': t_now, 'phase': float(phase),
                                    'from': switched_from, 'to': k})
        self._sent_component = k
        if plan.final:
            self._final_time = float(plan.times[-1])
        self.plans_sent += 1
        rec['plans'] += 1
        return Step(summary, plan, send=True, committed_now=committed_now,
                    switched_from=switched_from)

    def end(self, stamp_ns: int, clock_now: Optional[float] = None) -> Optional[Step]:
        """The human stopped: the last plan (sent only if committed), then 'done'."""
        if not self.active:
            return None
        self.absorb_backlog(float('inf'))
        t_end = (int(stamp_ns) - self._onset_ns) * 1e-9
        if np.isfinite(t_end) and t_end > self.t_now:
            self._t_latest = t_end
        step = self.step(final=True, clock_now=clock_now)
        self._close('end', t_end)
        return step

    def _close(self, reason: str, t_end: Optional[float]) -> None:
        self._backlog.clear()
        rec = self.current
        rec['end_reason'] = reason
        rec['end_elapsed'] = t_end
        rec['end_time'] = None if t_end is None else self._absolute(t_end)
        rec['final_component'] = rec['component']
        rec['final_label'] = rec['label']
        rec['state'] = 'done'
        self.state = 'done'
