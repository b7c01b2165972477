"""Experiment: does a phase that bends (the thesis's future work, section 4.2.2, eq. 34) predict
the partner better on the real interactions (NuiSI v1 and v2)? Prints one JSON object.

The phase z = g(t / T; b) is a monotone warp with z(0) = 0, z(1) = 1: g(u) = int_0^u r / int_0^1 r,
the relative phase rate r(s) = exp(sum_j b_j phi_j(s)) with Gaussian bumps phi_j (a monotone
family by construction, Ramsay & Li 1998's; b = 0 is the linear phase z = t / T). Each
demonstration's b is its MAP under its component, log p(D_i | k_i, b) + log N(b; 0, s^2 I) (the
observed agent, weights marginalised: eq. 21), and a component's warp is the mean b of its
members. On the same 5 stratified folds as `mixture-ip evaluate --scenario interactions`, the
supervised mixture (one component per interaction, so that the clustering is not what is
measured), partner RMS over the rest of the interaction after 30 / 50 / 70 % (mean over the
held-out recordings, cm, as docs/results.md):

- with the duration T known (oracles of the timing; the prefix conditions the weights): the
  linear phase t / T; the recording's own warp (fitted on its whole observed path); its
  component's mean warp; and the same three with the model trained on the registered
  demonstrations (each training recording at its own warped phase: the alternation of EM over
  weights and warps, one round);
- online, T unknown, as the estimator node predicts (p(k, alpha | D) over the estimator's alpha
  grid with z = g_k(alpha t), the speed marginalised under the tempered posterior of the
  model's speed weight): linear (and the package's own OnlineEstimator, to check the batch
  code), the component's mean warp, and the registered model with it; and the linear phase
  under other speed weights (how much the prefix tells of the speed); and a speed that may
  change at the present (the phase reached from the prefix's evidence, the rest of the
  movement at the speeds of the prior or of a tempered posterior: the one-step version of a
  phase velocity in the state);
- online, the warp tracked (the issue's item 2 in its exact form, by brute force): each
  component's Gaussian over the warp as training learns it (core.warped.PhaseWarps; learned
  here also where training chose the linear phase), and the posterior over the speed grid and
  the warp given the prefix, the warp integrated out two ways: over N_POINTS fixed points of
  the Gaussian (exact for that set of hypotheses, each a Kalman state the estimator would
  carry), and at each grid speed by Laplace's method at its MAP warp (what the end event
  does once T is known); the rest placed at each hypothesis's own warped phase.

And what a phase tracked as the movement goes could give the arm, which replans every 0.1 s and
so needs the partner only a little ahead: at every 0.25 s from 20 % of each held-out recording
on, the partner predicted h = 0, 0.3 and 1 s ahead (RMS over those instants, mean over the
recordings), by the package's estimator, with T known, and with the phase of each sample taken
from a DTW alignment of the observed path to its component's mean: of the whole recording (an
oracle of perfect phase tracking: any monotone phase, chosen knowing the future) and of the
prefix only (open-end DTW, causal; ahead of the present at the estimator's MAP speed).

And how much the beginning of a recording tells of its duration, which the linear phase needs
to place the rest of the partner's movement in time: after 30 / 50 / 70 %, the error of four
causal estimates of T (the component's mean duration, the package's speed posterior, open-end
DTW against the component's mean path, and against each of its training recordings), with the
partner RMS when each is taken as T; whether the shape of the prefix tells T (a bound: ridge
regression of log T on the prefix read at its own true phase, as if it were aligned perfectly,
trained on the component's training recordings read the same way); and, to tell the precision
an aim asks for, the partner RMS with T known but 3, 5 or 10 % off.

With ``--pace-changed`` every recording first gets the people's pace changed within the
movement (scenarios.corruption.retimed, the robustness bench's ``tempo``): holds and hurries a
warp is made for.

    OPENBLAS_NUM_THREADS=1 python experiments/nonlinear_phase.py [--versions v1,v2] [--pace-changed]
"""

