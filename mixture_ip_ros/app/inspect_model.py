"""`mixture-ip info MODEL`: what a model file holds, in a few lines (io.model_file reads and
checks it): the layout it was trained for, its patterns, and the training summary stored in
its metadata."""

import numpy as np

from mixture_ip_ros.app.summary import model_lines, pattern_lines, selection_lines
from mixture_ip_ros.io.model_file import load_model


def _dofs(names, units) -> str:
    return ', '.join(f'{n} [{u}]' if u else n for n, u in zip(names, units)) or 'none'


def model_summary(path) -> str:
    """The summary of the model file at ``path``; io.model_file.ModelFileError (a ValueError)
    if it is not a readable model."""
    model, meta = load_model(path)
    extra = meta.get('extra') or {}
    training = extra.get('training') or {}
    K = model.n_components
    lines = [f"{path}: model file format {meta['format_version']}, written by mixture_ip_ros "
             f"{meta.get('package_version', '?')}",
             f"observed ({meta.get('observed_frame') or 'frame not given'}): "
             f"{_dofs(meta['observed_names'], meta['observed_units'])}",
             f"controlled: {_dofs(meta['controlled_names'], meta['controlled_units'])}",
             f"{K} pattern{'s' if K != 1 else ''}; {model.basis_.n_basis} basis functions per "
             f"DOF, noise {model.noise}, "
             f"phase {'warped' if model.warps_ is not None else 'linear'}"
             + (f', translation groups {[list(g) for g in model.translation]}'
                if model.translation else '')]
    lines += pattern_lines(np.asarray(model.weights_), training.get('component_sizes'),
                           meta.get('component_labels'), 1.0 / np.asarray(model.alpha_mean_))
    if training:
        lines.append(f"training: {training.get('n_demonstrations', '?')} recordings")
        lines += ['  ' + ln for ln in selection_lines(training) + model_lines(training)]
    else:
        lines.append('training: no summary stored in this file')
    lines.append('novelty test: ' + ('calibrated' if model.novelty_ is not None else
                                     'none (the estimator cannot tell an unknown movement)'))
    lines += placement_lines(extra.get('partner_place'))
    return '\n'.join(lines)


def placement_lines(place) -> list:
    """The arm in a partner's place (`train --arm-in-partner-place`), as the model file
    recorded it (robot.partner_place.PartnerPlace.metadata); none for other models."""
    if not isinstance(place, dict):
        return []
    person = place.get('person1_in_world') or {}
    xyz, yaw = person.get('xyz'), person.get('yaw')
    scale = place.get('reach_scale', float('nan'))
    lines = [f"the arm ({place.get('robot', '?')}) in the partner's place, from "
             f"{place.get('source', '?')}: reach scale {scale:.3f}"]
    if xyz is not None and yaw is not None:
        lines.append(f'  person 1 at ({xyz[0]:.2f}, {xyz[1]:.2f}, {xyz[2]:.2f}) m, facing '
                     f'{np.degrees(yaw):.0f} deg, in the mocap frame')
    lag = place.get('flange_to_partner_cm') or {}
    if 'median' in lag:
        lines.append(f"  the flange followed the partner's hand within {lag['median']:.1f} cm "
                     f"(median), {lag.get('p95', float('nan')):.1f} cm (95th percentile)")
    return lines
