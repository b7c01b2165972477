"""Cross-validation of the Mixture of Interaction ProMPs: which demonstrations each fold's
models learn from and which they are scored on (:class:`Fold`: k seeded folds or leave-one-
out), what every fold shares (each demonstration prepared once, :func:`prepare_for_cv`), and
the one loop that fits a model per fold and scores it on the held-out part
(:func:`fold_scores`), which choosing K and the floor (core.selection), training's
calibrations (core.calibration) and the evaluations run.
"""

import inspect
from typing import NamedTuple

import numpy as np

from .mixture import MixtureIProMP, Prepared
from .parallel import map_threads

_DEFAULT_N_BASIS = inspect.signature(MixtureIProMP).parameters['n_basis'].default


class Fold(NamedTuple):
    """One split of n demonstrations: the indices a fold's models learn from and the indices
    they are scored on, each ascending."""

    train: np.ndarray
    test: np.ndarray


def cv_folds(n: int, n_folds: int, random_state=0):
    """Fold index (n,) of each demonstration: a seeded permutation cut into ``n_folds`` parts."""
    n_folds = int(min(n_folds, n))
    if n_folds < 2:
        raise ValueError(f'cross-validation needs at least 2 demonstrations, got {n}')
    order = np.random.default_rng(random_state).permutation(n)
    fold = np.empty(n, dtype=int)
    fold[order] = np.arange(n) % n_folds
    return fold


def k_folds(n: int, n_folds: int, random_state=0) -> list:
    """The :class:`Fold` of each of the :func:`cv_folds`, in the folds' order."""
    fold = cv_folds(n, n_folds, random_state)
    return [Fold(np.flatnonzero(fold != f), np.flatnonzero(fold == f))
            for f in range(fold.max() + 1)]


def leave_one_out(n: int, held_out=None) -> list:
    """A :class:`Fold` holding out each of ``held_out`` (indices; None: every one of the n
    demonstrations) on its own, the model learning from all the others."""
    everyone = np.arange(n)
    return [Fold(np.flatnonzero(everyone != i), np.array([i]))
            for i in (everyone if held_out is None else held_out)]


def fold_scores(folds, fit, score, settings=(None,), n_jobs=None) -> list:
    """``score(model, fold, setting)`` of the model ``fit(fold, setting)`` learns, for every
    fold and every setting (fold by fold, each fold's settings in their order), on ``n_jobs``
    threads (core.parallel.map_threads: the same result for any number). ``folds``: each a
    :class:`Fold`, or what the caller's ``fit`` and ``score`` take for one (an index into
    what it prepared per fold). ``fit`` returns None for a fold that cannot hold the model,
    whose entry is then None. A flat list."""
    def one(task):
        fold, setting = task
        model = fit(fold, setting)
        return None if model is None else score(model, fold, setting)
    return map_threads(one, [(fold, s) for fold in folds for s in settings], n_jobs)


def n_basis_of(params) -> int:
    """The number of basis functions per DOF of MixtureIProMP configuration ``params``."""
    return params.get('n_basis', _DEFAULT_N_BASIS)


def prepare_for_cv(demos, params) -> Prepared:
    """Every demonstration prepared once (checked as ``fit`` checks them) for fits with
    MixtureIProMP configuration ``params``."""
    return MixtureIProMP(**{**params, 'n_components': 1}).prepare(demos)


def check_prepared(prepared, demos, params):
    """Refuse a ``prepared`` that was not made of ``demos`` with MixtureIProMP configuration
    ``params`` (:func:`prepare_for_cv` with method 'regression'): its weights would silently
    stand for other ones."""
    dofs = demos[0].n_observed_dofs + demos[0].n_controlled_dofs
    smoothing = params.get('smoothing')
    if (prepared.smoothing is None
            or prepared.W.shape != (len(demos), dofs * n_basis_of(params))
            or prepared.n_observed != demos[0].n_observed_dofs
            or (smoothing is not None and not np.array_equal(
                np.broadcast_to(np.asarray(smoothing, dtype=float), prepared.smoothing.shape),
                prepared.smoothing))):
        raise ValueError('prepared was not made of these demonstrations with these parameters '
                         '(core.crossval.prepare_for_cv(demos, params) with method '
                         "'regression')")
