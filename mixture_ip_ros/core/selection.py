"""How many components, and how much covariance floor: held-out criteria of the Mixture of
Interaction ProMPs, computed from cross-validated fits through the estimator's public methods.

- the thesis's leave-one-out RMS of the controlled agent (Figs. 8 and 10),
  :func:`loo_rms_by_components`, given the final observed position or the whole path;
- the held-out log-likelihood of whole demonstrations, the completion of a held-out
  demonstration from its beginning and the controlled agent's held-out online RMS, each K at the
  covariance floor the criterion prefers (:func:`calibrated_heldout_curves`), what training
  calibrates the floor with;
- the plateau rule that reads a curve (:func:`selection_curve`).
What each demonstration contributes on its own is computed once (MixtureIProMP.prepare) and
every fold takes its part (Prepared.take).
"""

import inspect
from typing import NamedTuple

import numpy as np

from .basis import GaussianBasis
from .demonstration import Demonstration
from .interaction import trajectory_distribution
from .mixture import MixtureIProMP, Prepared
from .numerics import first_best, logsumexp_rows, tie_tolerance
from .online import OnlineEstimator, prefix_predictions
from .parallel import ProgressCount, map_threads
from .phase import alpha_log_density
from .promp import ObservationStats, log_evidence, observation_stats, stack_stats


# Covariance floors training calibrates over, as fractions of the within-
# component variance per weight: half decades wide enough for every scenario evaluated (their
# optima range from 3e-4, smooth generated reaches, to 1, letters and sampled covariances).
PRIOR_SCALES = tuple(float(f'{10.0 ** e:.3g}') for e in np.arange(0.5, -4.01, -0.5))

# Where the completion criterion cuts a held-out demonstration into the beginning it observes
# and the rest it predicts: the fractions recognition is reported at (app.evaluation), spread
# over the movement so that no single cut decides.
COMPLETION_FRACTIONS = (0.3, 0.5, 0.7)


def beginning_stats(basis, demos, fractions):
    """Per fraction f, the stacked statistics of every demonstration's beginning: its samples
    (every DOF of both agents) at phases z <= f."""
    out = []
    for f in fractions:
        out.append(stack_stats([observation_stats(basis, d.phase[d.phase <= f],
                                                  np.hstack([d.observed, d.controlled])[
                                                      d.phase <= f]) for d in demos]))
    return out


def checked_fractions(fractions):
    f = np.atleast_1d(np.asarray(fractions, dtype=float))
    if f.ndim != 1 or f.size == 0 or not np.all((f > 0) & (f < 1)):
        raise ValueError(f'fractions must be numbers in (0, 1), got {fractions!r}')
    return tuple(float(x) for x in f)


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
    final = (_final_views(GaussianBasis(params.get('n_basis', _DEFAULT_N_BASIS)), demos)
             if observe == 'final' else None)
    out = np.empty((len(candidates), len(demos)))
    everyone = np.arange(len(demos))
    for a, K in enumerate(candidates):
        for i, test in enumerate(demos):
            model = MixtureIProMP(n_components=K, **params).fit(data.take(everyone != i))
            out[a, i] = (_final_rms(model, final, [i])[0] if final is not None
                         else controlled_rms(model, test, observe))
            if progress:
                progress(a * len(demos) + i + 1, out.size, K)
    return out


def prepare_for_cv(demos, params) -> Prepared:
    """Every demonstration prepared once (checked as ``fit`` checks them) for fits with
    MixtureIProMP configuration ``params``."""
    return MixtureIProMP(**{**params, 'n_components': 1}).prepare(demos)


