"""The space patterns are told apart in (core.pattern_space): the warped distance against the
dynamic programme written out, the embedding against principal components where distances
are Euclidean, and patterns that a change of pace within each movement no longer hides."""

import numpy as np
import pytest

from mixture_ip_ros.core.basis import GaussianBasis
from mixture_ip_ros.core.demonstration import Demonstration
from mixture_ip_ros.core.mixture import MixtureIProMP
from mixture_ip_ros.core.pattern_space import (BAND, PatternSpace, embedded, sampled_paths,
                                               warped_distances)
from mixture_ip_ros.core.patterns import PatternMixture, adjusted_rand_index
from mixture_ip_ros.scenarios.corruption import retimed


def _dtw(a, b, shift):
    """The recursion of dynamic time warping, cell by cell: squared differences summed along
    the cheapest monotone alignment from (0, 0) to (n - 1, m - 1) that pairs no points more
    than ``shift`` apart."""
    n, m = len(a), len(b)
    cost = np.full((n + 1, m + 1), np.inf)
    cost[0, 0] = 0.0
    for i in range(1, n + 1):
        for j in range(max(1, i - shift), min(m, i + shift) + 1):
            cost[i, j] = np.sum((a[i - 1] - b[j - 1]) ** 2) + min(
                cost[i - 1, j], cost[i, j - 1], cost[i - 1, j - 1])
    return np.sqrt(cost[n, m])


def test_the_warped_distance_is_the_dynamic_programme_per_point():
    """Within the band (30 % of 21 points: 6 steps), unconstrained (band 1) and at equal phases
    (band 0), against the recursion written out."""
    rng = np.random.default_rng(0)
    paths = rng.normal(size=(5, 21, 2))
    equal = np.sqrt(((paths[:, None] - paths[None]) ** 2).sum(axis=(2, 3)) / 21)
    for band, shift in ((BAND, 6), (1.0, 20), (0.0, 0)):
        d = warped_distances(paths, band)
        oracle = np.array([[_dtw(a, b, shift) for b in paths] for a in paths]) / np.sqrt(21)
        assert np.allclose(d, oracle, atol=1e-12)
        assert np.allclose(d, d.T) and np.all(np.diag(d) == 0)
        # never above the distance at equal phases, which it is where no warp helps
        assert np.all(d <= equal + 1e-12)
    assert np.allclose(warped_distances(paths, 0.0), equal, atol=1e-12)
    # a bump 6 of the 20 steps late: forgiven within the band, not one step narrower
    z = np.arange(21.0)
    bumps = np.stack([np.exp(-((z - c) / 1.5) ** 2)[:, None] for c in (5.0, 11.0)])
    assert warped_distances(bumps)[0, 1] == pytest.approx(_dtw(*bumps, 6) / np.sqrt(21))
    assert warped_distances(bumps)[0, 1] < 0.5 * _dtw(*bumps, 5) / np.sqrt(21)
    assert np.all(warped_distances(paths, 1.0) <= warped_distances(paths) + 1e-12)
    with pytest.raises(ValueError, match='band'):
        warped_distances(paths, 1.5)
    # two paths that hold still half a unit apart: no alignment helps
    still = np.zeros((9, 2))
    assert warped_distances(np.stack([still, still + [0.5, 0.0]]))[0, 1] == pytest.approx(0.5)


def test_the_paths_are_read_from_the_weights_at_evenly_spaced_phases():
    rng = np.random.default_rng(1)
    N = 6
    W = rng.normal(size=(3, 2 * N))
    P = sampled_paths(W, N, 11)
    psi = GaussianBasis(N)(np.linspace(0, 1, 11))
    assert np.allclose(P[1, :, 1], psi @ W[1, N:])
    with pytest.raises(ValueError, match='whole number of DOFs'):
        sampled_paths(W[:, :-1], N)


def test_euclidean_distances_embed_as_their_principal_components():
    """Classical scaling of Euclidean distances: the coordinates reproduce every distance and
    are the principal component scores (up to each one's sign); the share of the spread is the
    components' explained variance."""
    from sklearn.decomposition import PCA
    rng = np.random.default_rng(2)
    X = rng.normal(size=(30, 4)) * [5.0, 2.0, 1.0, 0.2]
    d = np.sqrt(((X[:, None] - X[None]) ** 2).sum(axis=2))
    Y, ratio = embedded(d, variance=1.0)
    assert Y.shape == (30, 4)
    assert np.allclose(np.sqrt(((Y[:, None] - Y[None]) ** 2).sum(axis=2)), d, atol=1e-9)
    pca = PCA(4).fit(X)
    assert np.allclose(np.abs(Y), np.abs(pca.transform(X)), atol=1e-9)
    assert np.allclose(ratio, pca.explained_variance_ratio_)
    Y90, ratio90 = embedded(d, variance=0.9)
    assert ratio90.sum() >= 0.9 and ratio90[:-1].sum() < 0.9
    assert embedded(d, variance=0.1, min_components=3)[0].shape == (30, 3)
    # the same distances in another order: the same coordinates, row for row (signs fixed)
    order = rng.permutation(30)
    assert np.allclose(embedded(d[np.ix_(order, order)], 1.0)[0], Y[order], atol=1e-9)


