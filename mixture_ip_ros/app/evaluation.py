"""`mixture-ip evaluate`: the thesis's experiments on generated data, as PNG plots + metrics.json.

- box_assembly (thesis 3.4.2, Figs. 10-11): leave-one-out RMS vs number of components, K chosen at
  the plateau; component selection and robot hand error (forward kinematics of the predicted final
  posture vs the demonstrated one) from the final wrist position; beyond the thesis, the same
  online: the OnlineEstimator fed the first x % of the held-out wrist stream, phase unknown.
- pole (3.4.1, Figs. 7-8): leave-one-out RMS vs K; flange paths of one Gaussian vs the mixture.
- phase (4.3.1, Figs. 19, 26-27): RMS of the completed letter vs observed fraction, alpha estimate
  (the MAP between the online estimator's grid values).
- missing_data (4.3.2, Figs. 36-37, 42-43): EM vs per-trajectory regression from training letters
  with a block of 180 missing samples; EM log-likelihood per iteration.
- gestures (real human motion, beyond the thesis): PickupGestureWiimoteZ (scenarios.gestures), a
  single-agent set: who made the gesture, from the first 30/50/70/100 % of it, by the
  unsupervised mixture (K by held-out log-likelihood at calibrated covariance floors, components
  named by majority over the training labels), phase unknown (online) and known (the same
  samples), and online once the end time is given (the phase is 1 there); by the supervised
  mixture (one component per class); and baselines on the same
  split in the same run: a per-class ProMP, scikit-learn's GaussianMixture on the same ridge
  weights, 1-NN DTW.

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
from mixture_ip_ros.core.online import OnlineEstimator, spaced
from mixture_ip_ros.app.training import component_labels
from mixture_ip_ros.io.dataset import WRIST_OBSERVATION_NOISE
from mixture_ip_ros.io.files import write_text_atomic
from mixture_ip_ros.scenarios.generated import LETTER_OBSERVATION_NOISE

logger = logging.getLogger(__name__)

SCENARIOS = ('box_assembly', 'pole', 'phase', 'missing_data', 'gestures')
REPORT_FRACTIONS = (0.3, 0.5, 0.7)
GESTURE_FRACTIONS = (0.3, 0.5, 0.7, 1.0)


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
    classes: Optional[Sequence[str]] = None       # a subset of the classes (gestures only)

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


def gesture_config(quick: bool = False) -> EvalConfig:
    """All 10 people, K from 1 to 15; quick: 4 people (20 train / 20 test), K from 1 to 6."""
    if quick:
        return EvalConfig(candidates=tuple(range(1, 7)), fractions=GESTURE_FRACTIONS,
                          classes=('1', '2', '3', '4'))
    return EvalConfig(candidates=tuple(range(1, 16)), fractions=GESTURE_FRACTIONS)


def letter_config(quick: bool = False) -> EvalConfig:
    fractions = (np.round(np.arange(0.05, 1.0001, 0.05), 2) if quick
                 else np.round(np.arange(0.01, 1.0001, 0.01), 2))
    return EvalConfig(candidates=(1,), model={'n_basis': 15}, fractions=tuple(fractions))


# =========================================================================== entry point

def evaluate(scenario: str, out_dir: Path, seed: int = 0, quick: bool = False, *,
             bag_dir: Optional[Path] = None, demos: Optional[list] = None,
             config: Optional[EvalConfig] = None, robot=None) -> dict:
    """Run one scenario's experiments; write PNGs and ``metrics.json`` into ``out_dir``.

    box_assembly and pole learn from generated demonstrations (``seed``), or from ``bag_dir`` (a
    folder of demonstration bags, labels from the bags' metadata or labels.json), or from
    ``demos`` (labelled Demonstrations). ``config`` replaces the scenario's default settings
    (``quick`` picks smaller ones: fewer K candidates, folds, basis functions and time steps).
    ``robot`` (box_assembly and pole): the arm the demonstrations are for, a shipped name or a
    description file (None: the iiwa 14); it generates them, reads the bags' joints and gives
    the hand positions.
    """
    if scenario not in SCENARIOS:
        raise ValueError(f'unknown scenario {scenario!r}; known: {list(SCENARIOS)}')
    if bag_dir is not None and demos is not None:
        raise ValueError('give bag_dir or demos, not both')
    if scenario in ('phase', 'missing_data', 'gestures') and (bag_dir is not None or demos is not None):
        raise ValueError(f'scenario {scenario!r} uses generated letters only; '
                         'bag_dir/demos are for box_assembly and pole')
    if scenario not in ('box_assembly', 'pole') and robot is not None:
        raise ValueError(f'scenario {scenario!r} has no robot; robot is for box_assembly and pole')
    out_dir = Path(out_dir)
    from mixture_ip_ros.scenarios import generated as scen
    t0 = time.perf_counter()
    if scenario in ('box_assembly', 'pole'):
        from mixture_ip_ros.robot.kinematics import RobotKinematics
        kin = RobotKinematics(robot)
        if bag_dir is not None:
            demos, skipped = load_labelled_bags(bag_dir, kin.description)
            source = {'bags': str(bag_dir), 'skipped': [f'{p.name}: {r}' for p, r in skipped]}
        elif demos is not None:
            demos = list(demos)
            source = 'given demonstrations'
        else:
            demos = [g.to_demonstration() for g in scen.generate(scenario, seed, kinematics=kin)]
            source = f'generated seed {seed}'
        bad = sorted({d.n_controlled_dofs for d in demos} - {kin.dof})
        if bad:
            raise ValueError(f'the demonstrations have {bad[0]} controlled DOFs, the robot '
                             f'{kin.description.name} has {kin.dof} joints')
        out_dir.mkdir(parents=True, exist_ok=True)     # only once there is data to evaluate
        if scenario == 'box_assembly':
            metrics = evaluate_box_assembly(demos, out_dir, config or box_config(quick), kin)
        else:
            metrics = evaluate_pole(demos, out_dir, config or pole_config(quick), kin)
        metrics = {'robot': kin.description.name, **metrics}
    elif scenario == 'gestures':
        from mixture_ip_ros.scenarios import gestures
        out_dir.mkdir(parents=True, exist_ok=True)
        metrics = evaluate_gestures(
            gestures.gesture_demonstrations('train'), gestures.gesture_demonstrations('test'),
            out_dir, config or gesture_config(quick), seed)
        source = gestures.SOURCE
    else:
        cfg = config or letter_config(quick)
        out_dir.mkdir(parents=True, exist_ok=True)
        if scenario == 'phase':
            metrics = evaluate_phase(scen.phase_letters(seed), out_dir, cfg)
        else:
            metrics = evaluate_missing_data(scen.missing_data_letters(seed), out_dir, cfg)
        source = f'generated seed {seed}'
    metrics = {'scenario': scenario, 'seed': int(seed), 'quick': bool(quick), 'source': source,
               **metrics, 'runtime_s': round(time.perf_counter() - t0, 2)}
    metrics = _jsonable(metrics)
    write_text_atomic(out_dir / 'metrics.json', json.dumps(metrics, indent=1) + '\n')
    return metrics


def load_labelled_bags(bag_dir, robot=None):
    """(demonstrations, skipped bags) from a folder of bags of ``robot`` (a RobotDescription;
    None: the iiwa 14); labels from the bags' metadata or the folder's labels.json."""
    from mixture_ip_ros.io.dataset import load_dataset
    from mixture_ip_ros.robot.description import load_description
    from mixture_ip_ros.scenarios.generated import LABEL_FILE, read_labels
    robot = load_description(robot) if robot is None or isinstance(robot, str) else robot
    demos, skipped = load_dataset(bag_dir, joint_names=robot.joint_names,
                                  transform=robot.world_to_base())
    for s in skipped:
        logger.warning('skipped %s: %s', s.path, s.reason)
    if any(d.label is None for d in demos) and (Path(bag_dir) / LABEL_FILE).is_file():
        labels = read_labels(bag_dir)
        for d in demos:
            if d.label is None:
                d.label = labels.get(d.name)
    return demos, skipped


# =========================================================================== shared pieces

def _with_default_noise(config: EvalConfig, observation_noise) -> EvalConfig:
    """The scenario's observation noise (in its observed DOFs' unit) unless the config sets one."""
    return replace(config, model={'observation_noise': observation_noise, **config.model})


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
                z = test.phase
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
    completes a letter: z = alpha* t, clamped to [0, 1], with alpha* the MAP between grid values
    (OnlineEstimator.refined_alpha) and the weights' posterior at it. Returns (mean, per-time
    cov or None, alpha*)."""
    k = est.map_hypothesis()[0]
    a = est.refined_alpha(k)
    mu, sig, _ = est.posterior_at(k, a)
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

