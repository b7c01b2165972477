"""Train a Mixture of Interaction ProMPs from demonstrations (arrays, CSV files or bags), any
layout: the observed agent with >= 1 DOF, the controlled agent with >= 0.

K, unless given, is chosen from candidates by two criteria, each a curve over K:
- the cross-validated held-out log-likelihood of the demonstrations (both agents, phase known),
  for every layout, each K at the covariance floor its held-out likelihood prefers
  (:func:`core.mixture.calibrated_heldout_curves`);
- the thesis's leave-one-out RMS of the controlled agent given the final observed position
  (Figs. 8/10), where there is a controlled agent, each K at the floor that predicts the
  controlled agent best on the same cross-validated fits among the floors whose held-out
  likelihood is not significantly worse (:func:`core.mixture.calibrated_heldout_curves`).
``criterion='auto'`` decides by leave-one-out where there is a controlled agent (the thesis) and
by the held-out log-likelihood otherwise; both curves, the choice, the floor and whether the
deciding curve has a clear optimum go into the training summary. The model is fitted with the
chosen K and its floor (``prior_scale`` given by the caller is used as is).
"""

import inspect
import logging
import sys
from pathlib import Path

import numpy as np

from mixture_ip_ros.core.demonstration import Layout
from mixture_ip_ros.core.mixture import (PRIOR_SCALES, MixtureIProMP, calibrated_heldout_curves,
                                         loo_rms_by_components, selection_curve)
from mixture_ip_ros.core.novelty import calibrate as calibrate_novelty
from mixture_ip_ros.io.dataset import WRIST_OBSERVATION_NOISE, bag_layout
from mixture_ip_ros.io.model_file import save_model
from mixture_ip_ros.robot.description import load_description

logger = logging.getLogger(__name__)

CRITERIA = ('auto', 'loo', 'loglik')


def text_progress(stream=sys.stderr, what='choosing K'):
    """A one-line progress bar for the K curves."""
    def show(done, total, K):
        width = 30
        filled = int(width * done / total)
        stream.write(f'\r{what} K={K:<2d} [{"#" * filled}{"." * (width - filled)}] '
                     f'{done}/{total}')
        if done == total:
            stream.write('\n')
        stream.flush()
    return show


def _curve_summary(candidates, scores, curve):
    return {'candidates': list(candidates), 'mean': curve['mean'],
            'std': np.asarray(scores).std(axis=1).tolist(), 'se': curve['se'],
            'chosen': int(candidates[curve['index']]), 'clear_optimum': curve['clear'],
            'note': curve['note']}


def train(demos, *, n_components=None, candidates=range(1, 7), criterion: str = 'auto',
          n_folds: int = 5, progress=None, labels=None, prior_scales=PRIOR_SCALES, **params):
    """Fit the mixture; K given, or chosen by ``criterion`` ('auto', 'loo', 'loglik'; see the
    module docstring). ``labels`` makes a supervised fit (one component per class, K = number
    of classes). ``params`` go to MixtureIProMP; without ``prior_scale`` among them, the floor
    is calibrated over ``prior_scales`` when K is chosen. Returns (model, info dict):
    info['selection'] holds every curve computed, the criterion, the chosen K, its floor and
    whether its curve has a clear optimum (a flat curve is reported as such, never silently
    read as K = 1).
    """
    demos = list(demos)
    if criterion not in CRITERIA:
        raise ValueError(f'criterion must be one of {CRITERIA}, got {criterion!r}')
    if not demos:
        raise ValueError('no demonstrations to train on')
    has_controlled = demos[0].n_controlled_dofs > 0
    info = {'n_demonstrations': len(demos), 'n_observed_dofs': demos[0].n_observed_dofs,
            'n_controlled_dofs': demos[0].n_controlled_dofs}
    if labels is not None:
        n_components = len(set(labels))
        info['supervised'] = True
    if n_components is None:
        if criterion == 'auto':
            criterion = 'loo' if has_controlled else 'loglik'
        if criterion == 'loo' and not has_controlled:
            raise ValueError("criterion 'loo' needs a controlled agent; these demonstrations have "
                             "none (use 'loglik')")
        # The curves use per-demonstration regression fits (0.03 s each on the box data): an EM
        # fit takes 10-30 s, and leave-one-out needs one per demonstration and candidate K
        # (hours). The final model below is fitted with the method asked for.
        curve_params = {**params, 'method': 'regression'}
        scales = [params['prior_scale']] if 'prior_scale' in params else list(prior_scales)
        selection = {'criterion': criterion}
        n_train = len(demos) - int(np.ceil(len(demos) / min(n_folds, len(demos))))
        ll_candidates = [int(k) for k in candidates if k <= n_train]
        if not ll_candidates:
            raise ValueError(f'not enough demonstrations for {n_folds}-fold cross-validation')
        # One progress count over every fit of both curves.
        n_cal = len(scales) * len(ll_candidates) * int(min(n_folds, len(demos)))
        loo_candidates = [int(k) for k in candidates if k <= len(demos) - 1]
        total = n_cal + (len(loo_candidates) * len(demos) if has_controlled else 0)
        curves = calibrated_heldout_curves(demos, ll_candidates, (), scales, n_folds,
                                           _offset_progress(progress, 0, total), **curve_params)
        cal = curves['loglik']
        ll = cal['scores']
        selection['heldout_loglik'] = {
            **_curve_summary(ll_candidates, ll, selection_curve(ll, higher_is_better=True,
                                                               paired=True)),
            'n_folds': int(min(n_folds, len(demos))), 'unit': 'nats per demonstration',
            'prior_scale': cal['prior_scale'], 'prior_scales': cal['prior_scales'],
            'mean_by_prior_scale': cal['mean_by_scale'].tolist()}
        floor = dict(zip(ll_candidates, cal['prior_scale']))
        if has_controlled:
            # A K too large for the held-out folds (leave-one-out trains on one more
            # demonstration) takes the floor of the largest K they calibrated.
            calibrated = dict(zip(ll_candidates, curves['controlled_rms']['prior_scale']))
            floor_loo = {K: calibrated[max(k for k in ll_candidates if k <= K)]
                         for K in loo_candidates}
            if not loo_candidates:
                raise ValueError('not enough demonstrations for leave-one-out')
            rms = np.vstack([
                loo_rms_by_components(demos, [K], 'final',
                                      _offset_progress(progress, n_cal + a * len(demos), total),
                                      **{**curve_params, 'prior_scale': floor_loo[K]})
                for a, K in enumerate(loo_candidates)])
            selection['loo_rms'] = {
                **_curve_summary(loo_candidates, rms, selection_curve(rms)),
                'prior_scale': [floor_loo[K] for K in loo_candidates]}
            info['loo_method'] = 'regression'
            info['loo_candidates'] = loo_candidates
            info['loo_rms_mean'] = rms.mean(axis=1).tolist()
            info['loo_rms_std'] = rms.std(axis=1).tolist()
        chosen = selection['loo_rms' if criterion == 'loo' else 'heldout_loglik']
        n_components = chosen['chosen']
        floors = floor_loo if criterion == 'loo' else floor
        params = {**params, 'prior_scale': floors[n_components]}
        selection.update(chosen=int(n_components), clear_optimum=chosen['clear_optimum'],
                         note=chosen['note'], prior_scale=params['prior_scale'])
        if not chosen['clear_optimum']:
            logger.warning('K = %d by %s, but %s', n_components, criterion, chosen['note'])
        info['selection'] = selection
    model = MixtureIProMP(n_components=n_components, **params).fit(demos, labels=labels)
    info['n_components'] = int(n_components)
    info['noise_var'] = np.asarray(model.noise_var_).tolist()
    return model, info


