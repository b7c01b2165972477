"""K selection by every held-out criterion on every scenario, with a known number of patterns
where there is one.

For each data set, 5-fold cross-validation with the same fits for every criterion, each K at
the covariance floor the criterion itself prefers (core.mixture.calibrated_heldout_curves):
- 'loglik': the held-out log-likelihood of the demonstrations (both agents, phase known), what
  training uses; also at the fixed default floor (prior_scale 0.02) for comparison;
- 'completion': the predictive log density of the rest of a held-out demonstration given its
  beginning (z <= f, phase known), averaged over f = 0.3, 0.5, 0.7; and 'completion_by_cut':
  the same at each single cut, and with the ten cuts f = 0.1 .. 0.9 (how much the answer
  depends on where the movement is cut);
- 'completion_rms': the RMS error of the rest predicted from the beginning (the single-agent
  analogue of the thesis's leave-one-out RMS of the controlled agent).
The density curves are mean nats per demonstration relative to K = 1, with the paired standard
error of that difference; K by the paired plateau rule (the RMS by the thesis's one-standard-
error rule). 'sampled_tally': the K each criterion picks on ten single-agent sets of three
sampled patterns (seeds 0-9) at four within-pattern spreads, from well separated (0.002, the
default) to overlapping (0.1). Prints one JSON object.

    OPENBLAS_NUM_THREADS=1 python experiments/selection_curves.py
"""

import json
import os
import time

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

import numpy as np  # noqa: E402

from mixture_ip_ros.core.selection import (calibrated_heldout_curves,  # noqa: E402
                                           selection_curve)
from mixture_ip_ros.scenarios.folders import generate  # noqa: E402
from mixture_ip_ros.scenarios.letters import phase_letters  # noqa: E402
from mixture_ip_ros.scenarios.gestures import gesture_demonstrations  # noqa: E402
from mixture_ip_ros.scenarios.synthetic import mixture_demos  # noqa: E402

CUTS = ((0.3,), (0.5,), (0.7,), tuple(np.round(np.arange(0.1, 0.95, 0.1), 1)))


def data_sets():
    """(name, demonstrations, candidates, model parameters, the number of patterns or None)."""
    return [
        ('box_assembly', [g.to_demonstration() for g in generate('box_assembly', 0)],
         range(1, 7), {}, 3),
        ('pole', [g.to_demonstration() for g in generate('pole', 0)], range(1, 13),
         {}, None),
        ('letters', phase_letters(0).train, range(1, 5), {}, 1),
        ('sampled_3_patterns_2_controlled', mixture_demos(seed=5, n_obs=2, n_ctrl=3)[0],
         range(1, 7), {'n_basis': 8}, 3),
        ('sampled_3_patterns_single_agent', mixture_demos(seed=5, n_obs=2, n_ctrl=0)[0],
         range(1, 7), {'n_basis': 8}, 3),
        ('sampled_1_pattern', mixture_demos(seed=6, counts=(30,), durations=((1.0, 1.6),),
                                            n_ctrl=0)[0], range(1, 5), {'n_basis': 8}, 1),
        ('gestures_train', gesture_demonstrations('train'), range(1, 16), {}, None),
    ]


def density_summary(candidates, scores):
    curve = selection_curve(scores, higher_is_better=True, paired=True)
    d = scores - scores[0]
    se = d.std(axis=1, ddof=1) / np.sqrt(d.shape[1])
    return {'chosen': int(candidates[curve['index']]), 'clear': curve['clear'],
            'nats_vs_k1': np.round(d.mean(axis=1), 2).tolist(),
            'paired_se': np.round(se, 2).tolist()}


def rms_summary(candidates, scores):
    curve = selection_curve(scores)
    return {'chosen': int(candidates[curve['index']]), 'clear': curve['clear'],
            'mean': np.round(curve['mean'], 5).tolist(), 'se': np.round(curve['se'], 5).tolist()}


def choices(cal, candidates):
    out = {}
    for name, c in cal.items():
        if name == 'completion_rms':
            out[name] = candidates[selection_curve(c['scores'])['index']]
        else:
            out[name] = candidates[selection_curve(c['scores'], True, paired=True)['index']]
    return out


def sampled_tally(spreads=(0.002, 0.02, 0.05, 0.1), seeds=range(10)):
    out = {}
    for spread in spreads:
        picks = {'loglik': [], 'completion': [], 'completion_rms': []}
        for seed in seeds:
            demos = mixture_demos(seed=seed, n_obs=2, n_ctrl=0, spread=spread)[0]
            cands = [1, 2, 3, 4, 5, 6]
            got = choices(calibrated_heldout_curves(demos, cands, n_basis=8), cands)
            for name in picks:
                picks[name].append(int(got[name]))
        out[f'spread_{spread:g}'] = {name: {'chosen': p, 'right': sum(k == 3 for k in p)}
                                     for name, p in picks.items()}
    return out


def main():
    out = {}
    for name, demos, candidates, params, truth in data_sets():
        t0 = time.perf_counter()
        candidates = list(candidates)
        params = {'n_basis': 15, 'method': 'regression', **params}
        cal = calibrated_heldout_curves(demos, candidates, **params)
        fixed = calibrated_heldout_curves(demos, candidates, (), [0.02], controlled=False,
                                          **params)['loglik']['scores']
        by_cut = {}
        for cut in CUTS:
            c = calibrated_heldout_curves(demos, candidates, cut, **params)['completion']
            key = f'{cut[0]:g}' if len(cut) == 1 else f'{cut[0]:g}-{cut[-1]:g} ({len(cut)} cuts)'
            by_cut[key] = density_summary(candidates, c['scores'])
        out[name] = {'n_demonstrations': len(demos), 'patterns': truth,
                     'candidates': candidates,
                     'loglik': {**density_summary(candidates, cal['loglik']['scores']),
                                'prior_scale': cal['loglik']['prior_scale']},
                     'loglik_fixed_floor_0.02': density_summary(candidates, fixed),
                     'completion': {**density_summary(candidates, cal['completion']['scores']),
                                    'prior_scale': cal['completion']['prior_scale']},
                     'completion_by_cut': by_cut,
                     'completion_rms': {**rms_summary(candidates,
                                                      cal['completion_rms']['scores']),
                                        'prior_scale': cal['completion_rms']['prior_scale']},
                     'runtime_s': round(time.perf_counter() - t0, 1)}
    t0 = time.perf_counter()
    out['sampled_tally'] = {'patterns': 3, 'seeds': list(range(10)), **sampled_tally(),
                            'runtime_s': round(time.perf_counter() - t0, 1)}
    print(json.dumps(out))


if __name__ == '__main__':
    main()
