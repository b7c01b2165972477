"""Whether the ten people of PickupGestureWiimoteZ are clusters a held-out criterion can find.

On the 50 training gestures (labels used only where a row says so):
- 'heldout_by_fold_seed': the 5-fold held-out log-likelihood curve over K = 1..15 (each K at
  its calibrated floor, as training computes it) for fold seeds 0-4, in nats per gesture
  relative to K = 1, with the K the curve's maximum and the paired plateau rule pick;
- 'person_partition': at the floor the one-component model prefers, the 5-fold held-out
  log-likelihood of the partition by person (a supervised fit of each training fold) beside
  K = 1 and the unsupervised fits with K = 3 and 10, and the log-likelihood of the training
  gestures under each fit (nats per gesture, the same measure without the covariance prior,
  whose target differs between a supervised and an unsupervised fit; mean over the folds):
  how much better the people describe the gestures than one Gaussian, and whether EM finds a
  partition that fits them better;
- 'accuracy_by_k': train -> test, for every K at its calibrated floor, the unsupervised
  mixture's accuracy online (phase unknown) after 30/50/70/100 % of the recording, and the
  scikit-learn GaussianMixture's on the same weights with the same K (the evaluation's
  baseline), in %.

    OPENBLAS_NUM_THREADS=1 python experiments/gesture_k.py
"""

import json
import os
import time

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

import numpy as np  # noqa: E402

from mixture_ip_ros.app.evaluation.baselines import sklearn_gmm_accuracy  # noqa: E402
from mixture_ip_ros.app.evaluation.common import (majority_labels,  # noqa: E402
                                                  named_online)
from mixture_ip_ros.app.evaluation.gestures import GESTURE_FRACTIONS  # noqa: E402
from mixture_ip_ros.core.mixture import MixtureIProMP  # noqa: E402
from mixture_ip_ros.core.crossval import cv_folds  # noqa: E402
from mixture_ip_ros.core.selection import calibrated_heldout_curves, selection_curve  # noqa: E402
from mixture_ip_ros.scenarios.gestures import gesture_demonstrations  # noqa: E402

CANDIDATES = list(range(1, 16))
PARAMS = {'n_basis': 15, 'method': 'regression'}


def heldout_by_fold_seed(train, seeds=range(5)):
    out, floors = {}, None
    for seed in seeds:
        cal = calibrated_heldout_curves(train, CANDIDATES, (), n_folds=5, fold_seed=seed,
                                        **PARAMS)['loglik']
        mean = cal['scores'].mean(axis=1)
        plateau = selection_curve(cal['scores'], higher_is_better=True, paired=True)
        out[str(seed)] = {'nats_vs_k1': np.round(mean - mean[0], 2).tolist(),
                          'max_at': CANDIDATES[int(np.argmax(mean))],
                          'plateau_rule': CANDIDATES[plateau['index']],
                          'clear': plateau['clear']}
        floors = floors or cal['prior_scale']
    return out, floors


def person_partition(train, prior_scale):
    labels = np.array([d.label for d in train])
    fold = cv_folds(len(train), 5, 0)
    fits = {'one_gaussian': (1, False), 'unsupervised_k3': (3, False),
            'unsupervised_k10': (10, False), 'by_person': (10, True)}
    out = {}
    for name, (K, supervised) in fits.items():
        held, fitted = np.empty(len(train)), []
        for f in range(5):
            part = [d for d, g in zip(train, fold) if g != f]
            model = MixtureIProMP(K, prior_scale=prior_scale, **PARAMS).fit(
                part, labels=labels[fold != f] if supervised else None)
            held[fold == f] = model.score_demonstrations([d for d, g in zip(train, fold)
                                                          if g == f])
            fitted.append(model.score_demonstrations(part).mean())
        out[name] = {'heldout_nats': round(float(held.mean()), 2),
                     'training_nats': round(float(np.mean(fitted)), 2)}
    return {'prior_scale': prior_scale, **out}


def accuracy_by_k(train, test, floors):
    y_train = np.array([d.label for d in train])
    y_test = np.array([d.label for d in test])
    out = {}
    for K, floor in zip(CANDIDATES, floors):
        model = MixtureIProMP(K, prior_scale=floor, **PARAMS).fit(train)
        names = majority_labels(model, train)
        picked = named_online(model, names, test, GESTURE_FRACTIONS)
        gmm, _ = sklearn_gmm_accuracy(model.demonstration_weights(train), y_train,
                                      model.demonstration_weights(test), y_test, K,
                                      seeds=range(10))
        out[str(K)] = {'prior_scale': floor,
                       'unsupervised_online': np.round(
                           100 * (picked == y_test[:, None]).mean(axis=0)).tolist(),
                       'sklearn_gmm': round(100 * gmm)}
    return out


def main():
    t0 = time.perf_counter()
    train, test = gesture_demonstrations('train'), gesture_demonstrations('test')
    by_seed, floors = heldout_by_fold_seed(train)
    out = {'fractions': list(GESTURE_FRACTIONS), 'heldout_by_fold_seed': by_seed,
           'person_partition': person_partition(train, floors[0]),
           'accuracy_by_k': accuracy_by_k(train, test, floors)}
    out['runtime_s'] = round(time.perf_counter() - t0, 1)
    print(json.dumps(out))


if __name__ == '__main__':
    main()
