"""Train a Mixture of Interaction ProMPs from demonstrations (arrays, CSV files or bags), any
layout: the observed agent with >= 1 DOF, the controlled agent with >= 0.

K, unless given, is chosen from candidates by one of two criteria, each a curve over K:
- 'patterns' (the default, ``'auto'``): the leave-one-out log-likelihood of held-out
  demonstrations in the pattern space, where the patterns are found (core.pattern_space: the
  paths of both agents compared time-warped, a few coordinates; core.patterns: a t mixture
  with shrunk scales), each
  held-out demonstration allowed to be none of the patterns with probability 1/n; among the
  candidates within two paired standard errors of the best, those whose partitions are about
  as reproducible across subsamples as the most reproducible one's (cluster stability, median
  agreement), and of those the smallest within one paired standard error of their best
  (core.selection.choose_by_patterns);
- 'loo': the thesis's leave-one-out RMS of the controlled agent given the final observed
  position (Figs. 8/10), where there is a controlled agent, each K at the robot's floor: the
  best held-out likelihood among the floors that predict the controlled agent and name the
  patterns online not significantly worse than the best (core.selection.choose_by_loo).
The chosen K's curve, the choice, its covariance floor and whether the curve has a clear
optimum go into the training summary. The model is fitted with the chosen K at the floor
calibrated for it on held-out folds (the robot's floor where there is a controlled agent;
``prior_scale`` given by the caller is used as is; EM fits keep the configured floor), with
the speed weight and the phase (warped or linear) calibrated on held-out folds too
(core.calibration).

Why not the held-out likelihood of the full model: a dozen demonstrations per pattern against
a hundred weights or more; on real interactions (NuiSI) that curve cannot tell plainly
distinct interactions apart, while the pattern space finds them (docs/results.md, NuiSI).
"""

import inspect
import logging
from pathlib import Path
from typing import NamedTuple

import numpy as np

from mixture_ip_ros.app.naming import named_components
from mixture_ip_ros.app.progress import Stages
from mixture_ip_ros.core.calibration import (calibrated_speed_weight, calibrated_switch_rate,
                                             held_out_warp_gain)
from mixture_ip_ros.core.checks import labelling, labels_fit
from mixture_ip_ros.core.crossval import check_prepared, prepare_for_cv
from mixture_ip_ros.core.demonstration import Layout
from mixture_ip_ros.core.mixture import MixtureIProMP
from mixture_ip_ros.core.warped import PhaseWarps
from mixture_ip_ros.core.selection import (PRIOR_SCALES, calibrated_floor, choose_by_loo,
                                           choose_by_patterns)
from mixture_ip_ros.core.patterns import translation_groups
from mixture_ip_ros.core.novelty import calibrate as calibrate_novelty
from mixture_ip_ros.core.parallel import checked_jobs
from mixture_ip_ros.io.dataset import WRIST_OBSERVATION_NOISE, bag_layout
from mixture_ip_ros.io.model_file import save_model
from mixture_ip_ros.robot.description import load_description

logger = logging.getLogger(__name__)

CRITERIA = ('auto', 'patterns', 'loo')


class ModelConfig(NamedTuple):
    """The MixtureIProMP configuration (``params``) training fits its model with: the
    caller's, and what its stages calibrate (``prior_scale``, ``speed_weight``, ``switch_rate``) as each one
    settles it. The held-out folds of every stage fit by regression (:meth:`for_folds`), far
    cheaper than EM fits, of which the curves need dozens; the final model is fitted with the
    method asked for."""

    params: dict

    def given(self, name: str) -> bool:
        return name in self.params

    @property
    def em(self) -> bool:
        return self.params.get('method') == 'em'

    def for_folds(self) -> dict:
        """The configuration of the held-out folds' fits."""
        return {**self.params, 'method': 'regression'}

    def settled(self, **values) -> 'ModelConfig':
        return ModelConfig({**self.params, **values})


class Preparation:
    """What each demonstration is on its own (core.crossval.prepare_for_cv with the folds'
    configuration: its weights, residuals, the set's smoothing), made once, the first time a
    stage asks for it (``prepared``: given by the caller), and taken by every stage's folds
    and, for a regression model, the final fit."""

    def __init__(self, demos, params, prepared=None):
        self.demos, self.params, self.made = demos, params, prepared

    def __call__(self):
        if self.made is None:
            self.made = prepare_for_cv(self.demos, self.params)
        return self.made


class _Run(NamedTuple):
    """What every stage of one training shares: the demonstrations (and ``labels`` of a
    supervised fit), the held-out folds' settings, the stages' clock and the preparation."""

    demos: list
    labels: object
    n_folds: int
    n_jobs: object
    progress: object
    prior_scales: object
    stages: Stages
    data: Preparation


