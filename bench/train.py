"""What `mixture-ip train` costs on the 48 box-assembly bags, and where the time goes.

The bags are generated into a temporary folder (`mixture-ip generate --scenario box_assembly`
defaults; not timed). Each run is a fresh process doing what `mixture-ip train bags/ --out
model.npz` does: load the bags (load_s), then app.training.train_to_file with K chosen over
1..6 (train_s), its stages as training reports them (info['seconds']): the demonstrations
prepared once (prepare_s), K by the pattern space's leave-one-out curve (patterns_s), the chosen
K's covariance floor calibrated on held-out folds (heldout_s), both together selection_s, the
speed weight (speed_s), the switch rate (switch_s), the final fit (fit_s), the held-out choice of the phase (choice_s),
the phase warps if chosen (warps_s), the novelty calibration (novelty_s) and the save
(save_s). n_fits counts every mixture fit, on any thread; peak_rss_mb is the run's peak
resident memory. Top-level keys are medians over the runs (the machine may be shared).

``reference`` is the same path by the straightforward loop, in the same script: the floor's
held-out curves from one MixtureIProMP(...).fit of the demonstrations of each fold (same folds,
seeds and floors), every EM run of the pattern mixture (each start of each leave-one-out and
cluster-stability fit) on its own rather than side by side (PatternMixture.fit_many), and one
fold after another on one thread (n_jobs=1); the speed weight's, the novelty test's and the
final fit take the one preparation in both. The ratio ``speedup_vs_reference`` is what
reusing per-demonstration work across folds, batching the pattern fits and running the folds
on both cores gain; ``same_selection`` whether both chose the same K and floor with curves
equal to 1e-9.

Prints one JSON object.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/train.py [--runs 5] [--reference-runs 5]
"""

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

KEYS = ('train_s', 'load_s', 'prepare_s', 'selection_s', 'patterns_s', 'heldout_s', 'speed_s',
        'switch_s', 'novelty_s', 'fit_s', 'choice_s', 'warps_s', 'save_s', 'peak_rss_mb', 'n_fits')
# The JSON's keys for training's stages (app.progress.Stages, info['seconds']).
STAGES = {'prepare_s': 'preparing', 'patterns_s': 'choosing K', 'heldout_s': 'covariance floor',
          'speed_s': 'speed weight', 'switch_s': 'switch rate', 'fit_s': 'final fit',
          'choice_s': 'phase choice', 'warps_s': 'phase warps',
          'novelty_s': 'novelty',
          'save_s': 'saving'}


def count_calls(owner, name, counter):
    """Count the calls of owner.name in counter[0], from any thread."""
    original, lock = getattr(owner, name), threading.Lock()

    def wrapper(*args, **kwargs):
        with lock:
            counter[0] += 1
        return original(*args, **kwargs)
    setattr(owner, name, wrapper)


def plain_heldout(demos, candidates, fractions=(), prior_scales=(), n_folds=5, progress=None,
                  fold_seed=0, n_jobs=None, prepared=None, **params):
    """calibrated_heldout_curves (the held-out log-likelihood and, with a controlled agent, the
    controlled agent's online RMS and the patterns named online) by the straightforward loop
    (one fit per fold and floor, from the fold's demonstrations, one after another: ``n_jobs``
    and ``prepared`` are not used). The online scores are core.scores.online_scores' (the
    oracle of test_completion checks them against the estimator fed sample by sample)."""
    import numpy as np
    from mixture_ip_ros.core.mixture import MixtureIProMP
    from mixture_ip_ros.core.crossval import cv_folds, prepare_for_cv
    from mixture_ip_ros.core.scores import online_scores
    fold = cv_folds(len(demos), n_folds, fold_seed)
    scales = [float(s) for s in prior_scales]
    params = {k: v for k, v in params.items() if k != 'prior_scale'}
    # The weights' smoothing is the set's (chosen once on every demonstration, as the folds
    # of the fast path share it): each fold's fit from scratch is given it.
    every = prepare_for_cv(demos, params)
    params.setdefault('smoothing', every.smoothing)
    shape = (len(scales), len(candidates), len(demos))
    S = {'loglik': np.empty(shape), 'controlled_rms': np.empty(shape), 'named': np.empty(shape)}
    # each demonstration's pattern: the pattern mixture's of them all, for every K
    patterns = [MixtureIProMP(n_components=K, **params).initial_clusters(every)
                for K in candidates]
    for b, scale in enumerate(scales):
        for a, K in enumerate(candidates):
            pattern = patterns[a]
            for f in range(fold.max() + 1):
                test = np.flatnonzero(fold == f)
                model = MixtureIProMP(n_components=K, prior_scale=scale, **params).fit(
                    [d for d, g in zip(demos, fold) if g != f])
                S['loglik'][b, a, test] = model.score_demonstrations([demos[i] for i in test])
                member, theirs = np.argmax(model.resp_, axis=1), pattern[fold != f]
                names = [np.bincount(theirs[member == k]).argmax() if np.any(member == k)
                         else None for k in range(K)]
                for i in test:
                    got = online_scores(model, [demos[i]], pattern[[i]], names)
                    S['controlled_rms'][b, a, i], S['named'][b, a, i] = got.rms[0], got.named[0]
    out = {}
    for name, scores in S.items():
        mean = scores.mean(axis=2)
        if name == 'controlled_rms':
            # the best log-likelihood among the floors whose online RMS is within one paired
            # standard error of the best floor's and, of those, that name the patterns within
            # two paired standard errors of the best of them
            best = []
            for a in range(len(candidates)):
                rms, named = scores[:, a], S['named'][:, a]
                low = rms[np.argmin(rms.mean(axis=1))]
                allowed = [b for b in range(len(scales)) if (rms[b] - low).mean()
                           <= (rms[b] - low).std(ddof=1) / np.sqrt(len(demos))]
                top = named[max(allowed, key=lambda b: named[b].mean())]
                allowed = [b for b in allowed if (top - named[b]).mean()
                           <= 2 * (top - named[b]).std(ddof=1) / np.sqrt(len(demos)) + 1e-9]
                best.append(max(allowed, key=lambda b: S['loglik'][b, a].mean()))
            best = np.array(best)
        else:
            best = np.argmax(mean, axis=0)
        out[name] = {'scores': scores[best, np.arange(len(candidates))],
                     'prior_scale': [scales[i] for i in best], 'prior_scales': scales,
                     'mean_by_scale': mean}
    return out


