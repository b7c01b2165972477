"""Train a Mixture of Interaction ProMPs from demonstrations (arrays, CSV files or bags), any
layout: the observed agent with >= 1 DOF, the controlled agent with >= 0.

K, unless given, is chosen from candidates by one of two criteria, each a curve over K:
- 'patterns' (the default, ``'auto'``): the leave-one-out log-likelihood of held-out
  demonstrations in the pattern space, where the patterns are found (core.patterns: the
  paths of both agents, a few principal components, a t mixture with shrunk scales), each
  held-out demonstration allowed to be none of the patterns with probability 1/n; among the
  candidates within two paired standard errors of the best, those whose partitions are about
  as reproducible across subsamples as the most reproducible one's (cluster stability, median
  agreement), and of those the smallest within one paired standard error of their best;
- 'loo': the thesis's leave-one-out RMS of the controlled agent given the final observed
  position (Figs. 8/10), where there is a controlled agent, each K at the floor that predicts
  the controlled agent best on cross-validated fits among the floors whose held-out likelihood
  is not significantly worse (:func:`core.mixture.calibrated_heldout_curves`).
The chosen K's curve, the choice, its covariance floor and whether the curve has a clear
optimum go into the training summary. The model is fitted with the chosen K at the floor
calibrated for it on held-out folds (the robot's floor where there is a controlled agent;
``prior_scale`` given by the caller is used as is; EM fits keep the configured floor).

Why not the held-out likelihood of the full model: a dozen demonstrations per pattern against
45-150 weights; on real interactions (NuiSI) that curve picked K = 1 for four and six plainly
distinct interactions, while the pattern space finds them (docs/results.md, NuiSI).
"""

from contextlib import contextmanager
import inspect
import logging
import sys
import time
from pathlib import Path

import numpy as np

from mixture_ip_ros.core.demonstration import Layout
from mixture_ip_ros.core.mixture import MixtureIProMP
from mixture_ip_ros.core.online import SPEED_WEIGHTS, speed_log_scores
from mixture_ip_ros.core.selection import (PRIOR_SCALES, calibrated_heldout_curves, cv_folds,
                                           loo_rms_by_components, not_significantly_worse,
                                           prepare_for_cv, selection_curve)
from mixture_ip_ros.core.patterns import (PatternSpace, heldout_curve, partition_stability,
                                          translation_groups)
from mixture_ip_ros.core.novelty import calibrate as calibrate_novelty
from mixture_ip_ros.core.numerics import first_best, tie_tolerance
from mixture_ip_ros.core.parallel import checked_jobs, map_threads
from mixture_ip_ros.io.dataset import WRIST_OBSERVATION_NOISE, bag_layout
from mixture_ip_ros.io.model_file import save_model
from mixture_ip_ros.robot.description import load_description

logger = logging.getLogger(__name__)

CRITERIA = ('auto', 'patterns', 'loo')


def text_progress(stream=None, what='choosing K'):
    """The progress of the K curves on ``stream`` (default: stderr): on a terminal a bar redrawn
    in place; otherwise (a log file, CI) a line at each quarter of the fits, since every redraw
    would be a line of its own there."""
    stream = sys.stderr if stream is None else stream
    isatty = getattr(stream, 'isatty', None)
    on_terminal = bool(isatty and isatty())
    quarters = [0]

    def show(done, total, K):
        if on_terminal:
            width = 30
            filled = int(width * done / total)
            stream.write(f'\r{what} K={K:<2d} [{"#" * filled}{"." * (width - filled)}] '
                         f'{done}/{total}')
            if done == total:
                stream.write('\n')
        else:
            quarter = 4 * done // total
            if quarter <= quarters[0]:
                return
            quarters[0] = quarter
            stream.write(f'{what}: {done}/{total} fits ({25 * quarter} %)\n')
        stream.flush()
    return show


