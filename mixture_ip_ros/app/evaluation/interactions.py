"""Real two-person interactions (NuiSI v1 and v2), and any folder of labelled recordings: do the
patterns the package finds without labels match the interactions, and how well does it
recognise the interaction and predict the partner from part of the observed person's movement?

Stratified 5-fold cross-validation (seed 0): in each fold the package trains on the other four
folds as ``training.train`` does (K chosen from those recordings only, covariance floor
calibrated), labels only name its components afterwards (majority). Per fold:

- ``ari``: the training recordings' components against their interactions (adjusted Rand
  index); ``heldout_ari``: the held-out recordings', each in the component most probable given
  its whole observed path (eq. 11, phase known);
- online, phase unknown, as the estimator node works (OnlineEstimator fed the first 30, 50, 70,
  100 % of the observed agent at its decimation rate): the interaction recognised (the MAP
  component's name), and the controlled agent predicted over the rest of the interaction as the
  node plans it (the MAP component's expected path, the phase speed marginalised under the
  speed weight training calibrated) against the recorded one: RMS over the remaining samples
  and the error at the last one;
- the same for the model with K = 1, the supervised model (one component per interaction)
  and, to tell the choice of K from the rest, the unsupervised model with K the number of
  interactions (``true_k_accuracy_by_fraction``); for the model with K chosen, the interaction
  recognised with the phase known (eq. 11 with alpha = 1/T and p(alpha | k), on the samples the
  estimator absorbs: ``phase_known_accuracy_by_fraction``), so that what the online estimator
  loses to the unknown phase shows apart from what the clustering loses, the online
  accuracy per interaction (``recognition_accuracy_by_interaction``) and, at half the movement
  and at its end, which interaction was recognised for which (counts:
  ``recognition_confusion_by_fraction``);
- baselines on the same folds: k-means and a GaussianMixture on the resampled paths of both
  agents with the true number of interactions (ARI), and the nearest training recording by
  open-end DTW on the observed prefix (its interaction; its partner path, time-scaled).
Numbers are means over the held-out recordings of all folds (ARIs: over the folds).

With ``EvalConfig.labelled_per_class`` > 0 the mixture with K chosen is given the labels of that
many training recordings of every interaction (semi-supervised: training.train with labels for
some) and ``unlabelled_ari`` is its ARI on the other training recordings; the model with K the
number of interactions stays unsupervised.
"""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor, as_completed
from functools import partial
from multiprocessing import get_context
import os
from pathlib import Path
import time

import numpy as np

from mixture_ip_ros.app.evaluation.baselines import NearestNeighbour, clustering_baselines
from mixture_ip_ros.app.evaluation.common import (EvalConfig, majority_labels,
                                                  phase_known_components, trained)
from mixture_ip_ros.app.naming import named_components
from mixture_ip_ros.core.online import OnlineEstimator
from mixture_ip_ros.core.playback import observed_rows, prefix_predictions, rest_rows
from mixture_ip_ros.viz import plots

FRACTIONS = (0.3, 0.5, 0.7, 1.0)
# Where the confusion tables are read: half the movement, and all of it.
CONFUSION_FRACTIONS = (0.5, 1.0)
N_FOLDS = 5
METHODS = ('mixture', 'single', 'supervised', 'true_k', 'nearest', 'phase_known')


def interactions_config(quick: bool = False) -> EvalConfig:
    """K over 1..9 (more than the six interactions of v1); quick: 1..6."""
    return EvalConfig(candidates=tuple(range(1, 7 if quick else 10)), fractions=FRACTIONS)


def stratified_folds(labels, n_folds: int = N_FOLDS, seed: int = 0) -> np.ndarray:
    """Fold of each recording: every label's recordings dealt round the folds in a seeded
    order, so each fold holds about 1/n_folds of every interaction."""
    labels = np.asarray(labels)
    rng = np.random.default_rng(seed)
    fold = np.empty(len(labels), dtype=int)
    start = 0
    for lbl in sorted(set(labels.tolist()), key=str):
        members = rng.permutation(np.flatnonzero(labels == lbl))
        fold[members] = (start + np.arange(len(members))) % n_folds
        start += len(members)
    return fold


