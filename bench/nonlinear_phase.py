"""Experiment: the thesis's non-linear phase (section 4.2.2, eq. 34, its future work) on the
gestures, against the linear phase z = t / T. Prints one JSON object.

Phase z = g(u; beta), u = t / T: a monotone warp from positive sigmoid basis functions plus a
linear term (eq. 34 with phi(t) sigmoids, normalised so that g(0) = 0 and g(1) = 1; beta = 0
is the linear phase). Training alternates: fit the mixture on the current phases, then give
every demonstration the beta that maximises log p(D_i | k_i, beta) + log p(beta) under its own
component (beta_j = exp(b_j), b ~ N(0, prior_sd^2)). Testing (phase known up to the warp: T is
known, beta is not) scores each component by max_beta log p(D | k, beta) + log p(beta), on the
first fraction of the movement. Labels never reach the unsupervised fit.

    OPENBLAS_NUM_THREADS=1 python bench/nonlinear_phase.py [--supervised]
"""

import argparse
import json
import sys
import time

import numpy as np
from scipy import linalg, optimize

from mixture_ip_ros.app.training import majority_names
from mixture_ip_ros.app.evaluation.common import prefix_length
from mixture_ip_ros.core.demonstration import Demonstration
from mixture_ip_ros.core.mixture import MixtureIProMP
from mixture_ip_ros.core.promp import observation_stats, weight_posterior
from mixture_ip_ros.scenarios.gestures import gesture_demonstrations

CENTERS = np.array([0.2, 0.4, 0.6, 0.8])
SLOPE = 0.08


def warp(u, b):
    """g(u; beta) of eq. 34: linear + positive sigmoids, g(0) = 0, g(1) = 1, monotone."""
    beta = np.exp(b)
    sig = lambda x: 1.0 / (1.0 + np.exp(-(x[..., None] - CENTERS) / SLOPE))  # noqa: E731
    s0, s1 = sig(np.zeros(1))[0], sig(np.ones(1))[0]
    num = u + (sig(np.asarray(u)) - s0) @ beta
    return num / (1.0 + (s1 - s0) @ beta)


def loglik(model, k, z, y):
    st = observation_stats(model.basis_, z, y)
    do = model.n_observed_ * model.n_basis
    chol = linalg.cho_factor(model.covariances_[k][:do, :do], lower=True)
    noise = model.observed_noise_var_    # (P,) shared, or (K, P) per component
    return weight_posterior(st, model.means_[k][:do], chol,
                            noise if noise.ndim == 1 else noise[k])[2]


def best_warp(model, k, u, y, prior_sd, b0=None):
    def cost(b):
        return -(loglik(model, k, warp(u, b), y) - 0.5 * np.sum(b ** 2) / prior_sd ** 2)
    starts = [np.full(len(CENTERS), -3.0)] + ([b0] if b0 is not None else [])
    best = min((optimize.minimize(cost, s, method='Powell',
                                  options={'maxiter': 400, 'xtol': 1e-2, 'ftol': 1e-3})
                for s in starts), key=lambda r: r.fun)
    return best.x, -best.fun


def registered(demo, b):
    T = demo.duration
    return Demonstration(T * warp(demo.phase, b), demo.observed, None, demo.label, demo.name)


def accuracy(model, names, tests, fractions, prior_sd, warped):
    out = {}
    for f in fractions:
        ok = []
        for d in tests:
            n = max(prefix_length(d, f), 2)
            u, y = d.phase[:n], d.observed[:n]
            lp = np.log(model.weights_).copy()
            for k in range(model.n_components):
                lp[k] += (best_warp(model, k, u, y, prior_sd)[1] if warped
                          else loglik(model, k, u, y))
            ok.append(names[int(np.argmax(lp))] == d.label)
        out[f'{f:g}'] = float(np.mean(ok))
    return out


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument('--supervised', action='store_true')
    p.add_argument('--components', type=int, default=10)
    p.add_argument('--rounds', type=int, default=3)
    p.add_argument('--prior-sd', type=float, default=2.0)
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    train, test = gesture_demonstrations('train'), gesture_demonstrations('test')
    labels = np.array([d.label for d in train])
    fit_labels = labels if args.supervised else None
    fractions = (0.3, 0.5, 0.7, 1.0)
    K = len(set(labels)) if args.supervised else args.components

    def fit(demos):
        return MixtureIProMP(K).fit(demos, labels=fit_labels)
    model = fit(train)

    def named(m):
        return (list(m.classes_) if args.supervised
                else majority_names(np.argmax(m.resp_, 1), labels, K))
    result = {'supervised': args.supervised, 'n_components': K,
              'linear_phase': accuracy(model, named(model), test, fractions, args.prior_sd, False)}
    bs = [None] * len(train)
    ll_rounds = []
    for _ in range(args.rounds):
        comps = np.argmax(model.resp_, axis=1)
        total = 0.0
        for i, d in enumerate(train):
            bs[i], ll = best_warp(model, comps[i], d.phase, d.observed, args.prior_sd, bs[i])
            total += ll
        ll_rounds.append(total)
        model = fit([registered(d, b) for d, b in zip(train, bs)])
    result['training_loglik_by_round'] = ll_rounds
    result['warped_phase'] = accuracy(model, named(model), test, fractions, args.prior_sd, True)
    result['runtime_s'] = round(time.perf_counter() - t0, 1)
    print(json.dumps(result))


if __name__ == '__main__':
    sys.exit(main())