class Stages:
    """Where training's time goes: the wall time of each named stage (s) in ``seconds``, and
    each stage's start and end shown by ``show(name, seconds)`` (seconds None at the start;
    None: nothing shown). Used as ``with stages('choosing K'): ...``."""

    def __init__(self, show=None):
        self.seconds = {}
        self.show = show

    @contextmanager
    def __call__(self, name):
        if self.show:
            self.show(name, None)
        t0 = time.perf_counter()
        try:
            yield
        finally:
            spent = time.perf_counter() - t0
            self.seconds[name] = round(self.seconds.get(name, 0.0) + spent, 3)
            if self.show:
                self.show(name, spent)


def text_stages(stream=None):
    """Training's stages on ``stream`` (default: stderr): a stage's name as it starts on a
    terminal (its fits' bar follows, text_progress), and a line with its time as it ends."""
    stream = sys.stderr if stream is None else stream
    isatty = getattr(stream, 'isatty', None)
    on_terminal = bool(isatty and isatty())

    def show(name, seconds):
        if seconds is None:
            if on_terminal:
                stream.write(f'{name} ...\n')
        else:
            stream.write(f'{name}: {seconds:.1f} s\n')
        stream.flush()
    return show


_DEFAULT_N_BASIS = inspect.signature(MixtureIProMP).parameters['n_basis'].default


def _curve_summary(candidates, scores, curve):
    return {'candidates': list(candidates), 'mean': curve['mean'],
            'std': np.asarray(scores).std(axis=1).tolist(), 'se': curve['se'],
            'chosen': int(candidates[curve['index']]), 'clear_optimum': curve['clear'],
            'note': curve['note']}