def evaluate_box_assembly(demos, out_dir: Path, config: EvalConfig = None,
                          kinematics=None) -> dict:
    """Thesis 3.4.2 plus online selection; see the module docstring. Returns the metrics dict.
    ``kinematics``: the arm's RobotKinematics (None: the iiwa 14's)."""
    from mixture_ip_ros.viz import plots
    from mixture_ip_ros.robot.kinematics import RobotKinematics
    config = _with_default_noise(config or box_config(), WRIST_OBSERVATION_NOISE)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    demos = prepare(demos, config.subsample)
    if any(d.label is None for d in demos):
        raise ValueError('box_assembly evaluation needs labelled demonstrations')
    kin = kinematics or RobotKinematics()
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

def evaluate_pole(demos, out_dir: Path, config: EvalConfig = None, kinematics=None) -> dict:
    """Thesis 3.4.1: RMS vs K, and one Gaussian vs the mixture as flange paths around the pole.
    ``kinematics``: the arm's RobotKinematics (None: the iiwa 14's)."""
    from mixture_ip_ros.viz import plots
    from mixture_ip_ros.scenarios.generated import (POLE_BOTH_SIDES_Y, link_points,
                                              pole_clearance)
    from mixture_ip_ros.robot.scene import POLE_HEIGHT, POLE_RADIUS, POLE_XY
    from mixture_ip_ros.robot.kinematics import RobotKinematics
    config = _with_default_noise(config or pole_config(), WRIST_OBSERVATION_NOISE)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    demos = prepare(demos, config.subsample)
    kin = kinematics or RobotKinematics()
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
    config = _with_default_noise(config or letter_config(), LETTER_OBSERVATION_NOISE)
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
    config = _with_default_noise(config or letter_config(), LETTER_OBSERVATION_NOISE)
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
    z = demo.phase
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


