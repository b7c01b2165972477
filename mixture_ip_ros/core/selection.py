"""How many components, and how much covariance floor: held-out criteria of the Mixture of
Interaction ProMPs, computed from cross-validated fits (core.crossval) through the estimator's
public methods, and the choices training makes with them.

- the thesis's leave-one-out RMS of the controlled agent (Figs. 8 and 10),
  :func:`loo_rms_by_components`, given the final observed position or the whole path;
- the held-out log-likelihood of whole demonstrations, the completion of a held-out
  demonstration from its beginning, the controlled agent's held-out online RMS and the patterns
  named online, each K at the covariance floor the criterion prefers
  (:func:`calibrated_heldout_curves`);
- the plateau rule that reads a curve (:func:`selection_curve`);
- training's choices: K by the pattern space (:func:`choose_by_patterns`) or by the thesis's
  leave-one-out (:func:`choose_by_loo`), and the floor of a given K (:func:`calibrated_floor`).
What each demonstration contributes on its own is computed once (core.crossval.prepare_for_cv)
and every fold takes its part (Prepared.take).
"""

from typing import NamedTuple

import numpy as np

from .basis import GaussianBasis
from .crossval import fold_scores, k_folds, leave_one_out, n_basis_of, prepare_for_cv
from .mixture import MixtureIProMP
from .named import majority_names
from .numerics import first_best, tie_tolerance
from .parallel import ProgressCount, map_threads
from .pattern_space import PatternSpace
from .patterns import heldout_curve, partition_stability
from .scores import (COMPLETION_FRACTIONS, beginning_stats, checked_fractions,
                     completion_statistics, controlled_rms, final_rms, final_views,
                     online_scores)


# Held-out evidence (nats summed over the demonstrations: the log of Geisser and Eddy's
# pseudo-Bayes factor) with which a larger K overrules parsimony: Kass and Raftery's (1995)
# "strong" evidence, 2 ln B > 6.
EVIDENCE_NATS = 3.0

# Covariance floors training calibrates over, as fractions of the within-component variance
# per weight: half decades, wide enough for the optima of every scenario evaluated (smooth
# generated reaches at the small end, letters and sampled covariances at the large).
PRIOR_SCALES = tuple(float(f'{10.0 ** e:.3g}') for e in np.arange(0.5, -4.01, -0.5))


def loo_rms_by_components(demonstrations, candidates, observe: str = 'final', progress=None,
                          **params):
    """Leave-one-out RMS error of the controlled agent's predicted mean trajectory (thesis Figs.
    8 and 10) for every K in ``candidates``. The held-out demonstration is observed at its final
    observed position (``observe='final'``, as in the thesis) or along its whole path ('full').
    ``progress(done, total, K)`` is called after each fit. Needs a controlled agent (for a
    single-agent set use the held-out log-likelihood of :func:`calibrated_heldout_curves`).

    Every fold's model is the one ``MixtureIProMP(K, **params).fit`` learns from the other
    demonstrations; what each demonstration contributes on its own (statistics, weights at the
    set's smoothing) is computed once for all folds.

    Returns an array (len(candidates), n) of per-demonstration RMS errors.
    """
    demos = list(demonstrations)
    if demos and demos[0].n_controlled_dofs == 0:
        raise ValueError('leave-one-out RMS of the controlled agent needs a controlled agent; '
                         'these demonstrations have none (use the held-out log-likelihood)')
    data = prepare_for_cv(demos, params)
    final = (final_views(GaussianBasis(n_basis_of(params)), demos)
             if observe == 'final' else None)
    counter = ProgressCount(progress, len(candidates) * len(demos))

    def fit(fold, K):
        return MixtureIProMP(n_components=K, **params).fit(data.take(fold.train))

    def score(model, fold, K):
        rms = (final_rms(model, final, fold.test)[0] if final is not None
               else controlled_rms(model, demos[fold.test[0]], observe))
        counter.step(K)
        return rms
    folds = leave_one_out(len(demos))
    out = np.empty((len(candidates), len(demos)))
    for a, K in enumerate(candidates):
        out[a] = fold_scores(folds, fit, score, (K,), n_jobs=1)
    return out


class _FoldPart(NamedTuple):
    """What every fit of one fold shares: the demonstrations it learns from (``train``, a
    Prepared, and their indices ``members``), the held-out indices ``test``, their statistics
    and their beginnings'."""

    train: object
    members: np.ndarray
    test: np.ndarray
    test_stats: object
    test_beginnings: object


