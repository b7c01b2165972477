"""One human-robot demonstration on a common time base (the unit every learner consumes)."""

from dataclasses import dataclass
from typing import Optional

import numpy as np


@dataclass
class Demonstration:
    """Samples of both agents over the human's movement, t = 0 at onset.

    ``observed`` rows that are NaN are missing (occlusion): learners treat them as unobserved,
    never as data. ``label`` is for evaluation only; no learner reads it.
    """

    t: np.ndarray
    observed: np.ndarray
    controlled: np.ndarray
    label: Optional[str] = None
    name: Optional[str] = None

    def __post_init__(self):
        self.t = np.asarray(self.t, dtype=float)
        self.observed = np.asarray(self.observed, dtype=float)
        self.controlled = np.asarray(self.controlled, dtype=float)
        who = f'demonstration {self.name!r}' if self.name else 'demonstration'
        if self.t.ndim != 1 or self.t.size < 2:
            raise ValueError(f'{who}: t must be a 1-D array of at least 2 times, got shape {self.t.shape}')
        if not np.all(np.isfinite(self.t)):
            raise ValueError(f'{who}: t contains NaN or Inf')
        if np.any(np.diff(self.t) <= 0):
            raise ValueError(f'{who}: t must be strictly increasing')
        if self.t[0] < 0:
            raise ValueError(f'{who}: t must start at or after the onset (t[0] >= 0), got {self.t[0]}')
        for field in ('observed', 'controlled'):
            a = getattr(self, field)
            if a.ndim != 2 or a.shape[0] != self.t.size:
                raise ValueError(f'{who}: {field} must have shape (len(t), dofs) = ({self.t.size}, n), '
                                 f'got {a.shape}')
            if np.any(np.isinf(a)):
                raise ValueError(f'{who}: {field} contains Inf')
            bad_rows = np.isnan(a).any(axis=1) & ~np.isnan(a).all(axis=1)
            if np.any(bad_rows):
                raise ValueError(f'{who}: {field} has partially missing rows; a missing sample must be '
                                 f'NaN in every DOF')
        if np.isnan(self.observed).all():
            raise ValueError(f'{who}: observed agent has no observed sample')

    @property
    def duration(self) -> float:
        """Movement duration T in seconds; the phase is z = t / T."""
        return float(self.t[-1])

    @property
    def n_observed_dofs(self) -> int:
        return self.observed.shape[1]

    @property
    def n_controlled_dofs(self) -> int:
        return self.controlled.shape[1]