def train(demos, *, n_components=None, candidates=range(1, 10), criterion: str = 'auto',
          n_folds: int = 5, progress=None, labels=None, prior_scales=PRIOR_SCALES, stages=None,
          n_jobs=None, prepared=None, **params):
    """Fit the mixture; K given, or chosen by ``criterion`` ('auto' = 'patterns', or 'loo';
    see the module docstring). ``labels`` makes a supervised fit (one component per class,
    K = number of classes); with None for the demonstrations without a label, a
    semi-supervised one (MixtureIProMP.fit: the named ones fixed to their label's component,
    the others learned; K given or chosen among the candidates not below the number of
    labels, the floor calibrated as without labels). ``params`` go to MixtureIProMP; without
    ``prior_scale`` among them, the floor is calibrated over ``prior_scales`` on ``n_folds``
    held-out folds. Returns
    (model, info dict): info['selection'] holds the curve of the criterion, the chosen K, its
    floor and whether the curve has a clear optimum (a flat curve is reported as such, never
    silently read as K = 1); info['phase'] whether the phase bends ('chosen': the warps kept
    where a warp predicts held-out folds better, 'held_out_gain' the mean of
    core.warped.PhaseWarps.gains; EM, and too few demonstrations for a fold, keep them, gain None)
    and info['warp_failed'] the demonstrations whose warp did not converge; info['seconds'] the
    time of each stage (``stages``, a :class:`app.progress.Stages`, also shows them). The
    held-out folds run on ``n_jobs`` threads (core.parallel.map_threads; None: every core this
    process may use), with the same result for any number; ``progress`` may be called from
    them, one call at a time, and ``random_state`` is an integer seed (a generator would be
    shared by the threads). ``prepared``: what core.crossval.prepare_for_cv made of ``demos``
    with these ``params`` and method 'regression', where the caller has it (else made here
    once, when a stage needs it).
    """
    demos = list(demos)
    _check_arguments(demos, criterion, n_jobs, params, prepared)
    labels = _checked_labels(labels, demos, n_components)
    stages = Stages() if stages is None else stages
    config = ModelConfig(params)
    run = _Run(demos, labels, n_folds, n_jobs, progress, prior_scales, stages,
               Preparation(demos, config.for_folds(), prepared))
    info = _data_summary(demos, labels, params)
    named = labelling(labels)
    if named == 'all':
        n_components = len(set(labels))
    elif named == 'some' and n_components is None:
        names = len(set(labels) - {None})
        candidates = [k for k in candidates if k >= names]
        if not candidates:
            raise ValueError(f'every candidate K is below the {names} labels (each label is a '
                             'component of its own): allow more components')
    selection = None
    if n_components is None:
        selection = _choose_k(run, candidates, criterion, config)
        n_components = selection['chosen']
        info['selection'] = selection
    # The floor is calibrated on held-out regression fits; EM learns from demonstrations with
    # gaps, whose regression fits say little about it, and keeps the configured floor.
    if not config.given('prior_scale') and named != 'all' and not config.em:
        floor = _choose_floor(run, n_components, criterion, selection, config)
        if floor is not None:
            config = config.settled(prior_scale=floor)
        if selection is not None:
            selection['prior_scale'] = floor
    # The same for the speed weight; EM's demonstrations may lack a whole agent, which the
    # regression fits of the calibration cannot take: EM keeps the configured weight.
    if not config.given('speed_weight') and not config.em:
        weight, info['speed_scores'] = _calibrate_speed(run, n_components, config)
        config = config.settled(speed_weight=weight)
    # The switch rate, read by the estimator as the speed weight is (the same folds).
    if not config.given('switch_rate') and not config.em:
        rate, info['switch_scores'] = _calibrate_switch(run, n_components, config)
        config = config.settled(switch_rate=rate)
    with stages('final fit'):
        model = _final_fit(run, n_components, config)
    info['phase'] = _choose_phase(run, n_components, config)
    if info['phase']['chosen'] == 'warped':
        with stages('phase warps'):
            model.warps_ = PhaseWarps().fit(model, demos)
    failed = [] if model.warps_ is None else model.warps_.failed_
    if failed:
        logger.warning('the phase warp of %d demonstration(s) did not converge; they are '
                       'left out of the Gaussian over the warp: %s', len(failed),
                       ', '.join(map(str, failed)))
    info['n_components'] = int(n_components)
    # each component's members: the demonstrations it explains best, for the reports
    info['component_sizes'] = np.bincount(np.argmax(model.resp_, axis=1),
                                          minlength=int(n_components)).tolist()
    info['prior_scale'] = float(model.prior_scale)
    info['speed_weight'] = float(model.speed_weight)
    info['switch_rate'] = float(model.switch_rate)
    info['noise_var'] = np.asarray(model.noise_var_).tolist()
    info['warp_failed'] = [str(n) for n in failed]
    info['seconds'] = dict(stages.seconds)
    return model, info