def _heldout_scores(demonstrations, candidates, scales, n_folds, progress, fold_seed, params,
                    fractions=(), controlled=False, n_jobs=None, data=None):
    """Held-out scores, each (len(scales), len(candidates), n): every fold's model is the one
    ``MixtureIProMP(K, prior_scale=scale, **params).fit`` learns from the other folds, scored
    on the fold. 'loglik': :meth:`MixtureIProMP.score_demonstrations`; with ``fractions`` also
    'completion' and 'completion_rms', core.scores.score_completion's two scores averaged over
    the fractions. What each demonstration contributes on its own is computed once, and each
    fold's k-means start of each K once for every scale (it does not depend on the floor).
    With ``controlled`` and a controlled agent, also 'controlled_rms' and 'named':
    core.scores.online_scores of the held-out demonstration (RMS NaN for one with nothing to
    predict), its pattern the one the demonstrations' pattern mixture with K components gives
    it (MixtureIProMP.initial_clusters of them all, which no floor changes), each component of
    a fold's model named by the pattern most of its training demonstrations have.
    ``progress(done, total, K)`` after each fit. The fits run side by side on ``n_jobs``
    threads (core.crossval.fold_scores; None: every core), each filling its own entries.
    ``data``: core.crossval.prepare_for_cv of the demonstrations, if the caller has it."""
    demos = list(demonstrations)
    folds = k_folds(len(demos), n_folds, fold_seed)
    data = prepare_for_cv(demos, params) if data is None else data
    shape = (len(scales), len(candidates), len(demos))
    out = {'loglik': np.empty(shape)}
    basis = GaussianBasis(n_basis_of(params))
    if controlled and demos[0].n_controlled_dofs:
        out['controlled_rms'], out['named'] = np.empty(shape), np.empty(shape)
        patterns = map_threads(lambda K: MixtureIProMP(n_components=K, **params)
                               .initial_clusters(data) if K > 1 else np.zeros(len(demos), int),
                               candidates, n_jobs)
    if fractions:
        out['completion'], out['completion_rms'] = np.empty(shape), np.empty(shape)
        beginnings = beginning_stats(basis, demos, checked_fractions(fractions))
    counter = ProgressCount(progress, len(scales) * len(candidates) * len(folds))
    parts = [_FoldPart(data.take(fold.train), fold.train, fold.test, data.take(fold.test).stats,
                       [st.take(fold.test) for st in beginnings] if fractions else None)
             for fold in folds]
    keys = [(f, a) for f in range(len(parts)) for a in range(len(candidates))]

    def start(key):
        train, K = parts[key[0]].train, candidates[key[1]]
        return (MixtureIProMP(n_components=K, **params).initial_clusters(train)
                if len(train.W) >= K else None)
    # The k-means start of a fold's K is the same for every floor: made once, then every
    # (fold, K, floor) fit is a task of its own (more tasks than threads keeps both busy).
    inits = dict(zip(keys, map_threads(start, keys, n_jobs)))

    def fit(f, setting):
        a, b = setting
        model = MixtureIProMP(n_components=candidates[a], **{**params, 'prior_scale': scales[b]})
        return model.fit(parts[f].train, init=inits[f, a])

    def score(model, f, setting):
        (a, b), (_, members, test, test_stats, test_beginnings) = setting, parts[f]
        out['loglik'][b, a, test] = model.score_statistics(test_stats, data.alphas[test])
        if 'controlled_rms' in out:
            pattern = patterns[a]
            names = majority_names(np.argmax(model.resp_, axis=1), pattern[members],
                                   model.n_components)
            out['controlled_rms'][b, a, test], out['named'][b, a, test] = online_scores(
                model, [demos[i] for i in test], pattern[test], names)
        if fractions:
            density, rms = completion_statistics(model, test_stats, test_beginnings,
                                                 data.alphas[test])
            out['completion'][b, a, test] = density.mean(axis=1)
            out['completion_rms'][b, a, test] = rms.mean(axis=1)
        counter.step(candidates[a])
    settings = [(a, b) for a in range(len(candidates)) for b in range(len(scales))]
    fold_scores(range(len(parts)), fit, score, settings, n_jobs)
    return out