def _shapes(rng, n_each=10, n_samples=120):
    """Two interactions of one DOF per person that differ in shape only: a bump, and a bump
    that comes back down half-way (the partner mirrors the person); durations 1.5-2.5 s."""
    demos, labels = [], []
    for k in range(2):
        for _ in range(n_each):
            T = rng.uniform(1.5, 2.5)
            t = np.linspace(0, T, n_samples)
            z = t / T
            y = np.sin(np.pi * z) if k == 0 else np.sin(np.pi * z) * (1 - 0.6 * np.exp(
                -((z - 0.5) / 0.12) ** 2))
            y = y * rng.uniform(0.9, 1.1) + rng.normal(0, 0.01, n_samples)
            demos.append(Demonstration(t, y[:, None], -y[:, None], k))
            labels.append(k)
    return demos, labels


def test_a_change_of_pace_within_each_movement_does_not_hide_the_patterns():
    """Each recording restamped by a smooth monotone warp (the robustness bench's pace model,
    stronger): the partition at equal phases falls apart, the warped one is the interactions,
    and each recording, its pace changed, lands near where it lands at one pace, nearest the
    mean of its own interaction's recordings at one pace."""
    rng = np.random.default_rng(3)
    demos, labels = _shapes(rng)
    paced = retimed(demos, np.random.default_rng(4), std=0.6, correlation=0.2)
    model = MixtureIProMP(1, n_basis=15)
    W0 = model.prepare(demos).W
    W = model.prepare(paced).W
    X = PatternSpace(15, 1).fit_transform(W)
    found = PatternMixture(2, n_init=10, random_state=0).fit(X).predict(X)
    assert adjusted_rand_index(found, labels) == 1.0
    # at equal phases (the paths' own Euclidean distances) the pace outweighs the shape
    P = sampled_paths(W, 15).reshape(len(W), -1)
    equal = np.sqrt(((P[:, None] - P[None]) ** 2).sum(axis=2))
    Xe = embedded(equal)[0]
    assert adjusted_rand_index(PatternMixture(2, n_init=10, random_state=0).fit(Xe).predict(Xe),
                               labels) < 0.9
    both = PatternSpace(15, 1).fit_transform(np.vstack([W0, W]))
    moved = np.linalg.norm(both[:20] - both[20:], axis=1)
    means = np.array([both[:10].mean(axis=0), both[10:20].mean(axis=0)])
    # the band forgives most of a pace this strong, not all of it (core.pattern_space.BAND)
    assert np.median(moved) < 0.25 * np.linalg.norm(means[0] - means[1])
    nearest = np.argmin(np.linalg.norm(both[20:, None] - means[None], axis=2), axis=1)
    assert np.array_equal(nearest, labels)


def test_when_a_movement_starts_in_its_recording_can_tell_patterns_apart():
    """One movement, two groups of people: one starts it 10 % into the recording, the other
    55 % in, after resting (as PickupGestureWiimoteZ's people differ). An unconstrained
    alignment lets the rest absorb the wait and finds one pattern; the band keeps the two."""
    rng = np.random.default_rng(6)
    demos, labels = [], []
    for k, start in enumerate((0.1, 0.55)):
        for _ in range(10):
            t = np.linspace(0.0, 2.0, 150)
            s = np.clip((t / 2.0 - start - rng.normal(0, 0.02)) / 0.35, 0.0, 1.0)
            y = np.sin(np.pi * s) * rng.uniform(0.9, 1.1) + rng.normal(0, 0.01, len(t))
            demos.append(Demonstration(t, y[:, None], np.zeros((len(t), 0)), k))
            labels.append(k)
    W = MixtureIProMP(1, n_basis=15).prepare(demos).W
    paths = sampled_paths(W, 15)

    def found(band):
        X = embedded(warped_distances(paths, band))[0]
        return adjusted_rand_index(PatternMixture(2, n_init=10, random_state=0).fit(X)
                                   .predict(X), labels)
    assert found(BAND) == 1.0
    assert found(1.0) < 0.5          # unconstrained, the wait is forgiven
    banded = warped_distances(paths)
    assert banded[:10, 10:].min() > 3 * max(banded[:10, :10].max(), banded[10:, 10:].max())


def test_each_agent_weighs_the_same_and_bad_settings_are_refused():
    rng = np.random.default_rng(5)
    N = 6
    W = np.hstack([rng.normal(size=(20, 2 * N)), 100 * rng.normal(size=(20, 3 * N))])
    space = PatternSpace(N, n_observed=2)
    space.fit_transform(W)
    assert np.allclose(space.scale_[:2], space.scale_[0])
    assert space.scale_[2] > 50 * space.scale_[0]
    P = sampled_paths(W, N) / space.scale_
    assert np.allclose([P[:, :, :2].var(axis=0).mean(axis=0).sum(),
                        P[:, :, 2:].var(axis=0).mean(axis=0).sum()], 1.0)
    with pytest.raises(ValueError, match='variance'):
        PatternSpace(N, 2, variance=0).fit_transform(W)
    with pytest.raises(ValueError, match='n_observed'):
        PatternSpace(N, 6).fit_transform(W)
    with pytest.raises(ValueError, match='finite'):
        PatternSpace(N, 2).fit_transform(np.where(np.eye(20, 5 * N) > 0, np.nan, W))
    with pytest.raises(ValueError, match='at least 2'):
        PatternSpace(N, 2).fit_transform(W[:1])
