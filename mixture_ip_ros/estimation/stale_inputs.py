"""When the estimator's inputs have gone stale, on the caller's clock (ROS-free).

Two rules of the planner (estimation.planner), each with a limit in seconds (0 = no check):

- the arm's state: older than ``max_joint_state_age``, no plan is sent and the robot is not
  committed, since a plan starts from the arm's present state. So too for a state received
  more than that after the present: the clock was reset (a restarted sim restarts the simulated
  clock) and the state is another arm's, until the new one's comes. An arm never heard from is
  planned for without its state, as before one comes;
- the wrist stream: an interaction that hears no observation for longer than
  ``max_wrist_silence`` has lost its observer (set above the observer's max_gap, after which
  the observer itself ends an interaction whose stream went silent). It ends ('wrist_silent')
  without a plan, and a robot that moved holds.

Each spell of a stale arm state is told once: :meth:`StaleInputs.stale_state` says whether it
is new. A clock that reads zero is not running yet (simulated time before the first /clock):
nothing is judged on it.
"""

from typing import Optional, Tuple


class StaleInputs:
    """When the arm's state and the wrist observations came (ns of the caller's clock)."""

    def __init__(self):
        self._state_ns = None   # the arm's latest state came
        self._told = False      # the present spell of a stale state was told
        self._reset = False     # the clock was reset since it came: stale until the next
        self._heard_ns = None   # the interaction's latest wrist observation came

    def joint_state(self, now_ns: Optional[int]) -> None:
        self._state_ns = int(now_ns) if now_ns else None
        self._told = self._reset = False

    def heard(self, now_ns: Optional[int]) -> None:
        """A wrist observation came (``now_ns`` None or 0: the time is not known)."""
        if now_ns:
            self._heard_ns = int(now_ns)

    def onset(self) -> None:
        """A new interaction: its silence is counted from the first call after it."""
        self._heard_ns = None

    def stale_state(self, now_ns: Optional[int], limit: float) -> Tuple[Optional[str], bool]:
        """(why the arm's state is too old at ``now_ns``, or None; whether that spell is new)."""
        if limit <= 0 or not now_ns or self._state_ns is None:
            return None, False
        age = (int(now_ns) - self._state_ns) * 1e-9
        if -limit <= age <= limit and not self._reset:
            return None, False
        new, self._told = not self._told, True
        # received after the present: on a clock since reset (a sim restarted), which the
        # new clock may come back to without a new state
        self._reset = self._reset or age < -limit
        if self._reset:
            return ('the latest joint state came on the clock before it was reset: the arm '
                    'is re-read', new)
        return f'no joint state for {age:.3g} s (max_joint_state_age {limit:g} s)', new

    def silence(self, now_ns: Optional[int], limit: float) -> Optional[str]:
        """Why the interaction in progress has lost its wrist stream at ``now_ns``, or None."""
        if limit <= 0 or not now_ns:
            return None
        if self._heard_ns is None:
            self._heard_ns = int(now_ns)
        quiet = (int(now_ns) - self._heard_ns) * 1e-9
        if quiet <= limit:
            return None
        return f'no wrist observation for {quiet:.3g} s (max_wrist_silence {limit:g} s)'
