"""`mixture-ip evaluate --scenario change_of_mind`: people who change their mind mid-movement
(thesis chapters 4 and 5), on real two-person interactions (NuiSI v1 and v2).

Each of 5 stratified folds trains the mixture as ``training.train`` ships it (K chosen, its
switch rate calibrated) on the other folds; its held-out recordings are played to the online
estimator sample by sample, unchanged and spliced: every ordered pair of held-out recordings
of different interactions joined at a share of the first drawn from core.splice.SHARES
(core.splice.splice: B from the same share of its own movement, reached from A's
hand within 0.3 s). Two estimators read the same streams with the same model: 'switching'
(the model's switch rate) and 'no_switch' (rate 0, eq. 11: a belief that weighs every sample
since the onset alike). Reported for each:

- ``followed``: the share of splices whose belief at the last sample is B;
- ``delay_s``: from the change until the belief is on B and stays there to the end (median,
  90th percentile; a splice never settled on B counts as never, inf);
- ``unchanged_recognised``: the belief right after 30, 50, 70 and 100 % of the unchanged
  held-out recordings; ``unchanged_late_changes``: the share of them whose belief changes
  after 30 % of the movement;
- ``hand_error_end_cm``: the controlled person's hand at the last sample against the
  estimator's expected path there (OnlineEstimator.expected_controlled under the believed
  component), median over the splices, and the same over the unchanged recordings.
"""

from functools import partial
import time

import numpy as np

from mixture_ip_ros.app.evaluation.common import majority_labels, trained
from mixture_ip_ros.app.evaluation.interactions import (N_FOLDS, interactions_config,
                                                        run_in_processes, stratified_folds)
from mixture_ip_ros.core.online import OnlineEstimator
from mixture_ip_ros.core.playback import observed_rows, prefixes
from mixture_ip_ros.core.splice import SHARES, splice

FRACTIONS = (0.3, 0.5, 0.7, 1.0)
METHODS = ('switching', 'no_switch')


def _belief_path(est, demo, names):
    """(sample times, the believed interaction after each sample, the estimator at the end)."""
    rows = observed_rows(demo)
    t = demo.t[rows]
    said = [names[int(np.argmax(est.component_posterior()))] for _ in prefixes(est, demo, t)]
    return t, np.array(said, dtype=object)


def _hand_error(est, demo):
    """|hand - expected hand| (the DOFs' unit) at the last sample with the controlled agent."""
    rows = np.flatnonzero(~np.isnan(demo.controlled).any(axis=1))
    if not rows.size or demo.n_controlled_dofs == 0:
        return np.nan
    last = rows[-1]
    pos = est.expected_controlled([demo.t[last]], derivatives=False)[1]
    return float(np.linalg.norm(pos[0] - demo.controlled[last]))


def _settled(t, said, target, t_change):
    """Seconds from ``t_change`` until ``said`` is ``target`` to the end (inf: never)."""
    wrong = np.flatnonzero(said != target)
    if not wrong.size:
        return max(0.0, float(t[0]) - t_change)
    if wrong[-1] == len(t) - 1:
        return np.inf
    return max(0.0, float(t[wrong[-1] + 1]) - t_change)


