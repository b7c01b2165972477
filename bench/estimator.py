"""Online estimator update cost vs. naive batch recomputation of eq. 18 (same run).

K = 3 components, M = 50 alpha hypotheses, 15 basis functions per DOF, 3 observed + 7
controlled DOFs. Prints one JSON object.
"""

import json
import os
import time

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

import numpy as np  # noqa: E402

from mixture_ip_ros.core.mixture import MixtureIProMP  # noqa: E402
from mixture_ip_ros.core.online import OnlineEstimator  # noqa: E402
from mixture_ip_ros.core.phase import log_evidence_batch  # noqa: E402
from mixture_ip_ros.scenarios.synthetic import mixture_demos  # noqa: E402


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


def main():
    demos, _, _, _ = mixture_demos(seed=0, n_obs=3, n_ctrl=7, n_basis=15)
    model = MixtureIProMP(3, n_basis=15).fit(demos)
    est = OnlineEstimator(model, n_alpha=50, min_interval=0.0)
    demo = max(demos, key=lambda d: d.duration)
    rng = np.random.default_rng(0)
    # Stream of 1000 observations at 1 kHz along a demonstration (interpolated) with noise.
    t = np.linspace(1e-3, 1.0, 1000)
    y = np.stack([np.interp(t * demo.duration, demo.t, demo.observed[:, j]) for j in range(3)], 1)
    y += 0.002 * rng.standard_normal(y.shape)
    est.update(t[0], y[0])                                  # compile / warm up
    est.reset()
    times = []
    for ti, yi in zip(t, y):
        t0 = time.perf_counter()
        est.update(ti, yi)
        est.joint_posterior()
        times.append(time.perf_counter() - t0)
    times = np.array(times) * 1e6
    result = {'update_us_median': float(np.median(times)),
              'update_us_p99': float(np.percentile(times, 99))}
    for m, reps in ((50, 5), (200, 3), (500, 2)):
        idx = np.linspace(0, len(t) - 1, m).astype(int)
        result[f'naive_us_m{m}'] = naive_update_us(model, est.alphas, t[idx], y[idx], reps)
    result['speedup_m500'] = result['naive_us_m500'] / result['update_us_median']
    result['hypotheses'] = int(est.sigma.shape[0])
    result['observed_weight_dim'] = int(est.sigma.shape[1])
    print(json.dumps(result))


if __name__ == '__main__':
    main()