def kept_share(rows, labels, fraction: float, seed: int) -> np.ndarray:
    """``fraction`` of ``rows`` of every label (at least two each, rounded), drawn with
    ``seed``; sorted."""
    if not 0 < fraction <= 1:
        raise ValueError(f'train_fraction must be in (0, 1], got {fraction!r}')
    rng = np.random.default_rng(seed)
    keep = []
    for lbl in sorted(set(labels[rows].tolist()), key=str):
        members = rows[labels[rows] == lbl]
        n = min(len(members), max(2, int(round(fraction * len(members)))))
        keep.append(rng.choice(members, n, replace=False))
    return np.sort(np.concatenate(keep))


def named_share(rows, labels, n: int, seed: int) -> np.ndarray:
    """``n`` of ``rows`` of every label (all of a label with fewer), drawn with ``seed``;
    sorted."""
    rng = np.random.default_rng(seed)
    out = [rng.choice(members, min(n, len(members)), replace=False)
           for lbl in sorted(set(labels[rows].tolist()), key=str)
           for members in [rows[labels[rows] == lbl]]]
    return np.sort(np.concatenate(out))


def confusion(truth, said, classes) -> dict:
    """{true label: {recognised label: count}}: every one of ``classes`` a row, every label
    recognised a column (the classes, then any other name a component has), zeros kept."""
    said = np.asarray(said, dtype=object)
    columns = list(classes) + sorted({str(s) for s in said if s is not None} - set(classes))
    return {c: {s: int(np.sum((truth == c) & (said == s))) for s in columns} for c in classes}


def _ari(a, b) -> float:
    from sklearn.metrics import adjusted_rand_score
    return float(adjusted_rand_score(a, b))


def path_errors(pred, truth):
    """(RMS over the samples, error at the last one), metres."""
    d = np.linalg.norm(pred - truth, axis=1)
    return float(np.sqrt(np.mean(d ** 2))), float(d[-1])


def contact_row(demo):
    """The sample where the two agents' positions are closest (the recorded contact of a
    handshake or a fist bump, the closest approach of the others), among those where both are
    recorded; None without a controlled agent of the observed one's dimension."""
    if demo.n_controlled_dofs != demo.n_observed_dofs:
        return None
    both = np.flatnonzero(~np.isnan(demo.observed).any(axis=1)
                          & ~np.isnan(demo.controlled).any(axis=1))
    if not both.size:
        return None
    gap = np.linalg.norm(demo.observed[both] - demo.controlled[both], axis=1)
    return int(both[np.argmin(gap)])


def _people_contact_distance(demos, unit):
    """The two recorded agents' mean distance at their contact (:func:`contact_row`), None
    where no recording has one."""
    gaps = [np.linalg.norm(d.observed[row] - d.controlled[row]) for d in demos
            for row in [contact_row(d)] if row is not None]
    return float(unit * np.mean(gaps)) if gaps else None


def _at_contact(pred, rest, row, truth):
    """The prediction's error at the contact sample ``row`` if it is among ``rest`` (the
    samples predicted), else NaN (the contact was already observed)."""
    where = np.flatnonzero(rest == row) if row is not None else ()
    if not len(where):
        return np.nan
    return float(np.linalg.norm(pred[where[0]] - truth[row]))


