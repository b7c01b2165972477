"""Checks of a mixture's inputs: the demonstrations it is fitted to, a supervised fit's labels
and an observation it is conditioned on. Each raises ValueError naming what is wrong."""

import numpy as np

from .demonstration import Demonstration


def label_indices(labels, n, n_components):
    """(sorted distinct labels, index of each demonstration's label (n,)) for a supervised fit
    of ``n`` demonstrations with one component per label."""
    labels = np.asarray(labels)
    if labels.shape != (n,):
        raise ValueError(f'labels must have one entry per demonstration ({n}), got shape '
                         f'{labels.shape}')
    classes, index = np.unique(labels, return_inverse=True)
    if len(classes) != n_components:
        raise ValueError(f'a supervised fit has one component per class: n_components='
                         f'{n_components} but the labels name {len(classes)} classes')
    return [c.item() if hasattr(c, 'item') else c for c in classes], index


def checked_demonstrations(demonstrations) -> list:
    """``demonstrations`` as a list: at least one, each a Demonstration, all with the same
    numbers of observed and controlled DOFs."""
    demos = list(demonstrations)
    if not all(isinstance(d, Demonstration) for d in demos):
        raise ValueError('demonstrations must be a list of Demonstration objects')
    if not demos:
        raise ValueError('no demonstrations given')
    shapes = {(d.n_observed_dofs, d.n_controlled_dofs) for d in demos}
    if len(shapes) != 1:
        raise ValueError(f'demonstrations disagree on (observed, controlled) DOFs: '
                         f'{sorted(shapes)}')
    return demos


def checked_observation(z, Y, n_observed):
    """(phases z (m,), observed agent Y (m, P)) as float arrays: m >= 1 samples, phases
    finite, values NaN (missing) or finite, not all missing."""
    z = np.atleast_1d(np.asarray(z, dtype=float))
    Y = np.asarray(Y, dtype=float)
    if Y.ndim == 1:
        Y = Y[None, :]
    if Y.shape != (z.shape[0], n_observed):
        raise ValueError(f'observation must have shape (len(z), {n_observed}) = '
                         f'({z.shape[0]}, {n_observed}), got {Y.shape}')
    if z.size == 0 or np.isnan(Y).all():
        raise ValueError('empty observation: nothing to condition on')
    if not np.all(np.isfinite(z)):
        raise ValueError('observation phases contain NaN or Inf')
    if np.any(np.isinf(Y)):
        raise ValueError('observation contains Inf')
    return z, Y
