"""What the estimator keeps about its work: what each replan produced, one record per
interaction, counts of the observations it took or refused, and latency statistics
(dataclasses, for diagnostics, logs and reports)."""

from dataclasses import dataclass, field
from typing import Optional

from mixture_ip_ros.estimation.plans import Plan, PosteriorSummary

# Why the estimator did not use an observation ('skipped', within min_interval of the last one
# used, is not a rejection).
OBSERVATION_REJECT_REASONS = ('wrong_frame', 'non_finite', 'before_onset', 'time_backwards',
                              'exception', 'bad_joint_state')
# Why a plan was not sent: not a valid trajectory (non-finite, times not increasing, not at rest
# at the end), beyond the robot's position limits or too fast for it even slowed down, or
# resting on observations stamped on another clock.
PLAN_REFUSALS = ('invalid', 'beyond_limits', 'off_clock')


def _absolute(onset_ns: int, elapsed: Optional[float]) -> Optional[float]:
    return None if elapsed is None else (onset_ns + round(elapsed * 1e9)) * 1e-9


@dataclass
class Step:
    """What one replan produced: always the posterior summary and the plan (its hypothesis is
    the one of the predicted path); ``send`` says whether the joint trajectory goes out;
    ``problem`` why the plan may not be published; ``unexplained`` why the movement is none the
    model knows (no commit; once the robot moves, ``hold``: it must stop where it is).
    ``trigger_ns``: the stamp of the latest evidence the plan rests on (the observation or the
    'end' event that brought it). ``withheld``: why a plan that would have gone out did not (the
    arm's state is stale); ``notice``: a line to log, once per spell of what it reports."""

    summary: PosteriorSummary
    plan: Optional[Plan]
    send: bool
    trigger_ns: int
    committed_now: bool = False
    switched_from: Optional[int] = None
    problem: Optional[str] = None
    unexplained: Optional[str] = None   # why the model does not explain the movement
    hold: bool = False                  # stop the robot where it is (unexplained, or silent)
    withheld: Optional[str] = None
    notice: Optional[str] = None
    command: Optional[Plan] = None      # what the controller gets: the plan within its horizon


@dataclass
class Switch:
    """The MAP component changed after the robot was committed."""

    elapsed: float          # s since the onset
    phase: float
    from_component: int
    to_component: int


@dataclass
class Interaction:
    """One interaction, from its onset to its end.

    Absolute times (``*_time``) are seconds on the observations' clock, ``*_elapsed`` seconds
    since the onset. ``component``, ``label``, ``confidence``, ``alpha`` and ``phase`` are those
    of the latest replan; ``final_*`` are set when the interaction closes. ``commit_phase`` is
    the phase at the commit, the first plan sent on a confident component, i.e. the fraction of
    the human movement seen (None if the robot never committed); ``hedged_plans`` counts the
    plans sent before it (PlannerSettings.hedge). ``end_reason`` is 'end' (the observer's
    event), 'new_onset' (another interaction started first), 'deactivated' (the node stopped),
    'unexplained' (the movement stopped being one the model knows after the robot started
    moving: it holds), 'stream_stopped' (the observer's 'end' came long after the stream
    stopped: no last plan) or 'clock_reset' (the clock jumped back); None while it runs. Also
    'wrist_silent': no wrist observation for too long (the observer is gone).
    """

    onset_stamp_ns: int
    state: str = 'observing'
    component: Optional[int] = None
    label: Optional[str] = None
    confidence: Optional[float] = None
    alpha: Optional[float] = None
    phase: float = 0.0
    final_component: Optional[int] = None
    final_label: Optional[str] = None
    commit_phase: Optional[float] = None
    commit_elapsed: Optional[float] = None
    commit_component: Optional[int] = None
    commit_observations: Optional[int] = None
    n_observations: int = 0
    n_received: int = 0
    n_skipped: int = 0
    n_rejected: int = 0
    plans: int = 0
    hedged_plans: int = 0
    switches: list = field(default_factory=list)
    gaps: int = 0
    end_reason: Optional[str] = None
    end_elapsed: Optional[float] = None
    unexplained: Optional[str] = None   # the latest reason the model did not explain it

    @property
    def onset_time(self) -> float:
        return self.onset_stamp_ns * 1e-9

    @property
    def commit_time(self) -> Optional[float]:
        return _absolute(self.onset_stamp_ns, self.commit_elapsed)

    @property
    def end_time(self) -> Optional[float]:
        return _absolute(self.onset_stamp_ns, self.end_elapsed)

    @property
    def committed(self) -> bool:
        return self.commit_phase is not None


@dataclass
class ObservationCounts:
    """Totals since the start, over every interaction."""

    received: int = 0
    used: int = 0
    skipped: int = 0
    rejected: dict = field(default_factory=lambda: dict.fromkeys(OBSERVATION_REJECT_REASONS, 0))
    plans_sent: int = 0
    plan_refusals: dict = field(default_factory=lambda: dict.fromkeys(PLAN_REFUSALS, 0))
    plans_time_scaled: int = 0          # slowed down to respect the joint limits, then sent
    holds: int = 0                      # committed interactions stopped: unexplained movement
    stale_joint_states: int = 0         # spells of plans not sent: the arm's state too old
    silent_ends: int = 0                # interactions ended: no wrist observation for too long
    clock_resets: int = 0               # interactions ended: the clock jumped back
    plans_uncut: int = 0                # sent whole: a stop at their horizon left the limits

    @property
    def n_rejected(self) -> int:
        return sum(self.rejected.values())

    @property
    def plan_failures(self) -> int:
        return sum(self.plan_refusals.values())


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
