"""Experiment: what the gesture recordings are cut to, decided on the training split only.

5-fold cross-validation on the 50 training gestures of PickupGestureWiimoteZ (stratified: one
gesture of each person per fold; the test split is never read), accuracy in % of naming the
person after 30/50/70/100 % of the recording, for three cuts of every recording:
- whole: as the archive cut it (what scenarios.gestures uses);
- onset: from the movement onset of segment_rest_deviation (bench/_common.py) to the end;
- onset_end: from that onset to its end.
Methods: the supervised mixture (one component per person) online with the phase unknown and
with the phase known (the same decimated samples), and the per-class ProMP baseline.

    OPENBLAS_NUM_THREADS=1 python experiments/gesture_representation.py
"""

import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))   # the checkout: bench._common

import numpy as np  # noqa: E402

from bench._common import segment_rest_deviation  # noqa: E402
from mixture_ip_ros.app.evaluation.baselines import PerClassProMP  # noqa: E402
from mixture_ip_ros.app.evaluation.common import (online_components,  # noqa: E402
                                                  phase_known_components)
from mixture_ip_ros.app.evaluation.gestures import GESTURE_FRACTIONS  # noqa: E402
from mixture_ip_ros.core.demonstration import Demonstration  # noqa: E402
from mixture_ip_ros.core.mixture import MixtureIProMP  # noqa: E402
from mixture_ip_ros.scenarios.gestures import gesture_demonstrations  # noqa: E402


def cut(demos, how):
    if how == 'whole':
        return demos
    out = []
    for d in demos:
        on, end = segment_rest_deviation(d.t, d.observed)
        lo = int(np.searchsorted(d.t, on - 1e-9))
        hi = int(np.searchsorted(d.t, end - 1e-9)) if how == 'onset_end' else len(d.t) - 1
        out.append(Demonstration(d.t[lo:hi + 1] - d.t[lo], d.observed[lo:hi + 1], None,
                                 label=d.label, name=d.name))
    return out


def cross_validate(demos, n_basis=15, min_interval=0.05, n_alpha=50):
    y = np.array([d.label for d in demos])
    fold = np.empty(len(demos), dtype=int)
    for c in set(y):
        idx = np.flatnonzero(y == c)
        fold[idx] = np.arange(len(idx)) % 5
    hits = {w: np.zeros((len(demos), len(GESTURE_FRACTIONS))) for w in
            ('supervised_phase_unknown', 'supervised_phase_known', 'per_class_promp')}
    for f in range(5):
        train = [d for d, g in zip(demos, fold) if g != f]
        model = MixtureIProMP(len(set(y[fold != f])), n_basis=n_basis).fit(train,
                                                                           labels=y[fold != f])
        promp = PerClassProMP(n_basis).fit(train, y[fold != f])
        cls = np.array(model.classes_)
        for i in np.flatnonzero(fold == f):
            d = demos[i]
            hits['supervised_phase_unknown'][i] = cls[online_components(
                model, d, GESTURE_FRACTIONS, n_alpha, min_interval)] == y[i]
            hits['supervised_phase_known'][i] = cls[phase_known_components(
                model, d, GESTURE_FRACTIONS, min_interval)] == y[i]
            hits['per_class_promp'][i] = [promp.predict_prefix(d, fr) == y[i]
                                          for fr in GESTURE_FRACTIONS]
    return {w: {f'{fr:g}': round(100 * float(h[:, c].mean()), 1)
                for c, fr in enumerate(GESTURE_FRACTIONS)} for w, h in hits.items()}


def main():
    t0 = time.perf_counter()
    train = gesture_demonstrations('train')
    out = {'split': 'train only, 5-fold stratified cross-validation', 'unit': '% correct',
           'fractions': [float(f) for f in GESTURE_FRACTIONS]}
    for how in ('whole', 'onset', 'onset_end'):
        demos = cut(train, how)
        out[how] = {'median_duration_s': float(np.median([d.duration for d in demos])),
                    **cross_validate(demos)}
    out['runtime_s'] = round(time.perf_counter() - t0, 1)
    print(json.dumps(out))


if __name__ == '__main__':
    main()