# =========================================================================== gestures

def _prefix_length(demo, fraction) -> int:
    """Number of samples in the first ``fraction`` of the movement (t <= fraction T), >= 1."""
    return max(1, int(np.searchsorted(demo.t, fraction * demo.duration + 1e-9, side='right')))


def online_components(model, demo, fractions, n_alpha=50, min_interval=0.05, **settings):
    """The most probable component (eq. 12 with the phase marginalised) of the online estimator
    fed ``demo`` sample by sample, phase unknown, after each fraction of the movement.
    ``settings``: further OnlineEstimator arguments (e.g. alpha_range_std)."""
    est = OnlineEstimator(model, n_alpha=n_alpha, min_interval=min_interval, **settings)
    rows = np.flatnonzero(~np.isnan(demo.observed).any(axis=1))
    out, j = [], 0
    for f in fractions:
        j = _feed_until(est, demo, rows, j, f * demo.duration)
        out.append(int(np.argmax(est.component_posterior())))
    return out


def online_component_given_end(model, demo, n_alpha=50, min_interval=0.05):
    """The most probable component once the online estimator has been fed the whole of ``demo``
    sample by sample (phase unknown) and is told when it ended (the observer's 'end' event, at
    its last sample): OnlineEstimator.end_posterior, where the phase is 1."""
    est = OnlineEstimator(model, n_alpha=n_alpha, min_interval=min_interval)
    rows = np.flatnonzero(~np.isnan(demo.observed).any(axis=1))
    _feed_until(est, demo, rows, 0, demo.duration)
    return int(np.argmax(est.end_posterior(float(demo.t[rows[-1]]))))


