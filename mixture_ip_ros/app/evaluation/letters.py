"""The letters (thesis chapter 4): phase estimation (4.3.1, Figs. 19, 26-27), the RMS of the
completed letter vs observed fraction and the alpha estimate (the MAP between the online
estimator's grid values); missing data (4.3.2, Figs. 36-37, 42-43), EM against per-trajectory
regression from training letters with a block of 180 missing samples, and EM's log-likelihood
per iteration. One pattern, so one component, at the floor training calibrates for it."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy import linalg

from mixture_ip_ros.app.evaluation.common import (EvalConfig, observed_prediction,
                                                  trained, with_default_noise)
from mixture_ip_ros.core.mixture import MixtureIProMP
from mixture_ip_ros.core.online import OnlineEstimator
from mixture_ip_ros.core.playback import prefixes
from mixture_ip_ros.core.promp import observation_stats, weight_posterior
from mixture_ip_ros.scenarios.letters import LETTER_OBSERVATION_NOISE
from mixture_ip_ros.viz import plots


def letter_config(quick: bool = False) -> EvalConfig:
    fractions = (np.round(np.arange(0.05, 1.0001, 0.05), 2) if quick
                 else np.round(np.arange(0.01, 1.0001, 0.01), 2))
    return EvalConfig(candidates=(1,), model={'n_basis': 15}, fractions=tuple(fractions))


# =========================================================================== entry point



def letter_completion(model, test, fractions, n_alpha=50, min_interval=0.05, keep=()):
    """Observe the first fraction of ``test`` (by time steps, as the thesis), estimate the phase,
    complete the letter. Returns RMS (len(fractions),), MAP alpha (len(fractions),), and for the
    fractions in ``keep`` a snapshot {fraction: (pred mean, pred cov, alpha posterior)}."""
    est = OnlineEstimator(model, n_alpha=n_alpha, min_interval=min_interval)
    n = test.t.size
    rms = np.full(len(fractions), np.nan)
    alpha = np.full(len(fractions), np.nan)
    snaps = {}
    ends = [max(int(np.ceil(f * n)) - 1, 0) for f in fractions]   # the thesis's time steps
    for c, (f, last, _) in enumerate(zip(fractions, ends, prefixes(est, test, test.t[ends]))):
        if est.n_observations == 0:
            continue
        snap = any(abs(f - k) < 1e-9 for k in keep)
        mean, cov, a = observed_prediction(est, test.t, with_cov=snap)
        rms[c] = np.sqrt(np.mean((mean - test.observed) ** 2))
        alpha[c] = a
        if snap:
            snaps[float(f)] = (mean, cov, est.alpha_posterior(), est.alphas.copy(), last)
    return rms, alpha, snaps


def _letter_rms_table(model, tests, config, keep=()):
    fractions = np.asarray(config.fractions, dtype=float)
    R, A, S = [], [], []
    for i, test in enumerate(tests):
        r, a, s = letter_completion(model, test, fractions, config.n_alpha, config.min_interval,
                                    keep if i == 0 else ())
        R.append(r)
        A.append(a)
        S.append(s)
    return fractions, np.array(R), np.array(A), S


def _by_fraction(fractions, R):
    return {f'{f:g}': [float(np.nanmean(R[:, c])), float(np.nanstd(R[:, c]))]
            for c, f in enumerate(fractions)}


def evaluate_phase(data, out_dir: Path, config: EvalConfig = None) -> dict:
    """Thesis 4.3.1 (Figs. 16-27): train on 20 letters, complete 20 test letters online."""
    config = with_default_noise(config or letter_config(), LETTER_OBSERVATION_NOISE)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    model, info = trained(data.train, config, n_components=1, method='regression')
    keep = (0.05, 0.1, 0.2, 0.4, 0.6)
    cfg = replace(config, fractions=tuple(sorted(set(np.round(config.fractions, 2)) | set(keep))))
    fractions, R, A, S = _letter_rms_table(model, data.test, cfg, keep)
    true_alpha = np.asarray(data.test_alpha)
    step = float(np.mean(np.diff(OnlineEstimator(model, n_alpha=cfg.n_alpha).alphas)))
    err = np.abs(A - true_alpha[:, None])
    c40 = int(np.argmin(np.abs(fractions - 0.4)))
    plots.letter_rms(out_dir / 'phase_rms_per_trajectory.png', out_dir / 'phase_rms_mean_std.png',
                     fractions, R, 'Phase estimation (thesis Figs. 26-27)')
    plots.letter_completion_panels(out_dir / 'phase_completion.png', data.test[0], S[0],
                                   data.train, true_alpha[0])
    plots.alpha_error(out_dir / 'phase_alpha_error.png', fractions, A, true_alpha, step)
    by_fraction = _by_fraction(fractions, R)
    return {
        'rms_by_fraction': by_fraction,
        'rms_at': {f'{f:g}': by_fraction[f'{f:g}'] for f in (0.2, 0.4, 0.6, 0.8, 1.0)},
        'alpha_accuracy_at_40': float(np.mean(err[:, c40] <= step + 1e-12)),
        'alpha_nearest_at_40': float(np.mean(err[:, c40] <= 0.5 * step + 1e-12)),
        'alpha_rel_error_median_at_40': float(np.median(err[:, c40] / true_alpha)),
        'alpha_grid_step': step,
        'prior_scale': info['prior_scale'],
        'speed_weight': info['speed_weight'],
        'units': {'rms': 'letter units (letter height ~2), per coordinate, [mean, std] over test '
                         'letters', 'alpha_accuracy_at_40': 'fraction of test letters whose MAP '
                         'alpha is within one grid step of the true alpha'},
        'n_train': len(data.train), 'n_test': len(data.test),
        'config': cfg.to_dict(),
        'plots': ['phase_rms_per_trajectory.png', 'phase_rms_mean_std.png', 'phase_completion.png',
                  'phase_alpha_error.png'],
    }


def evaluate_missing_data(data, out_dir: Path, config: EvalConfig = None) -> dict:
    """Thesis 4.3.2 (Figs. 36-37, 42-43): EM vs regression from training letters with gaps."""
    config = with_default_noise(config or letter_config(), LETTER_OBSERVATION_NOISE)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    # Both at the same, configured floor: the experiment compares two ways of learning from
    # gaps (and training keeps the configured floor for EM, see training.train).
    floor = {'prior_scale': config.model.get('prior_scale', MixtureIProMP().prior_scale)}
    models = {m: trained(data.train, config, n_components=1, method=m, **floor)[0]
              for m in ('em', 'regression')}
    tables = {m: _letter_rms_table(models[m], data.test, config) for m in models}
    fractions = tables['em'][0]
    ll = np.asarray(models['em'].log_likelihood_)
    monotone = bool(np.all(np.diff(ll) >= -1e-9 * np.maximum(1.0, np.abs(ll[1:]))))
    mean_em = np.nanmean(tables['em'][1], axis=0)
    mean_reg = np.nanmean(tables['regression'][1], axis=0)
    # Paired over the same test letters: a difference counts where it exceeds two standard errors.
    diff = tables['regression'][1] - tables['em'][1]
    se = np.nanstd(diff, axis=0, ddof=1) / np.sqrt(np.sum(~np.isnan(diff), axis=0))
    gain = np.nanmean(diff, axis=0)

    # Figs. 36-37: one training letter as each method reconstructs it from its observed part.
    i = int(np.argmax([np.isnan(tr.observed[:, 0]).mean() for tr in data.train]))
    demo = data.train[i]
    z = demo.phase
    em = models['em']
    st = observation_stats(em.basis_, z, demo.observed)
    w_em = weight_posterior(st, em.means_[0], linalg.cho_factor(em.covariances_[0], lower=True),
                            em.noise_var_)[0]
    N = em.n_basis
    w_reg = models['regression'].demonstration_weights([demo])[0]
    psi = em.basis_(z)
    recon = {'regression': psi @ w_reg.reshape(-1, N).T, 'em': psi @ w_em.reshape(-1, N).T}
    plots.missing_data(out_dir / 'missing_data_rms_em_vs_regression.png',
                       out_dir / 'missing_data_em_loglik.png',
                       out_dir / 'missing_data_reconstruction.png',
                       fractions, tables['em'][1], tables['regression'][1], ll,
                       data.train_complete[i], demo, recon)
    return {
        'rms_by_fraction': {'em': _by_fraction(fractions, tables['em'][1]),
                            'regression': _by_fraction(fractions, tables['regression'][1])},
        'em_better_at_every_fraction': bool(np.all(mean_em < mean_reg)),
        'em_better_fraction_of_points': float(np.mean(mean_em < mean_reg)),
        'paired': {'em_significantly_better': int(np.sum(gain > 2 * se)),
                   'regression_significantly_better': int(np.sum(gain < -2 * se)),
                   'n_fractions': int(len(fractions)),
                   'mean_rms_reduction_by_em': float(np.mean((mean_reg - mean_em) / mean_reg))},
        'em_loglik': ll.tolist(),
        'em_loglik_monotone': monotone,
        'em_iterations': int(len(ll)),
        'missing_fraction_of_training_samples': float(np.mean([np.isnan(d.observed[:, 0]).mean()
                                                               for d in data.train])),
        'units': {'rms': 'letter units, per coordinate, [mean, std] over test letters'},
        'n_train': len(data.train), 'n_test': len(data.test),
        'config': config.to_dict(),
        'plots': ['missing_data_rms_em_vs_regression.png', 'missing_data_em_loglik.png',
                  'missing_data_reconstruction.png'],
    }