def _fold(demos, labels, fold, config: EvalConfig, seed: int, f: int) -> dict:
    """Fold ``f`` of :func:`evaluate_labelled`: the models trained on the other folds, every
    method's results on this fold's recordings (their rows), the fold's summary, the mixture's
    prediction at half the movement of the first recording of each interaction, timings."""
    classes = sorted(set(labels.tolist()), key=str)
    has_partner = demos[0].n_controlled_dofs > 0
    fractions = tuple(float(x) for x in config.fractions)
    train_i, test_i = np.flatnonzero(fold != f), np.flatnonzero(fold == f)
    if config.train_fraction < 1:
        train_i = kept_share(train_i, labels, config.train_fraction, seed + f)
    train = [demos[i] for i in train_i]
    # The mixture's labels: none, or a few training recordings of every interaction named.
    fit_labels = None
    if config.labelled_per_class:
        named = set(named_share(train_i, labels, config.labelled_per_class, seed + f).tolist())
        fit_labels = [labels[i] if i in named else None for i in train_i]
    shape = (len(test_i), len(fractions))
    right = {m: np.zeros(shape, dtype=bool) for m in METHODS}
    said = np.empty(shape, dtype=object)          # the interaction the mixture recognised
    rms = {m: np.full(shape, np.nan) for m in METHODS}
    final = {m: np.full(shape, np.nan) for m in METHODS}
    contact = {m: np.full(shape, np.nan) for m in METHODS}
    phase_error = np.full(shape, np.nan)
    contacts = [contact_row(demos[i]) for i in test_i]
    examples, timings = {}, {}
    t0 = time.perf_counter()
    # One thread per fold's training: the folds already fill the cores, a process each
    # (run_in_processes).
    fit = partial(trained, train, config, n_jobs=1)
    model, info = fit(random_state=seed, labels=fit_labels)
    single, _ = fit(n_components=1)
    supervised, _ = fit(labels=labels[train_i])
    # Training with K given fits what training with K chosen fits once it chose that K.
    true_k = (model if info['n_components'] == len(classes) and fit_labels is None else
              fit(n_components=len(classes), random_state=seed)[0])
    timings['training_s'] = time.perf_counter() - t0
    names = (majority_labels(model, train) if fit_labels is None
             else named_components(model, train))
    comp_train = np.argmax(model.resp_, axis=1)
    heldout = [int(np.argmax(model.component_posterior(
        demos[i].phase[ok], demos[i].observed[ok], alpha=1.0 / demos[i].duration)))
        for i in test_i for ok in [observed_rows(demos[i])]]
    t0 = time.perf_counter()
    namers = {'mixture': (model, names), 'single': (single, majority_labels(single, train)),
              'supervised': (supervised, list(supervised.classes_)),
              'true_k': (true_k, majority_labels(true_k, train))}
    for r, i in enumerate(test_i):
        right['phase_known'][r] = [names[k] == labels[i] for k in phase_known_components(
            model, demos[i], fractions, config.min_interval)]
    for m, (mod, nm) in namers.items():
        est = OnlineEstimator(mod, n_alpha=config.n_alpha, min_interval=config.min_interval)
        for r, i in enumerate(test_i):
            for c, (k, pred, rest, alpha) in enumerate(
                    prefix_predictions(est, demos[i], fractions)):
                right[m][r, c] = nm[k] == labels[i]
                if m == 'mixture':
                    said[r, c] = nm[k]
                    # against the recording's own progress t / T at the prefix's end
                    phase_error[r, c] = fractions[c] * abs(alpha * demos[i].duration - 1.0)
                if pred is not None and has_partner:
                    rms[m][r, c], final[m][r, c] = path_errors(pred, demos[i].controlled[rest])
                    contact[m][r, c] = _at_contact(pred, rest, contacts[r], demos[i].controlled)
                    if m == 'mixture' and abs(fractions[c] - 0.5) < 1e-9:
                        examples.setdefault(labels[i], (i, rest, pred, nm[k]))
    timings['online_s'] = time.perf_counter() - t0
    t0 = time.perf_counter()
    clustering = clustering_baselines(train, labels[train_i], len(classes),
                                      seeds=range(seed, seed + 5))
    nn = NearestNeighbour(config.min_interval, config.model.get('translation', ())).fit(
        train, labels[train_i])
    for r, i in enumerate(test_i):
        d = demos[i]
        for c, (j, scale, shift) in enumerate(nn.matches(d, fractions)):
            rest = rest_rows(d, fractions[c] * d.duration)
            label, pred = nn.predict(j, scale, d.t[rest], shift)
            right['nearest'][r, c] = label == labels[i]
            if rest.size and has_partner:
                rms['nearest'][r, c], final['nearest'][r, c] = path_errors(pred, d.controlled[rest])
                contact['nearest'][r, c] = _at_contact(pred, rest, contacts[r], d.controlled)
    timings['baselines_s'] = time.perf_counter() - t0
    summary = {'n_components': int(info['n_components']),
               'prior_scale': info['prior_scale'],
               'clear_optimum': bool(info['selection']['clear_optimum']),
               'speed_weight': info['speed_weight'],
               'curve': info['selection']['mean'],
               'ari': _ari(labels[train_i], comp_train),
               'heldout_ari': _ari(labels[test_i], heldout),
               'component_labels': names,
               'baseline_kmeans_ari': clustering['kmeans'],
               'baseline_gmm_pca_ari': clustering['gmm_pca']}
    if fit_labels is not None:
        free = np.array([lbl is None for lbl in fit_labels])
        summary['unlabelled_ari'] = _ari(labels[train_i][free], comp_train[free])
    return {'rows': test_i, 'right': right, 'said': said, 'rms': rms, 'final': final,
            'contact': contact, 'phase_error': phase_error, 'fold': summary,
            'examples': examples, 'timings': timings}