def calibrated_heldout_curves(demonstrations, candidates, fractions=COMPLETION_FRACTIONS,
                              prior_scales=PRIOR_SCALES, n_folds: int = 5, progress=None,
                              fold_seed=0, controlled: bool = True, n_jobs=None, prepared=None,
                              **params):
    """Every held-out criterion for K from the same cross-validated fits, each K at the
    covariance floor the criterion itself prefers.

    The floor is the variance a component gets in the directions its few members do not span
    (fewer demonstrations than weights). Too small, and a held-out demonstration of the same
    pattern falls outside the component; too large, and the components blur into each other.
    The right amount depends on the data (smooth generated reaches want a floor orders of
    magnitude below what sampled covariances and letters want), so no fixed value is right
    for every data set. The same folds for every floor and K; the maximum over a few floors
    makes every K's curve equally optimistic, so the paired comparison between K stays fair.
    The criteria:

    - 'loglik': log p(D_i, alpha_i) of the held-out demonstration (higher is better);
    - with ``controlled`` (default) and a controlled agent, 'controlled_rms': the controlled
      agent predicted online from the observed agent's beginning, the phase unknown, as the
      estimator node predicts it (:func:`core.scores.online_scores`) on the held-out folds,
      lower is better; and 'named', how often the estimator's MAP component from those
      beginnings names the held-out demonstration's pattern (higher is better).
      The floor of 'controlled_rms' is the one with the best held-out likelihood among the
      floors whose RMS is within one paired standard error of the lowest (the
      one-standard-error rule of RMS curves, as :func:`selection_curve` reads the thesis's)
      and that name the patterns not significantly worse than the best of them (two paired
      standard errors: the naming only keeps out a floor that is clearly worse at it): what
      the robot is for decides, the partner it predicts and the pattern it names, and among
      the floors it cannot tell apart the one that describes the demonstrations best. Two
      standard errors would let the likelihood pull the floor up to where the prediction is
      visibly worse. The likelihood alone scores whole demonstrations with their phase known
      and prefers floors that blur the patterns for a beginning whose phase is not, where
      online recognition and the partner's prediction are worse
      (experiments/floor_online.py); with few demonstrations the RMS is too uncertain to
      stop it (four or five of each NuiSI v2 interaction, the pace changed: the RMS allows
      0.316, where the inner folds' beginnings name their pattern a quarter of the time, 90 %
      at 0.0316), so the naming gates it too. The RMS alone
      barely moves below some floor, so its minimum there is noise at the grid's edge, which
      the likelihood settles.
    - with ``fractions``, the single-agent analogue of the thesis's leave-one-out of the
      controlled agent, what a model of one agent's movements is used for (recognise a
      movement and predict its rest from its beginning): 'completion', the predictive log
      density of the rest given the beginning, log p(D_i[z > f] | D_i[z <= f], alpha_i),
      and 'completion_rms', the RMS error of the rest predicted from the beginning (lower is
      better), each averaged over the fractions f (:func:`core.scores.score_completion`).

    The folds run on ``n_jobs`` threads (None: every core; the same result for any number).
    ``prepared``: :func:`core.crossval.prepare_for_cv` of the demonstrations with these
    ``params``, where the caller has it (training shares it between its stages).
    Returns {criterion: {'scores' (len(candidates), n): each K's per-demonstration score at
    its floor, 'prior_scale': the floor per candidate, 'prior_scales' and 'mean_by_scale'
    (len(prior_scales), len(candidates)): the mean of every curve tried}}; 'named' is a gate
    of 'controlled_rms', not a criterion for K (its floor is the one that names best).
    """
    demos = list(demonstrations)
    scales = [float(s) for s in prior_scales]
    if not scales or not all(np.isfinite(s) and s > 0 for s in scales):
        raise ValueError(f'prior_scales must be positive numbers, got {prior_scales!r}')
    params = {k: v for k, v in params.items() if k != 'prior_scale'}
    scores = _heldout_scores(demos, candidates, scales, n_folds, progress, fold_seed, params,
                             tuple(fractions), controlled, n_jobs, prepared)
    out = {}
    for name, S in scores.items():
        if name == 'controlled_rms':
            mean = np.nanmean(S, axis=2)
            best = np.empty(len(candidates), dtype=int)
            for a in range(len(candidates)):
                scored = ~np.isnan(S[:, a]).any(axis=0)
                allowed = (not_significantly_worse(-S[:, a][:, scored], n_se=1.0)
                           if scored.any() else np.ones(len(scales), dtype=bool))
                kept = np.flatnonzero(allowed)
                kept = kept[not_significantly_worse(scores['named'][kept, a])]
                best[a] = kept[first_best(scores['loglik'][kept, a].mean(axis=1))]
        else:
            # A tie takes the first floor: PRIOR_SCALES run from the largest, the simplest.
            mean = S.mean(axis=2)
            best = np.array([first_best(mean[:, a], not name.endswith('_rms'))
                             for a in range(len(candidates))], dtype=int)
        out[name] = {'scores': S[best, np.arange(len(candidates))],
                     'prior_scale': [scales[b] for b in best], 'prior_scales': scales,
                     'mean_by_scale': mean}
    return out


