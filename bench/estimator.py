"""Online estimator update cost vs. naive batch recomputation of eq. 18 (same run).

K = 3 components, M = 50 alpha hypotheses, 15 basis functions per DOF, 3 observed + 7
controlled DOFs: a stream of 1000 observations at 1 kHz along a demonstration, each update
followed by the posterior query (as the estimator node does). Also in the same run:

- ``switching``: the same stream with changes of mind allowed (``switch_rate`` SWITCH_RATE per
  second, core.switching: the change points' segments beside the hypotheses since the onset),
  its time and its median as a multiple of the exact update's in this run;
- ``pruned``: the same stream with ``prune_below`` (hypotheses below it are dropped), its time,
  how many hypotheses are tracked at the end, the mass dropped, and the largest difference of
  its posterior from the exact one over the stream;
- ``scaling``: the exact update for K = 3, 6, 12 components and M = 50, 100 alpha hypotheses
  (models fitted to K sampled patterns), so that the cost of more patterns is known;
- ``end_event``: the component posterior once the movement's end is known
  (OnlineEstimator.end_posterior, once per interaction) after a 10 s movement at the node's
  20 Hz (200 samples), with the linear phase and with each component's MAP warp (the model's
  phase warps, which training learns where they predict held-out recordings better), K = 3
  and 6.

Prints one JSON object.
"""

import copy
import json
import os
import time

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

import numpy as np  # noqa: E402

from mixture_ip_ros.core.mixture import MixtureIProMP  # noqa: E402
from mixture_ip_ros.core.online import OnlineEstimator  # noqa: E402
from mixture_ip_ros.core.phase import log_evidence_batch  # noqa: E402
from mixture_ip_ros.core.warped import PhaseWarps  # noqa: E402
from mixture_ip_ros.scenarios.synthetic import mixture_demos  # noqa: E402

PRUNE_BELOW = 1e-12
SWITCH_RATE = 0.3


def naive_update_us(model, alphas, t, Y, reps):
    do = model.n_observed_ * model.n_basis
    times = []
    for _ in range(reps):
        t0 = time.perf_counter()
        for k in range(model.n_components):
            mu, C = model.means_[k][:do], model.covariances_[k][:do, :do]
            for a in alphas:
                log_evidence_batch(mu, C, model.basis_, t, Y, a, model.observed_noise_var_)
        times.append(time.perf_counter() - t0)
    return float(np.median(times) * 1e6)


def stream(demo, n=1000, seed=0):
    """n observations at 1 kHz along ``demo`` played in one second, with 2 mm noise."""
    t = np.linspace(1e-3, 1.0, n)
    y = np.stack([np.interp(t * demo.duration, demo.t, demo.observed[:, j])
                  for j in range(demo.observed.shape[1])], 1)
    return t, y + 0.002 * np.random.default_rng(seed).standard_normal(y.shape)


def timed_updates(est, t, y, on_update=None):
    """Per-observation time (us) of update + joint_posterior over the stream."""
    est.update(t[0], y[0])                                  # compile / warm up
    est.reset()
    times = []
    for ti, yi in zip(t, y):
        t0 = time.perf_counter()
        est.update(ti, yi)
        est.joint_posterior()
        times.append(time.perf_counter() - t0)
        if on_update is not None:
            on_update(est)
    return np.array(times) * 1e6


def stats(times):
    return {'update_us_median': float(np.median(times)),
            'update_us_p99': float(np.percentile(times, 99))}


def scaling():
    out = {}
    for K in (3, 6, 12):
        demos = mixture_demos(seed=K, counts=(12,) * K, n_obs=3, n_ctrl=7, n_basis=15,
                              durations=((1.0, 2.4),) * K)[0]
        model = MixtureIProMP(K, n_basis=15).fit(demos)
        t, y = stream(max(demos, key=lambda d: d.duration))
        for M in (50, 100):
            times = timed_updates(OnlineEstimator(model, n_alpha=M, min_interval=0.0), t, y)
            out[f'K{K}_M{M}'] = {'hypotheses': K * M, **stats(times),
                                 'us_per_hypothesis': float(np.median(times) / (K * M))}
    return out


def end_event():
    """Median ms of end_posterior over 5 calls, linear phase and warped, K = 3 and 6."""
    out = {}
    for K in (3, 6):
        demos = mixture_demos(seed=K, counts=(12,) * K, n_obs=3, n_ctrl=7, n_basis=15,
                              durations=((1.0, 2.4),) * K)[0]
        warped = MixtureIProMP(K, n_basis=15).fit(demos)
        warped.warps_ = PhaseWarps().fit(warped, demos)
        linear = copy.copy(warped)
        linear.warps_ = None
        t, y = stream(max(demos, key=lambda d: d.duration))
        for name, model in (('linear', linear), ('warped', warped)):
            est = OnlineEstimator(model, n_alpha=50, min_interval=0.05)
            est.offer_many(10.0 * t, y)                # 10 s at 20 Hz: 200 samples
            times = []
            for _ in range(5):
                t0 = time.perf_counter()
                est.end_posterior(10.0)
                times.append(time.perf_counter() - t0)
            out[f'K{K}_{name}_ms'] = float(np.median(times) * 1e3)
        out[f'K{K}_samples'] = int(est.n_observations)
    return out


def main():
    demos, _, _, _ = mixture_demos(seed=0, n_obs=3, n_ctrl=7, n_basis=15)
    model = MixtureIProMP(3, n_basis=15).fit(demos)
    est = OnlineEstimator(model, n_alpha=50, min_interval=0.0)
    t, y = stream(max(demos, key=lambda d: d.duration))
    exact_joints = []
    result = stats(timed_updates(est, t, y, lambda e: exact_joints.append(e.joint_posterior())))
    for m, reps in ((50, 5), (200, 3), (500, 2)):
        idx = np.linspace(0, len(t) - 1, m).astype(int)
        result[f'naive_us_m{m}'] = naive_update_us(model, est.alphas, t[idx], y[idx], reps)
    result['speedup_m500'] = result['naive_us_m500'] / result['update_us_median']
    result['hypotheses'] = int(est.log_evidence.size)
    result['observed_weight_dim'] = int(est.n_observed * est.n_basis)

    switching = OnlineEstimator(model, n_alpha=50, min_interval=0.0, switch_rate=SWITCH_RATE)
    times = timed_updates(switching, t, y)
    result['switching'] = {'switch_rate': SWITCH_RATE, **stats(times),
                           'ratio_to_exact': float(np.median(times))
                           / result['update_us_median']}
    pruned = OnlineEstimator(model, n_alpha=50, min_interval=0.0, prune_below=PRUNE_BELOW)
    joints = []
    times = timed_updates(pruned, t, y, lambda e: joints.append(e.joint_posterior()))
    result['pruned'] = {'prune_below': PRUNE_BELOW, **stats(times),
                        'tracked_at_end': int(pruned.n_tracked),
                        'pruned_mass': pruned.pruned_mass,
                        'max_abs_posterior_difference': float(np.max(np.abs(
                            np.array(joints) - np.array(exact_joints))))}
    result['scaling'] = scaling()
    result['end_event'] = end_event()
    print(json.dumps(result))


if __name__ == '__main__':
    main()