def train(demos, *, n_components=None, candidates=range(1, 10), criterion: str = 'auto',
          n_folds: int = 5, progress=None, labels=None, prior_scales=PRIOR_SCALES, stages=None,
          n_jobs=None, prepared=None, **params):
    """Fit the mixture; K given, or chosen by ``criterion`` ('auto' = 'patterns', or 'loo';
    see the module docstring). ``labels`` makes a supervised fit (one component per class,
    K = number of classes). ``params`` go to MixtureIProMP; without ``prior_scale`` among them,
    the floor is calibrated over ``prior_scales`` on ``n_folds`` held-out folds. Returns
    (model, info dict): info['selection'] holds the curve of the criterion, the chosen K, its
    floor and whether the curve has a clear optimum (a flat curve is reported as such, never
    silently read as K = 1); info['phase'] whether the phase bends ('chosen': the warps kept
    where a warp predicts held-out folds better, 'held_out_gain' the mean of
    MixtureIProMP.warp_gains; EM, and too few demonstrations for a fold, keep them, gain None)
    and info['warp_failed'] the demonstrations whose warp did not converge; info['seconds'] the
    time of each stage (``stages``, a :class:`Stages`, also shows them). The held-out folds
    run on ``n_jobs`` threads (core.parallel.map_threads; None: every core this process may
    use), with the same result for any number; ``progress`` may be called from them, one call at a time, and
    ``random_state`` is an integer seed (a generator would be shared by the threads).
    ``prepared``: what core.selection.prepare_for_cv made of ``demos`` with these ``params``
    and method 'regression', where the caller has it (else made here once, when a stage needs
    it).
    """
    demos = list(demos)
    checked_jobs(n_jobs)
    seed = params.get('random_state', 0)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise ValueError(f'random_state must be an integer seed, got {seed!r} (the held-out '
                         'folds run on threads, which would share a generator)')
    stages = Stages() if stages is None else stages
    if criterion not in CRITERIA:
        raise ValueError(f'criterion must be one of {CRITERIA}, got {criterion!r}')
    if not demos:
        raise ValueError('no demonstrations to train on')
    if prepared is not None:
        _check_prepared(prepared, demos, params)
    has_controlled = demos[0].n_controlled_dofs > 0
    info = {'n_demonstrations': len(demos), 'n_observed_dofs': demos[0].n_observed_dofs,
            'n_controlled_dofs': demos[0].n_controlled_dofs}
    if labels is not None:
        n_components = len(set(labels))
        info['supervised'] = True
    groups = translation_groups(params.get('translation'), demos[0].n_observed_dofs
                                + demos[0].n_controlled_dofs)
    if groups:
        info['translation'] = [list(g) for g in groups]
    # The curves and floors use per-demonstration regression fits (0.03 s each on the box
    # data): an EM fit takes 10-30 s, and they need dozens. The final model below is fitted
    # with the method asked for.
    curve_params = {**params, 'method': 'regression'}
    # What each demonstration is on its own (its weights, residuals, the set's smoothing):
    # made once, taken by every stage's folds and, for a regression model, the final fit.
    def data():
        nonlocal prepared
        if prepared is None:
            prepared = prepare_for_cv(demos, curve_params)
        return prepared
    n_fold = int(min(n_folds, len(demos)))
    n_train = len(demos) - int(np.ceil(len(demos) / max(n_fold, 1)))
    if n_components is None:
        criterion = 'patterns' if criterion == 'auto' else criterion
        if criterion == 'loo' and not has_controlled:
            raise ValueError("criterion 'loo' needs a controlled agent; these demonstrations have "
                             "none (use 'patterns')")
        candidates = [int(k) for k in candidates if k <= len(demos) - 1]
        if not candidates or len(demos) < 3:
            raise ValueError(f'{len(demos)} demonstrations are too few to choose K')
        with stages('choosing K'):
            if criterion == 'patterns':
                selection = _pattern_selection(data(), candidates, curve_params)
            else:
                selection = _loo_selection(demos, candidates, n_folds, progress, prior_scales,
                                           curve_params, n_jobs, data())
        n_components = selection['chosen']
        if not selection['clear_optimum']:
            logger.warning('K = %d by %s, but %s', n_components, criterion, selection['note'])
        info['selection'] = selection
    # The floor is calibrated on held-out regression fits; EM learns from demonstrations with
    # gaps, whose regression fits say little about it, and keeps the configured floor.
    if 'prior_scale' not in params and labels is None and params.get('method') != 'em':
        if criterion == 'loo' and 'selection' in info:
            params = {**params, 'prior_scale': info['selection']['prior_scale']}
        elif n_components <= n_train:
            with stages('covariance floor'):
                params = {**params, 'prior_scale': _calibrated_floor(
                    demos, n_components, n_folds, progress, prior_scales, curve_params, n_jobs,
                    data())}
        if 'selection' in info:
            info['selection']['prior_scale'] = params.get('prior_scale')
    # The same for the speed weight; EM's demonstrations may lack a whole agent, which the
    # regression fits of the calibration cannot take: EM keeps the configured weight.
    if 'speed_weight' not in params and params.get('method') != 'em':
        with stages('speed weight'):
            weight, scores = _calibrated_speed_weight(demos, data(), n_components, labels,
                                                      n_folds, {**params, 'method': 'regression'},
                                                      n_jobs)
        params = {**params, 'speed_weight': weight}
        info['speed_scores'] = scores
    with stages('final fit'):
        model = MixtureIProMP(n_components=n_components, **params)
        regression = model.method == 'regression' and prepared is not None
        model.fit(prepared if regression else demos, labels=labels)
    # The phase warps where they predict held-out recordings better than the linear phase;
    # EM's demonstrations may lack a whole agent, which the folds' regression fits cannot
    # take: EM keeps them.
    info['phase'] = {'held_out_gain': None, 'chosen': 'warped'}
    if params.get('method') != 'em':
        with stages('phase choice'):
            gain = _held_out_warp_gain(demos, data(), n_components, labels, n_folds,
                                       {**params, 'method': 'regression'}, n_jobs)
        info['phase'] = {'held_out_gain': gain,
                         'chosen': 'warped' if gain is None or gain > 0 else 'linear'}
        if gain is not None:
            logger.info('phase: %s (a warp predicts held-out recordings %+.2f nats each against '
                        'the linear phase)', info['phase']['chosen'], gain)
    if info['phase']['chosen'] == 'warped':
        with stages('phase warps'):
            model.fit_warps(demos)
    if model.warp_failed_:
        logger.warning('the phase warp of %d demonstration(s) did not converge; they are '
                       'left out of the Gaussian over the warp: %s', len(model.warp_failed_),
                       ', '.join(map(str, model.warp_failed_)))
    info['n_components'] = int(n_components)
    info['prior_scale'] = float(model.prior_scale)
    info['speed_weight'] = float(model.speed_weight)
    info['noise_var'] = np.asarray(model.noise_var_).tolist()
    info['warp_failed'] = [str(n) for n in model.warp_failed_]
    info['seconds'] = dict(stages.seconds)
    return model, info