def not_significantly_worse(g, n_se: float = 2.0):
    """Mask of the rows of ``g`` (options, n; per-demonstration scores, higher is better) whose
    paired difference to the best row is within ``n_se`` standard errors: the options the data
    cannot tell from the best (a difference within :func:`core.numerics.tie_tolerance` of the
    limit is within)."""
    d = g[first_best(g.mean(axis=1))] - g
    n = g.shape[1]
    se = d.std(axis=1, ddof=1) / np.sqrt(n) if n > 1 else np.zeros(len(g))
    return d.mean(axis=1) <= n_se * se + tie_tolerance(g)


def select_n_components(scores, higher_is_better: bool = False, paired: bool = False):
    """Smallest K (index into the candidates) whose mean score is within one standard error of
    the best: where the curve reaches its plateau (LOO RMS, lower is better; or held-out
    log-likelihood, ``higher_is_better``). See :func:`selection_curve` for ``paired``."""
    return selection_curve(scores, higher_is_better, paired)['index']


def selection_curve(scores, higher_is_better: bool = False, paired: bool = False,
                    choose=None):
    """The K choice and its evidence from per-demonstration scores (candidates, n).

    Plateau rule: the smallest K within one standard error of the best K's scores (the
    thesis's RMS curves) or, ``paired``, the smallest K not significantly worse than the best:
    its per-demonstration difference to the best K within two standard errors. Held-out
    log-likelihoods need the paired form: each demonstration's own level (its number of
    samples, its noise) varies far more between demonstrations than between K, while the
    paired differences are so consistent that one standard error would call a negligible
    gain of a superfluous component significant.

    Whether the curve has a clear optimum (paired differences, two standard errors): the chosen
    K beats the first candidate, or the first candidate is chosen and beats every other.
    Otherwise the curve is flat within its noise and the note says so.

    ``choose``: a second criterion among the candidates the curve cannot tell apart, given
    their indices (the plateau; ``paired`` only), returning the index chosen; by default the
    smallest.
    Returns a dict: index, mean, se (per candidate), clear (bool), note (str).
    """
    s = np.asarray(scores, dtype=float)
    g = s if higher_is_better else -s               # higher is better from here on
    n = s.shape[1]

    def se_of(x):
        return float(x.std(ddof=1) / np.sqrt(n)) if n > 1 else 0.0
    mean = s.mean(axis=1)
    se = np.array([se_of(r) for r in s])
    best = first_best(g.mean(axis=1))
    if paired:
        within = not_significantly_worse(g)
    else:
        within = g.mean(axis=1) >= g[best].mean() - se[best] - tie_tolerance(g)
    if choose is not None and not paired:
        raise ValueError('choose needs the paired plateau')
    plateau = np.flatnonzero(within)
    index = int(plateau[0] if choose is None else choose(plateau.tolist()))
    if index not in plateau:
        raise ValueError(f'choose returned {index}, not one of the plateau {plateau.tolist()}')

    def beats(a, b):
        d = g[a] - g[b]
        return d.mean() > 2 * se_of(d) + tie_tolerance(g)
    if len(s) == 1:
        clear, note = False, 'a single candidate: nothing was compared'
    elif index > 0:
        clear = beats(index, 0)
        note = ('clear: better than the first candidate by more than two paired standard errors'
                if clear else 'no clear optimum: the curve is flat within two paired standard '
                              'errors of the first candidate')
    else:
        clear = all(beats(0, b) for b in range(1, len(s)))
        note = ('clear: the first candidate beats every other by more than two paired standard '
                'errors' if clear else 'no clear optimum: the curve is flat (no candidate is '
                'better than the first by two paired standard errors); the first is kept by '
                'parsimony')
    return {'index': index, 'mean': mean.tolist(), 'se': se.tolist(), 'clear': bool(clear),
            'note': note}