def _offset_progress(progress, offset, total):
    """``progress`` of one batch of fits, ``offset`` fits into ``total`` fits in all."""
    if progress is None:
        return None
    return lambda done, _, K: progress(offset + done, total, K)


def component_labels(model, demos):
    """Majority training label of each component (for reports only; None if unlabeled)."""
    labels = [d.label for d in demos]
    if any(lbl is None for lbl in labels):
        return None
    out = []
    for k in range(model.n_components):
        members = [lbl for lbl, r in zip(labels, model.resp_) if int(np.argmax(r)) == k]
        # ties go to the first label in sorted order: the same names in every run
        out.append(max(sorted(set(members), key=str), key=members.count) if members
                   else f'component_{k}')
    return out


def _model_params(kwargs) -> dict:
    """The MixtureIProMP configuration among ``train``'s keyword arguments."""
    names = inspect.signature(MixtureIProMP).parameters
    return {k: v for k, v in kwargs.items() if k in names and k != 'n_components'}


def default_layout(demos, robot=None) -> Layout:
    """The layout of bag demonstrations: the wrist (3, m) observed, ``robot``'s joints (rad)
    controlled; any other layout must be named (a model file records every DOF's name and
    unit)."""
    layout = bag_layout(load_description(robot).joint_names)
    d = demos[0]
    if (d.n_observed_dofs, d.n_controlled_dofs) != (len(layout.observed), len(layout.controlled)):
        raise ValueError(f'demonstrations with {d.n_observed_dofs} observed and '
                         f'{d.n_controlled_dofs} controlled DOFs need a layout naming them '
                         f'(train_to_file(..., layout=Layout(observed=..., controlled=...)))')
    return layout


def train_to_file(demos, out_path, layout: Layout = None, observed_frame: str = None, *,
                  robot=None, **kwargs):
    """:func:`train`, calibrate its novelty test (core.novelty: the evidence of held-out
    demonstrations, for an unsupervised model), then save the model with the layout's names
    and units and the training summary. By default the layout is the bags' (the wrist, and
    ``robot``'s joints: a shipped name, a description file or a RobotDescription; None: the
    iiwa 14) and the observed agent is in the robot's base frame. A wrist in metres gets the
    wrist's observation noise unless ``observation_noise`` is given."""
    demos = list(demos)
    robot = load_description(robot)
    layout = (layout or default_layout(demos, robot)).check(demos)
    if layout.observed == bag_layout().observed and layout.observed_units == ('m',) * 3:
        kwargs.setdefault('observation_noise', WRIST_OBSERVATION_NOISE)
    model, info = train(demos, **kwargs)
    if kwargs.get('labels') is None:
        # Held-out folds fitted by regression, as the K curves: EM would take minutes.
        params = {**_model_params(kwargs), 'method': 'regression',
                  'prior_scale': model.prior_scale}      # the floor chosen with K
        model.novelty_ = calibrate_novelty(
            demos, lambda part: MixtureIProMP(n_components=model.n_components,
                                              **params).fit(part))
        info['novelty'] = {'prefix': model.novelty_.prefix.round(3).tolist(),
                           'window': round(model.novelty_.window, 3)}
    save_model(Path(out_path), model, layout=layout,
               observed_frame=robot.base_frame if observed_frame is None else observed_frame,
               component_labels=component_labels(model, demos),
               extra={'training': info, 'robot': robot.name})
    return model, info
