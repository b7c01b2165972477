"""Box assembly (thesis 3.4.2, Figs. 10-11): the model training ships for the demonstrations
(K and covariance floor); per held-out demonstration, component selection and robot hand error
(forward kinematics of the predicted final posture against the demonstrated one) from the final
wrist position, and beyond the thesis the same online: the OnlineEstimator fed the first x % of
the held-out wrist stream, phase unknown. The thesis's leave-one-out RMS vs K (Fig. 10) beside
it."""

from __future__ import annotations

from pathlib import Path
import time

import numpy as np

from mixture_ip_ros.app.evaluation.common import (REPORT_FRACTIONS, EvalConfig,
                                                  fold_indices, last_observed_row,
                                                  loo_by_components, majority_labels,
                                                  rms_vs_k_dict, subsampled, trained,
                                                  with_default_noise)
from mixture_ip_ros.core.mixture import MixtureIProMP
from mixture_ip_ros.core.selection import select_n_components
from mixture_ip_ros.core.online import OnlineEstimator
from mixture_ip_ros.core.playback import prefixes
from mixture_ip_ros.io.dataset import WRIST_OBSERVATION_NOISE
from mixture_ip_ros.robot.kinematics import RobotKinematics
from mixture_ip_ros.viz import plots


def box_config(quick: bool = False) -> EvalConfig:
    if quick:
        return EvalConfig(candidates=(1, 2, 3, 4), model={'n_basis': 10}, fold_stride=3,
                          subsample=3, fractions=(0.1, 0.3, 0.5, 0.7, 1.0))
    return EvalConfig()


