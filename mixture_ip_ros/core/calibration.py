"""Training's held-out calibrations of how a fitted mixture reads a movement online, each
scored on folds held out of the model (:func:`held_out_scores`):

- the phase-speed weight eta (:func:`calibrated_speed_weight`): how well the tempered speed
  posterior p_eta(alpha | D, k*) of an online estimator, fed the beginning of a movement held
  out of the model, predicts that movement's own speed (:func:`speed_log_scores`);
- the phase (:func:`held_out_warp_gain`): whether the phase warps (core.warped) predict
  held-out movements better than the linear phase.
"""

import numpy as np

from .checks import labels_fit
from .crossval import fold_scores, k_folds
from .mixture import MixtureIProMP
from .numerics import first_best
from .online import OnlineEstimator
from .phase import log_density_on_grid, tempered_speed_posterior
from .playback import prefixes
from .warped import PhaseWarps

# The speed weights training chooses from, and the points of a movement it scores them at.
SPEED_WEIGHTS = (1.0, 0.5, 0.2, 0.1, 0.05, 0.02, 0.01, 0.0)
SPEED_FRACTIONS = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)


def speed_log_scores(model, demonstrations, weights=SPEED_WEIGHTS, fractions=SPEED_FRACTIONS,
                     n_alpha: int = 50, min_interval: float = 0.05):
    """How well each speed weight eta predicts held-out movements' speeds: for every
    demonstration (held out from ``model``) and every ``fraction`` of it, the log density that
    the tempered posterior of the estimator's MAP component, after the estimator was fed that
    first fraction online, puts at the movement's own speed 1/T (a proper score of the phase
    posterior: core.phase.log_density_on_grid). Returns (summed log densities per weight (len
    weights,), number of terms)."""
    est = OnlineEstimator(model, n_alpha=n_alpha, min_interval=min_interval)
    total, n = np.zeros(len(weights)), 0
    for demo in demonstrations:
        for _ in prefixes(est, demo, np.multiply(fractions, demo.duration)):
            if not est.n_observations:
                continue
            terms = est.speed_log_terms(est.map_hypothesis()[0])
            total += [log_density_on_grid(tempered_speed_posterior(*terms, w), est.alphas,
                                          1.0 / demo.duration) for w in weights]
            n += 1
    return total, n


def held_out_scores(demos, data, n_components, labels, n_folds, params, score, n_jobs=None):
    """``score(model, held_out_demonstrations)`` of each of ``n_folds`` folds (seed 0), the
    model a ``MixtureIProMP(n_components, **params)`` fit of the other folds of ``data``
    (core.crossval.prepare_for_cv of ``demos``) with their ``labels`` (None: unsupervised), on
    ``n_jobs`` threads, in the folds' order; folds that cannot hold the model (too few
    demonstrations, or labels that cannot name its components: core.checks.labels_fit) are
    left out."""
    def fit(fold, _):
        fit_labels = None if labels is None else [labels[i] for i in fold.train]
        if len(fold.train) < n_components or not labels_fit(fit_labels, n_components):
            return None
        return MixtureIProMP(n_components=n_components, **params).fit(
            data.take(fold.train), labels=fit_labels)

    def held_out(model, fold, _):
        return score(model, [demos[i] for i in fold.test])
    scores = fold_scores(k_folds(len(demos), n_folds, 0), fit, held_out, n_jobs=n_jobs)
    return [r for r in scores if r is not None]


def calibrated_speed_weight(demos, data, n_components, labels, n_folds, params, n_jobs=None):
    """The speed weight (:data:`SPEED_WEIGHTS`) whose tempered phase posterior predicts
    held-out demonstrations' speeds best from their beginnings (:func:`speed_log_scores`,
    summed over ``n_folds`` folds: :func:`held_out_scores`; ties: the larger weight, nearer
    eq. 16), and the mean score of each weight; (1, None) where no fold can hold the model."""
    if len(demos) < 2:
        return 1.0, None
    total, n = np.zeros(len(SPEED_WEIGHTS)), 0
    for score, m in held_out_scores(demos, data, n_components, labels, n_folds, params,
                                    speed_log_scores, n_jobs):
        total += score
        n += m
    if n == 0:
        return 1.0, None
    best = first_best(total)              # SPEED_WEIGHTS start at eq. 16's weight, 1
    return SPEED_WEIGHTS[best], {f'{w:g}': float(t / n) for w, t in zip(SPEED_WEIGHTS, total)}


def held_out_warp_gain(demos, data, n_components, labels, n_folds, params, n_jobs=None):
    """How much better the phase warps predict held-out demonstrations than the linear phase:
    the mean of core.warped.PhaseWarps.gains (nats per demonstration) over ``n_folds`` folds
    (:func:`held_out_scores`); None where no fold can hold the model."""
    if len(demos) < 2:
        return None
    gains = held_out_scores(demos, data, n_components, labels, n_folds, params,
                            lambda model, held_out: PhaseWarps().gains(model, held_out), n_jobs)
    return float(np.mean(np.concatenate(gains))) if gains else None