import argparse
import json
import os
import sys
import time

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

import numpy as np  # noqa: E402
from scipy import linalg  # noqa: E402
from scipy.special import logsumexp  # noqa: E402
from scipy.stats import norm, qmc  # noqa: E402
from sklearn.linear_model import RidgeCV  # noqa: E402
from sklearn.pipeline import make_pipeline  # noqa: E402
from sklearn.preprocessing import StandardScaler  # noqa: E402

from mixture_ip_ros.app.evaluation.common import trained  # noqa: E402
from mixture_ip_ros.app.evaluation.interactions import (interactions_config,  # noqa: E402
                                                        stratified_folds)
from mixture_ip_ros.core.online import OnlineEstimator, supported  # noqa: E402
from mixture_ip_ros.core.playback import (absorbed_rows, observed_rows,  # noqa: E402
                                          prefix_predictions, prefixes, rest_rows)
from mixture_ip_ros.core.phase import tempered_speed_posterior  # noqa: E402
from mixture_ip_ros.core.promp import observation_stats, weight_posterior  # noqa: E402
from mixture_ip_ros.core.warp import N_WARP, laplace, map_warp, registered, warp  # noqa: E402
from mixture_ip_ros.core.warped import (PhaseWarps, WarpEvidence,  # noqa: E402
                                        observed_prior)
from mixture_ip_ros.scenarios.corruption import corrupted  # noqa: E402

FRACTIONS = (0.3, 0.5, 0.7)
ETAS = (1.0, 0.5, 0.2, 0.05, 0.0)
# The speed may change now: the phase reached from one tempered posterior, the rest of the
# movement at the speeds of another (0: the prior's).
SPLITS = ((1.0, 0.0), (0.2, 0.0), (1.0, 0.2))
DURATION_ESTIMATES = ("the component's mean duration", "the package's (speed posterior)",
                      "open-end DTW to the component's mean path",
                      'open-end DTW to each training recording of the component (median)',
                      "oracle: regression on the prefix's shape, read at its true phase")
SHAPE_POINTS = 6                             # phases per DOF where the regression reads a prefix
DURATION_OFF = (0.03, 0.05, 0.1)              # T known this far off: the precision an aim needs
HORIZONS = (0.0, 0.3, 1.0)                   # s ahead of a replan
REPLAN_FROM, REPLAN_STEP = 0.2, 0.25         # replans from 20 % of the movement, every 0.25 s
MAX_STEP = 4                                 # DTW: template steps a sample may move the phase on
# The warp tracked online: N_POINTS quasi-random points of a standard normal in N_WARP dimensions
# (scrambled Sobol, seed 0), each component's learned Gaussian's mean + sd * point.
N_POINTS = 16
WARP_POINTS = norm.ppf(qmc.Sobol(N_WARP, scramble=True, seed=0).random(N_POINTS))


class Observed:
    """Component k's prior over the observed agent's weights and its noise at a sample spacing."""

    def __init__(self, model, k, interval=None):
        do = model.n_observed_ * model.n_basis
        self.model, self.k = model, k
        self.mean = model.means_[k][:do]
        self.chol = linalg.cho_factor(model.covariances_[k][:do, :do], lower=True)
        self.noise = model.observed_noise(k, interval)
        C = model.covariances_[k]
        self.gain = linalg.cho_solve(self.chol, C[:do, do:]).T   # controlled on observed

    def posterior(self, z, y):
        """(posterior mean of the observed weights, log p(D | k)) at phases z."""
        mu, _, ll = weight_posterior(observation_stats(self.model.basis_, z, y), self.mean,
                                     self.chol, self.noise)
        return mu, ll

    def path(self, n):
        """The component's mean observed path at n phases evenly from 0 to 1: (z, (n, P))."""
        z = np.linspace(0.0, 1.0, max(2, n))
        return z, self.model.basis_(z) @ self.mean.reshape(-1, self.model.n_basis).T

    def partner(self, mu, z):
        """The controlled agent's mean at phases z given the observed weights' mean mu."""
        m = self.model
        w = (m.means_[self.k][len(mu):] + self.gain @ (mu - self.mean)).reshape(-1, m.n_basis)
        return m.basis_(np.clip(z, 0.0, 1.0)) @ w.T


