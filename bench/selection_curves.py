"""K selection by held-out log-likelihood on every scenario with a known number of patterns.

For each data set: the 5-fold held-out log-likelihood of the demonstrations (both agents, phase
known), each K at the covariance floor its held-out likelihood prefers
(core.mixture.calibrated_heldout_loglik), the K chosen by the paired plateau rule, whether the
optimum is clear, and the same curve at the fixed default floor (prior_scale 0.02) for
comparison. Curves are mean nats per demonstration relative to K = 1, with the paired standard
error of that difference. Prints one JSON object.

    OPENBLAS_NUM_THREADS=1 python bench/selection_curves.py
"""

import json
import os
import time

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

import numpy as np  # noqa: E402

from mixture_ip_ros.core.mixture import (calibrated_heldout_loglik,  # noqa: E402
                                         heldout_loglik_by_components, selection_curve)
from mixture_ip_ros.scenarios import generated  # noqa: E402
from mixture_ip_ros.scenarios.gestures import gesture_demonstrations  # noqa: E402
from mixture_ip_ros.scenarios.synthetic import mixture_demos  # noqa: E402


def data_sets():
    """(name, demonstrations, candidates, model parameters, the number of patterns or None)."""
    return [
        ('box_assembly', [g.to_demonstration() for g in generated.generate('box_assembly', 0)],
         range(1, 7), {}, 3),
        ('pole', [g.to_demonstration() for g in generated.generate('pole', 0)], range(1, 13),
         {}, None),
        ('letters', generated.phase_letters(0).train, range(1, 5), {}, 1),
        ('sampled_3_patterns_2_controlled', mixture_demos(seed=5, n_obs=2, n_ctrl=3)[0],
         range(1, 7), {'n_basis': 8}, 3),
        ('sampled_3_patterns_single_agent', mixture_demos(seed=5, n_obs=2, n_ctrl=0)[0],
         range(1, 7), {'n_basis': 8}, 3),
        ('sampled_1_pattern', mixture_demos(seed=6, counts=(30,), durations=((1.0, 1.6),),
                                            n_ctrl=0)[0], range(1, 5), {'n_basis': 8}, 1),
        ('gestures_train', gesture_demonstrations('train'), range(1, 16), {}, None),
    ]


def summary(candidates, scores):
    curve = selection_curve(scores, higher_is_better=True, paired=True)
    d = scores - scores[0]
    se = d.std(axis=1, ddof=1) / np.sqrt(d.shape[1])
    return {'chosen': int(candidates[curve['index']]), 'clear': curve['clear'],
            'nats_vs_k1': np.round(d.mean(axis=1), 2).tolist(),
            'paired_se': np.round(se, 2).tolist()}


def main():
    out = {}
    for name, demos, candidates, params, truth in data_sets():
        t0 = time.perf_counter()
        candidates = list(candidates)
        params = {'n_basis': 15, 'method': 'regression', **params}
        cal = calibrated_heldout_loglik(demos, candidates, **params)
        fixed = heldout_loglik_by_components(demos, candidates, prior_scale=0.02, **params)
        out[name] = {'n_demonstrations': len(demos), 'patterns': truth,
                     'candidates': candidates,
                     'calibrated': {**summary(candidates, cal['scores']),
                                    'prior_scale': cal['prior_scale']},
                     'fixed_floor_0.02': summary(candidates, fixed),
                     'runtime_s': round(time.perf_counter() - t0, 1)}
    print(json.dumps(out))


if __name__ == '__main__':
    main()
