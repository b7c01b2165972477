"""Pole pointing (thesis 3.4.1, Figs. 7-8): the model training ships (K and covariance floor),
the thesis's leave-one-out RMS vs K, and flange paths of one Gaussian against the mixture around
the pole (which of them pass through it)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mixture_ip_ros.app.evaluation.common import (EvalConfig, fold_indices, loo_by_components,
                                                  rms_vs_k_dict, subsampled, trained,
                                                  with_default_noise)
from mixture_ip_ros.core.selection import select_n_components
from mixture_ip_ros.io.dataset import WRIST_OBSERVATION_NOISE
from mixture_ip_ros.robot.kinematics import RobotKinematics
from mixture_ip_ros.robot.scene import POLE_HEIGHT, POLE_RADIUS, POLE_XY
from mixture_ip_ros.scenarios.pole import POLE_BOTH_SIDES_Y, link_points, pole_clearance
from mixture_ip_ros.viz import plots


def pole_config(quick: bool = False) -> EvalConfig:
    if quick:
        return EvalConfig(candidates=(1, 2, 4, 6), model={'n_basis': 10}, fold_stride=2,
                          subsample=3)
    return EvalConfig(candidates=tuple(range(1, 13)))



def evaluate_pole(demos, out_dir: Path, config: EvalConfig = None, kinematics=None) -> dict:
    """Thesis 3.4.1: RMS vs K, and one Gaussian vs the mixture as flange paths around the pole.
    ``kinematics``: the arm's RobotKinematics (None: the iiwa 14's)."""
    config = with_default_noise(config or pole_config(), WRIST_OBSERVATION_NOISE)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    demos = subsampled(demos, config.subsample)
    kin = kinematics or RobotKinematics()
    candidates = [int(k) for k in config.candidates if k <= len(demos) - 1]
    if 1 not in candidates:
        candidates = [1] + candidates
    folds = fold_indices(len(demos), config.fold_stride)
    # K and the covariance floor that training ships; the thesis's leave-one-out curve (Fig. 8)
    # at that floor beside it.
    _, info = trained(demos, config)
    K_selected = info['n_components']
    params = {**config.model, 'prior_scale': info['prior_scale'],
              'speed_weight': info['speed_weight']}
    if K_selected not in candidates:
        candidates = sorted(set(candidates) | {K_selected})
    rms, preds = loo_by_components(demos, candidates, folds, params, keep_predictions=True)
    # Fig. 7 compares one Gaussian with a mixture (the thesis used 8 clusters there): the
    # shipped K, or, if training ships K = 1, the best K >= 2 by the thesis's curve.
    K = K_selected
    if K == 1 and len(candidates) > 1:
        K = candidates[1 + int(np.argmin(rms[1:].mean(axis=1)))]
    pole_xy, pole_radius, pole_height = np.asarray(POLE_XY, dtype=float), POLE_RADIUS, POLE_HEIGHT
    # An arm capsule this close to the pole axis touches it.
    hit = pole_radius + kin.description.link_radius

    def paths_and_hits(Qs):
        paths, hits, clear = [], [], []
        for Q in Qs:
            paths.append(kin.fk_positions(Q))
            c = min(pole_clearance(link_points(kin, q), pole_xy, pole_height) for q in Q[::2])
            clear.append(c)
            hits.append(c < hit)
        return paths, np.array(hits), np.array(clear)

    truth = [demos[i].controlled for i in folds]
    true_paths, true_hits, _ = paths_and_hits(truth)
    single_paths, single_hits, _ = paths_and_hits(preds[1])
    mix_paths, mix_hits, _ = paths_and_hits(preds[K])
    # Side of the pole: sign of the flange's y halfway through (the via point of a demonstration).
    mid = [int(np.argmin(np.abs(demos[i].phase - 0.5))) for i in folds]

    def side(paths):
        return np.array([np.sign(p[m, 1] - pole_xy[1]) for p, m in zip(paths, mid)])

    true_side = side(true_paths)
    # Spots near the middle can be reached around either side (and some are demonstrated on both):
    # the final wrist position cannot tell which side the held-out demonstration took there.
    two_sided = np.array([abs(p[-1, 1] - pole_xy[1]) <= POLE_BOTH_SIDES_Y for p in true_paths])

    def side_accuracy(paths):
        ok = side(paths) == true_side
        return {'one_sided': float(ok[~two_sided].mean()) if np.any(~two_sided) else None,
                'two_sided': float(ok[two_sided].mean()) if np.any(two_sided) else None}

    def flange_rms(paths, sel=None):
        e = np.array([np.sqrt(np.mean(np.sum((p - q) ** 2, axis=1)))
                      for p, q in zip(paths, true_paths)])
        return float(np.mean(e if sel is None else e[sel]))

    plots.rms_vs_k(out_dir / 'pole_rms_vs_k.png', candidates, rms, K_selected,
                   'Pole: leave-one-out RMS vs components (thesis Fig. 8)',
                   ylabel='joint RMS error [rad]', compared=K)
    plots.pole_paths(out_dir / 'pole_single_vs_mixture.png', true_paths, single_paths, mix_paths,
                     K, pole_xy, pole_radius, [demos[i].label for i in folds])
    a1, aK = candidates.index(1), candidates.index(K)
    return {
        'n_components_selected': int(K_selected),
        'k_selection': info.get('selection'),
        'prior_scale': info['prior_scale'],
        'speed_weight': info['speed_weight'],
        'n_components_thesis_loo': int(candidates[select_n_components(rms)]),
        'n_components_compared': int(K),
        'rms_vs_k': rms_vs_k_dict(candidates, rms),
        'rms_median_vs_k': {str(k): float(np.median(r)) for k, r in zip(candidates, rms)},
        'rms_single': float(rms[a1].mean()),
        'rms_mixture': float(rms[aK].mean()),
        'rms_selected': float(rms[candidates.index(K_selected)].mean()),
        'rms_single_one_sided': float(rms[a1][~two_sided].mean()),
        'rms_mixture_one_sided': float(rms[aK][~two_sided].mean()),
        'flange_rms_cm_single': 100 * flange_rms(single_paths),
        'flange_rms_cm_mixture': 100 * flange_rms(mix_paths),
        'flange_rms_cm_single_one_sided': 100 * flange_rms(single_paths, ~two_sided),
        'flange_rms_cm_mixture_one_sided': 100 * flange_rms(mix_paths, ~two_sided),
        'side_accuracy_single': side_accuracy(single_paths),
        'side_accuracy_mixture': side_accuracy(mix_paths),
        'n_two_sided_spots': int(two_sided.sum()),
        'pole_collision_rate_single': float(single_hits.mean()),
        'pole_collision_rate_mixture': float(mix_hits.mean()),
        'pole_collision_rate_demonstrations': float(true_hits.mean()),
        'units': {'rms_vs_k': 'rad, [mean, std] over folds',
                  'flange_rms_cm': 'cm, 3-D, mean over folds'},
        'n_demonstrations': len(demos),
        'n_folds': len(folds),
        'config': config.to_dict(),
        'plots': ['pole_rms_vs_k.png', 'pole_single_vs_mixture.png'],
    }


# =========================================================================== letters