def decimated_rows(t, min_interval):
    """Indices of the samples the online estimator absorbs from times ``t``: the first, then
    each one at least ``min_interval`` after the last one absorbed (OnlineEstimator.admit)."""
    rows, last = [], None
    for i, ti in enumerate(t):
        if last is None or spaced(ti, last, min_interval):
            rows.append(i)
            last = ti
    return np.array(rows, dtype=int)


def phase_known_components(model, demo, fractions, min_interval=0.05, duration=True):
    """The most probable component (eq. 11) given the first fractions with the phase z = t / T
    known, hence also alpha = 1/T and (``duration``) its evidence p(alpha | k). The samples are
    the ones the online estimator absorbs (``min_interval``), so phase known and unknown differ
    in the phase only."""
    rows = np.flatnonzero(~np.isnan(demo.observed).any(axis=1))
    rows = rows[decimated_rows(demo.t[rows], min_interval)]
    out = []
    for f in fractions:
        use = rows[rows < _prefix_length(demo, f)]
        out.append(int(np.argmax(model.component_posterior(
            demo.phase[use], demo.observed[use], alpha=1.0 / demo.duration if duration else None))))
    return out


class PerClassProMP:
    """Baseline: one ProMP per class by ridge regression (eq. 14), the classes' weight
    covariances by Ledoit-Wolf shrinkage, one observation noise variance per DOF shared by all
    classes (pooled residuals); a prefix is scored by eq. 18 with the phase known."""

    def __init__(self, n_basis: int = 15, ridge: float = 1e-6):
        self.n_basis = n_basis
        self.ridge = ridge

    def fit(self, demos, labels):
        from sklearn.covariance import LedoitWolf
        from mixture_ip_ros.core.basis import GaussianBasis
        from mixture_ip_ros.core.promp import expected_sq_residual, observation_stats
        self.basis_ = GaussianBasis(self.n_basis)
        stats = [observation_stats(self.basis_, d.phase, d.observed) for d in demos]
        N = self.n_basis
        W = np.array([np.concatenate([np.linalg.solve(st.G[j] + self.ridge * np.eye(N), st.b[j])
                                      for j in range(len(st.m))]) for st in stats])
        zero = np.zeros((W.shape[1], W.shape[1]))
        sq = sum(expected_sq_residual(st, w, zero) for st, w in zip(stats, W))
        self.noise_var_ = sq / sum(st.m for st in stats)
        labels = np.asarray(labels)
        self.classes_ = sorted(set(labels.tolist()))
        self.means_ = np.array([W[labels == c].mean(axis=0) for c in self.classes_])
        self.covariances_ = np.array([LedoitWolf().fit(W[labels == c]).covariance_
                                      + 1e-9 * np.eye(W.shape[1]) for c in self.classes_])
        return self

    def predict_prefix(self, demo, fraction):
        from mixture_ip_ros.core.phase import log_evidence_batch
        n = _prefix_length(demo, fraction)
        ok = ~np.isnan(demo.observed[:n]).any(axis=1)
        t, Y = demo.t[:n][ok], demo.observed[:n][ok]
        ll = [log_evidence_batch(m, C, self.basis_, t, Y, 1.0 / demo.duration, self.noise_var_)
              for m, C in zip(self.means_, self.covariances_)]
        return self.classes_[int(np.argmax(ll))]