def _check_prepared(prepared, demos, params):
    """Refuse a ``prepared`` that was not made of these demonstrations with these
    parameters: its weights would silently stand for other ones."""
    n_basis = params.get('n_basis', _DEFAULT_N_BASIS)
    dofs = demos[0].n_observed_dofs + demos[0].n_controlled_dofs
    smoothing = params.get('smoothing')
    if (prepared.smoothing is None or prepared.W.shape != (len(demos), dofs * n_basis)
            or prepared.n_observed != demos[0].n_observed_dofs
            or (smoothing is not None and not np.array_equal(
                np.broadcast_to(np.asarray(smoothing, dtype=float), prepared.smoothing.shape),
                prepared.smoothing))):
        raise ValueError('prepared was not made of these demonstrations with these parameters '
                         '(core.selection.prepare_for_cv(demos, params) with method '
                         "'regression')")


def _pattern_selection(data, candidates, params) -> dict:
    """K by the held-out likelihood in the pattern space (core.patterns), and among the K it
    cannot tell apart, by how reproducible their partitions are (``data``: prepare_for_cv of
    the demonstrations)."""
    space = PatternSpace(params.get('n_basis', _DEFAULT_N_BASIS), data.n_observed,
                         translation=params.get('translation', ())).fit(data.W)
    X = space.transform(data.W)
    held = heldout_curve(X, candidates)
    stability = {}
    # Which K the held-out likelihood supports: those within two paired standard errors of
    # the best (the plateau). Within it, the likelihood alone would split a pattern whose
    # spread is not Gaussian (box assembly's plates, drawn from a 45 cm wide box: K = 4), a
    # split the data do not hold, which cluster stability detects (a split of one pattern
    # falls where each subsample's members put it; core.patterns.partition_stability). The
    # agreement of a K's subsample pairs is read by its median, not its mean: an EM fit on a
    # subsample that now and then lands in another local optimum costs a partition the data
    # reproduce exactly in most pairs its mean, not its median (NuiSI v2's handshake and
    # parachute fist-bump: 1.0 in most of 20 pairs, mean 0.91-0.99), while an arbitrary split
    # is reproduced exactly in few (box plates: median 0.92). So: the K whose median agreement
    # reaches the lower quartile of the most reproducible K's (as reproducible as a quarter of
    # its own pairs); of those, the smallest within one paired standard error of their best
    # held-out likelihood (in a space of one or two dimensions a split of one pattern can be
    # reproducible too, and gains nothing held out).
    def most_reproducible(plateau):
        fits = [i for i in plateau if candidates[i] <= round(0.8 * len(X))]
        if len(fits) < 2:
            return plateau[0]
        agreement = partition_stability(X, [candidates[i] for i in fits])
        median = np.median(agreement, axis=1)
        stability.update({int(candidates[i]): float(m) for i, m in zip(fits, median)})
        quartile = np.percentile(agreement[first_best(median)], 25)
        ok = [i for i, m in zip(fits, median) if m >= quartile - tie_tolerance(agreement)]
        near = not_significantly_worse(held.robust[ok], n_se=1.0)
        return ok[int(np.flatnonzero(near)[0])]
    curve = selection_curve(held.robust, higher_is_better=True, paired=True,
                            choose=most_reproducible)
    summary = _curve_summary(candidates, held.robust, curve)
    return {'criterion': 'patterns', **summary,
            'unit': 'nats per demonstration, leave-one-out, in the pattern space',
            'stability': stability,
            'pattern_dims': int(len(space.components_)),
            'smoothing': data.smoothing.tolist(),
            'explained_variance': float(space.explained_variance_ratio_.sum())}


