"""Train a Mixture of Interaction ProMPs from demonstrations (arrays or a folder of bags)."""

import logging
import sys
from pathlib import Path

import numpy as np

from mixture_ip_ros.core.mixture import (MixtureIProMP, loo_rms_by_components,
                                         select_n_components)
from mixture_ip_ros.io.model_file import save_model
from mixture_ip_ros.robot.description import load_description

logger = logging.getLogger(__name__)

OBSERVED_NAMES = ('wrist_x', 'wrist_y', 'wrist_z')


def choose_n_components(demos, candidates, progress=None, **params):
    """K by leave-one-out (thesis Figs. 8/10): RMS of the held-out controlled trajectory given
    its final wrist position, for every candidate K; the plateau's first K is chosen.

    Returns (K, rms) with rms of shape (len(candidates), n_demos).
    """
    candidates = [int(k) for k in candidates if k <= len(demos) - 1]
    if not candidates:
        raise ValueError('not enough demonstrations for leave-one-out')
    rms = loo_rms_by_components(demos, candidates, 'final', progress, **params)
    return candidates[select_n_components(rms)], rms


def text_progress(stream=sys.stderr):
    """A one-line progress bar for choose_n_components."""
    def show(done, total, K):
        width = 30
        filled = int(width * done / total)
        stream.write(f'\rleave-one-out K={K:<2d} [{"#" * filled}{"." * (width - filled)}] '
                     f'{done}/{total}')
        if done == total:
            stream.write('\n')
        stream.flush()
    return show


def train(demos, *, n_components=None, candidates=range(1, 7), progress=None, **params):
    """Fit the mixture; K given or chosen by leave-one-out. Returns (model, info dict)."""
    info = {'n_demonstrations': len(demos)}
    if n_components is None:
        # Leave-one-out on per-demonstration regression fits (0.03 s each on the box data):
        # an EM fit takes 10-30 s, and leave-one-out needs one per demonstration and
        # candidate K (hours). The final model below is fitted with the method asked for.
        n_components, rms = choose_n_components(demos, candidates, progress,
                                                 **{**params, 'method': 'regression'})
        info['loo_method'] = 'regression'
        info['loo_candidates'] = [int(k) for k in candidates if k <= len(demos) - 1]
        info['loo_rms_mean'] = rms.mean(axis=1).tolist()
        info['loo_rms_std'] = rms.std(axis=1).tolist()
    model = MixtureIProMP(n_components=n_components, **params).fit(demos)
    info['n_components'] = int(n_components)
    return model, info


def component_labels(model, demos):
    """Majority training label of each component (for reports only; None if unlabeled)."""
    labels = [d.label for d in demos]
    if any(lbl is None for lbl in labels):
        return None
    out = []
    for k in range(model.n_components):
        members = [lbl for lbl, r in zip(labels, model.resp_) if int(np.argmax(r)) == k]
        out.append(max(set(members), key=members.count) if members else f'component_{k}')
    return out


def train_to_file(demos, out_path, *, robot=None, **kwargs):
    """Train and save; the controlled DOFs are ``robot``'s joints and the wrist is in its base
    frame (a shipped name, a description file or a RobotDescription; None: the iiwa 14)."""
    robot = load_description(robot)
    model, info = train(demos, **kwargs)
    save_model(Path(out_path), model, observed_names=OBSERVED_NAMES,
               controlled_names=robot.joint_names, observed_frame=robot.base_frame,
               component_labels=component_labels(model, demos),
               extra={'training': info, 'robot': robot.name})
    return model, info