def _curve_summary(candidates, scores, curve) -> dict:
    return {'candidates': list(candidates), 'mean': curve['mean'],
            'std': np.asarray(scores).std(axis=1).tolist(), 'se': curve['se'],
            'chosen': int(candidates[curve['index']]), 'clear_optimum': curve['clear'],
            'note': curve['note']}


def _offset_progress(progress, offset, total):
    """``progress`` of one batch of fits, ``offset`` fits into ``total`` fits in all (None:
    the batch's own total)."""
    if progress is None:
        return None
    return lambda done, n, K: progress(offset + done, n if total is None else total, K)


def choose_by_patterns(data, candidates, params) -> dict:
    """K by the held-out likelihood in the pattern space (core.pattern_space), and among the K it
    cannot tell apart, by how reproducible their partitions are (``data``: prepare_for_cv of
    the demonstrations with MixtureIProMP configuration ``params``). Returns training's
    summary of the choice: the curve, the chosen K, whether it is a clear optimum, each K's
    stability and the pattern space's size."""
    N, P = n_basis_of(params), data.n_observed
    groups = params.get('translation', ())
    space = PatternSpace(N, P, translation=groups)
    X = space.fit_transform(data.W)
    observed = None
    if data.W.shape[1] > P * N:
        # The observed agent alone, as the robot sees it online: of each translation group,
        # its observed DOFs shift together.
        mine = tuple(h for h in (tuple(j for j in g if j < P) for g in groups or ()) if h)
        observed = PatternSpace(N, P, translation=mine).fit_transform(data.W[:, :P * N])
    return {'criterion': 'patterns', **patterns_in_space(X, candidates, observed),
            'unit': 'nats per demonstration, leave-one-out, in the pattern space',
            'pattern_dims': int(X.shape[1]),
            'smoothing': data.smoothing.tolist(),
            'explained_variance': float(space.explained_variance_ratio_.sum())}


def patterns_in_space(X, candidates, observed=None) -> dict:
    """The number of patterns among ``candidates`` of demonstrations at the rows of ``X``
    (pattern-space coordinates; ``observed``: the observed agent's alone, None where it is
    the only one): the curve, the chosen K, whether it is a clear optimum and each K's
    stability (:func:`choose_by_patterns`)."""
    held = heldout_curve(X, candidates)
    stability = {}
    # Which K the held-out likelihood supports: those within two paired standard errors of
    # the best (the plateau). Within it, the likelihood alone would split a pattern whose
    # spread is not Gaussian (box assembly's plates, drawn from a wide box), a split the data
    # do not hold, which cluster stability detects (a split of one pattern falls where each
    # subsample's members put it; core.patterns.partition_stability). The agreement of a K's
    # subsample pairs is read by its median, not its mean: an EM fit on a subsample that now
    # and then lands in another local optimum costs a partition the data reproduce exactly in
    # most pairs its mean, not its median (NuiSI v2's handshake and parachute fist-bump),
    # while an arbitrary split is reproduced exactly in few (box assembly's plates). So: the K
    # whose median agreement reaches the lower quartile of the most reproducible K's (as
    # reproducible as a quarter of its own pairs); of those, the smallest within one paired
    # standard error of their best held-out likelihood (in a space of one or two dimensions a
    # split of one pattern can be reproducible too, and gains nothing held out) that no larger
    # K overrules: at least as reproducible, and better held out by EVIDENCE_NATS both in
    # this space and in the observed agent's alone. One standard error alone is a
    # parsimony that grows as the demonstrations get fewer: with four or five of each pattern
    # it is as large as the gain of every true split (NuiSI v2 with half the recordings: four
    # interactions found exactly and reproduced in 9 of 10 folds, K 2 or 3 chosen in 5). The
    # evidence of a split grows with every demonstration the split explains, and a split in
    # the controlled agent's paths alone, which the robot cannot tell online from the
    # observed agent, thins every component's data for nothing (the pole's two sides split in
    # four: 3.8 nats better held out; in the observed agent's paths, where the sides are not
    # found at all, four components gain 2.7 over two; the flange error on one-sided spots
    # 3.2 -> 5.3 cm).
    def most_reproducible(plateau):
        fits = [i for i in plateau if candidates[i] <= round(0.8 * len(X))]
        if len(fits) < 2:
            return plateau[0]
        agreement = partition_stability(X, [candidates[i] for i in fits])
        median = np.median(agreement, axis=1)
        stability.update({int(candidates[i]): float(m) for i, m in zip(fits, median)})
        quartile = np.percentile(agreement[first_best(median)], 25)
        ok = [i for i, m in zip(fits, median) if m >= quartile - tie_tolerance(agreement)]
        g = held.robust[ok]
        near = np.flatnonzero(not_significantly_worse(g, n_se=1.0))
        total, reproduced = g.sum(axis=1), median[[fits.index(i) for i in ok]]
        tol, rtol = tie_tolerance(total), tie_tolerance(agreement)
        seen = {}

        def seen_total(a):
            """The observed agent's summed held-out log-likelihood at candidate ok[a]."""
            if observed is None:
                return total[a]
            if a not in seen:
                seen[a] = float(heldout_curve(observed, [candidates[ok[a]]]).robust.sum())
            return seen[a]

        def overruled(j):
            return any(total[b] - total[j] > EVIDENCE_NATS + tol
                       and reproduced[b] >= reproduced[j] - rtol
                       and seen_total(b) - seen_total(j) > EVIDENCE_NATS + tol
                       for b in range(j + 1, len(ok)))
        # The default is never taken: the best is in near, and nothing larger is better.
        return ok[int(next((j for j in near if not overruled(j)), first_best(g.mean(axis=1))))]
    curve = selection_curve(held.robust, higher_is_better=True, paired=True,
                            choose=most_reproducible)
    return {**_curve_summary(candidates, held.robust, curve), 'stability': stability}