def fit_warp(comp, demo, prior_sd):
    """The MAP b of ``demo``'s observed path under ``comp`` and N(0, prior_sd^2 I), and whether
    the optimiser converged (a recording whose fit does not converge keeps the linear phase)."""
    ok = observed_rows(demo)
    u, y = demo.phase[ok], demo.observed[ok]
    return map_warp(lambda b: comp.posterior(warp(u, b), y)[1], np.zeros(N_WARP), prior_sd)


def rms(pred, truth):
    return float(np.sqrt(np.mean(np.sum((pred - truth) ** 2, axis=1))))


def prefixes_and_rests(demo, config):
    """For each of FRACTIONS f: (times, positions) of the observed agent's samples the estimator
    absorbs up to f T, and the samples after f T where the controlled agent was recorded."""
    used = absorbed_rows(demo, config.min_interval)
    for f in FRACTIONS:
        sel = used[demo.t[used] <= f * demo.duration + 1e-9]
        yield demo.t[sel], demo.observed[sel], rest_rows(demo, f * demo.duration)


def online(model, warps, demo, config, etas):
    """Partner RMS after each fraction, T unknown: {eta: [per fraction]} for the MAP component's
    expected path over the speed grid, phases z = g(alpha t; b). ``warps`` (K, S, N_WARP): each
    component's warp points, equally probable a priori; the posterior over (alpha, b) on the
    grid times the points is exact: p(D | k, alpha) the mean over the points of p(D | k, alpha,
    b_s) (S = 1: one warp per component), p(b_s | D, k, alpha) ~ p(D | k, alpha, b_s)."""
    est = OnlineEstimator(model, n_alpha=config.n_alpha, min_interval=config.min_interval)
    K, M, S = model.n_components, len(est.alphas), warps.shape[1]
    log_prior = est.log_prior
    comps = [Observed(model, k, config.min_interval) for k in range(K)]
    out = {eta: [] for eta in etas}
    for t, y, rest in prefixes_and_rests(demo, config):
        evidence, mus = np.empty((K, M, S)), {}
        for k in range(K):
            for m, a in enumerate(est.alphas):
                for s in range(S):
                    mus[k, m, s], evidence[k, m, s] = comps[k].posterior(warp(a * t, warps[k, s]),
                                                                         y)
        speed_evidence = logsumexp(evidence, axis=2) - np.log(S)
        k = int(np.argmax(logsumexp(log_prior + speed_evidence, axis=1)))
        for eta in etas:
            if isinstance(eta, tuple):      # (eta of the phase reached, eta of the rest's speed)
                now, later = (speeds(speed_evidence[k], log_prior[k], e) for e in eta)
            else:
                now = speeds(speed_evidence[k], log_prior[k],
                             model.speed_weight if eta is None else eta)
                later = None
            pred = 0.0
            for m, pm in zip(*now):
                for s, ps in zip(*supported(np.exp(evidence[k, m] - evidence[k, m].max()))):
                    if later is None:       # one speed from the onset to the end
                        z = est.alphas[m] * demo.t[rest]
                        pred = pred + pm * ps * comps[k].partner(mus[k, m, s],
                                                                 warp(z, warps[k, s]))
                        continue
                    for j, pj in zip(*later):   # the phase reached at t[-1], then another speed
                        z = est.alphas[m] * t[-1] + est.alphas[j] * (demo.t[rest] - t[-1])
                        pred = pred + pm * pj * ps * comps[k].partner(mus[k, m, s],
                                                                      warp(z, warps[k, s]))
            out[eta].append(rms(pred, demo.controlled[rest]))
    return out


