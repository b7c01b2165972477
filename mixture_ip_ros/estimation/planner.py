"""What the estimator node decides, without ROS: one interaction at a time (idle -> observing ->
committed -> done), the online estimate of (component, phase speed), when to commit the robot,
when to replan, and the plan it is sent.

Every entry point takes the present on the caller's clock (``now_ns``, the node clock: simulated
time under use_sim_time) and says whether a replan is due; :meth:`OnlinePlanner.replan` returns
the :class:`Step` to publish. No wall clock is read, so a run on simulated time is
deterministic. Observations are stamped; time inside an interaction is seconds since its
onset on the stamps' clock.

Held samples: observations that arrive outside an interaction are held (estimation.held). At an
onset those from the dated onset on are admitted (thinned by min_interval) into a backlog that is
conditioned on ``backlog_slice`` samples per call, while live observations are conditioned on at
once: the posterior does not depend on the order (OnlineEstimator.absorb), and a live sample
never waits behind the whole backlog. The robot is committed only once the backlog is absorbed:
on all the evidence, as if every sample had been conditioned on when it came.

Commit (:func:`should_commit`): the first plan is sent once p(k* | D) >= ``confidence_threshold``
with at least ``min_observations`` observations used and, given calibrated novelty thresholds
(core.novelty), the model explains the movement; afterwards every replan is sent, also when k*
changes (the controller blends from its current state into the new plan), until the movement
stops being explained: then the robot holds and the interaction ends ('unexplained').

Stale inputs (estimation.stale_inputs) send no plan or end the interaction, each spell counted
once, its Step carrying one ``notice`` to log. The controller gets each plan within its
``horizon`` (estimation.horizon), so an arm the planner stops extending comes to rest.

Hedging (``hedge``): when only the confidence is missing, the plan with the component
marginalised too is sent (each likely interaction's expected path weighted by p(k | D)), so the
robot is under way when it commits: a handshake's hands can meet 1.5 s after its onset, too
soon for an arm starting from rest at the commit. Hedged plans are no commit: an unexplained
movement stops them with a hold, and an interaction never committed gets no final plan.

A replay stopped or restarted ends the interaction without an error (estimation.stream_clock):
an 'end' that comes when the clock has gone on past observations that came on it, or back
before them, sends no plan ('stream_stopped'), and a clock that jumps back ends the interaction
in progress ('clock_reset').
"""

from collections import deque
from dataclasses import dataclass, replace
from typing import Optional

import numpy as np

from mixture_ip_ros.core.novelty import GapWatch, NoveltyMonitor, NoveltyThresholds
from mixture_ip_ros.estimation.held import HeldSamples
from mixture_ip_ros.estimation.horizon import within_horizon
from mixture_ip_ros.estimation.planner_settings import PlannerSettings
from mixture_ip_ros.estimation.plans import (JointLimits, Plan, PosteriorSummary, build_plan,
                                             check_plan, end_summary, posterior_summary,
                                             within_limits)
from mixture_ip_ros.estimation.records import Interaction, ObservationCounts, Step, Switch
from mixture_ip_ros.estimation.schedule import ReplanSchedule
from mixture_ip_ros.estimation.stale_inputs import StaleInputs
from mixture_ip_ros.estimation.stream_clock import StreamClock

STATES = ('idle', 'observing', 'committed', 'done')
MAX_LAG = 1.0   # s; a present further ahead of the latest observation means another clock


def should_commit(component_posterior, n_observations: int, confidence_threshold: float,
                  min_observations: int) -> bool:
    """Whether the robot may start: enough evidence and a confident most probable component."""
    return (n_observations >= min_observations
            and float(np.max(component_posterior)) >= confidence_threshold)