def controlled_rms(model, demo: Demonstration, observe: str = 'final'):
    """RMS error of the predicted controlled trajectory of ``demo`` over its own samples."""
    z = demo.phase
    rows = np.flatnonzero(~np.isnan(demo.observed).any(axis=1))
    if observe == 'final':
        rows = rows[-1:]
    elif observe != 'full':
        raise ValueError(f"observe must be 'final' or 'full', got {observe!r}")
    k, mean, _ = model.condition(z[rows], demo.observed[rows])
    dofs = range(model.n_observed_, model.n_observed_ + model.n_controlled_)
    pred = trajectory_distribution(mean, None, model.basis_, z, dofs=dofs)['position']
    ok = ~np.isnan(demo.controlled).any(axis=1)
    return float(np.sqrt(np.mean((pred[ok] - demo.controlled[ok]) ** 2)))


class _FinalView(NamedTuple):
    """What :func:`controlled_rms` (observe='final') needs of each demonstration, whatever model
    it is scored under: the basis at its final observed sample ``phi`` (n, N) and that sample
    ``y`` (n, P); per demonstration the basis at its samples with the controlled agent observed
    ``psi`` and those samples ``yc``. Cross-validation computes it once for every fold."""

    phi: np.ndarray
    y: np.ndarray
    psi: list
    yc: list


def _final_views(basis, demos) -> _FinalView:
    rows = [np.flatnonzero(~np.isnan(d.observed).any(axis=1))[-1] for d in demos]
    ok = [~np.isnan(d.controlled).any(axis=1) for d in demos]
    return _FinalView(basis(np.array([d.phase[r] for d, r in zip(demos, rows)])),
                      np.array([d.observed[r] for d, r in zip(demos, rows)]),
                      [basis(d.phase[m]) for d, m in zip(demos, ok)],
                      [d.controlled[m] for d, m in zip(demos, ok)])


def _final_rms(model, view: _FinalView, idx) -> np.ndarray:
    """:func:`controlled_rms` (observe='final') of the demonstrations ``idx`` of ``view`` at
    once: one observation, so the Kalman form of eq. 4 (a P x P innovation per component)
    gives the evidence of eq. 11 and the conditional mean of eq. 13 directly."""
    idx = np.asarray(idx)
    P, N = model.n_observed_, model.n_basis
    do, K = P * N, model.n_components
    phi, y = view.phi[idx], view.y[idx]                                    # (m, N), (m, P)
    mu, cov = model.means_, model.covariances_
    hm = np.einsum('kpn,in->ikp', mu[:, :do].reshape(K, P, N), phi)        # H mu, (m, K, P)
    SH = np.einsum('kdpn,in->ikdp', cov[:, :, :do].reshape(K, -1, P, N), phi)  # Sigma H^T
    S = np.einsum('ikpnq,in->ikpq', SH[:, :, :do].reshape(len(idx), K, P, N, P), phi)
    nv = model.observed_noise_var_
    S = S + (np.eye(P) * nv[..., None, :])                       # (P,) tied or (K, P) each
    r = y[:, None, :] - hm
    chol = np.linalg.cholesky(S)
    u = np.linalg.solve(chol, r[..., None])[..., 0]
    logdet = 2 * np.log(np.diagonal(chol, axis1=-2, axis2=-1)).sum(axis=-1)
    lp = np.log(model.weights_) - 0.5 * ((u ** 2).sum(axis=-1) + logdet)
    k = np.argmax(lp, axis=1)
    m = np.arange(len(idx))
    gain = np.linalg.solve(S[m, k], r[m, k][..., None])[..., 0]            # S^-1 (y - H mu)
    mean = mu[k] + np.einsum('idp,ip->id', SH[m, k], gain)
    out = np.empty(len(idx))
    for j, i in enumerate(idx):
        pred = view.psi[i] @ mean[j, do:].reshape(-1, N).T
        out[j] = np.sqrt(np.mean((pred - view.yc[i]) ** 2)) if len(pred) else np.nan
    return out