def online_laplace(model, demo, config):
    """Partner RMS after each fraction, T unknown, the warp integrated out at each grid speed by
    Laplace's method under the component's learned Gaussian (core.warped.PhaseWarps):
    p(D | k, alpha) = int p(D | k, alpha, b) p(b | k) db at the MAP b of that speed, whose
    phase g(alpha t; b) then places the rest; the speed under the model's speed weight."""
    est = OnlineEstimator(model, n_alpha=config.n_alpha, min_interval=config.min_interval)
    K, M = model.n_components, len(est.alphas)
    log_prior = est.log_prior
    comps = [Observed(model, k, config.min_interval) for k in range(K)]
    priors = [observed_prior(model, k) for k in range(K)]
    out = []
    for t, y, rest in prefixes_and_rests(demo, config):
        evidence, b = np.full((K, M), -np.inf), np.zeros((K, M, N_WARP))
        for k in range(K):
            prior = model.warps_.mean_[k], model.warps_.sd_[k]
            for m, a in enumerate(est.alphas):
                ev = WarpEvidence(model, k, a * t, y, config.min_interval, priors[k])
                b[k, m], converged = map_warp(ev, *prior, gradient=True)
                if converged:           # else the speed is left out, as training leaves it
                    evidence[k, m] = laplace(ev, b[k, m], *prior)[0]
        k = int(np.argmax(logsumexp(log_prior + evidence, axis=1)))
        pred = 0.0
        for m, pm in zip(*speeds(evidence[k], log_prior[k], model.speed_weight)):
            mu = comps[k].posterior(warp(est.alphas[m] * t, b[k, m]), y)[0]
            pred = pred + pm * comps[k].partner(mu, warp(est.alphas[m] * demo.t[rest], b[k, m]))
        out.append(rms(pred, demo.controlled[rest]))
    return out


def speeds(evidence, log_prior, eta):
    """The grid speeds holding the tempered posterior (OnlineEstimator.speed_hypotheses): their
    indices and renormalised probabilities."""
    return supported(np.exp(tempered_speed_posterior(evidence, log_prior, eta)))


def known_duration(comp, warps, demo, config):
    """Partner RMS after each fraction with T known, per named warp b: {name: [per fraction]}."""
    out = {name: [] for name in warps}
    for t, y, rest in prefixes_and_rests(demo, config):
        for name, b in warps.items():
            mu = comp.posterior(warp(t / demo.duration, b), y)[0]
            out[name].append(rms(comp.partner(mu, warp(demo.t[rest] / demo.duration, b)),
                                 demo.controlled[rest]))
    return out


def aligned_phases(y, template, open_end):
    """The phase of each sample of ``y`` (n, P) by DTW against ``template`` (the component's
    mean path at phases z, (G, P)): the best alignment, squared distances, from the start of
    both to the end of both (``open_end`` False) or to the template phase where the prefix ends
    best (open-end). Each sample moves the phase on by 0 to MAX_STEP template steps: the
    template is sampled at twice the samples a movement of the component's mean duration has,
    so the phase runs at most at twice the mean speed and may stop."""
    z, template = template
    n, G = len(y), len(z)
    cost = np.sum((y[:, None, :] - template[None]) ** 2, axis=2)
    D = np.full((n, G), np.inf)
    step = np.zeros((n, G), dtype=int)
    D[0, 0] = cost[0, 0]
    for i in range(1, n):
        prev = np.stack([np.r_[np.full(s, np.inf), D[i - 1, :G - s]]
                         for s in range(MAX_STEP + 1)])
        step[i] = np.argmin(prev, axis=0)
        D[i] = cost[i] + prev[step[i], np.arange(G)]
    j = int(np.argmin(D[-1])) if open_end else G - 1
    if not np.isfinite(D[-1, j]):          # the end not reachable: the best reachable one
        j = int(np.argmin(D[-1]))
    out = np.empty(n)
    for i in range(n - 1, -1, -1):
        out[i] = z[j]
        j -= step[i, j]
    return out


