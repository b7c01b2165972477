"""Baselines, each made as strong as a careful user would make it and run on the same split in
the same run as the mixture: a per-class ProMP, scikit-learn's clustering and mixtures, and
nearest neighbours by dynamic time warping."""

from __future__ import annotations

import numpy as np

from mixture_ip_ros.app.evaluation.common import prefix_length
from mixture_ip_ros.core.named import majority_names
from mixture_ip_ros.core.basis import GaussianBasis
from mixture_ip_ros.core.crossval import cv_folds
from mixture_ip_ros.core.phase import log_evidence_batch
from mixture_ip_ros.core.playback import absorbed_rows, observed_rows
from mixture_ip_ros.core.promp import expected_sq_residual, observation_stats, ridge_weights

# Ridges tried on a class's weight covariance, as fractions of the mean weight variance.
SHRINKAGES = (1e-4, 1e-3, 1e-2, 1e-1, 1.0)


class PerClassProMP:
    """One ProMP per class: ridge weights (eq. 14), each class's weight covariance its sample
    covariance plus a ridge, one observation noise variance per DOF shared by the classes
    (pooled residuals); a prefix is scored by eq. 18 with the phase known (z = t / T). The ridge
    (a fraction of the mean weight variance, :data:`SHRINKAGES`) is chosen by 5-fold
    cross-validation on the training set: the best accuracy over ``fractions`` (ties: the
    larger ridge)."""

    def __init__(self, n_basis: int = 15, ridge: float = 1e-6, shrinkage=None,
                 fractions=(0.3, 0.5, 0.7, 1.0)):
        self.n_basis = n_basis
        self.ridge = ridge
        self.shrinkage = shrinkage
        self.fractions = fractions

    def fit(self, demos, labels):
        labels = np.asarray(labels)
        if self.shrinkage is None:
            fold = cv_folds(len(demos), 5, 0)
            scores = []
            for s in SHRINKAGES:
                right = []
                for f in range(fold.max() + 1):
                    train = [d for d, g in zip(demos, fold) if g != f]
                    model = PerClassProMP(self.n_basis, self.ridge, s).fit(train,
                                                                          labels[fold != f])
                    right += [model.predict_prefix(d, fr) == y for d, y in
                              zip([d for d, g in zip(demos, fold) if g == f], labels[fold == f])
                              for fr in self.fractions]
                scores.append(np.mean(right))
            best = max(range(len(SHRINKAGES)), key=lambda i: (scores[i], i))
            self.shrinkage_ = SHRINKAGES[best]
        else:
            self.shrinkage_ = self.shrinkage
        self.basis_ = GaussianBasis(self.n_basis)
        stats = [observation_stats(self.basis_, d.phase, d.observed) for d in demos]
        W = np.array([ridge_weights(self.basis_, d.phase, d.observed, self.ridge) for d in demos])
        zero = np.zeros((W.shape[1], W.shape[1]))
        sq = sum(expected_sq_residual(st, w, zero) for st, w in zip(stats, W))
        self.noise_var_ = sq / sum(st.m for st in stats)
        self.classes_ = sorted(set(labels.tolist()))
        ridge = self.shrinkage_ * float(np.mean(W.var(axis=0))) * np.eye(W.shape[1])
        self.means_ = np.array([W[labels == c].mean(axis=0) for c in self.classes_])
        self.covariances_ = np.array([
            (np.cov(W[labels == c], rowvar=False) if np.sum(labels == c) > 1 else zero) + ridge
            for c in self.classes_])
        return self

    def predict_prefix(self, demo, fraction):
        rows = observed_rows(demo)
        rows = rows[rows < prefix_length(demo, fraction)]
        t, Y = demo.t[rows], demo.observed[rows]
        ll = [log_evidence_batch(m, C, self.basis_, t, Y, 1.0 / demo.duration, self.noise_var_)
              for m, C in zip(self.means_, self.covariances_)]
        return self.classes_[int(np.argmax(ll))]


