"""Checks of a mixture's inputs: the demonstrations it is fitted to, the labels of a fit in which
all or some of them are named, and an observation it is conditioned on. Each raises ValueError
naming what is wrong."""

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


def named_indices(labels, n, n_components):
    """(sorted distinct names, index of each demonstration's name or -1 where it has none
    (n,)) for a fit in which some demonstrations are named and the rest (None) are not, with
    ``n_components`` >= the number of names."""
    labels = list(labels) if labels is not None else None
    if labels is None or len(labels) != n:
        raise ValueError(f'labels must have one entry per demonstration ({n}), got '
                         f'{None if labels is None else len(labels)}')
    named = [i for i, lbl in enumerate(labels) if lbl is not None]
    classes, index = np.unique(np.asarray([labels[i] for i in named]), return_inverse=True)
    if len(classes) > n_components:
        raise ValueError(f'the labels name {len(classes)} classes, more than n_components='
                         f'{n_components}: each name is a component of its own')
    out = np.full(n, -1)
    out[named] = index.ravel()
    return [c.item() if hasattr(c, 'item') else c for c in classes], out


def labelling(labels) -> str:
    """How ``labels`` (one entry per demonstration, None for one without a name) name the
    demonstrations: 'none' (no labels, or every entry None), 'all' or 'some'."""
    if labels is None:
        return 'none'
    missing = sum(lbl is None for lbl in labels)
    return 'none' if missing == len(labels) else 'all' if missing == 0 else 'some'


def labels_fit(labels, n_components) -> bool:
    """Whether a fit of ``n_components`` can take ``labels`` (None: no labels): every
    demonstration named, one component per name; some named, at most one name per component;
    none named (or no labels), any."""
    named = labelling(labels)
    names = len({lbl for lbl in labels if lbl is not None}) if named != 'none' else 0
    return (named == 'none' or (named == 'all' and names == n_components)
            or (named == 'some' and names <= n_components))


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


def checked_switch_rate(rate) -> float:
    """A switch rate (changes of mind per second, core.switching) as a float: a number >= 0;
    ValueError otherwise."""
    if (isinstance(rate, bool) or not isinstance(rate, (int, float, np.integer, np.floating))
            or not (np.isfinite(rate) and rate >= 0.0)):
        raise ValueError(f'switch_rate must be a number of switches per second >= 0, '
                         f'got {rate!r}')
    return float(rate)


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
