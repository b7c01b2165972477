"""A trained model scored on labelled recordings without retraining (`mixture-ip evaluate
--model`): each recording played to the online estimator as the estimator node is fed it, the
interaction recognised from 30, 50, 70 and 100 % of it and the controlled agent predicted over
the rest, as the cross-validated evaluation (app.evaluation.interactions) measures a fold.

The model never learned the labels: each component is named by the majority label of the
recordings it explains best given their whole observed path (eq. 11, phase known; app.naming).
Those are the recordings scored, so the naming is the most favourable one: the scores are
held-out ones only if the recordings were not among the model's training recordings.
"""

from __future__ import annotations

import numpy as np
from sklearn.metrics import adjusted_rand_score

from mixture_ip_ros.app.evaluation.interactions import FRACTIONS, path_errors
from mixture_ip_ros.core.named import majority_names
from mixture_ip_ros.core.demonstration import Layout
from mixture_ip_ros.core.online import OnlineEstimator
from mixture_ip_ros.core.playback import observed_rows, prefix_predictions


def model_columns(meta, observed=None, controlled=None, observed_units=None,
                  controlled_units=None) -> Layout:
    """The CSV columns to read for a model with file metadata ``meta``: the names given (one per
    DOF of the model) or else the model's own, in the model's units; ValueError if the names
    given do not fit the model or the units contradict its."""
    layout = Layout(tuple(meta['observed_names']), tuple(meta['controlled_names']),
                    tuple(meta['observed_units']), tuple(meta['controlled_units']))
    names = {}
    for agent, given in (('observed', observed), ('controlled', controlled)):
        own = getattr(layout, agent)
        if given and len(given) != len(own):
            raise ValueError(f'--{agent} names {len(given)} columns; the model has '
                             f'{len(own)} {agent} DOFs ({", ".join(own) or "none"})')
        names[agent] = tuple(given) if given else own
    for agent, given in (('observed', observed_units), ('controlled', controlled_units)):
        own = getattr(layout, agent + '_units')
        given = tuple(given or ())
        if len(given) == 1 and len(own) > 1:
            given = given * len(own)
        if given and given != own:
            raise ValueError(f'--{agent}-units {", ".join(given)}: the model was trained on '
                             f'{", ".join(u or "?" for u in own)}')
    return Layout(names['observed'], names['controlled'], layout.observed_units,
                  layout.controlled_units)


def evaluate_model(model, demos, fractions=FRACTIONS, *, cm: bool = True, n_alpha: int = 50,
                   min_interval: float = 0.05, progress=None) -> dict:
    """Score ``model`` (a fitted MixtureIProMP) on labelled Demonstrations of its layout (see
    the module docstring); ``cm``: partner errors in cm (the controlled DOFs in metres), else in
    their own unit. ``progress(line)`` is told at each quarter of the recordings. The metrics'
    keys are described in docs/metrics.md."""
    demos = list(demos)
    labels = np.array([str(d.label) for d in demos], dtype=object)
    if not demos or any(d.label is None for d in demos):
        raise ValueError('scoring a model needs labelled recordings (a label for every one)')
    classes = sorted(set(labels.tolist()))
    K = int(model.n_components)
    whole = [int(np.argmax(model.component_posterior(d.phase[ok], d.observed[ok],
                                                     alpha=1.0 / d.duration)))
             for d in demos for ok in [observed_rows(d)]]
    names = [n if n is not None else f'component_{k}'
             for k, n in enumerate(majority_names(whole, labels, K))]
    fractions = tuple(float(f) for f in fractions)
    keys = [f'{f:g}' for f in fractions]
    has_partner = demos[0].n_controlled_dofs > 0
    shape = (len(demos), len(fractions))
    right = np.zeros(shape, dtype=bool)
    rms, final, phase_error = (np.full(shape, np.nan) for _ in range(3))
    est = OnlineEstimator(model, n_alpha=n_alpha, min_interval=min_interval)
    quarter = 0
    for r, d in enumerate(demos):
        for c, (k, pred, rest, alpha) in enumerate(prefix_predictions(est, d, fractions)):
            right[r, c] = names[k] == labels[r]
            phase_error[r, c] = fractions[c] * abs(alpha * d.duration - 1.0)
            if pred is not None and has_partner:
                rms[r, c], final[r, c] = path_errors(pred, d.controlled[rest])
        if progress is not None and 4 * (r + 1) // len(demos) > quarter:
            quarter = 4 * (r + 1) // len(demos)
            progress(f'played {r + 1}/{len(demos)} recordings to the online estimator')
    unit, err_unit = (100.0, 'cm') if cm else (1.0, 'unit')

    def by_fraction(values, scale=1.0):
        return {k: (None if np.all(np.isnan(values[:, c])) else
                    float(scale * np.nanmean(values[:, c]))) for c, k in enumerate(keys)}
    counts = [[int(np.sum((np.asarray(whole) == k) & (labels == c))) for c in classes]
              for k in range(K)]
    metrics = {
        'n_recordings': len(demos), 'interactions': classes, 'n_components': K,
        'component_labels': names,
        'components_vs_labels': {'labels': classes, 'counts': counts},
        'ari': float(adjusted_rand_score(labels.tolist(), whole)),
        'recognition_accuracy_by_fraction': {k: float(right[:, c].mean())
                                             for c, k in enumerate(keys)},
        'recognition_accuracy_by_interaction': {
            c: {k: float(right[labels == c, j].mean()) for j, k in enumerate(keys)}
            for c in classes},
        'chance_accuracy': float(max(np.mean(labels == c) for c in classes)),
        'phase_error_by_fraction': by_fraction(phase_error),
    }
    if has_partner:
        metrics[f'partner_rms_{err_unit}_by_fraction'] = by_fraction(rms, unit)
        metrics[f'partner_final_{err_unit}_by_fraction'] = by_fraction(final, unit)
    metrics['config'] = {'fractions': list(fractions), 'n_alpha': int(n_alpha),
                         'min_interval': float(min_interval)}
    return metrics