def online_rms(model, demos, fractions=None, n_alpha: int = 50,
               min_interval: float = 0.05) -> np.ndarray:
    """How well ``model`` predicts each of ``demos``' controlled agent online, as the estimator
    node does: after the first f T of the observed agent (phase unknown) for each ``fraction``
    f (default COMPLETION_FRACTIONS), the MAP component's expected path of the controlled agent
    over the rest of the movement (core.online.prefix_predictions); the RMS error over the
    rest's samples and DOFs, averaged over the fractions. (len(demos),), NaN for a
    demonstration with nothing left to predict at any fraction."""
    fractions = checked_fractions(COMPLETION_FRACTIONS if fractions is None else fractions)
    est = OnlineEstimator(model, n_alpha=n_alpha, min_interval=min_interval)
    out = np.full(len(demos), np.nan)
    for i, demo in enumerate(demos):
        errors = [np.sqrt(np.mean((p.controlled - demo.controlled[p.rest]) ** 2))
                  for p in prefix_predictions(est, demo, fractions) if p.controlled is not None]
        if errors:
            out[i] = np.mean(errors)
    return out


def score_completion(model, demonstrations, fractions=None):
    """How well ``model`` (a fitted MixtureIProMP) predicts the rest of each demonstration from
    its beginning, the phase known (z = t / T, so alpha = 1/T too), for every ``fraction`` f
    (default COMPLETION_FRACTIONS): the beginning B is the samples at z <= f, the rest R those
    at z > f, every DOF of both agents. Returns (log_density, rms), each (n, len(fractions)):

    - log p(R | B, alpha) = log p(R, B, alpha) - log p(B, alpha) under the mixture (eq. 6
      with eq. 21 and p(alpha | k)): the predictive density of the rest, each component
      weighted by its posterior given the beginning (eq. 11);
    - the RMS error of the rest predicted as the thesis predicts (eqs. 12-13): the most
      probable component given B and alpha, conditioned on B, its mean at the rest's
      phases; over every DOF of the rest in the DOF's own unit (comparable across K, not
      across data sets).
    """
    model._check_fitted()
    fractions = checked_fractions(COMPLETION_FRACTIONS if fractions is None else fractions)
    demos = list(demonstrations)
    D = model.n_observed_ + model.n_controlled_
    for demo in demos:
        if demo.n_observed_dofs + demo.n_controlled_dofs != D:
            raise ValueError(f'demonstration {demo.name!r} has {demo.n_observed_dofs} + '
                             f'{demo.n_controlled_dofs} DOFs; the model has '
                             f'{model.n_observed_} + {model.n_controlled_}')
    full = stack_stats([observation_stats(model.basis_, d.phase,
                                          np.hstack([d.observed, d.controlled]))
                        for d in demos])
    return completion_statistics(model, full, beginning_stats(model.basis_, demos, fractions),
                                  np.array([1.0 / d.duration for d in demos]))

def completion_statistics(model, full: ObservationStats, beginnings, alphas):
    """The :func:`score_completion` of stacked statistics of the whole demonstrations, of
    their beginnings (one stack per fraction) and their alpha = 1/T."""
    K, D = model.n_components, model.n_observed_ + model.n_controlled_
    N = model.n_basis
    n = len(alphas)
    noise = np.broadcast_to(model.noise_var_, (K, D))
    prior = np.log(model.weights_) + alpha_log_density(alphas, model.alpha_mean_,
                                                      model.alpha_std_ ** 2)
    whole = prior + np.column_stack([log_evidence(full, model.means_[k], model.covariances_[k],
                                                  noise[k]) for k in range(K)])
    log_whole = logsumexp_rows(whole)
    density = np.empty((n, len(beginnings)))
    rms = np.empty((n, len(beginnings)))
    for c, begin in enumerate(beginnings):
        lp = prior.copy()
        post = np.empty((K, n, D * N))
        for k in range(K):
            ll, post[k] = log_evidence(begin, model.means_[k], model.covariances_[k], noise[k],
                                       posterior_means=True)
            lp[:, k] += ll                                                  # eq. 11
        density[:, c] = log_whole - logsumexp_rows(lp)
        w = post[np.argmax(lp, axis=1), np.arange(n)].reshape(n, D, N)     # eqs. 12-13
        # The rest's statistics are the whole's minus the beginning's (sums over samples).
        G, b = full.G - begin.G, full.b - begin.b
        sq = (full.yy - begin.yy - 2 * np.einsum('ijn,ijn->ij', w, b)
              + np.einsum('ijn,ijnk,ijk->ij', w, G, w))
        m = (full.m - begin.m).sum(axis=1)
        rms[:, c] = np.sqrt(np.maximum(sq.sum(axis=1), 0.0) / np.maximum(m, 1.0))
    return density, rms


