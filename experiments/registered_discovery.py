"""Experiment: does registering the recordings in time before discovery make it survive a pace
that changes within each movement? Prints one JSON object.

On all the recordings of NuiSI v1 and v2, clean and with the people's pace changed (the
robustness bench's ``tempo``: scenarios.corruption.retimed, log pace std 0.3 correlated over a
fifth of the movement, onset and end kept), training's discovery (K chosen as `mixture-ip
train` chooses it) and the adjusted Rand index of its partition against the interactions.
Then the same discovery on the recordings registered in time: each recording's phase
z = g(t / T; b) a monotone warp (core.warp's family, b = 0 the linear phase),
b its MAP under a template, log p(both people's paths | template, b) - |b|^2 / (2 sd^2) (the
weights marginalised: eq. 21 with the noise of samples at the recording's rate), the thesis's
eq. 34 with a fixed Gaussian over b. Two templates: each recording's discovered component
(``component``), or one component for all (``common``: the K = 1 model, the registration of
functional data analysis); the template is learned again from the registered recordings and
every recording registered again from its original stamps, ``--iterations`` times. Each line:
K and the ARI after each round, and the mean |b|. And the warp inside the mixture's EM
(``em``): K kept from the discovery, every recording's warp fitted under every component, the
recording given to the component that explains it best with its warp (so that registration
may move it to another one), the mixture refitted from there; then K chosen again.
``--learn-prior`` learns each template's Gaussian over b (eq. 34's prior, per component).

    OPENBLAS_NUM_THREADS=1 python experiments/registered_discovery.py [--versions v1,v2]
        [--iterations 3] [--prior-sd 0.3] [--learn-prior] [--templates component,common,em]
"""

import argparse
from functools import partial
import json
import os
import time

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

import numpy as np  # noqa: E402
from scipy import linalg  # noqa: E402
from sklearn.metrics import adjusted_rand_score  # noqa: E402

from mixture_ip_ros.app.evaluation.common import trained  # noqa: E402
from mixture_ip_ros.app.evaluation.interactions import run_in_processes, interactions_config  # noqa: E402
from mixture_ip_ros.core.mixture import MixtureIProMP  # noqa: E402
from mixture_ip_ros.core.noise import noise_factor  # noqa: E402
from mixture_ip_ros.core.promp import observation_stats, weight_posterior  # noqa: E402
from mixture_ip_ros.core.warp import N_WARP, map_warp, registered, warp, warp_prior  # noqa: E402
from mixture_ip_ros.scenarios import nuisi  # noqa: E402
from mixture_ip_ros.scenarios.corruption import corrupted  # noqa: E402

CASES = {'clean': (), 'tempo': ('tempo',)}
TEMPLATES = ('component', 'common', 'em')
LEARN_STEPS, SD_FLOOR = 3, 0.05


def templates(model):
    """(mean, Cholesky factor of the covariance, noise per DOF at the recordings' own rate) of
    every component, both people."""
    nv = model.noise_var_ * noise_factor(model.noise_time_, model.sample_period_, 0.0)
    return [(model.means_[k], linalg.cho_factor(model.covariances_[k], lower=True),
             nv if nv.ndim == 1 else nv[k]) for k in range(model.n_components)]


def evidence(basis, template, demo):
    """log p(both people's paths | template, b) as a function of the warp b (eq. 21, the
    weights marginalised)."""
    Y = np.hstack([demo.observed, demo.controlled])
    ok = ~np.isnan(Y).any(axis=1)
    u, Y = demo.phase[ok], Y[ok]
    mean, chol, noise = template
    return lambda b: weight_posterior(observation_stats(basis, warp(u, b), Y), mean, chol,
                                      noise)[2]


def warps(basis, temps, comp, data, prior_sd, learn):
    """Every recording's MAP b under its template. With ``learn``, the Gaussian over b of each
    template's recordings is learned too (eq. 34: EM, ``LEARN_STEPS`` steps from N(0, sd^2 I),
    its sd kept above ``SD_FLOOR``)."""
    priors = {c: (np.zeros(N_WARP), np.full(N_WARP, prior_sd)) for c in set(comp)}
    for _ in range(LEARN_STEPS if learn else 1):
        b = np.array([map_warp(evidence(basis, temps[c], d), *priors[c])[0]
                      for c, d in zip(comp, data)])
        priors = {c: warp_prior(b[np.equal(comp, c)], sd_floor=SD_FLOOR) for c in priors}
    return b


