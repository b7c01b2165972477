"""The caller's clock as the estimator sees it beside the observations' stamps: whether the
observations come on it, and whether it jumped back.

A replay stopped or restarted is no error: when the stream stops mid-interaction the observer's
'end' (after max_gap of silence) arrives seconds after the last observation, and when a
simulated clock restarts with a replay the clock jumps back before the stamps. Another clock
altogether (stamps never near the caller's) is an error: plans resting on it are refused.
A clock reading None or 0 (simulated time before its first /clock) is not known.
"""

from typing import Optional


class StreamClock:

    def __init__(self):
        self.now_ns = None            # the clock at the latest call that gave it
        self.arrived_on_clock = None  # whether the latest observation came on it (None: unknown)

    @staticmethod
    def within(stamp_ns: int, now_ns: int, offset: float) -> bool:
        """Whether ``stamp_ns`` is within ``offset`` s of ``now_ns`` (always, for offset 0: no
        check)."""
        return offset <= 0 or abs(int(stamp_ns) - int(now_ns)) <= round(offset * 1e9)

    def tick(self, now_ns: Optional[int], offset: float) -> bool:
        """Note the clock; True if it jumped back by more than ``offset`` s (> 0) since the last
        reading (a simulated clock restarted)."""
        if not now_ns:
            return False
        last, self.now_ns = self.now_ns, int(now_ns)
        return offset > 0 and last is not None and self.now_ns < last - round(offset * 1e9)

    def observed(self, stamp_ns: int, now_ns: Optional[int], offset: float) -> None:
        """An observation stamped ``stamp_ns`` arrived at ``now_ns``."""
        if now_ns:
            self.arrived_on_clock = self.within(stamp_ns, now_ns, offset)

    def stream_stopped(self, fresh_ns: int, now_ns: Optional[int], offset: float) -> bool:
        """Whether evidence stamped ``fresh_ns``, off the clock at ``now_ns``, is so because the
        stream stopped (its observations came on the clock, which has since gone on past them,
        or back before them) rather than because it is on another clock."""
        return (bool(now_ns) and self.arrived_on_clock is True
                and not self.within(fresh_ns, now_ns, offset))