def sklearn_gmm_accuracy(W_train, labels_train, W_test, labels_test, n_components, seeds):
    """Baseline: scikit-learn's GaussianMixture (full covariances) on ridge weights with the
    given K, the best of ``seeds`` by training likelihood, components named by majority over
    the training labels. Returns (accuracy, the chosen seed)."""
    from sklearn.mixture import GaussianMixture
    fits = [GaussianMixture(n_components, covariance_type='full', random_state=int(s)).fit(W_train)
            for s in seeds]
    scores = [g.score(W_train) for g in fits]
    best = int(np.argmax(scores))
    g = fits[best]
    names = _majority_names(g.predict(W_train), labels_train, n_components)
    pred = [names[k] for k in g.predict(W_test)]
    return float(np.mean(np.asarray(pred) == np.asarray(labels_test))), int(seeds[best])


def dtw_1nn_accuracy(train_series, labels_train, test_series, labels_test):
    """Baseline: 1-nearest-neighbour by dynamic time warping (dtaidistance, unconstrained
    window, squared differences) on the whole series."""
    from dtaidistance import dtw
    tr = [np.ascontiguousarray(s, dtype=np.double) for s in train_series]
    pred = []
    for s in test_series:
        s = np.ascontiguousarray(s, dtype=np.double)
        d = [dtw.distance_fast(s, x) for x in tr]
        pred.append(labels_train[int(np.argmin(d))])
    return float(np.mean(np.asarray(pred) == np.asarray(labels_test)))


def _majority_names(assigned, labels, n_components):
    labels = np.asarray(labels)
    out = []
    for k in range(n_components):
        members = labels[np.asarray(assigned) == k].tolist()
        out.append(max(sorted(set(members)), key=members.count) if members else None)
    return out