def horizons(comps, k, est, demo, config, durations):
    """Partner RMS h ahead of each replan instant, per method: {name: [per horizon]}. ``comps``:
    every component's Observed; ``k``: the recording's own (the oracles'; the causal DTW takes
    the estimator's MAP component, as the package does); ``durations``: each component's mean
    training duration (its DTW template's sampling)."""
    used = absorbed_rows(demo, config.min_interval)
    T = demo.duration
    # the sensor's sample interval after decimation (a property of the stream, not of the future)
    dt = float(np.median(np.diff(demo.t[used])))

    templates = [comps[c].path(int(round(2 * durations[c] / dt))) for c in range(len(comps))]
    whole = aligned_phases(demo.observed[used], templates[k], open_end=False)
    names = ("the package's estimator", 'T known', 'aligned on the whole recording (DTW, an '
             'oracle)', "aligned on the prefix (open-end DTW; the MAP component), ahead at the "
             'MAP speed')
    err = {name: {h: [] for h in HORIZONS} for name in names}
    recorded = ~np.isnan(demo.controlled).any(axis=1)

    def partner_at(t):
        return np.array([np.interp(t, demo.t[recorded], demo.controlled[recorded, j])
                         for j in range(demo.n_controlled_dofs)])
    for cut in prefixes(est, demo, np.arange(REPLAN_FROM * T, T, REPLAN_STEP)):
        sel = demo.t[used] <= cut + 1e-9
        t_seen, y = demo.t[used][sel], demo.observed[used][sel]
        known = comps[k].posterior(t_seen / T, y)[0]
        oracle = comps[k].posterior(whole[sel], y)[0]
        k_map, alpha = est.map_hypothesis()
        z_prefix = aligned_phases(y, templates[k_map], open_end=True)
        causal = comps[k_map].posterior(z_prefix, y)[0]
        for h in HORIZONS:
            t = cut + h
            if t > T:
                continue
            z_whole = np.interp(t, demo.t[used], whole)
            z_ahead = min(z_prefix[-1] + alpha * (t - t_seen[-1]), 1.0)
            preds = (est.expected_controlled([t], derivatives=False)[1][0],
                     comps[k].partner(known, np.array([t / T]))[0],
                     comps[k].partner(oracle, np.array([z_whole]))[0],
                     comps[k_map].partner(causal, np.array([z_ahead]))[0])
            for name, p in zip(names, preds):
                err[name][h].append(float(np.sum((p - partner_at(t)) ** 2)))
    return {name: [float(np.sqrt(np.mean(e[h]))) if e[h] else np.nan for h in HORIZONS]
            for name, e in err.items()}


