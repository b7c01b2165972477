"""One demonstration on a common time base (the unit every learner consumes): the observed agent
(>= 1 DOF) and the controlled agent (>= 0 DOFs; none for a single-agent set such as gestures)."""

from dataclasses import dataclass
from typing import Optional

import numpy as np


@dataclass
class Demonstration:
    """Samples of both agents over the observed agent's movement, t = 0 at its onset.

    ``observed`` (T, P) or (T,) for one DOF; ``controlled`` (T, Q), (T,) for one DOF, or None
    for none (stored as (T, 0)). ``observed`` rows that are NaN are missing (occlusion): learners
    treat them as unobserved, never as data. ``label`` is for evaluation only; no learner reads
    it unless asked to (supervised fits).
    """

    t: np.ndarray
    observed: np.ndarray
    controlled: Optional[np.ndarray] = None
    label: Optional[str] = None
    name: Optional[str] = None

    def __post_init__(self):
        self.t = np.asarray(self.t, dtype=float)
        who = f'demonstration {self.name!r}' if self.name else 'demonstration'
        if self.t.ndim != 1 or self.t.size < 2:
            raise ValueError(f'{who}: t must be a 1-D array of at least 2 times, got shape {self.t.shape}')
        if not np.all(np.isfinite(self.t)):
            raise ValueError(f'{who}: t contains NaN or Inf')
        if np.any(np.diff(self.t) <= 0):
            raise ValueError(f'{who}: t must be strictly increasing')
        # The phase is z = t / T (eq. 15): a time base that does not start at the onset would
        # shift every phase (t[0] = 1 s of a 6 s movement starts at z = 0.17).
        if self.t[0] != 0:
            raise ValueError(f'{who}: t must start at the onset, t[0] = 0, got t[0] = {self.t[0]:g} '
                             f'(pass t - t[0])')
        if self.controlled is None:
            self.controlled = np.zeros((self.t.size, 0))
        for field in ('observed', 'controlled'):
            a = np.asarray(getattr(self, field), dtype=float)
            if a.ndim == 1:
                a = a[:, None]
            setattr(self, field, a)
            if a.ndim != 2 or a.shape[0] != self.t.size:
                raise ValueError(f'{who}: {field} must have shape (len(t), dofs) = ({self.t.size}, n), '
                                 f'got {a.shape}')
            if np.any(np.isinf(a)):
                raise ValueError(f'{who}: {field} contains Inf')
            bad_rows = np.isnan(a).any(axis=1) & ~np.isnan(a).all(axis=1)
            if np.any(bad_rows):
                raise ValueError(f'{who}: {field} has partially missing rows (first at t = '
                                 f'{self.t[np.argmax(bad_rows)]:g}); a missing sample must be '
                                 f'NaN in every DOF')
        if self.observed.shape[1] < 1:
            raise ValueError(f'{who}: the observed agent needs at least one DOF')
        if np.isnan(self.observed).all():
            raise ValueError(f'{who}: observed agent has no observed sample')

    @property
    def duration(self) -> float:
        """Movement duration T in seconds; the phase is z = t / T."""
        return float(self.t[-1])

    @property
    def phase(self) -> np.ndarray:
        """z(t) = alpha t with alpha = 1 / T (eq. 15, phase in [0, 1]) at every sample."""
        return self.t / self.t[-1]

    @property
    def n_observed_dofs(self) -> int:
        return self.observed.shape[1]

    @property
    def n_controlled_dofs(self) -> int:
        return self.controlled.shape[1]


@dataclass(frozen=True)
class Layout:
    """Names and units of every DOF of both agents, in the order of the demonstrations' columns:
    what a model file records and a consumer checks its streams against.

    ``observed_units`` / ``controlled_units``: one unit string per DOF ('' = unspecified),
    or None for all unspecified.
    """

    observed: tuple
    controlled: tuple = ()
    observed_units: Optional[tuple] = None
    controlled_units: Optional[tuple] = None

    def __post_init__(self):
        for agent in ('observed', 'controlled'):
            names = tuple(str(n) for n in getattr(self, agent))
            object.__setattr__(self, agent, names)
            units = getattr(self, agent + '_units')
            units = ('',) * len(names) if units is None else tuple(str(u) for u in units)
            if len(units) == 1 and len(names) > 1:
                units = units * len(names)
            object.__setattr__(self, agent + '_units', units)
            if len(units) != len(names):
                raise ValueError(f'{len(units)} {agent} units for {len(names)} {agent} DOFs')
            if any(not n for n in names):
                raise ValueError(f'{agent} DOF names must be non-empty, got {list(names)}')
            if len(set(names)) != len(names):
                raise ValueError(f'{agent} DOF names repeat: {list(names)}')
        if not self.observed:
            raise ValueError('the observed agent needs at least one DOF name')
        if set(self.observed) & set(self.controlled):
            raise ValueError(f'names in both agents: {sorted(set(self.observed) & set(self.controlled))}')

    def check(self, demonstrations):
        """Raise ValueError unless every demonstration has this layout's numbers of DOFs."""
        for d in demonstrations:
            if (d.n_observed_dofs, d.n_controlled_dofs) != (len(self.observed), len(self.controlled)):
                who = f'demonstration {d.name!r}' if d.name else 'a demonstration'
                raise ValueError(f'{who} has {d.n_observed_dofs} observed and {d.n_controlled_dofs} '
                                 f'controlled DOFs; the layout names {len(self.observed)} '
                                 f'({", ".join(self.observed)}) and {len(self.controlled)}')
        return self