def fold_tasks(demos, config: EvalConfig, seed: int) -> list:
    """The folds of :func:`evaluate_labelled` as independent tasks (checked first)."""
    labels = np.array([d.label for d in demos])
    if any(lbl is None for lbl in labels):
        raise ValueError('the evaluation needs a label for every recording')
    classes = sorted(set(labels.tolist()), key=str)
    if len(classes) < 2 or min(np.sum(labels == c) for c in classes) < N_FOLDS:
        raise ValueError(f'{N_FOLDS}-fold cross-validation needs at least {N_FOLDS} recordings '
                         f'of each of at least 2 labels, got {len(demos)} of {len(classes)}')
    fold = stratified_folds(labels, N_FOLDS, seed)
    return [partial(_fold, demos, labels, fold, config, seed, f) for f in range(N_FOLDS)]


def run_in_processes(tasks, on_done=None) -> list:
    """The tasks' results in order, one process per core; ``on_done(done, total, index,
    result)`` is called as each task ends (in the order they end). Each task is pickled to its
    worker with its recordings. The workers are forked from a server process that imported this
    module and nothing else (multiprocessing's forkserver), not from the caller: a worker
    forked from a process that had run ROS nodes inherited their DDS threads' objects, and its
    garbage collector crashed it (a segmentation fault in the test suite). The estimator's
    kernels come compiled from numba's cache."""
    on_done = on_done or (lambda done, total, index, result: None)
    workers = min(len(tasks), len(os.sched_getaffinity(0)))
    if workers <= 1:
        results = []
        for index, task in enumerate(tasks):
            results.append(task())
            on_done(index + 1, len(tasks), index, results[-1])
        return results
    context = get_context('forkserver')
    context.set_forkserver_preload([__name__])
    with ProcessPoolExecutor(workers, mp_context=context) as pool:
        jobs = {pool.submit(task): index for index, task in enumerate(tasks)}
        for done, job in enumerate(as_completed(jobs), 1):
            on_done(done, len(tasks), jobs[job], job.result())
        return [job.result() for job in jobs]


def fold_progress(progress, names):
    """:func:`run_in_processes`'s ``on_done`` for folds of :func:`fold_tasks` that say how each
    went on ``progress(line)`` (None: nothing shown); ``names``: the data set of each task."""
    if progress is None:
        return None

    def on_done(done, total, index, result):
        seconds = sum(result['timings'].values())
        progress(f'{names[index]}: fold {index % N_FOLDS + 1} of {N_FOLDS} done '
                 f'({done}/{total}): K = {result["fold"]["n_components"]}, '
                 f'{len(result["rows"])} held out, {seconds:.0f} s')
    return on_done


def evaluate_labelled(demos, out_dir: Path, config: EvalConfig = None, name: str = 'recordings',
                      seed: int = 0, cm: bool = True, progress=None, *,
                      dof_names=None) -> dict:
    """The cross-validated metrics of the module docstring for labelled Demonstrations (any
    numbers of observed and controlled DOFs; partner errors need a controlled agent); plots
    go to ``out_dir`` prefixed with ``name``. ``cm``: errors reported in cm (the DOFs in
    metres), else in the DOFs' own unit. ``progress(line)``: told as each fold ends.
    ``dof_names``: (observed names, controlled names) for the plots' colour keys."""
    config = config or interactions_config()
    demos = list(demos)
    tasks = fold_tasks(demos, config, seed)
    if progress is not None:
        progress(f'{name}: {N_FOLDS}-fold cross-validation of {len(demos)} recordings')
    results = run_in_processes(tasks, fold_progress(progress, [name] * len(tasks)))
    return fold_metrics(demos, results, out_dir, config, name, cm, dof_names=dof_names)


