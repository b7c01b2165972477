"""Real human motion, one agent: PickupGestureWiimoteZ (scenarios.gestures). Who made the
gesture, from the first 30/50/70/100 % of it: by the model training ships for the training
gestures (unsupervised: K chosen as training chooses it; components named by majority over the
training labels), phase unknown (online) and known (the same samples), and online once the end
time is given (the phase is 1 there); by the supervised mixture (one component per person); and
baselines on the same split in the same run: a per-class ProMP, scikit-learn's GaussianMixture
on the model's weights, 1-NN DTW."""

from __future__ import annotations

from pathlib import Path
import time

import numpy as np

from mixture_ip_ros.app.evaluation.baselines import (PerClassProMP, dtw_1nn_accuracy,
                                                     sklearn_gmm_accuracy)
from mixture_ip_ros.app.evaluation.common import (EvalConfig, majority_labels, named_online,
                                                  online_component_given_end,
                                                  phase_known_components, trained)
from mixture_ip_ros.core.mixture import MixtureIProMP
from mixture_ip_ros.core.warped import PhaseWarps
from mixture_ip_ros.viz import plots

GESTURE_FRACTIONS = (0.3, 0.5, 0.7, 1.0)


def gesture_config(quick: bool = False) -> EvalConfig:
    """All 10 people, K from 1 to 15; quick: 4 people (20 train / 20 test), K from 1 to 6."""
    if quick:
        return EvalConfig(candidates=tuple(range(1, 7)), fractions=GESTURE_FRACTIONS,
                          classes=('1', '2', '3', '4'))
    return EvalConfig(candidates=tuple(range(1, 16)), fractions=GESTURE_FRACTIONS)



