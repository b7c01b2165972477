"""Names for a fitted mixture's components: the majority label of each component's training
demonstrations (an unsupervised fit never reads labels; they name its components afterwards),
or the labels a fit was given."""

from pathlib import Path

import numpy as np

from mixture_ip_ros.core.named import majority_names


def component_labels(model, demos):
    """Majority training label of each component of ``model``, fitted to ``demos`` in that
    order (component_k for one with no member; None if a demonstration is unlabelled)."""
    labels = [d.label for d in demos]
    if any(lbl is None for lbl in labels):
        return None
    names = majority_names(np.argmax(model.resp_, axis=1), labels, model.n_components)
    return [name if name is not None else f'component_{k}' for k, name in enumerate(names)]


def named_components(model, demos):
    """The name of each component of ``model`` (fitted to ``demos`` in that order) for its
    model file: a fit's labels where they name it (``model.classes_``: supervised, or named
    demonstrations among others), else :func:`component_labels`'s name (the majority of the
    demonstrations' own labels, component_k without them); None where no component has a
    name from either."""
    today = component_labels(model, demos)
    classes = getattr(model, 'classes_', None)
    if classes is None:
        return today
    return [str(c) if c is not None else (today[k] if today is not None else f'component_{k}')
            for k, c in enumerate(classes)]


def recording_labels(mapping: dict, demos) -> list:
    """Each demonstration's label in ``mapping`` (a labels file's: recording file name or stem
    -> label; absent or null: none), as a string, or None."""
    out = []
    for d in demos:
        name = str(d.name or '')
        label = mapping.get(name, mapping.get(Path(name).stem))
        out.append(None if label is None else str(label))
    return out