def fold_metrics(demos, results, out_dir: Path, config: EvalConfig, name: str, cm: bool, *,
                 dof_names=None) -> dict:
    """:func:`evaluate_labelled`'s metrics and plots from its folds' results."""
    labels = np.array([d.label for d in demos])
    classes = sorted(set(labels.tolist()), key=str)
    has_partner = demos[0].n_controlled_dofs > 0
    unit = 100.0 if cm else 1.0
    fractions = tuple(float(f) for f in config.fractions)
    keys = [f'{f:g}' for f in fractions]
    right = {m: np.zeros((len(demos), len(fractions)), dtype=bool) for m in METHODS}
    rms = {m: np.full((len(demos), len(fractions)), np.nan) for m in METHODS}
    final = {m: np.full((len(demos), len(fractions)), np.nan) for m in METHODS}
    contact = {m: np.full((len(demos), len(fractions)), np.nan) for m in METHODS}
    phase_error = np.full((len(demos), len(fractions)), np.nan)
    said = np.empty((len(demos), len(fractions)), dtype=object)
    per_fold, examples = [], {}
    timings = {'training_s': 0.0, 'online_s': 0.0, 'baselines_s': 0.0}
    for r in results:
        said[r['rows']] = r['said']
        for m in METHODS:
            right[m][r['rows']], rms[m][r['rows']] = r['right'][m], r['rms'][m]
            final[m][r['rows']] = r['final'][m]
            contact[m][r['rows']] = r['contact'][m]
        phase_error[r['rows']] = r['phase_error']
        per_fold.append(r['fold'])
        for lbl, (i, rest, pred, named) in r['examples'].items():
            examples.setdefault(lbl, (demos[i], rest, pred, named))
        for key in timings:
            timings[key] += r['timings'][key]

    def by_fraction(values, scale=1.0):
        return {k: (None if np.all(np.isnan(values[:, c])) else
                    float(scale * np.nanmean(values[:, c]))) for c, k in enumerate(keys)}
    accuracy = {m: {k: float(right[m][:, c].mean()) for c, k in enumerate(keys)}
                for m in METHODS}
    metrics = {
        'n_recordings': len(demos), 'interactions': classes, 'n_folds': N_FOLDS,
        'n_components_selected': [p['n_components'] for p in per_fold],
        'ari': float(np.mean([p['ari'] for p in per_fold])),
        'heldout_ari': float(np.mean([p['heldout_ari'] for p in per_fold])),
        'recognition_accuracy_by_fraction': accuracy['mixture'],
        'baseline_kmeans_ari': float(np.mean([p['baseline_kmeans_ari'] for p in per_fold])),
        'baseline_gmm_pca_ari': float(np.mean([p['baseline_gmm_pca_ari'] for p in per_fold])),
        'baseline_nn_accuracy_by_fraction': accuracy['nearest'],
        'single_accuracy_by_fraction': accuracy['single'],
        'supervised_accuracy_by_fraction': accuracy['supervised'],
        'true_k_accuracy_by_fraction': accuracy['true_k'],
        'phase_known_accuracy_by_fraction': accuracy['phase_known'],
        'phase_error_by_fraction': by_fraction(phase_error),
        'recognition_accuracy_by_interaction': {
            c: {k: float(right['mixture'][labels == c, j].mean()) for j, k in enumerate(keys)}
            for c in classes},
        'recognition_confusion_by_fraction': {
            k: confusion(labels, said[:, j], classes) for j, k in enumerate(keys)
            if any(abs(fractions[j] - f) < 1e-9 for f in CONFUSION_FRACTIONS)},
        'folds': per_fold,
    }
    if per_fold and 'unlabelled_ari' in per_fold[0]:
        # a few training recordings of every interaction named (EvalConfig.labelled_per_class)
        metrics['unlabelled_ari'] = float(np.mean([p['unlabelled_ari'] for p in per_fold]))
    err_unit = 'cm' if cm else 'unit'
    if has_partner:
        metrics.update({
            f'partner_rms_{err_unit}_by_fraction': by_fraction(rms['mixture'], unit),
            f'partner_final_{err_unit}_by_fraction': by_fraction(final['mixture'], unit),
            f'baseline_nn_partner_rms_{err_unit}_by_fraction': by_fraction(rms['nearest'], unit),
            f'baseline_nn_partner_final_{err_unit}_by_fraction': by_fraction(final['nearest'],
                                                                            unit),
            f'single_partner_rms_{err_unit}_by_fraction': by_fraction(rms['single'], unit),
            f'single_partner_final_{err_unit}_by_fraction': by_fraction(final['single'], unit),
            f'supervised_partner_rms_{err_unit}_by_fraction': by_fraction(rms['supervised'],
                                                                          unit),
            f'supervised_partner_final_{err_unit}_by_fraction': by_fraction(final['supervised'],
                                                                            unit),
            **{f'{prefix}partner_contact_{err_unit}_by_fraction': by_fraction(contact[m], unit)
               for m, prefix in (('mixture', ''), ('nearest', 'baseline_nn_'),
                                 ('single', 'single_'), ('supervised', 'supervised_'))},
            'contact_observed_share_by_fraction': {
                k: float(np.mean(np.isnan(contact['mixture'][:, c]))) for c, k in enumerate(keys)},
            f'people_contact_distance_{err_unit}': _people_contact_distance(demos, unit)})
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    chance = max(np.mean(labels == c) for c in classes)
    plots.accuracy_vs_fraction(
        out_dir / f'{name}_accuracy_vs_fraction.png', fractions,
        {'mixture, K chosen, phase unknown (online)': [accuracy['mixture'][k] for k in keys],
         'mixture, supervised, online': [accuracy['supervised'][k] for k in keys],
         '1-NN open-end DTW (baseline)': [accuracy['nearest'][k] for k in keys]}, {},
        f'{name}: the interaction recognised from part of the observed movement',
        chance=chance)
    names_plot = [f'{name}_accuracy_vs_fraction.png']
    if has_partner:
        plots.errors_vs_fraction(
            out_dir / f'{name}_partner_error_vs_fraction.png', fractions[:-1],
            {'mixture, K chosen': rms['mixture'][:, :-1] * unit,
             'mixture, supervised': rms['supervised'][:, :-1] * unit,
             'one ProMP (K = 1)': rms['single'][:, :-1] * unit,
             'nearest neighbour (baseline)': rms['nearest'][:, :-1] * unit},
            f'{name}: the partner predicted over the rest of the interaction',
            f'RMS over the rest [{"cm" if cm else "DOF unit"}]')
        plots.partner_paths(out_dir / f'{name}_partner_paths.png',
                            [examples[c] for c in classes if c in examples], scale=unit,
                            unit='cm' if cm else 'DOF unit', dof_names=dof_names)
        names_plot += [f'{name}_partner_error_vs_fraction.png', f'{name}_partner_paths.png']
    metrics['timings_s'] = {k: round(v, 2) for k, v in timings.items()}
    metrics['units'] = {'ari': 'adjusted Rand index, mean over folds',
                        'accuracy': 'fraction of held-out recordings (all folds)',
                        'partner': f'{err_unit}: RMS of the controlled agent over the samples '
                                   'after the observed fraction, and its error at the last '
                                   'one, mean over held-out recordings (no rest after 100 %); '
                                   'at the contact (the samples where the two agents are '
                                   'closest), mean over the recordings whose contact comes '
                                   'after the observed fraction',
                        'phase_error': 'the estimated phase alpha* f T against the progress f '
                                       'at the prefix\'s end, mean absolute',
                        'chance': 'the largest interaction share',
                        'confusion': 'held-out recordings (all folds) of each interaction '
                                     '(rows) by the interaction the mixture recognised online '
                                     'from that fraction of the movement (columns; a '
                                     'component no interaction names: component_k)'}
    metrics['chance_accuracy'] = float(chance)
    metrics['config'] = config.to_dict()
    metrics['plots'] = names_plot
    return metrics


