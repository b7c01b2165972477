"""A person who changes their mind mid-movement (the thesis's chapters 4 and 5): one recording's
beginning, another's rest, joined smoothly. Used to check that the online belief follows the
change (core.switching) and to calibrate how readily it does.

:func:`splice` takes the first share ``at`` of recording A and the rest of recording B from the
same share of B's own movement on: the person turns to B's path from where A left the hand,
and keeps B's pace. Both agents are joined the same way: the gap between A's last sample and
B's first is added to B's samples and fades out over ``blend`` seconds (a minimum-jerk ramp,
so that position, velocity and acceleration stay continuous where it ends). Where the people
in A's last sample and in B's sample at the same share stand apart is not the point: B's path is
reached where the fade ends. Where A's last sample or B's first has an agent missing (NaN),
that agent is not offset: its path goes from A's to B's as recorded.
"""

from typing import NamedTuple

import numpy as np

from .demonstration import Demonstration

# How long a person takes to turn from one path to another: a reach's correction takes some
# tenths of a second.
BLEND = 0.3
# Where a change of mind is spliced, as a share of the first movement: neither so early that
# the first interaction was hardly begun nor so late that the second has little left.
SHARES = (0.3, 0.4, 0.5, 0.6)


class Splice(NamedTuple):
    """A spliced recording and where it changes: ``demo`` (labelled as B), ``t_change`` (s
    since onset: the first sample of B's rest), ``first`` and ``second`` (the labels of A and
    B)."""

    demo: Demonstration
    t_change: float
    first: object
    second: object


def _fade(s):
    """1 at s <= 0 to 0 at s >= 1, minimum-jerk: zero slope and curvature at both ends."""
    s = np.clip(s, 0.0, 1.0)
    return 1.0 - s ** 3 * (10.0 - 15.0 * s + 6.0 * s ** 2)


def splice(a: Demonstration, b: Demonstration, at: float, blend: float = BLEND) -> Splice:
    """A's first ``at`` (0 < at < 1) of its movement, then B's movement from ``at`` of its own
    duration on, shifted to start one of B's sample periods after A's last sample, offset so
    that it starts at A's last positions and fading into B's own path over ``blend`` s.
    Raises ValueError for a share outside (0, 1), recordings of different layouts, or a share
    that leaves either part without a sample."""
    if not 0.0 < at < 1.0:
        raise ValueError(f'the share of the first movement must be in (0, 1), got {at!r}')
    if (a.n_observed_dofs, a.n_controlled_dofs) != (b.n_observed_dofs, b.n_controlled_dofs):
        raise ValueError('the two recordings have different layouts')
    if not blend >= 0.0:
        raise ValueError(f'the blend must be >= 0 s, got {blend!r}')
    head = np.flatnonzero(a.t <= a.t[0] + at * a.duration + 1e-9)
    tail = np.flatnonzero(b.t >= b.t[0] + at * b.duration - 1e-9)
    if head.size < 2 or tail.size < 2:
        raise ValueError(f'a share of {at} leaves too few samples of one recording')
    period = float(np.median(np.diff(b.t)))
    t_change = float(a.t[head[-1]] - a.t[0]) + period
    t_tail = b.t[tail] - b.t[tail[0]] + t_change
    fade = _fade((t_tail - t_change) / blend) if blend > 0 else (t_tail == t_change) * 1.0

    def joined(x, y):
        gap = x[head[-1]] - y[tail[0]]
        gap = np.where(np.isnan(gap), 0.0, gap)
        return np.vstack([x[head], y[tail] + fade[:, None] * gap])

    demo = Demonstration(np.r_[a.t[head] - a.t[0], t_tail], joined(a.observed, b.observed),
                         joined(a.controlled, b.controlled), label=b.label,
                         name=f'{a.name}>{b.name}@{at:g}')
    return Splice(demo, t_change, a.label, b.label)