def _loo_selection(demos, candidates, n_folds, progress, prior_scales, params, n_jobs=None,
                   prepared=None) -> dict:
    """K by the thesis's leave-one-out RMS of the controlled agent, each K at the robot's
    floor calibrated on held-out folds (a K too large for the folds, as leave-one-out trains on
    one more demonstration, takes the floor of the largest K they calibrated)."""
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


def _calibrated_floor(demos, K, n_folds, progress, prior_scales, params, n_jobs=None,
                      prepared=None) -> float:
    """The covariance floor of a K-component model, calibrated on held-out folds: the one with
    the best held-out likelihood or, where there is a controlled agent, the one that predicts
    it best among those not significantly worse (core.mixture.calibrated_heldout_curves)."""
    curves = calibrated_heldout_curves(demos, [K], (), list(prior_scales), n_folds,
                                       _offset_progress(progress, 0, None), n_jobs=n_jobs,
                                       prepared=prepared, **params)
    which = 'controlled_rms' if 'controlled_rms' in curves else 'loglik'
    return float(curves[which]['prior_scale'][0])


def _held_out_scores(demos, data, n_components, labels, n_folds, params, score, n_jobs=None):
    """``score(model, held_out_demonstrations)`` of each of ``n_folds`` folds, the model a
    regression fit of the other folds of ``data`` (prepare_for_cv of ``demos``), as the floor's
    are, on ``n_jobs`` threads, in the folds' order; folds that cannot hold the model (too few
    demonstrations, or not every label) are left out."""
    fold = cv_folds(len(demos), n_folds, 0)

    def one_fold(f):
        train_i, test_i = np.flatnonzero(fold != f), np.flatnonzero(fold == f)
        fit_labels = None if labels is None else [labels[i] for i in train_i]
        if len(train_i) < n_components or (fit_labels is not None
                                           and len(set(fit_labels)) != n_components):
            return None
        model = MixtureIProMP(n_components=n_components, **params).fit(
            data.take(train_i), labels=fit_labels)
        return score(model, [demos[i] for i in test_i])
    return [r for r in map_threads(one_fold, range(fold.max() + 1), n_jobs) if r is not None]


def _calibrated_speed_weight(demos, data, n_components, labels, n_folds, params, n_jobs=None):
    """The speed weight (core.online.SPEED_WEIGHTS) whose tempered phase posterior predicts
    held-out demonstrations' speeds best from their beginnings (core.online.speed_log_scores,
    summed over ``n_folds`` folds: :func:`_held_out_scores`; ties: the larger weight, nearer
    eq. 16), and the mean score of each weight; (1, None) where no fold can hold the model."""
    if len(demos) < 2:
        return 1.0, None
    total, n = np.zeros(len(SPEED_WEIGHTS)), 0
    for score, m in _held_out_scores(demos, data, n_components, labels, n_folds, params,
                                     speed_log_scores, n_jobs):
        total += score
        n += m
    if n == 0:
        return 1.0, None
    best = first_best(total)              # SPEED_WEIGHTS start at eq. 16's weight, 1
    return SPEED_WEIGHTS[best], {f'{w:g}': float(t / n) for w, t in zip(SPEED_WEIGHTS, total)}


def _held_out_warp_gain(demos, data, n_components, labels, n_folds, params, n_jobs=None):
    """How much better the phase warps predict held-out demonstrations than the linear phase:
    the mean of MixtureIProMP.warp_gains (nats per demonstration) over ``n_folds`` folds
    (:func:`_held_out_scores`); None where no fold can hold the model."""
    if len(demos) < 2:
        return None
    gains = _held_out_scores(demos, data, n_components, labels, n_folds, params,
                             lambda model, held_out: model.warp_gains(held_out), n_jobs)
    return float(np.mean(np.concatenate(gains))) if gains else None


def _offset_progress(progress, offset, total):
    """``progress`` of one batch of fits, ``offset`` fits into ``total`` fits in all (None:
    the batch's own total)."""
    if progress is None:
        return None
    return lambda done, n, K: progress(offset + done, n if total is None else total, K)


