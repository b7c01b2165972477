"""`mixture-ip evaluate`: the thesis's experiments on generated data, as PNG plots + metrics.json.

- box_assembly (thesis 3.4.2, Figs. 10-11): leave-one-out RMS vs number of components, K chosen at
  the plateau; component selection and robot hand error (forward kinematics of the predicted final
  posture vs the demonstrated one) from the final wrist position; beyond the thesis, the same
  online: the OnlineEstimator fed the first x % of the held-out wrist stream, phase unknown.
- pole (3.4.1, Figs. 7-8): leave-one-out RMS vs K; flange paths of one Gaussian vs the mixture.
- phase (4.3.1, Figs. 19, 26-27): RMS of the completed letter vs observed fraction, alpha estimate.
- missing_data (4.3.2, Figs. 36-37, 42-43): EM vs per-trajectory regression from training letters
  with a block of 180 missing samples; EM log-likelihood per iteration.

Everything is leave-one-out (or a separate test set for the letters): a held-out demonstration
never reaches the model it is tested on. Labels are read for scoring only.
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from mixture_ip_ros.core.demonstration import Demonstration
from mixture_ip_ros.core.interaction import trajectory_distribution
from mixture_ip_ros.core.mixture import MixtureIProMP, controlled_rms, select_n_components
from mixture_ip_ros.core.online import OnlineEstimator
from mixture_ip_ros.app.training import component_labels

logger = logging.getLogger(__name__)

SCENARIOS = ('box_assembly', 'pole', 'phase', 'missing_data')
REPORT_FRACTIONS = (0.3, 0.5, 0.7)


@dataclass
class EvalConfig:
    """Settings of one evaluation run (written to metrics.json so a run can be repeated).

    ``model`` holds MixtureIProMP constructor parameters (besides n_components). ``fold_stride``
    > 1 holds out only every stride-th demonstration (each model is still trained on all the
    others); ``subsample`` keeps every n-th time step of every demonstration.
    """

    candidates: Sequence[int] = tuple(range(1, 7))
    model: dict = field(default_factory=lambda: {'n_basis': 15})
    fold_stride: int = 1
    subsample: int = 1
    fractions: Sequence[float] = tuple(np.round(np.arange(0.05, 1.0001, 0.05), 2))
    n_alpha: int = 50
    min_interval: float = 0.05

    def to_dict(self):
        d = asdict(self)
        d['candidates'] = [int(k) for k in self.candidates]
        d['fractions'] = [float(f) for f in self.fractions]
        return d


def box_config(quick: bool = False) -> EvalConfig:
    if quick:
        return EvalConfig(candidates=(1, 2, 3, 4), model={'n_basis': 10}, fold_stride=3,
                          subsample=3, fractions=(0.1, 0.3, 0.5, 0.7, 1.0))
    return EvalConfig()


def pole_config(quick: bool = False) -> EvalConfig:
    if quick:
        return EvalConfig(candidates=(1, 2, 4, 6), model={'n_basis': 10}, fold_stride=2,
                          subsample=3)
    return EvalConfig(candidates=tuple(range(1, 13)))


def letter_config(quick: bool = False) -> EvalConfig:
    fractions = (np.round(np.arange(0.05, 1.0001, 0.05), 2) if quick
                 else np.round(np.arange(0.01, 1.0001, 0.01), 2))
    return EvalConfig(candidates=(1,), model={'n_basis': 15}, fractions=tuple(fractions))


# =========================================================================== entry point

def evaluate(scenario: str, out_dir: Path, seed: int = 0, quick: bool = False, *,
             bag_dir: Optional[Path] = None, demos: Optional[list] = None,
             config: Optional[EvalConfig] = None) -> dict:
    """Run one scenario's experiments; write PNGs and ``metrics.json`` into ``out_dir``.

    box_assembly and pole learn from generated demonstrations (``seed``), or from ``bag_dir`` (a
    folder of demonstration bags, labels from the bags' metadata or labels.json), or from
    ``demos`` (labelled Demonstrations). ``config`` replaces the scenario's default settings
    (``quick`` picks smaller ones: fewer K candidates, folds, basis functions and time steps).
    """
    if scenario not in SCENARIOS:
        raise ValueError(f'unknown scenario {scenario!r}; known: {list(SCENARIOS)}')
    if bag_dir is not None and demos is not None:
        raise ValueError('give bag_dir or demos, not both')
    if scenario in ('phase', 'missing_data') and (bag_dir is not None or demos is not None):
        raise ValueError(f'scenario {scenario!r} uses generated letters only; '
                         'bag_dir/demos are for box_assembly and pole')
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    from mixture_ip_ros.scenarios import generated as scen
    t0 = time.perf_counter()
    if scenario in ('box_assembly', 'pole'):
        if bag_dir is not None:
            demos, skipped = load_labelled_bags(bag_dir)
            source = {'bags': str(bag_dir), 'skipped': [f'{p.name}: {r}' for p, r in skipped]}
        elif demos is not None:
            demos = list(demos)
            source = 'given demonstrations'
        else:
            demos = [g.to_demonstration() for g in scen.generate(scenario, seed)]
            source = f'generated seed {seed}'
        if scenario == 'box_assembly':
            metrics = evaluate_box_assembly(demos, out_dir, config or box_config(quick))
        else:
            metrics = evaluate_pole(demos, out_dir, config or pole_config(quick))
    else:
        cfg = config or letter_config(quick)
        if scenario == 'phase':
            metrics = evaluate_phase(scen.phase_letters(seed), out_dir, cfg)
        else:
            metrics = evaluate_missing_data(scen.missing_data_letters(seed), out_dir, cfg)
        source = f'generated seed {seed}'
    metrics = {'scenario': scenario, 'seed': int(seed), 'quick': bool(quick), 'source': source,
               **metrics, 'runtime_s': round(time.perf_counter() - t0, 2)}
    metrics = _jsonable(metrics)
    (out_dir / 'metrics.json').write_text(json.dumps(metrics, indent=1) + '\n')
    return metrics


def load_labelled_bags(bag_dir):
    """(demonstrations, skipped bags) from a folder of bags; labels from the bags' metadata or
    the folder's labels.json."""
    from mixture_ip_ros.io.dataset import load_dataset
    from mixture_ip_ros.scenarios.generated import LABEL_FILE, read_labels
    demos, skipped = load_dataset(bag_dir)
    for s in skipped:
        logger.warning('skipped %s: %s', s.path, s.reason)
    if any(d.label is None for d in demos) and (Path(bag_dir) / LABEL_FILE).is_file():
        labels = read_labels(bag_dir)
        for d in demos:
            if d.label is None:
                d.label = labels.get(d.name)
    return demos, skipped


# =========================================================================== shared pieces

def prepare(demos, subsample: int = 1) -> list:
    """Every ``subsample``-th time step, always keeping the final one (the thesis's observation)."""
    if subsample <= 1:
        return list(demos)
    out = []
    for d in demos:
        idx = np.arange(0, d.t.size, subsample)
        if idx[-1] != d.t.size - 1:
            idx = np.r_[idx, d.t.size - 1]
        out.append(Demonstration(d.t[idx], d.observed[idx], d.controlled[idx], d.label, d.name))
    return out


def fold_indices(n: int, stride: int) -> np.ndarray:
    return np.arange(0, n, max(1, int(stride)))


def last_observed_row(demo) -> int:
    rows = np.flatnonzero(~np.isnan(demo.observed).any(axis=1))
    return int(rows[-1])


def loo_by_components(demos, candidates, folds, model_params, keep_predictions=False):
    """Leave-one-out over the held-out ``folds`` for every K: per-fold RMS of the controlled
    trajectory given the final wrist position (core ``controlled_rms``, as training uses), and
    optionally the predicted mean joint trajectories {K: [(T, Q) per fold]}."""
    rms = np.empty((len(candidates), len(folds)))
    preds = {int(K): [] for K in candidates}
    for a, K in enumerate(candidates):
        for b, i in enumerate(folds):
            train = demos[:i] + demos[i + 1:]
            model = MixtureIProMP(n_components=int(K), **model_params).fit(train)
            test = demos[i]
            rms[a, b] = controlled_rms(model, test, 'final')
            if keep_predictions:
                r = last_observed_row(test)
                z = test.t / test.duration
                preds[int(K)].append(model.predict_controlled(z[r:r + 1], test.observed[r:r + 1],
                                                              z)['position'])
    return rms, preds


def rms_vs_k_dict(candidates, rms):
    return {str(int(K)): [float(r.mean()), float(r.std())] for K, r in zip(candidates, rms)}


def majority_labels(model, demos):
    labels = component_labels(model, demos)
    if labels is None:
        raise ValueError('evaluation needs labelled demonstrations (labels are used for scoring)')
    return labels


def observed_prediction(est: OnlineEstimator, t, with_cov: bool = False):
    """The observed agent's predicted path at times ``t`` under the MAP (k, alpha), as the thesis
    completes a letter: z = alpha* t, clamped to [0, 1]. Returns (mean, per-time cov or None,
    alpha*)."""
    k, a = est.map_hypothesis()
    m = int(np.argmin(np.abs(est.alphas - a)))
    mu, sig = est.observed_weights(k, m)
    z = np.clip(a * np.asarray(t, dtype=float), 0.0, 1.0)
    if not with_cov:
        basis = est.model.basis_
        return basis(z) @ mu.reshape(-1, basis.n_basis).T, None, a
    d = trajectory_distribution(mu, sig, est.model.basis_, z, a)
    return d['position'], d['position_cov'], a


def _feed_until(est, demo, rows, j, t_max):
    """Feed the observed rows with t <= t_max, starting at rows[j]; returns the next j."""
    while j < len(rows) and demo.t[rows[j]] <= t_max + 1e-9:
        est.update(float(demo.t[rows[j]]), demo.observed[rows[j]])
        j += 1
    return j


# =========================================================================== box assembly

def evaluate_box_assembly(demos, out_dir: Path, config: EvalConfig = None) -> dict:
    """Thesis 3.4.2 plus online selection; see the module docstring. Returns the metrics dict."""
    from mixture_ip_ros.viz import plots
    from mixture_ip_ros.robot.kinematics import RobotKinematics
    config = config or box_config()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    demos = prepare(demos, config.subsample)
    if any(d.label is None for d in demos):
        raise ValueError('box_assembly evaluation needs labelled demonstrations')
    kin = RobotKinematics()
    candidates = [int(k) for k in config.candidates if k <= len(demos) - 1]
    folds = fold_indices(len(demos), config.fold_stride)
    t0 = time.perf_counter()
    rms, _ = loo_by_components(demos, candidates, folds, config.model)
    K = candidates[select_n_components(rms)]
    t_loo = time.perf_counter() - t0

    fractions = np.asarray(config.fractions, dtype=float)
    labels_true, final_correct, final_err, posteriors = [], [], [], []
    online_correct = np.zeros((len(folds), len(fractions)), dtype=bool)
    online_err = np.full((len(folds), len(fractions)), np.nan)
    example = None
    for b, i in enumerate(folds):
        test = demos[i]
        train = demos[:i] + demos[i + 1:]
        model = MixtureIProMP(n_components=K, **config.model).fit(train)
        names = majority_labels(model, train)
        q_true = kin.fk(test.controlled[-1])[0]
        # Thesis: the final wrist position alone, phase known (z of that sample).
        r = last_observed_row(test)
        z_obs = np.array([test.t[r] / test.duration])
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
        rows = np.flatnonzero(~np.isnan(test.observed).any(axis=1))
        j = 0
        for c, f in enumerate(fractions):
            j = _feed_until(est, test, rows, j, f * test.duration)
            if est.n_observations == 0:
                continue
            pred = est.predict([1.0])
            online_correct[b, c] = names[pred['component']] == test.label
            q = pred['controlled']['position'][0]
            online_err[b, c] = np.linalg.norm(kin.fk(q)[0] - q_true)
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
    full_model = MixtureIProMP(n_components=K, **config.model).fit(demos)

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
        'loo_rms_runtime_s': round(t_loo, 2),
        'plots': ['box_rms_vs_k.png', 'box_components_posterior.png', 'box_online.png',
                  'box_hand_error.png'],
    }