def _check_arguments(demos, criterion, n_jobs, params, prepared):
    """Refuse what would make training fail late or its threads or shared preparation lie."""
    checked_jobs(n_jobs)
    seed = params.get('random_state', 0)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise ValueError(f'random_state must be an integer seed, got {seed!r} (the held-out '
                         'folds run on threads, which would share a generator)')
    if criterion not in CRITERIA:
        raise ValueError(f'criterion must be one of {CRITERIA}, got {criterion!r}')
    if not demos:
        raise ValueError('no demonstrations to train on')
    if prepared is not None:
        check_prepared(prepared, demos, params)


def _checked_labels(labels, demos, n_components):
    """``labels`` as a list, one per demonstration (None where a demonstration has none), or
    None where none is named; ValueError where they cannot make a fit."""
    if labels is None:
        return None
    labels = list(labels)
    if len(labels) != len(demos):
        raise ValueError(f'labels must have one entry per demonstration ({len(demos)}), got '
                         f'{len(labels)}')
    if labelling(labels) == 'none':
        return None
    names = len(set(labels) - {None})
    if n_components is not None and not labels_fit(labels, n_components):
        raise ValueError(f'n_components={n_components} cannot hold the {names} labels: every '
                         'label is a component of its own (with every demonstration labelled, '
                         'K is their number)')
    return labels


def _data_summary(demos, labels, params) -> dict:
    """The training summary's account of the data: how many demonstrations of how many DOFs,
    whether supervised, the DOF groups translated together."""
    info = {'n_demonstrations': len(demos), 'n_observed_dofs': demos[0].n_observed_dofs,
            'n_controlled_dofs': demos[0].n_controlled_dofs}
    if labelling(labels) == 'all':
        info['supervised'] = True
    elif labels is not None:
        info['labelled'] = {'demonstrations': sum(lbl is not None for lbl in labels),
                            'labels': sorted({str(lbl) for lbl in labels if lbl is not None})}
    groups = translation_groups(params.get('translation'), demos[0].n_observed_dofs
                                + demos[0].n_controlled_dofs)
    if groups:
        info['translation'] = [list(g) for g in groups]
    return info


def _choose_k(run: _Run, candidates, criterion, config: ModelConfig) -> dict:
    """K by ``criterion`` among ``candidates`` (those the demonstrations can hold): the
    summary of core.selection.choose_by_patterns or choose_by_loo."""
    demos = run.demos
    criterion = 'patterns' if criterion == 'auto' else criterion
    if criterion == 'loo' and not demos[0].n_controlled_dofs > 0:
        raise ValueError("criterion 'loo' needs a controlled agent; these demonstrations have "
                         "none (use 'patterns')")
    candidates = [int(k) for k in candidates if k <= len(demos) - 1]
    if not candidates or len(demos) < 3:
        raise ValueError(f'{len(demos)} demonstrations are too few to choose K')
    with run.stages('choosing K'):
        if criterion == 'patterns':
            selection = choose_by_patterns(run.data(), candidates, config.for_folds())
        else:
            selection = choose_by_loo(demos, candidates, run.n_folds, run.progress,
                                      run.prior_scales, config.for_folds(), run.n_jobs,
                                      run.data())
    if not selection['clear_optimum']:
        logger.warning('K = %d by %s, but %s', selection['chosen'], criterion,
                       selection['note'])
    return selection


def _choose_floor(run: _Run, n_components, criterion, selection, config: ModelConfig):
    """The covariance floor of the model: the one leave-one-out chose K at, else the one
    calibrated for ``n_components`` on held-out folds; None where the folds cannot hold
    that many components."""
    if criterion == 'loo' and selection is not None:
        return selection['prior_scale']
    n_fold = int(min(run.n_folds, len(run.demos)))
    n_train = len(run.demos) - int(np.ceil(len(run.demos) / max(n_fold, 1)))
    if n_components > n_train:
        return None
    with run.stages('covariance floor'):
        return calibrated_floor(run.demos, n_components, run.n_folds, run.progress,
                                run.prior_scales, config.for_folds(), run.n_jobs, run.data())