def evaluate_gestures(train, test, out_dir: Path, config: EvalConfig = None,
                      seed: int = 0) -> dict:
    """Recognition of who made a gesture from part of it; see the module docstring.

    ``train``/``test``: labelled single-agent Demonstrations (every method, DTW included, sees
    the same series). Labels never reach the unsupervised fit; they name its components
    afterwards.
    """
    from mixture_ip_ros.viz import plots
    from mixture_ip_ros.core.mixture import (COMPLETION_FRACTIONS, calibrated_heldout_curves,
                                             selection_curve)
    config = config or gesture_config()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    if config.classes is not None:
        keep = {str(c) for c in config.classes}
        train = [d for d in train if d.label in keep]
        test = [d for d in test if d.label in keep]
    if any(d.label is None for d in train + test):
        raise ValueError('gesture evaluation needs labelled demonstrations')
    y_train = np.array([d.label for d in train])
    y_test = np.array([d.label for d in test])
    classes = sorted(set(y_train.tolist()), key=lambda c: (len(c), c))
    fractions = tuple(float(f) for f in config.fractions)
    keys = [f'{f:g}' for f in fractions]
    params = dict(config.model)
    timings = {}

    # Unsupervised: K by the held-out log-likelihood, each K at its calibrated covariance floor
    # (labels unused); the model is fitted with the chosen K and floor, as training does.
    t0 = time.perf_counter()
    candidates = [int(k) for k in config.candidates if k <= len(train) - len(train) // 5]
    curves = calibrated_heldout_curves(train, candidates, n_folds=5, fold_seed=seed,
                                       **{'method': 'regression', **params})
    cal = curves['loglik']
    ll = cal['scores']
    curve = selection_curve(ll, higher_is_better=True, paired=True)
    # Reported beside it, not used: the completion criterion from the same fits (what a model
    # of one agent is for; bench/selection_curves.py: less reliable on sampled sets).
    completion = selection_curve(curves['completion']['scores'], higher_is_better=True,
                                 paired=True)
    K = candidates[curve['index']]
    floor = cal['prior_scale'][curve['index']]
    model = MixtureIProMP(n_components=K, random_state=seed,
                          **{**params, 'prior_scale': floor}).fit(train)
    timings['unsupervised_fit_s'] = round(time.perf_counter() - t0, 2)
    names = majority_labels(model, train)

    def accuracy(pred_rows, truth):
        P = np.asarray(pred_rows)
        return {k: float(np.mean(P[:, c] == truth)) for c, k in enumerate(keys)}
    t0 = time.perf_counter()
    unsup = accuracy([[names[k] for k in online_components(model, d, fractions, config.n_alpha,
                                                           config.min_interval)] for d in test],
                     y_test)
    unsup_known = accuracy([[names[k] for k in phase_known_components(
        model, d, fractions, config.min_interval)] for d in test], y_test)

    def accuracy_given_end(mod, labels):
        return float(np.mean([labels[online_component_given_end(
            mod, d, config.n_alpha, config.min_interval)] == y for d, y in zip(test, y_test)]))
    unsup_end = accuracy_given_end(model, names)
    timings['unsupervised_test_s'] = round(time.perf_counter() - t0, 2)

    # Supervised: one component per class, tied noise and one covariance prior for all.
    t0 = time.perf_counter()
    sup_model = MixtureIProMP(n_components=len(classes), random_state=seed, **params).fit(
        train, labels=y_train)
    cls = sup_model.classes_
    sup = accuracy([[cls[k] for k in online_components(sup_model, d, fractions, config.n_alpha,
                                                       config.min_interval)] for d in test],
                   y_test)
    sup_known = accuracy([[cls[k] for k in phase_known_components(
        sup_model, d, fractions, config.min_interval)] for d in test], y_test)
    sup_end = accuracy_given_end(sup_model, cls)
    # What knowing the phase adds besides the duration: the same without p(alpha | k).
    sup_shape = accuracy([[cls[k] for k in phase_known_components(
        sup_model, d, fractions, config.min_interval, duration=False)] for d in test], y_test)
    timings['supervised_s'] = round(time.perf_counter() - t0, 2)

    # Baselines, same split, same run.
    t0 = time.perf_counter()
    n_basis = params.get('n_basis', 15)
    promp = PerClassProMP(n_basis).fit(train, y_train)
    promp_acc = accuracy([[promp.predict_prefix(d, f) for f in fractions] for d in test], y_test)
    W_train = model.demonstration_weights(train)
    W_test = model.demonstration_weights(test)
    gmm_acc, gmm_seed = sklearn_gmm_accuracy(W_train, y_train, W_test, y_test, K,
                                             seeds=range(seed, seed + 10))
    timings['baselines_promp_gmm_s'] = round(time.perf_counter() - t0, 2)

    # Reference, not the selected model: K fixed to the number of classes (their count is the
    # only thing read from the labels), the mixture at the default floor against scikit-learn
    # with the same K. Shows what the unsupervised fit does when the selection cannot choose.
    t0 = time.perf_counter()
    Kc = len(classes)
    ref = MixtureIProMP(n_components=Kc, random_state=seed, **params).fit(train)
    ref_names = majority_labels(ref, train)
    ref_acc = accuracy([[ref_names[k] for k in online_components(
        ref, d, fractions, config.n_alpha, config.min_interval)] for d in test], y_test)
    ref_end = accuracy_given_end(ref, ref_names)
    ref_gmm, _ = sklearn_gmm_accuracy(W_train, y_train, W_test, y_test, Kc,
                                      seeds=range(seed, seed + 10))
    timings['reference_k_classes_s'] = round(time.perf_counter() - t0, 2)
    t0 = time.perf_counter()
    dtw_acc = dtw_1nn_accuracy([d.observed[:, 0] for d in train], y_train,
                               [d.observed[:, 0] for d in test], y_test)
    timings['baseline_dtw_s'] = round(time.perf_counter() - t0, 2)

    assigned = np.argmax(model.resp_, axis=1)
    counts = np.array([[int(np.sum((assigned == k) & (y_train == c))) for c in classes]
                       for k in range(K)])
    chance = 1.0 / len(classes)
    plots.accuracy_vs_fraction(
        out_dir / 'gestures_accuracy_vs_fraction.png', fractions,
        {'mixture, unsupervised, phase unknown (online)': [unsup[k] for k in keys],
         'mixture, unsupervised, phase known': [unsup_known[k] for k in keys],
         'mixture, supervised, phase unknown (online)': [sup[k] for k in keys],
         'mixture, supervised, phase known': [sup_known[k] for k in keys],
         'per-class ProMP (baseline), phase known': [promp_acc[k] for k in keys]},
        {f'scikit-learn GMM, K = {K}': gmm_acc, '1-NN DTW': dtw_acc},
        f'PickupGestureWiimoteZ: who made the gesture ({len(classes)} people, '
        f'{len(test)} test gestures)', chance=chance,
        points={'mixture, supervised, online, then the end time given': (1.0, sup_end),
                'mixture, unsupervised, online, then the end time given': (1.0, unsup_end)})
    plots.clusters_vs_labels(out_dir / 'gestures_clusters_vs_labels.png', counts,
                             [n or '-' for n in names], classes,
                             f'Unsupervised mixture, K = {K}: training gestures per component')
    plots.loglik_vs_k(out_dir / 'gestures_loglik_vs_k.png', candidates, ll, K,
                      'Gestures: 5-fold held-out log-likelihood vs K (each at its calibrated floor)',
                      curve['note'])
    return {
        'n_components_selected': int(K),
        'unsupervised_accuracy_by_fraction': unsup,
        'unsupervised_accuracy_phase_known_by_fraction': unsup_known,
        'supervised_accuracy_by_fraction': sup,
        'supervised_accuracy_phase_known_by_fraction': sup_known,
        'supervised_accuracy_phase_known_without_duration_by_fraction': sup_shape,
        'unsupervised_accuracy_given_end': unsup_end,
        'supervised_accuracy_given_end': sup_end,
        'baseline_promp_accuracy_by_fraction': promp_acc,
        'baseline_sklearn_gmm_accuracy': gmm_acc,
        'baseline_dtw_accuracy': dtw_acc,
        'k_selection': {'criterion': 'held-out log-likelihood, 5 folds, each K at its '
                                     'calibrated covariance floor',
                        'candidates': candidates, 'mean_nats': curve['mean'],
                        'se_nats': curve['se'], 'prior_scale': cal['prior_scale'],
                        'prior_scale_selected': floor,
                        'clear_optimum': curve['clear'], 'note': curve['note'],
                        'completion': {
                            'criterion': 'predictive log density of the rest of a held-out '
                                         'gesture given its beginning (z <= f), mean over f = '
                                         + ', '.join(f'{f:g}' for f in COMPLETION_FRACTIONS)
                                         + '; reported, not used for the choice',
                            'chosen': candidates[completion['index']],
                            'mean_nats': completion['mean'], 'se_nats': completion['se'],
                            'prior_scale': curves['completion']['prior_scale'],
                            'clear_optimum': completion['clear'], 'note': completion['note']}},
        'component_labels': names,
        'clusters_vs_labels': {'classes': classes, 'counts': counts.tolist()},
        'baseline_sklearn_gmm_seed': gmm_seed,
        'reference_k_classes': {'n_components': Kc,
                                'unsupervised_accuracy_by_fraction': ref_acc,
                                'unsupervised_accuracy_given_end': ref_end,
                                'baseline_sklearn_gmm_accuracy': ref_gmm},
        'chance_accuracy': chance,
        'n_train': len(train), 'n_test': len(test), 'n_classes': len(classes),
        'durations_s': {'train_median': float(np.median([d.duration for d in train])),
                        'train_range': [float(min(d.duration for d in train)),
                                        float(max(d.duration for d in train))]},
        'noise_var': np.asarray(model.noise_var_).tolist(),
        'units': {'accuracy': 'fraction of test gestures whose person is named correctly',
                  'fractions': 'part of the recording observed (from its first sample)',
                  'given_end': 'the whole recording fed to the online estimator (phase '
                               'unknown), then its end time given, where the phase is 1 '
                               '(OnlineEstimator.end_posterior); beside the same without '
                               'the end, the "1" of the phase-unknown curves',
                  'noise_var': 'g^2'},
        'timings_s': timings,
        'config': config.to_dict(),
        'plots': ['gestures_accuracy_vs_fraction.png', 'gestures_clusters_vs_labels.png',
                  'gestures_loglik_vs_k.png'],
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