def rounds(version, case, template, iterations, prior_sd, learn) -> dict:
    demos = nuisi.demonstrations(version, 'train') + nuisi.demonstrations(version, 'test')
    data = corrupted(demos, CASES[case], seed=0)
    labels = [d.label for d in data]
    config = interactions_config()
    out = {'k': [], 'ari': [], 'mean_abs_b': []}
    current = data
    for it in range(iterations + 1):
        model, _ = trained(current, config, n_jobs=1)
        comp = np.argmax(model.resp_, axis=1)
        out['k'].append(int(model.n_components))
        out['ari'].append(round(float(adjusted_rand_score(labels, comp)), 3))
        if it == iterations:
            break
        if template == 'common':
            model, _ = trained(current, config, n_jobs=1, n_components=1)
            comp = np.zeros(len(data), dtype=int)
        b = warps(model.basis_, templates(model), comp, data, prior_sd, learn)
        out['mean_abs_b'].append(round(float(np.linalg.norm(b, axis=1).mean()), 3))
        current = [registered(d, bi) for d, bi in zip(data, b)]
    return out


def em_rounds(version, case, iterations, prior_sd, learn) -> dict:
    """The warp inside the mixture's EM (eq. 34 with a Gaussian over b per component): from the
    discovered model, each round gives every recording its MAP warp under every component and
    its plug-in score there, log pi_k + log p(D | k, b_ik) + log N(b_ik; m_k, s_k^2), assigns
    it to the best, refits the mixture (same K, EM started from those assignments) on the
    recordings registered by their own component's warp and, with ``learn``, each component's
    Gaussian over b from its members' warps. Last, K chosen again on the last registration."""
    demos = nuisi.demonstrations(version, 'train') + nuisi.demonstrations(version, 'test')
    data = corrupted(demos, CASES[case], seed=0)
    labels = [d.label for d in data]
    config = interactions_config()
    model, _ = trained(data, config, n_jobs=1)
    K = model.n_components
    params = {**config.model, 'prior_scale': model.prior_scale,
              'speed_weight': model.speed_weight}
    comp = np.argmax(model.resp_, axis=1)
    priors = [(np.zeros(N_WARP), np.full(N_WARP, prior_sd))] * K
    out = {'k': int(K), 'ari': [round(float(adjusted_rand_score(labels, comp)), 3)],
           'switched': []}
    current = data
    for _ in range(iterations):
        temps = templates(model)
        score, b = np.empty((len(data), K)), np.empty((len(data), K, N_WARP))
        for i, d in enumerate(data):
            for k in range(K):
                ev = evidence(model.basis_, temps[k], d)
                b[i, k] = map_warp(ev, *priors[k])[0]
                m, sd = priors[k]
                score[i, k] = (np.log(model.weights_[k]) + ev(b[i, k])
                               - 0.5 * np.sum(((b[i, k] - m) / sd) ** 2) - np.sum(np.log(sd)))
        new = np.argmax(score, axis=1)
        out['switched'].append(int(np.sum(new != comp)))
        comp = new
        own = b[np.arange(len(data)), comp]
        if learn:
            priors = [warp_prior(own[comp == k], sd_floor=SD_FLOOR) if np.any(comp == k)
                      else priors[k] for k in range(K)]
        current = [registered(d, bi) for d, bi in zip(data, own)]
        model = MixtureIProMP(n_components=K, **params).fit(current, init=comp)
        comp = np.argmax(model.resp_, axis=1)
        out['ari'].append(round(float(adjusted_rand_score(labels, comp)), 3))
    again, _ = trained(current, config, n_jobs=1)
    out['k_chosen_again'] = int(again.n_components)
    out['ari_chosen_again'] = round(float(adjusted_rand_score(
        labels, np.argmax(again.resp_, axis=1))), 3)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--versions', default='v1,v2')
    ap.add_argument('--iterations', type=int, default=3)
    ap.add_argument('--prior-sd', type=float, default=0.3)
    ap.add_argument('--learn-prior', action='store_true',
                    help="learn each template's Gaussian over b, starting from --prior-sd")
    ap.add_argument('--templates', default=','.join(TEMPLATES))
    args = ap.parse_args()
    t0 = time.perf_counter()
    runs = [(v, c, m) for v in args.versions.split(',') for c in CASES
            for m in args.templates.split(',')]
    results = run_in_processes([partial(em_rounds, v, c, args.iterations, args.prior_sd, args.learn_prior)
                    if m == 'em' else
                    partial(rounds, v, c, m, args.iterations, args.prior_sd, args.learn_prior)
                    for v, c, m in runs])
    out = {'prior_sd': args.prior_sd, 'learn_prior': args.learn_prior,
           'iterations': args.iterations}
    for (v, c, m), r in zip(runs, results):
        out.setdefault(v, {}).setdefault(c, {})[m] = r
    out['runtime_s'] = round(time.perf_counter() - t0, 1)
    print(json.dumps(out))


if __name__ == '__main__':
    main()