def evaluate_nuisi(out_dir: Path, config: EvalConfig = None, seed: int = 0,
                   versions=('v1', 'v2'), progress=None) -> dict:
    """NuiSI v1 and v2 (scenarios.nuisi): every recording of both upstream splits, person 1's
    hand observed, person 2's controlled. {version: metrics} plus the source.
    ``progress(line)``: told as each fold ends."""
    from mixture_ip_ros.scenarios import nuisi
    config = config or interactions_config()
    sets = {v: nuisi.demonstrations(v, 'train') + nuisi.demonstrations(v, 'test')
            for v in versions}
    # Every version's folds in one pool, the version with more samples first (its folds take
    # longest), so that the cores stay busy to the end.
    order = sorted(versions, key=lambda v: -sum(len(d.t) for d in sets[v]))
    tasks = [t for v in order for t in fold_tasks(sets[v], config, seed)]
    results = run_in_processes(tasks, fold_progress(
        progress, [f'nuisi_{v}' for v in order for _ in range(N_FOLDS)]))
    out = {}
    for g, v in enumerate(order):
        out[v] = {'source': nuisi.SOURCE.format(version=v, commit=nuisi.VERSIONS[v].commit),
                  **fold_metrics(sets[v], results[g * N_FOLDS:(g + 1) * N_FOLDS], out_dir, config,
                             f'nuisi_{v}', cm=True)}
    return {v: out[v] for v in versions}