def cv_folds(n: int, n_folds: int, random_state=0):
    """Fold index (n,) of each demonstration: a seeded permutation cut into ``n_folds`` parts."""
    n_folds = int(min(n_folds, n))
    if n_folds < 2:
        raise ValueError(f'cross-validation needs at least 2 demonstrations, got {n}')
    order = np.random.default_rng(random_state).permutation(n)
    fold = np.empty(n, dtype=int)
    fold[order] = np.arange(n) % n_folds
    return fold


def _heldout_scores(demonstrations, candidates, scales, n_folds, progress, fold_seed, params,
                    fractions=(), controlled=False, n_jobs=None, data=None):
    """Held-out scores, each (len(scales), len(candidates), n): every fold's model is the one
    ``MixtureIProMP(K, prior_scale=scale, **params).fit`` learns from the other folds, scored
    on the fold. 'loglik': :meth:`MixtureIProMP.score_demonstrations`; with ``fractions`` also
    'completion' and 'completion_rms', :func:`score_completion`'s two scores
    averaged over the fractions. What each demonstration contributes on its own is computed
    once, and each fold's k-means start of each K once for every scale (it does not depend on
    the floor). With ``controlled`` and a controlled agent, also 'controlled_rms':
    :func:`online_rms` of the held-out demonstration (NaN for one with nothing to predict).
    ``progress(done, total, K)`` after each fit. The fits run side by side on ``n_jobs``
    threads (core.parallel.map_threads; None: every core), each filling its own entries.
    ``data``: :func:`prepare_for_cv` of the demonstrations, if the caller has it."""
    demos = list(demonstrations)
    fold = cv_folds(len(demos), n_folds, fold_seed)
    data = prepare_for_cv(demos, params) if data is None else data
    shape = (len(scales), len(candidates), len(demos))
    out = {'loglik': np.empty(shape)}
    basis = GaussianBasis(params.get('n_basis', _DEFAULT_N_BASIS))
    if controlled and demos[0].n_controlled_dofs:
        out['controlled_rms'] = np.empty(shape)
    if fractions:
        out['completion'], out['completion_rms'] = np.empty(shape), np.empty(shape)
        beginnings = beginning_stats(basis, demos, checked_fractions(fractions))
    counter = ProgressCount(progress, len(scales) * len(candidates) * (fold.max() + 1))
    # Each fold: its training set, the held-out rows and their statistics (and beginnings).
    folds = []
    for f in range(fold.max() + 1):
        test = np.flatnonzero(fold == f)
        folds.append((data.take(fold != f), test, data.take(test).stats,
                      [st.take(test) for st in beginnings] if fractions else None))
    keys = [(f, a) for f in range(len(folds)) for a in range(len(candidates))]

    def start(key):
        train, K = folds[key[0]][0], candidates[key[1]]
        return (MixtureIProMP(n_components=K, **params).initial_clusters(train)
                if len(train.W) >= K else None)
    # The k-means start of a fold's K is the same for every floor: made once, then every
    # (fold, K, floor) fit is a task of its own (more tasks than threads keeps both busy).
    inits = dict(zip(keys, map_threads(start, keys, n_jobs)))

    def one_fit(task):
        f, a, b = task
        (train, test, test_stats, test_beginnings), K = folds[f], candidates[a]
        model = MixtureIProMP(n_components=K, **{**params, 'prior_scale': scales[b]})
        model.fit(train, init=inits[f, a])
        out['loglik'][b, a, test] = model.score_statistics(test_stats, data.alphas[test])
        if 'controlled_rms' in out:
            out['controlled_rms'][b, a, test] = online_rms(model, [demos[i] for i in test])
        if fractions:
            density, rms = completion_statistics(model, test_stats, test_beginnings,
                                                 data.alphas[test])
            out['completion'][b, a, test] = density.mean(axis=1)
            out['completion_rms'][b, a, test] = rms.mean(axis=1)
        counter.step(K)
    map_threads(one_fit, [(f, a, b) for f, a in keys for b in range(len(scales))], n_jobs)
    return out


