"""Training's held-out calibrations of how a fitted mixture reads a movement online, each
scored on folds held out of the model (:func:`held_out_scores`):

- the phase-speed weight eta (:func:`calibrated_speed_weight`): how well the tempered speed
  posterior p_eta(alpha | D, k*) of an online estimator, fed the beginning of a movement held
  out of the model, predicts that movement's own speed (:func:`speed_log_scores`);
- the phase (:func:`held_out_warp_gain`): whether the phase warps (core.warped) predict
  held-out movements better than the linear phase;
- the switch rate (:func:`calibrated_switch_rate`): how readily the online belief lets a
  person change their mind (core.switching), scored on held-out movements, unchanged and
  spliced into changes of mind (core.splice) (:func:`switch_log_scores`).
"""

import numpy as np

from .checks import labels_fit
from .crossval import fold_scores, k_folds
from .mixture import MixtureIProMP
from .numerics import first_best
from .online import OnlineEstimator
from .phase import log_density_on_grid, tempered_speed_posterior
from .playback import observed_rows, prefixes
from .splice import BLEND, SHARES, splice
from .warped import PhaseWarps

# The speed weights training chooses from, and the points of a movement it scores them at.
SPEED_WEIGHTS = (1.0, 0.5, 0.2, 0.1, 0.05, 0.02, 0.01, 0.0)
SPEED_FRACTIONS = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)
# The switch rates (per second) training chooses from. Scored from this share of an unchanged
# movement on: its beginning is where the patterns are still told apart, with or without
# changes of mind.
SWITCH_RATES = (0.0, 0.1, 0.3, 1.0)
SETTLED_FROM = 0.3
# Held-out movements per fold the switch rate is scored on (each also spliced into a change of
# mind), drawn at random: every rate plays each of them back.
SWITCH_STREAMS = 6


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


def _truth(model, demo):
    """The component a held-out demonstration belongs to: eq. 11 with its phase known."""
    rows = observed_rows(demo)
    return int(np.argmax(model.component_posterior(demo.phase[rows], demo.observed[rows],
                                                   alpha=1.0 / demo.duration)))


def _changes(demonstrations, truth, picked, rng):
    """(splice, index of the second) for each picked demonstration that another component's
    holds: its beginning joined to the rest of one of those, drawn with ``rng``, at a share
    from core.splice.SHARES."""
    for i in picked:
        others = [j for j, k in enumerate(truth) if k != truth[i]]
        if others:
            j = int(rng.choice(others))
            yield splice(demonstrations[i], demonstrations[j], float(rng.choice(SHARES))), j


def switch_scores(model, demonstrations, rates=SWITCH_RATES, n_alpha: int = 50,
                  min_interval: float = 0.05, seed: int = 0, n_streams: int = SWITCH_STREAMS):
    """How often each switch rate's belief (core.switching) names the pattern held-out movements
    follow: the share of samples whose most probable component is the pattern under way, from
    :data:`SETTLED_FROM` of an unchanged movement on, and from the end of the turn
    (core.splice.BLEND) on in changes of mind spliced from them (each movement's beginning
    joined to the rest of one of another component, at a share from core.splice.SHARES).
    At most ``n_streams`` movements, drawn with ``seed``. The pattern of a movement is the
    component that explains it best with its phase known (eq. 11). Returns (share per rate for
    the unchanged (len rates,), the same for the changes (len rates,)), NaN where none."""
    rng = np.random.default_rng(seed)
    picked = rng.permutation(len(demonstrations))[:n_streams]
    truth = [_truth(model, d) for d in demonstrations]
    streams = []            # (demonstration, pattern per sample, scored from (s), changed)
    for i in picked:
        d = demonstrations[i]
        streams.append((d, np.full(len(observed_rows(d)), truth[i]),
                        SETTLED_FROM * d.duration, 0))
    for i, (s, j) in zip(picked, _changes(demonstrations, truth, picked, rng)):
        t = s.demo.t[observed_rows(s.demo)]
        streams.append((s.demo, np.where(t < s.t_change, truth[i], truth[j]),
                        s.t_change + BLEND, 1))
    # One playback for every rate: rate 0 is the estimator's own belief, the others follow it.
    est = OnlineEstimator(model, n_alpha=n_alpha, min_interval=min_interval, switch_rate=0.0)
    positive = [r for r in rates if r > 0]
    est.compare_rates(positive)
    right = np.zeros((len(rates), 2))
    counted = np.zeros((len(rates), 2))
    for demo, pattern, t_from, changed in streams:
        t = demo.t[observed_rows(demo)]
        hits = []
        for c, _ in enumerate(prefixes(est, demo, t)):
            if t[c] >= t_from:
                beliefs = iter(est.rate_beliefs())
                hits.append([np.argmax(est.component_posterior() if r == 0 else next(beliefs))
                             == pattern[c] for r in rates])
        if hits:
            right[:, changed] += np.mean(hits, axis=0)
            counted[:, changed] += 1
    with np.errstate(invalid='ignore'):
        scores = right / counted
    return scores[:, 0], scores[:, 1]


def _mean_over_folds(scores) -> np.ndarray:
    """The mean per rate over the folds that scored one (NaN where none did)."""
    scores = np.asarray(scores, dtype=float)
    have = ~np.isnan(scores)
    total = np.where(have, scores, 0.0).sum(axis=0)
    count = have.sum(axis=0)
    return np.where(count > 0, total / np.maximum(count, 1), np.nan)


def calibrated_switch_rate(demos, data, n_components, labels, n_folds, params, n_jobs=None):
    """The switch rate (:data:`SWITCH_RATES`) whose belief names held-out movements' patterns
    most often (:func:`switch_scores` over ``n_folds`` folds: :func:`held_out_scores`), the
    unchanged movements and the changes of mind weighing alike (a person is not assumed to
    change their mind more or less often than not); ties: the smaller rate. (0, None) with one
    component or where no fold can hold the model; else (rate, mean score of each rate)."""
    if len(demos) < 2 or n_components < 2:
        return 0.0, None
    folds = held_out_scores(demos, data, n_components, labels, n_folds, params,
                            switch_scores, n_jobs)
    if not folds:
        return 0.0, None
    unchanged, changed = (_mean_over_folds([f[g] for f in folds]) for g in (0, 1))
    total = unchanged + np.where(np.isnan(changed), 0.0, changed)
    if not np.all(np.isfinite(total)):
        return 0.0, None
    best = first_best(total)
    return SWITCH_RATES[best], {f'{r:g}': float(x) for r, x in zip(SWITCH_RATES, total)}
