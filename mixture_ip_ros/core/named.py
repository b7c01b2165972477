"""Names and patterns: a cluster's majority name, and patterns where some demonstrations are
named, the start of semi-supervised EM (core.mixture.MixtureIProMP.fit with labels for some
demonstrations and None for the rest).

Names fix which pattern a named demonstration belongs to; how far each pattern reaches is still
found from all the demonstrations, in the pattern space where discovery finds it (core.patterns).
"""

import numbers

import numpy as np
from scipy.optimize import linear_sum_assignment

from .numerics import tie_tolerance


def majority_names(assigned, labels, n_components) -> list:
    """The majority label among the members of each of ``n_components`` clusters (``assigned``:
    each item's cluster), None for a cluster with none. Ties go to the first label in
    sorted order (numbers by value, names by their text), so every run names the components
    alike."""
    labels = np.asarray(labels, dtype=object)
    assigned = np.asarray(assigned)

    def order(label):
        return (0, label, '') if isinstance(label, numbers.Real) else (1, 0, str(label))
    out = []
    for k in range(n_components):
        members = labels[assigned == k].tolist()
        out.append(max(sorted(set(members), key=order), key=members.count) if members else None)
    return out


def matched_components(clusters, index, n_names: int, n_components: int) -> np.ndarray:
    """The component of each discovered pattern (``clusters`` (n,) in 0..n_components-1):
    each name (``index`` (n,): 0..n_names-1, -1 for an unnamed demonstration) takes the pattern
    that holds most of its named demonstrations, one pattern per name, the most named
    demonstrations kept in all (an assignment problem); the patterns no name takes are the
    components after the names', in their order. (n_components,)"""
    named = index >= 0
    counts = np.zeros((n_names, n_components))
    np.add.at(counts, (index[named], clusters[named]), 1)
    _, taken = linear_sum_assignment(-counts)
    order = list(taken) + [j for j in range(n_components) if j not in set(taken)]
    component = np.empty(n_components, dtype=int)
    component[order] = np.arange(n_components)
    return component


def named_patterns(X, clusters, index, n_names: int, n_components: int, fit) -> np.ndarray:
    """Each demonstration's component (n,) of ``n_components``: a named one's name (``index``,
    as in :func:`matched_components`), an unnamed one's pattern, found in the pattern space
    ``X`` (n, q) with the named demonstrations held in their names' patterns.

    Two starts: the patterns discovered without names (``clusters``), named by
    :func:`matched_components`; and the same with each unnamed demonstration of a named pattern
    moved to the name whose named demonstrations' mean is nearest. From each,
    ``fit(resp (n, K), fixed (n,))``, a core.patterns.PatternMixture fitted with the named
    demonstrations' responsibilities fixed (semi-supervised EM); the start whose fit is the
    more likely is kept (the first on a tie). The first trusts how far discovery's patterns
    reach, the names only saying which is which; the second trusts where the names are, which
    matters where discovery drew a border through a named pattern. Which holds is a question
    of the data, which the likelihood answers."""
    named = index >= 0
    matched = np.where(named, index,
                       matched_components(clusters, index, n_names, n_components)[clusters])
    means = np.array([X[index == c].mean(axis=0) for c in range(n_names)])
    nearest = np.argmin(((X[:, None] - means[None]) ** 2).sum(axis=2), axis=1)
    moved = np.where(named | (matched >= n_names), matched, nearest)
    best = None
    for start in (matched, moved):
        fitted = fit(np.eye(n_components)[start], named)
        if best is None or fitted.log_likelihood_ > best.log_likelihood_ + tie_tolerance(
                best.log_likelihood_):
            best = fitted
    return np.where(named, index, np.argmax(best.resp_, axis=1))