def _fold(demos, labels, fold, config, seed, f, switch_rate=None):
    train_i, test_i = np.flatnonzero(fold != f), np.flatnonzero(fold == f)
    train = [demos[i] for i in train_i]
    t0 = time.perf_counter()
    kwargs = {} if switch_rate is None else {'switch_rate': switch_rate}
    model, info = trained(train, config, n_jobs=1, random_state=seed, **kwargs)
    timings = {'training_s': time.perf_counter() - t0}
    names = majority_labels(model, train)
    rng = np.random.default_rng(seed + f)
    pairs = [(i, j) for i in test_i for j in test_i if labels[i] != labels[j]]
    shares = rng.choice(SHARES, size=len(pairs))
    out = {'rows': test_i, 'n_components': int(model.n_components),
           'switch_rate': float(model.switch_rate), 'speed_weight': float(model.speed_weight)}
    t0 = time.perf_counter()
    for method in METHODS:
        est = OnlineEstimator(model, n_alpha=config.n_alpha, min_interval=config.min_interval,
                              switch_rate=None if method == 'switching' else 0.0)
        unchanged = []
        for i in test_i:
            d = demos[i]
            t, said = _belief_path(est, d, names)
            at = [said[max(0, np.searchsorted(t, fr * d.duration + 1e-9, side='right') - 1)]
                  == labels[i] for fr in FRACTIONS]
            late = said[t >= 0.3 * d.duration]
            unchanged.append({'right': at, 'late_change': bool(np.any(late[1:] != late[:-1])),
                              'hand_error': _hand_error(est, d)})
        spliced = []
        for (i, j), share in zip(pairs, shares):
            s = splice(demos[i], demos[j], float(share))
            t, said = _belief_path(est, s.demo, names)
            spliced.append({'first': labels[i], 'second': labels[j], 'share': float(share),
                            'followed': bool(said[-1] == labels[j]),
                            'delay': _settled(t, said, labels[j], s.t_change),
                            'hand_error': _hand_error(est, s.demo)})
        out[method] = {'unchanged': unchanged, 'spliced': spliced}
    timings['online_s'] = time.perf_counter() - t0
    out['timings'] = timings
    return out


def _summary(results, unit):
    out = {}
    for method in METHODS:
        un = [u for r in results for u in r[method]['unchanged']]
        sp = [s for r in results for s in r[method]['spliced']]
        delays = np.array([s['delay'] for s in sp])
        out[method] = {
            'splices': len(sp),
            'followed': float(np.mean([s['followed'] for s in sp])),
            # a sample's own delay (no interpolation between never and a number)
            'delay_s': {'median': float(np.percentile(delays, 50, method='inverted_cdf')),
                        'p90': float(np.percentile(delays, 90, method='inverted_cdf')),
                        'settled': float(np.mean(np.isfinite(delays)))},
            'followed_by_share': {f'{a:g}': float(np.mean([s['followed'] for s in sp
                                                           if s['share'] == a]))
                                  for a in SHARES},
            'unchanged_recognised': {f'{fr:g}': float(np.mean([u['right'][c] for u in un]))
                                     for c, fr in enumerate(FRACTIONS)},
            'unchanged_late_changes': float(np.mean([u['late_change'] for u in un])),
            'hand_error_end_cm': {
                'spliced': float(np.nanmedian([s['hand_error'] for s in sp]) * unit),
                'unchanged': float(np.nanmedian([u['hand_error'] for u in un]) * unit)},
        }
    return out


def evaluate_change_of_mind(config=None, seed: int = 0, versions=('v1', 'v2'), progress=None,
                            switch_rate=None) -> dict:
    """The module docstring's metrics for NuiSI ``versions``: {version: metrics}.
    ``switch_rate`` fixes the models' rate instead of calibrating it."""
    from mixture_ip_ros.scenarios import nuisi
    config = config or interactions_config()
    out = {}
    for v in versions:
        demos = nuisi.demonstrations(v, 'train') + nuisi.demonstrations(v, 'test')
        labels = np.array([d.label for d in demos])
        fold = stratified_folds(labels, N_FOLDS, seed)
        tasks = [partial(_fold, demos, labels, fold, config, seed, f, switch_rate)
                 for f in range(N_FOLDS)]
        results = run_in_processes(tasks, None if progress is None else (
            lambda done, total, index, result, v=v: progress(
                f'nuisi_{v}: fold {done} of {total} done')))
        out[v] = {'source': nuisi.SOURCE.format(version=v, commit=nuisi.VERSIONS[v].commit),
                  'folds': [{'n_components': r['n_components'], 'switch_rate': r['switch_rate'],
                             'speed_weight': r['speed_weight'], 'timings': r['timings']}
                            for r in results],
                  **_summary(results, 100.0)}
    return out
