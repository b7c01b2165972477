"""What every evaluation shares: its settings, the model that training ships for a set of
demonstrations, the online estimator fed part of a demonstration, and metrics.json's values.

Everything is held out: a demonstration never reaches the model it is tested on. Labels are
read for scoring and to name components afterwards, never by an unsupervised fit.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
import logging
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from mixture_ip_ros.app.naming import component_labels
from mixture_ip_ros.app.training import train
from mixture_ip_ros.core.crossval import fold_scores, leave_one_out
from mixture_ip_ros.core.demonstration import Demonstration
from mixture_ip_ros.core.interaction import trajectory_distribution
from mixture_ip_ros.core.mixture import MixtureIProMP
from mixture_ip_ros.core.scores import controlled_rms
from mixture_ip_ros.core.online import OnlineEstimator
from mixture_ip_ros.core.playback import absorbed_rows, observed_rows, played_to, prefixes

logger = logging.getLogger(__name__)

REPORT_FRACTIONS = (0.3, 0.5, 0.7)


@dataclass
class EvalConfig:
    """Settings of one evaluation run (written to metrics.json so a run can be repeated).

    ``model`` holds MixtureIProMP constructor parameters (besides n_components). ``fold_stride``
    > 1 holds out only every stride-th demonstration (each model is still trained on all the
    others); ``subsample`` keeps every n-th time step of every demonstration;
    ``train_fraction`` < 1 (labelled recordings, app.evaluation.interactions) trains each fold
    on that share of its training recordings of every label (seeded), tested on all held out;
    ``labelled_per_class`` > 0 (the same) gives the mixture with K chosen the labels of that
    many training recordings of every label (seeded), the others unlabelled: semi-supervised.
    """

    candidates: Sequence[int] = tuple(range(1, 7))
    model: dict = field(default_factory=lambda: {'n_basis': 15})
    fold_stride: int = 1
    subsample: int = 1
    fractions: Sequence[float] = tuple(np.round(np.arange(0.05, 1.0001, 0.05), 2))
    n_alpha: int = 50
    min_interval: float = 0.05
    classes: Optional[Sequence[str]] = None       # a subset of the classes (gestures only)
    train_fraction: float = 1.0
    labelled_per_class: int = 0

    def to_dict(self):
        d = asdict(self)
        d['candidates'] = [int(k) for k in self.candidates]
        d['fractions'] = [float(f) for f in self.fractions]
        return d


def with_default_noise(config: EvalConfig, observation_noise) -> EvalConfig:
    """The scenario's observation noise (in its observed DOFs' unit) unless the config sets one."""
    return replace(config, model={'observation_noise': observation_noise, **config.model})


def subsampled(demos, subsample: int = 1) -> list:
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
    return int(observed_rows(demo)[-1])


def loo_by_components(demos, candidates, folds, model_params, keep_predictions=False):
    """Leave-one-out over the held-out ``folds`` (indices; core.crossval.leave_one_out, each
    model fitted from the other demonstrations) for every K: per-fold RMS of the controlled
    trajectory given the final wrist position (core.scores.controlled_rms), and optionally
    the predicted mean joint trajectories {K: [(T, Q) per fold]}."""
    preds = {int(K): [] for K in candidates}

    def fit(fold, K):
        return MixtureIProMP(n_components=K, **model_params).fit([demos[j] for j in fold.train])

    def score(model, fold, K):
        test = demos[fold.test[0]]
        rms = controlled_rms(model, test, 'final')
        if keep_predictions:
            r = last_observed_row(test)
            z = test.phase
            preds[K].append(model.predict_controlled(z[r:r + 1], test.observed[r:r + 1],
                                                     z)['position'])
        return rms
    held_out = leave_one_out(len(demos), folds)
    rms = np.empty((len(candidates), len(folds)))
    for a, K in enumerate(candidates):
        rms[a] = fold_scores(held_out, fit, score, (int(K),), n_jobs=1)
    return rms, preds


def rms_vs_k_dict(candidates, rms):
    return {str(int(K)): [float(r.mean()), float(r.std())] for K, r in zip(candidates, rms)}


def majority_labels(model, demos):
    """The name of each component: the majority label of its training demonstrations
    (app.naming.component_labels); labels are read for scoring only."""
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


def trained(demos, config: EvalConfig, **kwargs):
    """(model, training summary): what ``training.train`` ships for ``demos`` with the
    evaluation's model settings and K candidates (K chosen as training chooses it, its
    covariance floor calibrated) unless ``kwargs`` fix them (``n_components``, ``labels``)."""
    return train(demos, candidates=config.candidates, **{**config.model, **kwargs})



def prefix_length(demo, fraction) -> int:
    """Number of samples in the first ``fraction`` of the movement (t <= fraction T), >= 1."""
    return max(1, int(np.searchsorted(demo.t, fraction * demo.duration + 1e-9, side='right')))


def online_components(model, demo, fractions, n_alpha=50, min_interval=0.05, **settings):
    """The most probable component (eq. 12 with the phase marginalised) of the online estimator
    fed ``demo`` sample by sample, phase unknown, after each fraction of the movement.
    ``settings``: further OnlineEstimator arguments (e.g. alpha_range_std)."""
    est = OnlineEstimator(model, n_alpha=n_alpha, min_interval=min_interval, **settings)
    return [int(np.argmax(est.component_posterior()))
            for _ in prefixes(est, demo, np.multiply(fractions, demo.duration))]


def named_online(model, names, demos, fractions, n_alpha=50, min_interval=0.05,
                 **settings) -> np.ndarray:
    """The name (``names`` (K,)) of the component :func:`online_components` finds most probable
    after each of ``fractions`` of each of ``demos`` (``settings`` as there): (len(demos),
    len(fractions))."""
    return np.array([[names[k] for k in online_components(model, d, fractions, n_alpha,
                                                          min_interval, **settings)]
                     for d in demos], dtype=object)


def online_component_given_end(model, demo, n_alpha=50, min_interval=0.05):
    """The most probable component once the online estimator has been fed the whole of ``demo``
    sample by sample (phase unknown) and is told when it ended (the observer's 'end' event, at
    its last sample): OnlineEstimator.end_posterior, where the phase is 1."""
    est = OnlineEstimator(model, n_alpha=n_alpha, min_interval=min_interval)
    played_to(est, demo, demo.duration)
    return int(np.argmax(est.end_posterior(float(demo.t[observed_rows(demo)[-1]]))))


def phase_known_components(model, demo, fractions, min_interval=0.05, duration=True):
    """The most probable component (eq. 11) given the first fractions with the phase z = t / T
    known, hence also alpha = 1/T and (``duration``) its evidence p(alpha | k). The samples are
    the ones the online estimator absorbs (``min_interval``), so phase known and unknown differ
    in the phase only."""
    rows = absorbed_rows(demo, min_interval)
    out = []
    for f in fractions:
        use = rows[rows < prefix_length(demo, f)]
        out.append(int(np.argmax(model.component_posterior(
            demo.phase[use], demo.observed[use], alpha=1.0 / demo.duration if duration else None))))
    return out


def load_labelled_bags(bag_dir, robot=None):
    """(demonstrations, skipped bags) from a folder of bags of ``robot`` (a RobotDescription;
    None: the iiwa 14); labels from the bags' metadata or the folder's labels.json."""
    from mixture_ip_ros.io.dataset import load_dataset
    from mixture_ip_ros.robot.description import load_description
    from mixture_ip_ros.scenarios.folders import LABEL_FILE, read_labels
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


def jsonable(x):
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, (np.floating, float)):
        return None if not np.isfinite(x) else float(x)
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x