def sklearn_gmm_accuracy(W_train, labels_train, W_test, labels_test, n_components, seeds):
    """scikit-learn's GaussianMixture (full covariances) on weight vectors with the given K, the
    best of ``seeds`` by training likelihood, components named by majority over the training
    labels. Returns (accuracy, the chosen seed)."""
    from sklearn.mixture import GaussianMixture
    fits = [GaussianMixture(n_components, covariance_type='full', random_state=int(s)).fit(W_train)
            for s in seeds]
    scores = [g.score(W_train) for g in fits]
    best = int(np.argmax(scores))
    g = fits[best]
    names = majority_names(g.predict(W_train), labels_train, n_components)
    pred = [names[k] for k in g.predict(W_test)]
    return float(np.mean(np.asarray(pred) == np.asarray(labels_test))), int(seeds[best])


def dtw_1nn_accuracy(train_series, labels_train, test_series, labels_test):
    """1-nearest-neighbour by dynamic time warping (dtaidistance, unconstrained window, squared
    differences) on the whole series."""
    from dtaidistance import dtw
    tr = [np.ascontiguousarray(s, dtype=np.double) for s in train_series]
    pred = []
    for s in test_series:
        s = np.ascontiguousarray(s, dtype=np.double)
        d = [dtw.distance_fast(s, x) for x in tr]
        pred.append(labels_train[int(np.argmin(d))])
    return float(np.mean(np.asarray(pred) == np.asarray(labels_test)))


def resampled_paths(demos, n_points: int = 50) -> np.ndarray:
    """Both agents' paths over the phase resampled to ``n_points`` each (missing samples
    interpolated over), stacked: (n, n_points * DOFs), the representation k-means gets."""
    z = np.linspace(0.0, 1.0, n_points)
    out = []
    for d in demos:
        Y = np.hstack([d.observed, d.controlled])
        ok = ~np.isnan(Y).any(axis=1)
        out.append(np.concatenate([np.interp(z, d.phase[ok], Y[ok, j])
                                   for j in range(Y.shape[1])]))
    return np.array(out)


def clustering_baselines(demos, labels, n_clusters: int, seeds=range(5), n_pca: int = 8):
    """The adjusted Rand index against ``labels`` of scikit-learn's k-means and of its
    GaussianMixture (full covariances) on ``n_pca`` principal components, both with the true
    number of clusters on the paths of both agents resampled (:func:`resampled_paths`), each
    the mean over ``seeds``: {'kmeans': ..., 'gmm_pca': ...}."""
    from sklearn.cluster import KMeans
    from sklearn.decomposition import PCA
    from sklearn.metrics import adjusted_rand_score
    from sklearn.mixture import GaussianMixture
    X = resampled_paths(demos)
    P = PCA(min(n_pca, len(X) - 1), random_state=0).fit_transform(X)
    km = [adjusted_rand_score(labels, KMeans(n_clusters, n_init=10, random_state=s)
                              .fit_predict(X)) for s in seeds]
    gm = [adjusted_rand_score(labels, GaussianMixture(n_clusters, n_init=5, random_state=s)
                              .fit(P).predict(P)) for s in seeds]
    return {'kmeans': float(np.mean(km)), 'gmm_pca': float(np.mean(gm))}