_DEFAULT_N_BASIS = inspect.signature(MixtureIProMP).parameters['n_basis'].default


def calibrated_heldout_curves(demonstrations, candidates, fractions=COMPLETION_FRACTIONS,
                              prior_scales=PRIOR_SCALES, n_folds: int = 5, progress=None,
                              fold_seed=0, controlled: bool = True, n_jobs=None, prepared=None,
                              **params):
    """Every held-out criterion for K from the same cross-validated fits, each K at the
    covariance floor the criterion itself prefers.

    The floor is the variance a component gets in the directions its few members do not span
    (fewer demonstrations than weights). Too small, and a held-out demonstration of the same
    pattern falls outside the component; too large, and the components blur into each other.
    The right amount depends on the data (smooth generated reaches want 1e-3 of the within-
    pattern variance, sampled covariances and letters 0.3 to 3), so no fixed value is right
    for every data set. The same folds for every floor and K; the maximum over a few floors
    makes every K's curve equally optimistic, so the paired comparison between K stays fair.
    The criteria:

    - 'loglik': log p(D_i, alpha_i) of the held-out demonstration (higher is better);
    - with ``controlled`` (default) and a controlled agent, 'controlled_rms': the controlled
      agent predicted online from the observed agent's beginning, the phase unknown, as the
      estimator node predicts it (:func:`online_rms`) on the held-out folds, lower is better.
      Its floor is the one with the best held-out likelihood among the floors whose RMS is
      within one paired standard error of the lowest (the one-standard-error rule of RMS
      curves, as :func:`selection_curve` reads the thesis's): what the robot is for decides,
      and among the floors it cannot tell apart the one that describes the demonstrations
      best. Two standard errors let the likelihood pull the floor up to where the prediction
      is visibly worse (the arm in a NuiSI person's place, joint angles: 0.316, RMS 0.29 rad
      against 0.27 at 0.0316). The likelihood alone scores whole demonstrations with
      their phase known and prefers floors that blur the patterns for a beginning whose phase
      is not: on NuiSI v2 (bench/floor_online.py) it peaks at floors of 0.1 to 0.3, where
      online recognition from 30 % of the movement is 86 % and lower, against 98-100 % at
      0.03 to 0.001, the partner's error falling with it. The RMS alone barely moves below
      some floor, so its minimum there is noise at the grid's edge, which the likelihood
      settles.
    - with ``fractions``, the single-agent analogue of the thesis's leave-one-out of the
      controlled agent, what a model of one agent's movements is used for (recognise a
      movement and predict its rest from its beginning): 'completion', the predictive log
      density of the rest given the beginning, log p(D_i[z > f] | D_i[z <= f], alpha_i),
      and 'completion_rms', the RMS error of the rest predicted from the beginning (lower is
      better), each averaged over the fractions f (:func:`score_completion`).

    The folds run on ``n_jobs`` threads (None: every core; the same result for any number).
    ``prepared``: :func:`prepare_for_cv` of the demonstrations with these ``params``, where
    the caller has it (training shares it between its stages).
    Returns {criterion: {'scores' (len(candidates), n): each K's per-demonstration score at
    its floor, 'prior_scale': the floor per candidate, 'prior_scales' and 'mean_by_scale'
    (len(prior_scales), len(candidates)): the mean of every curve tried}}.
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
                ll = scores['loglik'][:, a].mean(axis=1)
                best[a] = first_best(np.where(allowed, ll, -np.inf))
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