def _calibrate_speed(run: _Run, n_components, config: ModelConfig):
    """(speed weight, mean held-out score of each weight):
    core.calibration.calibrated_speed_weight."""
    with run.stages('speed weight'):
        return calibrated_speed_weight(run.demos, run.data(), n_components, run.labels,
                                       run.n_folds, config.for_folds(), run.n_jobs)


def _calibrate_switch(run: _Run, n_components, config: ModelConfig):
    """(switch rate, mean held-out score of each rate): core.calibration.calibrated_switch_rate.
    """
    with run.stages('switch rate'):
        return calibrated_switch_rate(run.demos, run.data(), n_components, run.labels,
                                      run.n_folds, config.for_folds(), run.n_jobs)


def _final_fit(run: _Run, n_components, config: ModelConfig) -> MixtureIProMP:
    """The model, fitted to every demonstration with the method asked for (a regression fit
    from the preparation where a stage made it)."""
    model = MixtureIProMP(n_components=n_components, **config.params)
    regression = model.method == 'regression' and run.data.made is not None
    return model.fit(run.data.made if regression else run.demos, labels=run.labels)


def _choose_phase(run: _Run, n_components, config: ModelConfig) -> dict:
    """The phase warps where they predict held-out recordings better than the linear phase
    (core.calibration.held_out_warp_gain): info['phase']. EM's demonstrations may lack a
    whole agent, which the folds' regression fits cannot take: EM keeps them."""
    if config.em:
        return {'held_out_gain': None, 'chosen': 'warped'}
    with run.stages('phase choice'):
        gain = held_out_warp_gain(run.demos, run.data(), n_components, run.labels, run.n_folds,
                                  config.for_folds(), run.n_jobs)
    phase = {'held_out_gain': gain, 'chosen': 'warped' if gain is None or gain > 0 else 'linear'}
    if gain is not None:
        logger.info('phase: %s (a warp predicts held-out recordings %+.2f nats each against '
                    'the linear phase)', phase['chosen'], gain)
    return phase


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
                  robot=None, extra: dict = None, **kwargs):
    """:func:`train`, calibrate its novelty test (core.novelty: the evidence of held-out
    demonstrations), then save the model with the layout's names and units, its components'
    names (app.naming.named_components: the labels' where ``labels`` name them) and the
    training summary. By default the layout is the bags' (the wrist, and ``robot``'s joints: a
    shipped name, a description file or a RobotDescription; None: the iiwa 14) and the
    observed agent is in the robot's base frame. A wrist in metres gets the wrist's
    observation noise unless ``observation_noise`` is given. ``extra``: more records for the
    model file's metadata ``extra`` (app.arm_in_partner_place: the placement)."""
    demos = list(demos)
    robot = load_description(robot)
    layout = (layout or default_layout(demos, robot)).check(demos)
    if layout.observed == bag_layout().observed and layout.observed_units == ('m',) * 3:
        kwargs.setdefault('observation_noise', WRIST_OBSERVATION_NOISE)
    stages = kwargs.setdefault('stages', Stages())
    checked_jobs(kwargs.get('n_jobs'))
    if kwargs.get('prepared') is None:
        # Training's stages and the novelty folds below share it (train's ``prepared``).
        with stages('preparing'):
            kwargs['prepared'] = prepare_for_cv(demos, {**_model_params(kwargs),
                                                        'method': 'regression'})
    model, info = train(demos, **kwargs)
    # Held-out folds fitted by regression, as the K curves: EM fits would be far slower.
    # the floor chosen with K; the switch rate, so that the held-out evidence is the online one
    params = {**_model_params(kwargs), 'method': 'regression',
              'prior_scale': model.prior_scale, 'switch_rate': model.switch_rate}
    labels = kwargs.get('labels')

    def fold_model(index):
        # Each fold with its own labels where they can name the model's components (a fold
        # may miss a label every one of whose demonstrations it holds out), else without.
        fold_labels = None if labels is None else [labels[i] for i in index]
        if not labels_fit(fold_labels, model.n_components):
            fold_labels = None
        return MixtureIProMP(n_components=model.n_components, **params).fit(
            kwargs['prepared'].take(index), labels=fold_labels)
    with stages('novelty'):
        model.novelty_ = calibrate_novelty(demos, fold_model, n_jobs=kwargs.get('n_jobs'))
    info['novelty'] = {'prefix': model.novelty_.prefix.round(3).tolist(),
                       'window': round(model.novelty_.window, 3)}
    with stages('saving'):
        save_model(Path(out_path), model, layout=layout,
                   observed_frame=robot.base_frame if observed_frame is None else observed_frame,
                   component_labels=named_components(model, demos),
                   extra={**(extra or {}), 'training': info, 'robot': robot.name})
    info['seconds'] = dict(stages.seconds)
    return model, info