def durations_told(comps, k, est, demo, config, same, durations):
    """How much the beginning of ``demo`` tells of its duration T, after each fraction: per
    estimate of T, (mean |T_hat / T - 1|, partner RMS with the phase t / T_hat), the linear
    phase conditioned on the prefix as with T known. The estimates, all causal and all of the
    recording's own component k (so that only the timing is measured): the mean duration of
    the component's training recordings (the prior alone); the package's (the tempered speed
    posterior's mean 1 / alpha); t / z with z the phase the prefix reaches by open-end DTW
    against the component's mean path; and the median over the component's training
    recordings ``same`` of t T_i / t_i, t_i the time of recording i the prefix reaches by
    open-end DTW against it (nearest neighbours that need no model). And one that is not causal,
    a bound on what the prefix's shape tells of T: log T regressed (ridge, penalty by
    leave-one-out, the prediction kept within the training durations) on the observed path at
    SHAPE_POINTS phases up to the fraction, each recording read at its own true phase t / T
    (Fitts: a longer reach may take longer)."""
    used = absorbed_rows(demo, config.min_interval)
    T = demo.duration
    dt = float(np.median(np.diff(demo.t[used])))

    def at_phase(d, z):              # d's observed path at its true phases z = t / T
        ok = observed_rows(d)
        return np.stack([np.interp(z, d.t[ok] / d.duration, d.observed[ok, j])
                         for j in range(d.n_observed_dofs)], axis=1)

    mean_path = comps[k].path(int(round(2 * durations[k] / dt)))
    neighbours = []           # each at the phases a template has (aligned_phases' step bound)
    for d in same:
        z = np.linspace(0.0, 1.0, max(2, int(round(2 * d.duration / dt))))
        neighbours.append((z, at_phase(d, z)))

    def shape(d, fraction):          # the observed path up to ``fraction``, one row
        return at_phase(d, np.linspace(0.0, fraction, SHAPE_POINTS)).ravel()

    def shape_duration(fraction):
        # Within the training durations: with ~15 recordings and 18 features, leave-one-out
        # can choose a near-zero penalty whose fit extrapolates far (v1: 146 % off).
        regression = make_pipeline(StandardScaler(), RidgeCV(alphas=np.logspace(-2, 4, 25)))
        log_T = np.log([d.duration for d in same])
        regression.fit(np.stack([shape(d, fraction) for d in same]), log_T)
        return float(np.exp(np.clip(regression.predict(shape(demo, fraction)[None])[0],
                                    log_T.min(), log_T.max())))

    def partner_rms(T_hat):          # of the prefix (t, y) and the rest at the present cut
        mu = comps[k].posterior(t / T_hat, y)[0]
        return rms(comps[k].partner(mu, demo.t[rest] / T_hat), demo.controlled[rest])
    out = {}
    for fraction, cut in zip(FRACTIONS, prefixes(est, demo, np.multiply(FRACTIONS, T))):
        sel = used[demo.t[used] <= cut + 1e-9]
        t, y = demo.t[sel], demo.observed[sel]
        rest = rest_rows(demo, cut)
        m, p = est.speed_hypotheses(k)
        told = (durations[k], float(p @ (1.0 / est.alphas[m])),
                t[-1] / max(aligned_phases(y, mean_path, open_end=True)[-1], 1e-3),
                float(np.median([t[-1] / max(aligned_phases(y, path, open_end=True)[-1], 1e-3)
                                 for path in neighbours])),
                shape_duration(fraction))
        for name, T_hat in zip(DURATION_ESTIMATES, told):
            out.setdefault(name, []).append((abs(T_hat / T - 1.0), partner_rms(T_hat)))
        for e in DURATION_OFF:
            out.setdefault(f'T known, {100 * e:g} % off (either way)', []).append(
                (e, 0.5 * (partner_rms(T * (1 + e)) + partner_rms(T * (1 - e)))))
    return out