def majority_names(assigned, labels, n_components) -> list:
    """The majority label among the members of each of ``n_components`` clusters (``assigned``:
    each item's cluster), None for a cluster with none. Ties go to the first label in
    sorted order, so every run names the components alike."""
    labels = np.asarray(labels, dtype=object)
    assigned = np.asarray(assigned)
    out = []
    for k in range(n_components):
        members = labels[assigned == k].tolist()
        out.append(max(sorted(set(members), key=str), key=members.count) if members else None)
    return out


def component_labels(model, demos):
    """Majority training label of each component (for reports only; None if unlabeled)."""
    labels = [d.label for d in demos]
    if any(lbl is None for lbl in labels):
        return None
    names = majority_names(np.argmax(model.resp_, axis=1), labels, model.n_components)
    return [name if name is not None else f'component_{k}' for k, name in enumerate(names)]


def _model_params(kwargs) -> dict:
    """The MixtureIProMP configuration among ``train``'s keyword arguments."""
    names = inspect.signature(MixtureIProMP).parameters
    return {k: v for k, v in kwargs.items() if k in names and k != 'n_components'}


def default_layout(demos, robot=None) -> Layout:
    """The layout of bag demonstrations: the wrist (3, m) observed, ``robot``'s joints (rad)
    controlled; any other layout must be named (a model file records every DOF's name and
    unit)."""
    layout = bag_layout(load_description(robot).joint_names)
    d = demos[0]
    if (d.n_observed_dofs, d.n_controlled_dofs) != (len(layout.observed), len(layout.controlled)):
        raise ValueError(f'demonstrations with {d.n_observed_dofs} observed and '
                         f'{d.n_controlled_dofs} controlled DOFs need a layout naming them '
                         f'(train_to_file(..., layout=Layout(observed=..., controlled=...)))')
    return layout


def train_to_file(demos, out_path, layout: Layout = None, observed_frame: str = None, *,
                  robot=None, **kwargs):
    """:func:`train`, calibrate its novelty test (core.novelty: the evidence of held-out
    demonstrations, for an unsupervised model), then save the model with the layout's names
    and units and the training summary. By default the layout is the bags' (the wrist, and
    ``robot``'s joints: a shipped name, a description file or a RobotDescription; None: the
    iiwa 14) and the observed agent is in the robot's base frame. A wrist in metres gets the
    wrist's observation noise unless ``observation_noise`` is given."""
    demos = list(demos)
    robot = load_description(robot)
    layout = (layout or default_layout(demos, robot)).check(demos)
    if layout.observed == bag_layout().observed and layout.observed_units == ('m',) * 3:
        kwargs.setdefault('observation_noise', WRIST_OBSERVATION_NOISE)
    stages = kwargs.setdefault('stages', Stages())
    checked_jobs(kwargs.get('n_jobs'))
    unsupervised = kwargs.get('labels') is None
    if kwargs.get('prepared') is None and (unsupervised or kwargs.get('method') != 'em'):
        # Training's stages and the novelty folds below share it (train's ``prepared``).
        with stages('preparing'):
            kwargs['prepared'] = prepare_for_cv(demos, {**_model_params(kwargs),
                                                        'method': 'regression'})
    model, info = train(demos, **kwargs)
    if unsupervised:
        # Held-out folds fitted by regression, as the K curves: EM would take minutes.
        params = {**_model_params(kwargs), 'method': 'regression',
                  'prior_scale': model.prior_scale}      # the floor chosen with K
        with stages('novelty'):
            model.novelty_ = calibrate_novelty(
                demos, lambda index: MixtureIProMP(n_components=model.n_components,
                                                   **params).fit(kwargs['prepared'].take(index)),
                n_jobs=kwargs.get('n_jobs'))
        info['novelty'] = {'prefix': model.novelty_.prefix.round(3).tolist(),
                           'window': round(model.novelty_.window, 3)}
    with stages('saving'):
        save_model(Path(out_path), model, layout=layout,
                   observed_frame=robot.base_frame if observed_frame is None else observed_frame,
                   component_labels=component_labels(model, demos),
                   extra={'training': info, 'robot': robot.name})
    info['seconds'] = dict(stages.seconds)
    return model, info