def plain_ecm(batched):
    """PatternMixture._ecm run on one start at a time (the straightforward loop)."""
    import numpy as np

    def ecm(self, X, R, floors, fixed=None):
        runs = [batched(self, X[b:b + 1], R[b:b + 1], floors[b:b + 1], fixed)
                for b in range(len(X))]
        return tuple(np.concatenate(parts) for parts in zip(*runs))
    return ecm


def one_run(bags: Path, reference: bool) -> dict:
    """Load and train once in this process (the way `mixture-ip train` does)."""
    from mixture_ip_ros.app import training
    from mixture_ip_ros.core import mixture, patterns, selection
    from mixture_ip_ros.io.dataset import load_dataset
    from mixture_ip_ros.robot.description import load_description
    fits = [0]
    if reference:
        selection.calibrated_heldout_curves = plain_heldout
        patterns.PatternMixture._ecm = plain_ecm(patterns.PatternMixture._ecm)
    count_calls(mixture.MixtureIProMP, 'fit', fits)
    robot = load_description(None)
    t0 = time.perf_counter()
    demos, skipped = load_dataset(bags, joint_names=robot.joint_names,
                                  transform=robot.world_to_base())
    t1 = time.perf_counter()
    with tempfile.TemporaryDirectory() as out:
        model, info = training.train_to_file(
            demos, Path(out) / 'model.npz', robot=robot, n_basis=15, method='regression',
            criterion='auto', noise='tied', candidates=range(1, 7),
            n_jobs=1 if reference else None)
    t2 = time.perf_counter()
    sel = info['selection']
    stage = {key: info['seconds'].get(name, 0.0) for key, name in STAGES.items()}
    return {'train_s': t2 - t1, 'load_s': t1 - t0, **stage,
            'selection_s': stage['patterns_s'] + stage['heldout_s'],
            'peak_rss_mb': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            'n_fits': fits[0], 'n_demonstrations': len(demos),
            'n_skipped': len(skipped), 'chosen': sel['chosen'], 'prior_scale': sel['prior_scale'],
            'patterns_mean': sel['mean']}


def run_in_process(bags: Path, reference: bool) -> dict:
    cmd = [sys.executable, __file__, '--one', str(bags)] + (['--reference'] if reference else [])
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def medians(runs) -> dict:
    out = {k: round(statistics.median(r[k] for r in runs), 3) for k in KEYS}
    out['n_fits'] = int(out['n_fits'])
    out['runs'] = {k: [round(r[k], 3) for r in runs] for k in ('train_s', 'load_s')}
    return out


def same_curves(a: dict, b: dict, rtol: float = 1e-9) -> bool:
    import numpy as np
    return (a['chosen'] == b['chosen'] and a['prior_scale'] == b['prior_scale']
            and np.allclose(a['patterns_mean'], b['patterns_mean'], rtol=rtol, atol=0))


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--runs', type=int, default=5)
    p.add_argument('--reference-runs', type=int, default=5,
                   help='runs of the straightforward loop (0: skip it)')
    p.add_argument('--one', type=Path, default=None, help=argparse.SUPPRESS)
    p.add_argument('--reference', action='store_true', help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.one is not None:
        print(json.dumps(one_run(args.one, args.reference)))
        return
    from mixture_ip_ros.scenarios.folders import write_scenario_bags
    with tempfile.TemporaryDirectory() as tmp:
        bags = Path(tmp) / 'bags'
        write_scenario_bags('box_assembly', bags, seed=0)
        # Interleaved, so that a machine whose speed drifts over the minutes (a shared host)
        # slows both alike and the ratio compares like with like.
        runs, refs = [], []
        for i in range(max(args.runs, args.reference_runs)):
            if i < args.runs:
                runs.append(run_in_process(bags, False))
            if i < args.reference_runs:
                refs.append(run_in_process(bags, True))
    out = {'scenario': 'box_assembly', 'n_demonstrations': runs[0]['n_demonstrations'],
           'candidates': list(range(1, 7)), 'chosen': runs[0]['chosen'],
           'prior_scale': runs[0]['prior_scale'], **medians(runs),
           'cpu_count': os.cpu_count(), 'load_average': [round(x, 2) for x in os.getloadavg()]}
    if refs:
        ref = medians(refs)
        out['reference'] = ref
        out['speedup_vs_reference'] = round(ref['train_s'] / out['train_s'], 2)
        out['same_selection'] = all(same_curves(r, runs[0]) for r in refs)
    print(json.dumps(out))


if __name__ == '__main__':
    main()