def evaluate_gestures(train, test, out_dir: Path, config: EvalConfig = None,
                      seed: int = 0) -> dict:
    """Recognition of who made a gesture from part of it; see the module docstring.

    ``train``/``test``: labelled single-agent Demonstrations (every method, DTW included, sees
    the same series). Labels never reach the unsupervised fit; they name its components
    afterwards.
    """
    config = config or gesture_config()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    if config.classes is not None:
        keep = {str(c) for c in config.classes}
        train = [d for d in train if d.label in keep]
        test = [d for d in test if d.label in keep]
    if any(d.label is None for d in train + test):
        raise ValueError('gesture evaluation needs labelled demonstrations')
    y_train = np.array([d.label for d in train])
    y_test = np.array([d.label for d in test])
    classes = sorted(set(y_train.tolist()), key=lambda c: (len(c), c))
    fractions = tuple(float(f) for f in config.fractions)
    keys = [f'{f:g}' for f in fractions]
    params = dict(config.model)
    timings = {}

    # Unsupervised: what training ships for the training gestures (labels unused): K by its
    # criterion, the floor calibrated for that K.
    t0 = time.perf_counter()
    model, info = trained(train, config, random_state=seed)
    K = info['n_components']
    sel = info['selection']
    timings['unsupervised_fit_s'] = round(time.perf_counter() - t0, 2)
    names = majority_labels(model, train)

    def accuracy(pred_rows, truth):
        P = np.asarray(pred_rows)
        return {k: float(np.mean(P[:, c] == truth)) for c, k in enumerate(keys)}
    t0 = time.perf_counter()
    unsup = accuracy(named_online(model, names, test, fractions, config.n_alpha,
                                  config.min_interval), y_test)
    unsup_known = accuracy([[names[k] for k in phase_known_components(
        model, d, fractions, config.min_interval)] for d in test], y_test)

    def accuracy_given_end(mod, labels):
        return float(np.mean([labels[online_component_given_end(
            mod, d, config.n_alpha, config.min_interval)] == y for d, y in zip(test, y_test)]))
    unsup_end = accuracy_given_end(model, names)
    timings['unsupervised_test_s'] = round(time.perf_counter() - t0, 2)

    # Supervised: one component per class, tied noise and one covariance prior for all.
    t0 = time.perf_counter()
    sup_model = MixtureIProMP(n_components=len(classes), random_state=seed, **params).fit(
        train, labels=y_train)
    sup_model.warps_ = PhaseWarps().fit(sup_model, train)
    cls = sup_model.classes_
    sup = accuracy(named_online(sup_model, cls, test, fractions, config.n_alpha,
                                config.min_interval), y_test)
    sup_known = accuracy([[cls[k] for k in phase_known_components(
        sup_model, d, fractions, config.min_interval)] for d in test], y_test)
    sup_end = accuracy_given_end(sup_model, cls)
    # What knowing the phase adds besides the duration: the same without p(alpha | k).
    sup_shape = accuracy([[cls[k] for k in phase_known_components(
        sup_model, d, fractions, config.min_interval, duration=False)] for d in test], y_test)
    timings['supervised_s'] = round(time.perf_counter() - t0, 2)

    # Baselines, same split, same run.
    t0 = time.perf_counter()
    n_basis = params.get('n_basis', 15)
    promp = PerClassProMP(n_basis, fractions=fractions).fit(train, y_train)
    promp_acc = accuracy([[promp.predict_prefix(d, f) for f in fractions] for d in test], y_test)
    W_train = model.demonstration_weights(train)
    W_test = model.demonstration_weights(test)
    gmm_acc, gmm_seed = sklearn_gmm_accuracy(W_train, y_train, W_test, y_test, K,
                                             seeds=range(seed, seed + 10))
    timings['baselines_promp_gmm_s'] = round(time.perf_counter() - t0, 2)

    # Reference, not the selected model: K fixed to the number of classes (their count is the
    # only thing read from the labels), the mixture at the default floor against scikit-learn
    # with the same K. Shows what the unsupervised fit does when the selection cannot choose.
    t0 = time.perf_counter()
    Kc = len(classes)
    ref = MixtureIProMP(n_components=Kc, random_state=seed, **params).fit(train)
    ref.warps_ = PhaseWarps().fit(ref, train)
    ref_names = majority_labels(ref, train)
    ref_acc = accuracy(named_online(ref, ref_names, test, fractions, config.n_alpha,
                                    config.min_interval), y_test)
    ref_end = accuracy_given_end(ref, ref_names)
    ref_gmm, _ = sklearn_gmm_accuracy(W_train, y_train, W_test, y_test, Kc,
                                      seeds=range(seed, seed + 10))
    timings['reference_k_classes_s'] = round(time.perf_counter() - t0, 2)
    t0 = time.perf_counter()
    dtw_acc = dtw_1nn_accuracy([d.observed[:, 0] for d in train], y_train,
                               [d.observed[:, 0] for d in test], y_test)
    timings['baseline_dtw_s'] = round(time.perf_counter() - t0, 2)

    assigned = np.argmax(model.resp_, axis=1)
    counts = np.array([[int(np.sum((assigned == k) & (y_train == c))) for c in classes]
                       for k in range(K)])
    chance = 1.0 / len(classes)
    plots.accuracy_vs_fraction(
        out_dir / 'gestures_accuracy_vs_fraction.png', fractions,
        {'mixture, unsupervised, phase unknown (online)': [unsup[k] for k in keys],
         'mixture, unsupervised, phase known': [unsup_known[k] for k in keys],
         'mixture, supervised, phase unknown (online)': [sup[k] for k in keys],
         'mixture, supervised, phase known': [sup_known[k] for k in keys],
         'per-class ProMP (baseline), phase known': [promp_acc[k] for k in keys]},
        {f'scikit-learn GMM, K = {K}': gmm_acc, '1-NN DTW': dtw_acc},
        f'PickupGestureWiimoteZ: who made the gesture ({len(classes)} people, '
        f'{len(test)} test gestures)', chance=chance,
        points={'mixture, supervised, online, then the end time given': (1.0, sup_end),
                'mixture, unsupervised, online, then the end time given': (1.0, unsup_end)})
    plots.clusters_vs_labels(out_dir / 'gestures_clusters_vs_labels.png', counts,
                             [n or '-' for n in names], classes,
                             f'Unsupervised mixture, K = {K}: training gestures per component')
    plots.k_curve(out_dir / 'gestures_k_curve.png', sel['candidates'], sel['mean'], sel['se'], K,
                  'Gestures: leave-one-out log-likelihood in the pattern space vs K',
                  sel['note'])
    return {
        'n_components_selected': int(K),
        'unsupervised_accuracy_by_fraction': unsup,
        'unsupervised_accuracy_phase_known_by_fraction': unsup_known,
        'supervised_accuracy_by_fraction': sup,
        'supervised_accuracy_phase_known_by_fraction': sup_known,
        'supervised_accuracy_phase_known_without_duration_by_fraction': sup_shape,
        'unsupervised_accuracy_given_end': unsup_end,
        'supervised_accuracy_given_end': sup_end,
        'baseline_promp_accuracy_by_fraction': promp_acc,
        'baseline_sklearn_gmm_accuracy': gmm_acc,
        'baseline_dtw_accuracy': dtw_acc,
        'k_selection': sel,
        'prior_scale': info['prior_scale'],
        'speed_weight': info['speed_weight'],
        'baseline_promp_shrinkage': promp.shrinkage_,
        'component_labels': names,
        'clusters_vs_labels': {'classes': classes, 'counts': counts.tolist()},
        'baseline_sklearn_gmm_seed': gmm_seed,
        'reference_k_classes': {'n_components': Kc,
                                'unsupervised_accuracy_by_fraction': ref_acc,
                                'unsupervised_accuracy_given_end': ref_end,
                                'baseline_sklearn_gmm_accuracy': ref_gmm},
        'chance_accuracy': chance,
        'n_train': len(train), 'n_test': len(test), 'n_classes': len(classes),
        'durations_s': {'train_median': float(np.median([d.duration for d in train])),
                        'train_range': [float(min(d.duration for d in train)),
                                        float(max(d.duration for d in train))]},
        'noise_var': np.asarray(model.noise_var_).tolist(),
        'units': {'accuracy': 'fraction of test gestures whose person is named correctly',
                  'fractions': 'part of the recording observed (from its first sample)',
                  'given_end': 'the whole recording fed to the online estimator (phase '
                               'unknown), then its end time given, where the phase is 1, '
                               "each component's warp integrated out where the model has "
                               'warps (OnlineEstimator.end_posterior; the supervised and '
                               'reference models always, the unsupervised one where training '
                               'kept them); beside the same without '
                               'the end, the "1" of the phase-unknown curves',
                  'noise_var': 'g^2'},
        'timings_s': timings,
        'config': config.to_dict(),
        'plots': ['gestures_accuracy_vs_fraction.png', 'gestures_clusters_vs_labels.png',
                  'gestures_k_curve.png'],
    }