def version(v, prior_sd, pace_changed=False):
    from mixture_ip_ros.scenarios import nuisi
    demos = nuisi.demonstrations(v, 'train') + nuisi.demonstrations(v, 'test')
    if pace_changed:
        demos = corrupted(demos, ('tempo',), seed=0)
    labels = np.array([d.label for d in demos])
    folds = stratified_folds(labels)
    config = interactions_config()
    rows, ahead, told, failed, failed_learned, chosen = {}, {}, {}, [], [], []

    def add(name, values, to=rows):
        to.setdefault(name, []).append(values)
    for f in range(folds.max() + 1):
        train_i, test_i = np.flatnonzero(folds != f), np.flatnonzero(folds == f)
        train = [demos[i] for i in train_i]
        model, info = trained(train, config, n_jobs=1, labels=labels[train_i])
        chosen.append(info['phase']['chosen'])
        if model.warps_ is None:            # training chose the linear phase: warps anyway
            model.warps_ = PhaseWarps().fit(model, train)
        failed_learned += [str(x) for x in model.warps_.failed_]
        # The online warp's points: the same standard normal points for every component.
        points = model.warps_.mean_[:, None] + model.warps_.sd_[:, None] * WARP_POINTS
        names = list(model.classes_)
        comp_of = [names.index(labels[i]) for i in train_i]
        fits = [fit_warp(Observed(model, k), d, prior_sd) for k, d in zip(comp_of, train)]
        failed += [d.name for d, (_, good) in zip(train, fits) if not good]
        b = np.array([x for x, _ in fits])
        means = np.array([b[np.equal(comp_of, k)].mean(axis=0) for k in range(len(names))])
        at_warps = [registered(d, bi) for d, bi in zip(train, b)]
        reg_model, _ = trained(at_warps, config, n_jobs=1, labels=labels[train_i])
        linear = np.zeros((len(names), N_WARP))
        durations = [np.mean([d.duration for d, c in zip(train, comp_of) if c == k])
                     for k in range(len(names))]
        observed = [Observed(model, c, config.min_interval) for c in range(len(names))]
        est = OnlineEstimator(model, n_alpha=config.n_alpha, min_interval=config.min_interval)
        for i in test_i:
            d = demos[i]
            k = names.index(labels[i])
            for tag, mod in (('', model), ('registered, ', reg_model)):
                comp = Observed(mod, k, config.min_interval)
                own, good = fit_warp(Observed(mod, k), d, prior_sd)
                if not good:
                    failed.append(d.name)
                for name, r in known_duration(comp, {'linear': np.zeros(N_WARP),
                                                     "recording's own warp": own,
                                                     "component's mean warp": means[k]},
                                              d, config).items():
                    add(f'T known, {tag}{name}', r)
            lin = online(model, linear[:, None], d, config, (None,) + ETAS + SPLITS)
            add('online, linear', lin[None])
            for eta in ETAS:
                add(f'online, linear, speed weight {eta:g}', lin[eta])
            for now, later in SPLITS:
                add(f'online, the phase reached from speed weight {now:g}, the rest at speed '
                    f'weight {later:g}', lin[now, later])
            add("online, component's mean warp",
                online(model, means[:, None], d, config, (None,))[None])
            add("online, registered, component's mean warp",
                online(reg_model, means[:, None], d, config, (None,))[None])
            add(f"online, the warp tracked: {N_POINTS} points of the component's learned "
                'Gaussian', online(model, points, d, config, (None,))[None])
            add("online, the warp tracked: integrated at each speed by Laplace's method",
                online_laplace(model, d, config))
            add("online, the package's estimator",
                [rms(p.controlled, d.controlled[p.rest])
                 for p in prefix_predictions(est, d, FRACTIONS)])
            for name, r in horizons(observed, k, est, d, config, durations).items():
                add(name, r, ahead)
            same = [demos[j] for j in train_i if labels[j] == labels[i]]
            for name, r in durations_told(observed, k, est, d, config, same, durations).items():
                add(name, r, told)
    return {'partner_rms_cm_mean_by_fraction': {
        name: [round(100 * float(x), 1) for x in np.mean(r, axis=0)] for name, r in rows.items()},
        'partner_rms_cm_mean_by_horizon': {
        name: [round(100 * float(x), 1) for x in np.nanmean(r, axis=0)]
        for name, r in ahead.items()},
        'duration_told_by_fraction': {      # name: [[mean |T_hat / T - 1|, partner RMS cm]]
            name: [[round(float(e), 3), round(100 * float(x), 1)] for e, x in np.mean(r, axis=0)]
            for name, r in told.items()},
        'warp_fits_not_converged': failed,
        'learned_warp_fits_not_converged': failed_learned,
        'training_chose_warped': f"{chosen.count('warped')} of {len(chosen)}"}


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument('--versions', default='v1,v2')
    p.add_argument('--prior-sd', type=float, default=1.0,
                   help='prior standard deviation of the log phase rate weights b')
    p.add_argument('--pace-changed', action='store_true',
                   help="the recordings with the people's pace changed within each movement "
                   "(the robustness bench's tempo)")
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    out = {'fractions': list(FRACTIONS), 'horizons_s': list(HORIZONS), 'prior_sd': args.prior_sd,
           'n_warp': N_WARP, 'n_warp_points': N_POINTS, 'pace_changed': args.pace_changed}
    for v in args.versions.split(','):
        out[v] = version(v, args.prior_sd, args.pace_changed)
    out['runtime_s'] = round(time.perf_counter() - t0, 1)
    print(json.dumps(out))


if __name__ == '__main__':
    sys.exit(main())