# =========================================================================== pole

def evaluate_pole(demos, out_dir: Path, config: EvalConfig = None) -> dict:
    """Thesis 3.4.1: RMS vs K, and one Gaussian vs the mixture as flange paths around the pole."""
    from mixture_ip_ros.viz import plots
    from mixture_ip_ros.scenarios.generated import (POLE_BOTH_SIDES_Y, link_points,
                                              pole_clearance)
    from mixture_ip_ros.robot.scene import POLE_HEIGHT, POLE_RADIUS, POLE_XY
    from mixture_ip_ros.robot.kinematics import RobotKinematics
    config = config or pole_config()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    demos = prepare(demos, config.subsample)
    kin = RobotKinematics()
    candidates = [int(k) for k in config.candidates if k <= len(demos) - 1]
    if 1 not in candidates:
        candidates = [1] + candidates
    folds = fold_indices(len(demos), config.fold_stride)
    rms, preds = loo_by_components(demos, candidates, folds, config.model, keep_predictions=True)
    K_selected = candidates[select_n_components(rms)]
    # Fig. 7 compares one Gaussian with a mixture (the thesis used 8 clusters there): the selected
    # K, or, if the 1-SE rule falls back to K = 1, the best K >= 2. It can: spots reachable around
    # both sides make the error bimodal (right side ~0.02 rad, wrong side ~1 rad), so the mean
    # LOO RMS is noisy.
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
    mid = [int(np.argmin(np.abs(demos[i].t / demos[i].duration - 0.5))) for i in folds]

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