class OnlinePlanner:
    """The estimator node's logic; see the module docstring.

    ``observe(stamp_ns, y, now_ns)`` feeds an observation and returns (result, due): result is
    'used', 'skipped', 'held' (no interaction yet) or the reason it was rejected, due whether the
    caller should :meth:`replan` now. ``onset`` and ``tick`` (the replan timer) return whether a
    replan is due; ``end`` returns the last step.
    """

    def __init__(self, estimator, settings: PlannerSettings = PlannerSettings(), *,
                 labels=None, limits: Optional[JointLimits] = None,
                 novelty: Optional[NoveltyThresholds] = None):
        if labels is not None and len(labels) != estimator.n_components:
            raise ValueError(f'{len(labels)} component labels for {estimator.n_components} '
                             'components')
        self.estimator = estimator
        self.labels = None if labels is None else list(labels)
        # JointLimits: no plan beyond them is ever sent, and plans start where the arm can
        # reach them within these (estimation.plans.build_plan)
        self.limits = limits
        # Commit only to movements the model explains (core.novelty); None: on confidence alone.
        self._novelty = None if novelty is None else NoveltyMonitor(novelty)
        self._gaps = None if novelty is None else GapWatch(novelty.min_interval)
        self.robot_state = None   # the arm's latest (joints, joint speeds), set by the node
        self._inputs = StaleInputs()
        self.state = 'idle'
        self.interactions = []
        self.counts = ObservationCounts()
        self._settings = settings
        self._held = HeldSamples(settings.hold_window)
        self._schedule = ReplanSchedule(settings.replan_period, settings.replan_on_observation)
        self._backlog = deque()   # (t, y, judged) admitted at the onset, not yet absorbed
        self._onset_ns = None
        self._t_latest = None     # latest observation time (s since onset), used or skipped
        self._y_latest = None     # and the observed position then
        self._trigger_ns = None   # its stamp
        self._dirty = False       # something new since the last replan
        self._sent_component = None
        self._final_time = None   # time of the last final (at rest) plan's point
        self._clock = StreamClock()
        self._ended = None        # the last Step of an interaction a clock reset ended

    # -- settings ---------------------------------------------------------------------
    @property
    def settings(self) -> PlannerSettings:
        return self._settings

    def update_settings(self, **changes) -> None:
        """Change settings at run time (validated; nothing changes if one is invalid). The hold
        window applies to samples held from now on."""
        new = replace(self._settings, **changes)
        if new.hold_window != self._settings.hold_window:
            self._held = HeldSamples(new.hold_window)
        self._schedule.period = new.replan_period
        self._schedule.on_observation = new.replan_on_observation
        self._settings = new

    # -- queries ----------------------------------------------------------------------
    @property
    def current(self) -> Optional[Interaction]:
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
        """Held observations of the interaction not yet absorbed."""
        return len(self._backlog)

    def label(self, k: Optional[int]):
        return None if (k is None or self.labels is None) else self.labels[k]

    # -- input ------------------------------------------------------------------------
    def reject(self, reason: str) -> str:
        self.counts.rejected[reason] += 1
        return reason

    def refuse(self, reason: str) -> str:
        """Count an observation received and rejected before ``observe`` (e.g. wrong frame)."""
        self._received()
        return self._rejected_in_interaction(reason)

    def joint_state(self, q, qd, now_ns: Optional[int] = None) -> None:
        """The arm's latest joints and joint speeds, received at ``now_ns`` (caller's clock)."""
        self.robot_state = (q, qd)
        self._inputs.joint_state(now_ns)

    def onset(self, stamp_ns: int) -> bool:
        """Start an interaction at ``stamp_ns``: the held observations from then on are
        admitted into the backlog (older ones were rest before the movement: dropped). True if
        a replan is due (the first slice emptied the backlog)."""
        if self.active:
            self._close('new_onset', None)
        self.estimator.reset()
        if self._novelty is not None:
            self._novelty.reset()
            self._gaps.reset()
        self._schedule.restart()
        self._onset_ns = int(stamp_ns)
        self._t_latest = self._y_latest = self._ended = None
        self._trigger_ns = self._onset_ns
        self._dirty = True
        self._sent_component = None
        self._final_time = None
        self._inputs.onset()
        self.state = 'observing'
        excess = len(self.interactions) + 1 - self._settings.max_records
        if excess > 0:
            del self.interactions[:excess]
        self.interactions.append(Interaction(onset_stamp_ns=self._onset_ns))
        for ns, y in self._held.take_from(self._onset_ns):
            self.current.n_received += 1
            self._take(ns, y, defer=True)
        return self._absorb_slice()

    def gap(self) -> None:
        if self.active:
            self.current.gaps += 1

    def observe(self, stamp_ns: int, y, now_ns: Optional[int] = None):
        """Feed one observation; returns (result, whether a replan is due now)."""
        self._watch_clock(now_ns)
        self._clock.observed(stamp_ns, now_ns, self._settings.max_clock_offset)
        result = self._observe(int(stamp_ns), y)
        self._inputs.heard(now_ns)
        finished_backlog = self._absorb_slice()
        if result == 'used' and self._schedule.due_on_observation(self.t_now, now_ns):
            self._schedule.observation_replanned(self.t_now)
            return result, True
        return result, finished_backlog     # on all the evidence: may commit now

    def tick(self, now_ns: Optional[int] = None) -> bool:
        """The replan timer: absorbs a slice of the backlog; True if that finished it or no
        observation replanned for a period (a replan is due)."""
        self._watch_clock(now_ns)
        silent = self._silence(now_ns) is not None
        return (self._absorb_slice() or self._schedule.due_on_timer(now_ns) or silent
                or self._ended is not None)

    def end(self, stamp_ns: int, now_ns: Optional[int] = None) -> Optional[Step]:
        """The human stopped (``stamp_ns``, dated back to when the hand came to rest): the last
        plan, its component chosen with the end time known (:func:`end_summary`) and sent only
        if committed, then 'done'. None when there is nothing to send: no interaction, or the
        stream stopped (estimation.stream_clock: a plan would start in the past; no error)."""
        self._watch_clock(now_ns)
        if not self.active:
            return self._take_ended()
        self._absorb_slice(len(self._backlog))
        t_end = (int(stamp_ns) - self._onset_ns) * 1e-9
        if np.isfinite(t_end) and t_end > self.t_now:
            self._t_latest = t_end
        # The end is dated back to when the hand came to rest, at least the observer's
        # end_hold before it is confirmed: the clock check judges the latest observation.
        self._fresh_ns = max(int(stamp_ns), self._trigger_ns)
        if self._clock.stream_stopped(self._fresh_ns, now_ns, self._settings.max_clock_offset):
            self._close('stream_stopped', t_end if np.isfinite(t_end) else None)
            return None
        self._trigger_ns = int(stamp_ns)     # the end is dated back: often before the latest
        step = self.replan(now_ns, final=True, t_end=t_end)
        self._close('end', t_end)
        return step

    def deactivate(self) -> None:
        """The node stops commanding: the interaction in progress ends here."""
        if self.active:
            self._close('deactivated', None)

    def _received(self):
        self.counts.received += 1
        if self.active:
            self.current.n_received += 1

    def _observe(self, stamp_ns: int, y) -> str:
        self._received()
        y = np.asarray(y, dtype=float)
        if y.shape != (self.estimator.n_observed,) or not np.isfinite(y).all():
            return self._rejected_in_interaction('non_finite')
        if not self.active:
            self._held.add(stamp_ns, y)
            return 'held'
        return self._take(stamp_ns, y, defer=False)

    def _absorb_slice(self, n: Optional[int] = None) -> bool:
        """Condition on the next ``n`` (default backlog_slice) backlog observations; True if
        that emptied the backlog."""
        if not self._backlog:
            return False
        for _ in range(min(len(self._backlog), n or self._settings.backlog_slice)):
            t, y, judged = self._backlog.popleft()
            self.estimator.absorb(t, y)
            self._record_evidence(judged)
        self._dirty = True
        if self._backlog:
            return False
        self.estimator.prune()       # all the evidence is in: the order no longer matters
        return True

    def _take(self, stamp_ns: int, y, defer: bool) -> str:
        """An observation of the current interaction: conditioned on now, or (``defer``)
        appended to the backlog."""
        rec = self.current
        t = (stamp_ns - self._onset_ns) * 1e-9
        if t < 0:
            return self._rejected_in_interaction('before_onset')
        if self._t_latest is not None and t <= self._t_latest:
            return self._rejected_in_interaction('time_backwards')
        try:
            used = self.estimator.admit(t)
            # in time order, as admitted: whether it follows a gap (core.novelty). Held samples
            # absorbed after live ones keep their flags; their evidence is that of the order
            # absorbed (the whole is the same), as the statistics during a backlog always were.
            judged = not (used and self._gaps is not None and self._gaps.after_gap(t))
            if used and not defer:
                self.estimator.absorb(t, y)
                self._record_evidence(judged)
                if not self._backlog:
                    self.estimator.prune()
        except ValueError:
            return self._rejected_in_interaction('exception')
        self._t_latest = t
        self._y_latest = y
        self._trigger_ns = stamp_ns
        self._dirty = True
        if used:
            if defer:
                self._backlog.append((t, y, judged))
            self.counts.used += 1
            rec.n_observations += 1
            return 'used'
        self.counts.skipped += 1
        rec.n_skipped += 1
        return 'skipped'

    def _record_evidence(self, judged: bool):
        if self._novelty is not None:
            self._novelty.record(self.estimator.n_observations, self.estimator.log_marginal(),
                                 judged)

    def _rejected_in_interaction(self, reason):
        if self.active:
            self.current.n_rejected += 1
        return self.reject(reason)

    # -- planning ---------------------------------------------------------------------
    def replan(self, now_ns: Optional[int] = None, final: bool = False,
               t_end: Optional[float] = None) -> Optional[Step]:
        """Update the summary and the plan: None when there is no interaction or nothing new
        since the last replan.

        ``now_ns``: the present on the stamps' clock, when known. Observations reach the planner
        some milliseconds after their stamps; the plan starts from the present (if it is later
        than the latest observation by less than MAX_LAG s), so its first point and its end are
        never already in the past when the controller receives it. ``t_end``: the end of the
        movement (s since onset), known with the observer's 'end': the component is then chosen
        with the phase known (:func:`end_summary`)."""
        if not self.active:
            return self._take_ended()
        silence = None if final else self._silence(now_ns)
        if silence is not None:
            return self._end_silent(silence)
        if not (self._dirty or final):
            return None
        self._dirty = False
        self._schedule.replanned(now_ns)
        s = self._settings
        est = self.estimator
        rec = self.current
        t_now = self.t_now
        ended = t_end is not None and np.isfinite(t_end) and t_end > 0 and est.n_observations
        summary = end_summary(est, t_end) if ended else posterior_summary(est, t_now)
        k = summary.component
        rec.component, rec.label, rec.confidence = k, self.label(k), summary.confidence
        rec.alpha, rec.phase = summary.alpha, summary.phase
        t_plan = t_now
        if now_ns is not None:
            clock_now = (int(now_ns) - self._onset_ns) * 1e-9
            if t_now < clock_now <= t_now + MAX_LAG:
                t_plan = clock_now
        unexplained = None if self._novelty is None else self._novelty.unexplained()
        if unexplained is not None:
            rec.unexplained = unexplained
        # Before the commit: the robot moves on the hedged plan once only confidence is missing.
        waiting = self.state == 'observing' and (
            self._backlog or unexplained is not None
            or not should_commit(summary.probabilities, est.n_observations,
                                 s.confidence_threshold, s.min_observations))
        hedged = (waiting and s.hedge and not ended and not self._backlog
                  and unexplained is None and est.n_observations >= s.min_observations)
        plan = build_plan(est, t_plan, n_points=s.n_points, lookahead=s.lookahead,
                          settle_time=s.settle_time, component=k,
                          alpha=summary.alpha if ended else None,
                          final_time=self._final_time, robot=self.robot_state,
                          limits=self.limits,
                          final_position=self._y_latest if final and not hedged else None,
                          hedged=hedged, margin=s.delivery_margin)
        trigger = self._trigger_ns
        sendable, problem = self._checked(plan, t_plan, self._fresh_ns if final else trigger,
                                          now_ns)
        if problem is not None:
            return Step(summary, plan, send=False, trigger_ns=trigger, problem=problem)
        plan = sendable
        if unexplained is not None and (self.state == 'committed' or rec.hedged_plans):
            # The robot moves, and what the person does now is no movement the model knows: it
            # stops where it is; this interaction gets no more plans.
            self.counts.holds += 1
            self._close('unexplained', t_now)
            return Step(summary, plan, send=False, trigger_ns=trigger, hold=True,
                        unexplained=unexplained)
        if waiting and not hedged:
            return Step(summary, plan, send=False, trigger_ns=trigger, unexplained=unexplained)
        stale, new = self._inputs.stale_state(now_ns, s.max_joint_state_age)
        if stale is not None:
            self.counts.stale_joint_states += new
            return Step(summary, plan, send=False, trigger_ns=trigger, withheld=stale,
                        notice=f'{stale}: no plan is sent until it comes' if new else None)
        committed_now = False
        if not waiting and self.state == 'observing':
            committed_now = True
            self.state = rec.state = 'committed'
            rec.commit_phase, rec.commit_elapsed = summary.phase, t_now
            rec.commit_component, rec.commit_observations = k, est.n_observations
        if hedged:      # no component's plan: a switch is one committed plan to the next
            rec.hedged_plans += 1
        switched_from = None
        if self._sent_component is not None and k != self._sent_component:
            switched_from = self._sent_component
            rec.switches.append(Switch(t_now, summary.phase, switched_from, k))
        if not hedged:
            self._sent_component = k
        if plan.final:
            self._final_time = float(plan.times[-1])
        self.counts.plans_sent += 1
        rec.plans += 1
        return Step(summary, plan, send=True, trigger_ns=trigger, committed_now=committed_now,
                    switched_from=switched_from, command=self._command(plan, t_plan))

    def _command(self, plan: Plan, t_plan: float) -> Plan:
        """What the controller gets: the plan within its horizon (0: the whole plan)."""
        if self._settings.horizon <= 0:
            return plan
        command, whole = within_horizon(plan, t_plan + self._settings.horizon, self.limits)
        self.counts.plans_uncut += whole
        return command

    def _silence(self, now_ns) -> Optional[str]:
        return (self._inputs.silence(now_ns, self._settings.max_wrist_silence)
                if self.active else None)

    def _end_silent(self, why: str) -> Step:
        """End the interaction whose wrist stream is gone: no plan; a robot that moved holds."""
        moved = self.state == 'committed' or self.current.hedged_plans > 0
        self.counts.silent_ends += 1
        summary = posterior_summary(self.estimator, self.t_now)
        self._close('wrist_silent', self.t_now)
        return Step(summary, None, send=False, trigger_ns=self._trigger_ns, hold=moved,
                    notice=f'{why}: the interaction ends'
                    + (', the robot holds' if moved else ''))

    def _checked(self, plan, t_plan, fresh_ns, now_ns):
        """(the plan to send, None) or (None, why not), each refusal counted by kind. A plan
        that only needs slowing down to respect the joint limits is slowed down; one whose
        freshest evidence (``fresh_ns``) is stamped too far from the clock is not sent."""
        kind, why = 'invalid', check_plan(plan)
        if why is None and self.limits is not None:
            kind = 'beyond_limits'
            scaled, why, scale = within_limits(plan, self.limits, t_plan)
            if why is None and scale > 1.0:
                self.counts.plans_time_scaled += 1
                plan = scaled
        offset = self._settings.max_clock_offset
        # A clock at 0 is simulated time before its first /clock: no time to judge against.
        if why is None and offset > 0 and now_ns and \
                abs(fresh_ns - int(now_ns)) > round(offset * 1e9):
            kind = 'off_clock'
            why = (f'the observations are stamped {(fresh_ns - int(now_ns)) * 1e-9:+.3g} s '
                   "from this node's clock")
        if why is None:
            return plan, None
        self.counts.plan_refusals[kind] += 1
        return None, why

    def _watch_clock(self, now_ns: Optional[int]) -> None:
        """A clock jumping back by more than max_clock_offset (a simulated clock restarted)
        ends the interaction in progress: what comes next is stamped on the new time. The
        next :meth:`replan` (or :meth:`end`) returns its last Step: no plan; a robot that moved
        holds."""
        if self._clock.tick(now_ns, self._settings.max_clock_offset) and self.active:
            moved = self.state == 'committed' or self.current.hedged_plans > 0
            self.counts.clock_resets += 1
            summary = posterior_summary(self.estimator, self.t_now)
            self._close('clock_reset', None)
            self._ended = Step(summary, None, send=False, trigger_ns=self._trigger_ns,
                               hold=moved, notice='the clock jumped back: the interaction ends'
                               + (', the robot holds' if moved else ''))

    def _take_ended(self) -> Optional[Step]:
        step, self._ended = self._ended, None
        return step

    def _close(self, reason: str, t_end: Optional[float]) -> None:
        self._backlog.clear()
        rec = self.current
        rec.end_reason = reason
        rec.end_elapsed = t_end
        rec.final_component = rec.component
        rec.final_label = rec.label
        rec.state = 'done'
        self.state = 'done'