class NearestNeighbour:
    """The nearest training recording by open-end DTW on the observed agent's prefix (phase
    unknown: the prefix is matched against the beginning of each training recording, however
    fast it went; dtaidistance, squared differences); its label names the pattern, and its
    controlled agent, time-scaled by the match (the training time where the prefix ended over
    the prefix's own duration), is the prediction of the rest. Series are taken at the
    estimator's rate (``min_interval``), the samples the mixture sees.

    ``translation``: the mixture's translation groups (core.patterns.translation_groups;
    indices into the stacked [observed, controlled] DOFs), given where the model is told that
    where the interaction happened is not part of it. The baseline then gets the same
    knowledge: the observed DOFs of a group are compared by their velocities (derivative DTW,
    Keogh and Pazzani 2001; backward differences per second, so that a prefix uses its own
    samples and dropped frames do not count as stops), and the partner predicted is
    the match's moved by the difference of the two observed prefixes' mean positions (the
    prefix against the part of the training recording it was matched with)."""

    def __init__(self, min_interval: float = 0.05, translation=()):
        self.min_interval = min_interval
        self.translation = translation

    def _series(self, demo):
        rows = absorbed_rows(demo, self.min_interval)
        t, Y = demo.t[rows], np.array(demo.observed[rows], dtype=np.double)
        moved = self._moved_observed
        if moved:
            # Velocities from each sample and the one before (a prefix's own samples only, as
            # online), per second (stamps jitter and frames drop); the first takes the second's.
            X = Y[:, moved]
            V = np.zeros_like(X)
            V[1:] = np.diff(X, axis=0) / np.diff(t)[:, None]
            V[0] = V[1] if len(V) > 1 else 0.0
            Y[:, moved] = V
        return t, np.ascontiguousarray(Y), demo.observed[rows]

    def fit(self, demos, labels):
        from mixture_ip_ros.core.patterns import translation_groups
        self.demos_ = list(demos)
        self.labels_ = list(labels)
        P, Q = self.demos_[0].n_observed_dofs, self.demos_[0].n_controlled_dofs
        groups = translation_groups(self.translation, P + Q)
        self._moved_observed = [j for g in groups for j in g if j < P]
        # Each controlled DOF a group moves, with the observed DOFs of its group (a group with
        # none of them: nothing observed says where it went).
        self._moves_with = {j - P: [i for i in g if i < P] for g in groups for j in g
                            if j >= P and any(i < P for i in g)}
        self._train = [self._series(d) for d in self.demos_]
        return self

    def matches(self, demo, fractions):
        """Per fraction, (index of the nearest training recording, time scale, how far the
        controlled agent is moved (Q,))."""
        from dtaidistance import dtw_ndim
        t, Y, raw = self._series(demo)
        ends = [max(1, int(np.searchsorted(t, f * demo.duration + 1e-9, side='right')))
                for f in fractions]
        best = [None] * len(fractions)
        for i, (t_tr, Y_tr, _) in enumerate(self._train):
            # One accumulated-cost matrix gives every prefix's open-end distance: its row.
            _, paths = dtw_ndim.warping_paths_fast(Y, Y_tr)
            for c, n in enumerate(ends):
                row = paths[n, 1:]
                j = int(np.argmin(row))
                if best[c] is None or row[j] < best[c][0]:
                    best[c] = (row[j], i, j, t_tr[j] / t[n - 1] if t[n - 1] > 0 else 1.0)
        out = []
        for (_, i, j, scale), n in zip(best, ends):
            shift = np.zeros(demo.n_controlled_dofs)
            for q, obs in self._moves_with.items():
                shift[q] = np.mean(raw[:n, obs]) - np.mean(self._train[i][2][:j + 1, obs])
            out.append((i, scale, shift))
        return out

    def predict(self, index, scale, times, shift=None):
        """The label of training recording ``index`` and its controlled agent at ``times`` (s
        since onset) time-scaled by ``scale`` and moved by ``shift`` (Q,), (len, Q); Q = 0 for
        a single-agent recording, whose label is still the prediction."""
        d = self.demos_[index]
        keep = ~np.isnan(d.controlled).any(axis=1)
        s = np.clip(np.asarray(times, dtype=float) * scale, 0.0, d.t[keep][-1])
        pred = np.empty((s.size, d.n_controlled_dofs))
        for j in range(d.n_controlled_dofs):
            pred[:, j] = np.interp(s, d.t[keep], d.controlled[keep, j])
        return self.labels_[index], pred if shift is None else pred + shift