def letter_completion(model, test, fractions, n_alpha=50, min_interval=0.05, keep=()):
    """Observe the first fraction of ``test`` (by time steps, as the thesis), estimate the phase,
    complete the letter. Returns RMS (len(fractions),), MAP alpha (len(fractions),), and for the
    fractions in ``keep`` a snapshot {fraction: (pred mean, pred cov, alpha posterior)}."""
    est = OnlineEstimator(model, n_alpha=n_alpha, min_interval=min_interval)
    rows = np.flatnonzero(~np.isnan(test.observed).any(axis=1))
    n = test.t.size
    rms = np.full(len(fractions), np.nan)
    alpha = np.full(len(fractions), np.nan)
    snaps = {}
    j = 0
    for c, f in enumerate(fractions):
        last = int(np.ceil(f * n)) - 1
        j = _feed_until(est, test, rows, j, test.t[max(last, 0)])
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
    from mixture_ip_ros.viz import plots
    config = config or letter_config()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    model = MixtureIProMP(n_components=1, method='regression', **config.model).fit(data.train)
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
    from scipy import linalg

    from mixture_ip_ros.viz import plots
    from mixture_ip_ros.core.promp import observation_stats, ridge_weights, weight_posterior
    config = config or letter_config()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    models = {m: MixtureIProMP(n_components=1, method=m, **config.model).fit(data.train)
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
    z = demo.t / demo.duration
    em = models['em']
    st = observation_stats(em.basis_, z, demo.observed)
    w_em = weight_posterior(st, em.means_[0], linalg.cho_factor(em.covariances_[0], lower=True),
                            em.noise_var_)[0]
    N = em.n_basis
    w_reg = ridge_weights(models['regression'].basis_, z, demo.observed, models['regression'].ridge)
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


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, (np.floating, float)):
        return None if not np.isfinite(x) else float(x)
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x
