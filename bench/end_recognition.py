"""Recognition once the movement's end is known (the observer's 'end' event), with the linear
phase and with each component's own phase warp (the thesis's eq. 34, core.warp;
core.warped.PhaseWarps, which training fits where a warp predicts held-out recordings
better). Prints one JSON object.

On NuiSI v1 and v2, as recorded and with the people's pace changed within each recording (the
robustness bench's ``tempo``: scenarios.corruption.retimed), the interactions evaluation's 5
stratified folds: the discovered mixture (K chosen, each component named by its training
recordings' majority) and the supervised one, each held-out recording played to the estimator
and its end posterior read (OnlineEstimator.end_posterior: each component's warp integrated out);
the same model at the linear phase, its warps pinned at b = 0 (the same samples and noise: the
phase alone differs) and without warps (every sample absorbed at the recordings' own noise, as
a model without them reads a recording). Beside them the nearest training recording by DTW
(the evaluation's baseline) on the whole recording. Percent of held-out recordings recognised;
``chose_warped``: of the folds' models, how many training gave the warps (held-out prediction:
app.training's phase choice; the others are given them here, to be compared).

    OPENBLAS_NUM_THREADS=1 python bench/end_recognition.py [--versions v1,v2]
"""

import argparse
import copy
from functools import partial
import json
import time

import numpy as np

from mixture_ip_ros.app.evaluation.baselines import NearestNeighbour
from mixture_ip_ros.app.evaluation.common import (majority_labels, online_component_given_end,
                                                  trained)
from mixture_ip_ros.app.evaluation.interactions import (run_in_processes, interactions_config,
                                                        stratified_folds)
from mixture_ip_ros.core.warped import PhaseWarps
from mixture_ip_ros.scenarios import nuisi
from mixture_ip_ros.scenarios.corruption import corrupted

CASES = {'clean': (), 'tempo': ('tempo',)}


def phases(model):
    """``model`` as it is and at the linear phase, two ways: its warps pinned at b = 0 (read
    from the same samples with the same noise as the warped one: the phase alone differs), and
    without warps (every sample absorbed, at the recordings' noise: a model without them)."""
    pinned, plain = copy.copy(model), copy.copy(model)
    pinned.warps_ = copy.copy(model.warps_)
    pinned.warps_.mean_ = np.zeros_like(model.warps_.mean_)
    pinned.warps_.sd_ = np.full_like(model.warps_.sd_, 1e-6)
    plain.warps_ = None
    return {'warped': model, 'linear, same samples': pinned, 'linear, every sample': plain}


def case(version, name, seed=0) -> dict:
    demos = nuisi.demonstrations(version, 'train') + nuisi.demonstrations(version, 'test')
    demos = corrupted(demos, CASES[name], seed=seed)
    labels = np.array([d.label for d in demos])
    folds = stratified_folds(labels, seed=seed)
    config = interactions_config()
    right, ks, failed, chosen = {}, [], 0, []
    for f in range(folds.max() + 1):
        train_i, test_i = np.flatnonzero(folds != f), np.flatnonzero(folds == f)
        train = [demos[i] for i in train_i]
        found, info = trained(train, config, n_jobs=1, random_state=seed)
        supervised, sup_info = trained(train, config, n_jobs=1, labels=labels[train_i])
        ks.append(int(info['n_components']))
        chosen += [info['phase']['chosen'], sup_info['phase']['chosen']]
        for model in (found, supervised):
            if model.warps_ is None:          # training chose the linear phase: warps anyway
                model.warps_ = PhaseWarps().fit(model, train)
        failed += len(found.warps_.failed_) + len(supervised.warps_.failed_)
        models = {'discovered': (found, majority_labels(found, train)),
                  'supervised': (supervised, list(supervised.classes_))}
        for what, (model, names) in models.items():
            for phase, mod in phases(model).items():
                right.setdefault(f'{what}, {phase}', []).extend(
                    names[online_component_given_end(mod, demos[i], config.n_alpha,
                                                      config.min_interval)] == labels[i]
                    for i in test_i)
        nn = NearestNeighbour(config.min_interval, ()).fit(train, labels[train_i])
        right.setdefault('nearest recording (DTW)', []).extend(
            nn.labels_[nn.matches(demos[i], (1.0,))[0][0]] == labels[i] for i in test_i)
    return {'k': ks, 'warp_fits_not_converged': failed,
            'chose_warped': f"{chosen.count('warped')} of {len(chosen)}",
            **{m: round(100.0 * float(np.mean(r)), 1) for m, r in right.items()}}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--versions', default='v1,v2')
    args = ap.parse_args()
    t0 = time.perf_counter()
    runs = [(v, c) for v in args.versions.split(',') for c in CASES]
    results = run_in_processes([partial(case, v, c) for v, c in runs])
    out = {}
    for (v, c), r in zip(runs, results):
        out.setdefault(v, {})[c] = r
    out['runtime_s'] = round(time.perf_counter() - t0, 1)
    print(json.dumps(out))


if __name__ == '__main__':
    main()
