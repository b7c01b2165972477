"""Experiment: what the covariance floor does to online recognition and partner prediction on
real interactions (NuiSI), the phase unknown, as the estimator node works. Prints one JSON
object.

Each fold of the interactions evaluation (stratified 5-fold, seed 0) is trained as
``training.train`` ships it (K chosen, floor calibrated, speed weight calibrated), then again
with the same K and each fixed floor (the speed weight calibrated for it). Per floor: the
interaction recognised online from the first 30 / 50 / 70 / 100 % of the held-out recordings
(components named by the training majority), the partner's RMS over the rest (cm), and the
held-out likelihood the calibration reads (phase known, both agents, mean per recording over
the training recordings' inner folds, as core.selection computes it).

    OPENBLAS_NUM_THREADS=1 python experiments/floor_online.py [--version v2] [--floors 0.1,0.02]
"""

import argparse
import json
import time

import numpy as np

from mixture_ip_ros.app.evaluation.common import majority_labels, trained
from mixture_ip_ros.app.evaluation.interactions import (FRACTIONS, N_FOLDS, path_errors,
                                                        interactions_config, stratified_folds)
from mixture_ip_ros.core.online import OnlineEstimator
from mixture_ip_ros.core.playback import prefix_predictions
from mixture_ip_ros.core.selection import calibrated_heldout_curves
from mixture_ip_ros.scenarios import nuisi


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--version', default='v2', choices=sorted(nuisi.VERSIONS))
    ap.add_argument('--floors', default='1,0.316,0.1,0.0316,0.01,0.00316,0.001')
    args = ap.parse_args()
    floors = [float(s) for s in args.floors.split(',')]
    t0 = time.perf_counter()
    demos = (nuisi.demonstrations(args.version, 'train')
             + nuisi.demonstrations(args.version, 'test'))
    labels = np.array([d.label for d in demos])
    fold = stratified_folds(labels)
    config = interactions_config()
    keys = ['calibrated'] + [f'{s:g}' for s in floors]
    right = {k: np.zeros((len(demos), len(FRACTIONS))) for k in keys}
    rms = {k: np.full((len(demos), len(FRACTIONS)), np.nan) for k in keys}
    per_fold = []
    for f in range(N_FOLDS):
        train_i, test_i = np.flatnonzero(fold != f), np.flatnonzero(fold == f)
        train = [demos[i] for i in train_i]
        shipped, info = trained(train, config, random_state=0)
        K = info['n_components']
        curves = calibrated_heldout_curves(train, [K], (), floors, controlled=False,
                                           method='regression')
        models = {'calibrated': shipped}
        for s in floors:
            models[f'{s:g}'] = trained(train, config, n_components=K, prior_scale=s,
                                       random_state=0)[0]
        for key, model in models.items():
            names = majority_labels(model, train)
            est = OnlineEstimator(model, n_alpha=config.n_alpha,
                                  min_interval=config.min_interval)
            for i in test_i:
                for c, (k, pred, rest, _) in enumerate(prefix_predictions(est, demos[i],
                                                                     FRACTIONS)):
                    right[key][i, c] = names[k] == labels[i]
                    if pred is not None:
                        rms[key][i, c] = path_errors(pred, demos[i].controlled[rest])[0]
        per_fold.append({'n_components': K, 'calibrated_floor': info['prior_scale'],
                         'heldout_loglik': {f'{s:g}': float(v) for s, v in
                                            zip(floors, curves['loglik']['mean_by_scale'][:, 0])}})
    fr = [f'{x:g}' for x in FRACTIONS]
    print(json.dumps({
        'version': args.version, 'n_recordings': len(demos), 'folds': per_fold,
        'recognition_accuracy_by_fraction': {
            k: dict(zip(fr, np.round(100 * right[k].mean(axis=0), 1).tolist())) for k in keys},
        'partner_rms_cm_by_fraction': {
            k: dict(zip(fr[:-1], np.round(100 * np.nanmean(rms[k][:, :-1], axis=0), 1).tolist()))
            for k in keys},
        'runtime_s': round(time.perf_counter() - t0, 1)}))


if __name__ == '__main__':
    main()