def evaluate_box_assembly(demos, out_dir: Path, config: EvalConfig = None,
                          kinematics=None) -> dict:
    """Thesis 3.4.2 plus online selection; see the module docstring. Returns the metrics dict.
    ``kinematics``: the arm's RobotKinematics (None: the iiwa 14's)."""
    config = with_default_noise(config or box_config(), WRIST_OBSERVATION_NOISE)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    demos = subsampled(demos, config.subsample)
    if any(d.label is None for d in demos):
        raise ValueError('box_assembly evaluation needs labelled demonstrations')
    kin = kinematics or RobotKinematics()
    candidates = [int(k) for k in config.candidates if k <= len(demos) - 1]
    folds = fold_indices(len(demos), config.fold_stride)
    # K and the covariance floor that training ships for these demonstrations; the thesis's
    # leave-one-out curve (Fig. 10) at that floor beside it.
    t0 = time.perf_counter()
    shipped, info = trained(demos, config)
    K = info['n_components']
    params = {**config.model, 'prior_scale': info['prior_scale'],
              'speed_weight': info['speed_weight']}
    t_train = time.perf_counter() - t0
    rms, _ = loo_by_components(demos, candidates, folds, params)
    t_loo = time.perf_counter() - t0 - t_train

    fractions = np.asarray(config.fractions, dtype=float)
    labels_true, final_correct, final_err, posteriors = [], [], [], []
    online_correct = np.zeros((len(folds), len(fractions)), dtype=bool)
    online_err = np.full((len(folds), len(fractions)), np.nan)
    example = None
    for b, i in enumerate(folds):
        test = demos[i]
        train = demos[:i] + demos[i + 1:]
        model = MixtureIProMP(n_components=K, **params).fit(train)
        names = majority_labels(model, train)
        q_true = kin.fk(test.controlled[-1])[0]
        # Thesis: the final wrist position alone, phase known (z of that sample).
        r = last_observed_row(test)
        z_obs = np.array([test.phase[r]])
        y_obs = test.observed[r:r + 1]
        post = model.component_posterior(z_obs, y_obs)
        k = int(np.argmax(post))
        q_pred = model.predict_controlled(z_obs, y_obs, [1.0], component=k)['position'][0]
        labels_true.append(str(test.label))
        final_correct.append(names[k] == test.label)
        final_err.append(float(np.linalg.norm(kin.fk(q_pred)[0] - q_true)))
        posteriors.append(post)
        # Online: the first x % of the wrist stream, phase unknown.
        est = OnlineEstimator(model, n_alpha=config.n_alpha, min_interval=config.min_interval)
        for c, _ in enumerate(prefixes(est, test, np.multiply(fractions, test.duration))):
            if est.n_observations == 0:
                continue
            # the final posture the plan heads for: every phase speed's, weighted by its
            # posterior (each has ended by t = inf)
            k_online, q = est.expected_controlled([np.inf])[:2]
            online_correct[b, c] = names[k_online] == test.label
            online_err[b, c] = np.linalg.norm(kin.fk(q[0])[0] - q_true)
        if example is None or (test.label == 'plate' and example[1].label != 'plate'):
            example = (model, test, y_obs, z_obs, k)

    labels_true = np.array(labels_true)
    final_err = np.array(final_err)
    patterns = sorted({str(v) for v in labels_true})
    hand = {lbl: [100 * float(final_err[labels_true == lbl].mean()),
                  200 * float(final_err[labels_true == lbl].std())] for lbl in patterns}
    by_fraction = {f'{f:g}': float(online_correct[:, c].mean()) for c, f in enumerate(fractions)}
    hand_by_fraction = {
        lbl: {f'{f:g}': [100 * float(np.nanmean(online_err[labels_true == lbl, c])),
                         200 * float(np.nanstd(online_err[labels_true == lbl, c]))]
              for c, f in enumerate(fractions)} for lbl in patterns}
    full_model = shipped

    plots.rms_vs_k(out_dir / 'box_rms_vs_k.png', candidates, rms, K,
                   'Box assembly: leave-one-out RMS vs components (thesis Fig. 10)',
                   ylabel='joint RMS error [rad]')
    plots.box_components_and_posterior(out_dir / 'box_components_posterior.png', full_model,
                                       demos, majority_labels(full_model, demos), example)
    plots.box_online(out_dir / 'box_online.png', fractions, online_correct, online_err,
                     labels_true, final_correct, final_err)
    plots.hand_error_hist(out_dir / 'box_hand_error.png', final_err, labels_true)
    selection = {
        'n_components_selected': int(K),
        'k_selection': info.get('selection'),
        'prior_scale': info['prior_scale'],
        'speed_weight': info['speed_weight'],
        'n_components_thesis_loo': int(candidates[select_n_components(rms)]),
        'selection_accuracy_final': float(np.mean(final_correct)),
        'selection_accuracy_by_fraction': {f'{f:g}': by_fraction[f'{f:g}'] for f in REPORT_FRACTIONS
                                           if f'{f:g}' in by_fraction},
        'selection_accuracy_curve': by_fraction,
        'hand_error_cm': {k: v for k, v in hand.items() if k != 'screw'},
        'hand_error_cm_screw': hand.get('screw'),
        'hand_error_by_fraction_cm': hand_by_fraction,
        'misselected_final': [{'demo': demos[i].name, 'label': str(labels_true[b]),
                               'posterior': np.round(posteriors[b], 4).tolist()}
                              for b, i in enumerate(folds) if not final_correct[b]],
    }
    return {
        **selection,
        'rms_vs_k': rms_vs_k_dict(candidates, rms),
        'units': {'rms_vs_k': 'rad, [mean, std] over folds',
                  'hand_error_cm': 'cm, [mean, 2 sigma]'},
        'n_demonstrations': len(demos),
        'n_folds': len(folds),
        'component_labels': majority_labels(full_model, demos),
        'config': config.to_dict(),
        'training_runtime_s': round(t_train, 2),
        'loo_rms_runtime_s': round(t_loo, 2),
        'plots': ['box_rms_vs_k.png', 'box_components_posterior.png', 'box_online.png',
                  'box_hand_error.png'],
    }


# =========================================================================== pole
