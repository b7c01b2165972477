"""k-means (Lloyd iterations from k-means++ seeds), the starting partitions of the mixtures."""

import numpy as np


def kmeans(X, n_clusters: int, random_state=0, n_init: int = 10, max_iter: int = 100):
    """k-means++ seeded Lloyd iterations; the best of ``n_init`` runs (the first of equals).
    Returns labels (n,).

    Every random draw is in the seeding, so the runs are seeded first, one after another, and
    their Lloyd iterations then run side by side (:func:`lloyd`)."""
    X = np.asarray(X, dtype=float)
    if int(n_clusters) == 1:
        return np.zeros(len(X), dtype=int)               # what every run ends with
    rng = np.random.default_rng(random_state)
    labels, inertia = lloyd(X, np.stack([_seeded(X, int(n_clusters), rng)
                                         for _ in range(n_init)]), max_iter)
    return labels[int(np.argmin(inertia))]


def kmeans_runs(X, n_clusters: int, seeds, max_iter: int = 100) -> np.ndarray:
    """``kmeans(X, n_clusters, random_state=s, n_init=1)`` for every seed s, the runs side by
    side: labels (len(seeds), n)."""
    X = np.asarray(X, dtype=float)
    if int(n_clusters) == 1:
        return np.zeros((len(seeds), len(X)), dtype=int)
    C = np.stack([_seeded(X, int(n_clusters), np.random.default_rng(s)) for s in seeds])
    return lloyd(X, C, max_iter)[0]


def _seeded(X, K, rng):
    """k-means++ centres (K, dim) drawn with ``rng``."""
    n = len(X)
    C = np.empty((K, X.shape[1]))
    C[0] = X[rng.integers(n)]
    d2 = np.sum((X - C[0]) ** 2, axis=1)                # squared distance to the nearest centre
    for k in range(1, K):
        total = d2.sum()
        C[k] = X[rng.choice(n, p=d2 / total if total > 0 else np.full(n, 1 / n))]
        d2 = np.minimum(d2, np.sum((X - C[k]) ** 2, axis=1))
    return C


def lloyd(X, C, max_iter: int = 100):
    """Lloyd iterations from every run's centres C (runs, K, dim), side by side, each stopping
    on its own: when its labels repeat (its means are its centres again) or its centres move
    less than np.allclose's tolerance. Returns (labels (runs, n), inertia (runs,))."""
    C = np.array(C, dtype=float)
    runs, n = len(C), len(X)
    labels = np.full((runs, n), -1)
    active = np.arange(runs)
    x2 = np.einsum('ij,ij->i', X, X)
    for _ in range(max_iter):
        if not active.size:
            break
        new = _nearest_centres(X, x2, C[active])
        moved = ~(new == labels[active]).all(axis=1)
        active, new = active[moved], new[moved]
        labels[active] = new
        newC = _cluster_means(X, new, C[active])
        still = ~np.all(np.abs(newC - C[active]) <= 1e-8 + 1e-5 * np.abs(C[active]), axis=(1, 2))
        C[active[still]] = newC[still]
        active = active[still]
    inertia = np.array([np.sum((X - C[r][labels[r]]) ** 2) for r in range(runs)])
    return labels, inertia


def _nearest_centres(X, x2, C):
    """argmin_k ((x_i - c_rk) ** 2).sum() for every run r and row i (C (runs, K, dim)), the
    index exactly that sum picks. The distances are first expanded as |x|^2 + |c|^2 - 2 x.c
    (one matrix product); a row whose nearest two are closer than 1e-9 (|x|^2 + |c|^2), far
    above what rounding can move either form (~d eps of it), is decided by the direct sum."""
    c2 = np.einsum('rkd,rkd->rk', C, C)
    dist = x2[None, :, None] + c2[:, None, :] - 2 * (X @ C.transpose(0, 2, 1))   # (runs, n, K)
    labels = np.argmin(dist, axis=2)
    if C.shape[1] > 1:
        two = np.partition(dist, 1, axis=2)
        scale = x2[None, :] + c2.max(axis=1)[:, None]
        for r, i in zip(*np.nonzero(two[..., 1] - two[..., 0] <= 1e-9 * scale)):
            labels[r, i] = np.argmin(((X[i] - C[r]) ** 2).sum(-1))
    return labels


def _cluster_means(X, labels, C):
    """Every run's cluster means (labels (runs, n), centres C (runs, K, dim)), the rows of a
    cluster summed in order as X[labels == k].mean(0) sums them; an empty cluster keeps its
    centre."""
    runs, K, dim = C.shape
    keys = (np.arange(runs)[:, None] * K + labels).ravel()
    order = np.argsort(keys, kind='stable')
    counts = np.bincount(keys, minlength=runs * K)
    present = np.flatnonzero(counts)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])[present]
    out = C.reshape(runs * K, dim).copy()
    out[present] = (np.add.reduceat(X[order % len(X)], starts, axis=0)
                    / counts[present, None])
    return out.reshape(runs, K, dim)
