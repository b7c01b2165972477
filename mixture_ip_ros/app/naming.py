"""Names for a fitted mixture's components, for reports only: the majority label of each
component's training demonstrations. An unsupervised fit never reads labels; they name its
components afterwards."""

import numpy as np


def majority_names(assigned, labels, n_components) -> list:
    """The majority label among the members of each of ``n_components`` clusters (``assigned``:
    each item's cluster), None for a cluster with none. Ties go to the first label in
    sorted order, so every run names the components alike."""
    labels = np.asarray(labels, dtype=object)
    assigned = np.asarray(assigned)
    out = []
    for k in range(n_components):
        members = labels[assigned == k].tolist()
        out.append(max(sorted(set(members), key=str), key=members.count) if members else None)
    return out


def component_labels(model, demos):
    """Majority training label of each component of ``model``, fitted to ``demos`` in that
    order (component_k for one with no member; None if a demonstration is unlabelled)."""
    labels = [d.label for d in demos]
    if any(lbl is None for lbl in labels):
        return None
    names = majority_names(np.argmax(model.resp_, axis=1), labels, model.n_components)
    return [name if name is not None else f'component_{k}' for k, name in enumerate(names)]