def choose_by_loo(demos, candidates, n_folds, progress, prior_scales, params, n_jobs=None,
                  prepared=None) -> dict:
    """K by the thesis's leave-one-out RMS of the controlled agent, each K at the robot's
    floor calibrated on held-out folds (a K too large for the folds, as leave-one-out trains on
    one more demonstration, takes the floor of the largest K they calibrated). Returns
    training's summary of the choice: the curve, the chosen K, whether it is a clear optimum,
    each K's floor and the chosen K's (``prior_scale``)."""
    scales = [params['prior_scale']] if 'prior_scale' in params else list(prior_scales)
    n_fold = int(min(n_folds, len(demos)))
    n_train = len(demos) - int(np.ceil(len(demos) / n_fold))
    folded = [k for k in candidates if k <= n_train]
    if not folded:
        raise ValueError(f'not enough demonstrations for {n_folds}-fold cross-validation')
    n_cal = len(scales) * len(folded) * n_fold
    total = n_cal + len(candidates) * len(demos)
    curves = calibrated_heldout_curves(demos, folded, (), scales, n_folds,
                                       _offset_progress(progress, 0, total), n_jobs=n_jobs,
                                       prepared=prepared, **params)
    calibrated = dict(zip(folded, curves['controlled_rms']['prior_scale']))
    floor = {K: calibrated[max(k for k in folded if k <= K)] for K in candidates}
    rms = np.vstack([
        loo_rms_by_components(demos, [K], 'final',
                              _offset_progress(progress, n_cal + a * len(demos), total),
                              **{**params, 'prior_scale': floor[K]})
        for a, K in enumerate(candidates)])
    summary = _curve_summary(candidates, rms, selection_curve(rms))
    return {'criterion': 'loo', **summary, 'unit': 'rad (or the unit of the controlled DOFs)',
            'prior_scales': [floor[K] for K in candidates],
            'prior_scale': floor[summary['chosen']]}


def calibrated_floor(demos, K, n_folds, progress, prior_scales, params, n_jobs=None,
                     prepared=None) -> float:
    """The covariance floor of a K-component model, calibrated on held-out folds: the one with
    the best held-out likelihood; where there is a controlled agent, among the floors that
    predict it and name the patterns online not significantly worse than the best
    (:func:`calibrated_heldout_curves`)."""
    curves = calibrated_heldout_curves(demos, [K], (), list(prior_scales), n_folds,
                                       _offset_progress(progress, 0, None), n_jobs=n_jobs,
                                       prepared=prepared, **params)
    which = 'controlled_rms' if 'controlled_rms' in curves else 'loglik'
    return float(curves[which]['prior_scale'][0])
