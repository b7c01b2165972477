"""When the estimator replans: on the time of the caller's clock (the node clock: simulated time
under use_sim_time), never the wall clock, so a run on simulated time is deterministic.

An observation that is used replans at once when at least ``period`` has passed since the last
observation-triggered replan on the observations' stamps (the rate of the plans follows the
person's movement) and since the last replan of any kind on the caller's clock (a stream
replayed faster than that clock is not replanned faster than it). A timer, called every
``period``, covers pauses: it replans when nothing did for a period. So there is at most one
replan per period of the clock, whatever triggered it.
"""

from typing import Optional


class ReplanSchedule:

    def __init__(self, period: float, on_observation: bool = True):
        self.period = period
        self.on_observation = bool(on_observation)
        self._next_stamp = None         # s since onset: the next observation-triggered replan
        self._last_clock_ns = None      # clock of the last replan

    @property
    def period(self) -> float:
        return self._period

    @period.setter
    def period(self, seconds: float) -> None:
        if not seconds > 0 or seconds == float('inf'):
            raise ValueError(f'replan period must be a positive number of seconds, got {seconds}')
        self._period = float(seconds)
        self._period_ns = round(self._period * 1e9)

    def restart(self) -> None:
        """A new interaction: its stamps start again at zero."""
        self._next_stamp = None

    def due_on_observation(self, t: float, now_ns: Optional[int]) -> bool:
        """Whether an observation used at ``t`` (s since onset) replans; ``now_ns``: the clock."""
        if not self.on_observation:
            return False
        if self._next_stamp is not None and t < self._next_stamp - 1e-9:
            return False
        return self._clock_due(now_ns)

    def observation_replanned(self, t: float) -> None:
        """An observation at ``t`` (s since onset) triggered a replan."""
        self._next_stamp = t + self._period

    def replanned(self, now_ns: Optional[int]) -> None:
        """A replan of any kind happened at ``now_ns``."""
        if now_ns is not None:
            self._last_clock_ns = int(now_ns)

    def due_on_timer(self, now_ns: Optional[int]) -> bool:
        """Whether the timer's call at ``now_ns`` replans (nothing did for a period)."""
        return self._clock_due(now_ns)

    def _clock_due(self, now_ns):
        if now_ns is None or self._last_clock_ns is None:
            return True
        elapsed = int(now_ns) - self._last_clock_ns
        return elapsed >= self._period_ns or elapsed < 0    # < 0: the clock was reset
