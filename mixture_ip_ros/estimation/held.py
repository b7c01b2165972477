"""Observations held outside an interaction, for a back-dated onset.

The observer forwards every sample as it comes and confirms an onset some 0.1-1 s after the hand
left rest, dating it back. The samples from the dated onset on are part of the movement, so the
estimator keeps the most recent ``window`` seconds (of their stamps) until an onset takes them.
"""

from collections import deque

MAX_HELD = 20_000   # held observations at most (2.5 s at 8 kHz), whatever their stamps


class HeldSamples:

    def __init__(self, window: float, max_samples: int = MAX_HELD):
        if not (window > 0 and window != float('inf')):
            raise ValueError(f'hold_window must be > 0 s, got {window}')
        self._window_ns = round(float(window) * 1e9)
        self._samples = deque(maxlen=int(max_samples))   # (stamp ns, y)

    def __len__(self) -> int:
        return len(self._samples)

    def add(self, stamp_ns: int, y) -> None:
        s = self._samples
        if s and stamp_ns <= s[-1][0]:
            s.clear()        # the stamps' clock restarted (the observer sends them in order)
        s.append((stamp_ns, y))
        while s[0][0] < stamp_ns - self._window_ns:
            s.popleft()

    def take_from(self, onset_ns: int) -> list:
        """The held (stamp ns, y) at or after ``onset_ns``, oldest first; forgets them all (the
        older ones were rest before the movement)."""
        out = [(ns, y) for ns, y in self._samples if ns >= onset_ns]
        self._samples.clear()
        return out
