"""The space patterns are told apart in, whatever pace each person kept.

A demonstration's ProMP weights describe its path at its own linear phase z = t / T. People
hold and hurry within a movement, so two demonstrations of one interaction reach the same
places at different phases, and a distance taken at equal phases (the path metric, the mean
squared distance over z) sees a change of pace as a change of shape: on NuiSI with the pace
changed within each movement it outweighs the difference between interactions, and discovery
merges some and splits others. The thesis's own remedy, each demonstration's warp of the phase
(eq. 34), has to be learned against a template, which is what discovery has yet to find: a
common template warps different interactions towards one another, one per component needs the
partition first.

The distance here is dynamic time warping between the two demonstrations' paths, each read
from its weights on :data:`N_POINTS` phases (both agents on one alignment: an interaction's
two people share its phase; a translation group's common offset removed first, as
core.patterns.without_offsets defines it; each agent scaled to unit total variance, so that
an agent weighs the same whatever number of DOFs describes it). The alignment runs from the
shared start to the shared end (onset and end are known, so only the pace between them is
forgiven) and pairs no two phases more than :data:`BAND` of the movement apart, so the
distance is symmetric, needs no template and is the path metric where the paces agree.

The demonstrations then get coordinates whose Euclidean distances are these (classical
multidimensional scaling, Torgerson 1952: the principal components of the paths where no warp
is needed), the leading ones that hold ``variance`` of the spread, where core.patterns' mixture
of t distributions finds the patterns and their number.

Why a band: a person who holds or hurries moves a sample by a fraction of the movement, while
an unconstrained alignment can shift anything, by letting a stretch where nothing moves (a
rest before the movement, a hold) absorb the shift. When a movement starts within its
recording, or how long a person rests in it, can be what tells two patterns apart (who made a
gesture, in PickupGestureWiimoteZ, where the unconstrained alignment found 2 patterns among
ten people). The band is about as wide as the strongest change of pace the package is tested
to forgive shifts two recordings against each other (test_pattern_space: log pace std 0.6
within each movement, twice the robustness bench's; two recordings paced independently are
17 % of the movement apart at the median, 31-34 % at the 90th percentile). It is not set by
the gestures: a band of 10 % tells their people apart better still, and fails that test.

The mixture's EM (core.mixture) then starts from these patterns and learns each component at
the linear phase, as the online estimator reads it.
"""

import numpy as np

from .basis import GaussianBasis
from .patterns import VARIANCE_KEPT, without_offsets

# Phases each path is read at: finer than any basis the package fits (up to 20-30 functions
# over the phase), coarse enough for n^2 alignments of 50 x 50 cells.
N_POINTS = 50
# The largest shift of a phase the alignment forgives, as a share of the movement (the module
# docstring says why there is one): at 50 points, 14 of the 49 steps.
BAND = 0.3


def sampled_paths(W, n_basis: int, n_points: int = N_POINTS) -> np.ndarray:
    """Every DOF's path psi(z)^T w at ``n_points`` phases evenly over [0, 1]: (n, n_points, D)
    of stacked weights W (n, D * n_basis)."""
    W = np.asarray(W, dtype=float)
    n, d = W.shape
    if d % n_basis:
        raise ValueError(f'{d} weights are not a whole number of DOFs of {n_basis} basis functions')
    psi = GaussianBasis(n_basis)(np.linspace(0.0, 1.0, n_points))       # (n_points, N)
    return np.einsum('zb,idb->izd', psi, W.reshape(n, d // n_basis, n_basis))


def warped_distances(paths, band: float = BAND) -> np.ndarray:
    """(n, n) dynamic time warping distances between paths (n, n_points, D): the least root
    mean squared distance over monotone alignments of the two from shared start to shared end
    that pair no two points more than ``band`` of the path apart (a Sakoe-Chiba band: a
    largest shift of floor(band (n_points - 1)) steps; 1: unconstrained), the sum of squared
    differences along the alignment divided by ``n_points`` (so that it is the root mean
    squared distance at equal phases where no warp is needed). dtaidistance's C
    implementation."""
    from dtaidistance import dtw_ndim
    if not 0 <= band <= 1:
        raise ValueError(f'band must be in [0, 1], got {band!r}')
    series = [np.ascontiguousarray(p, dtype=np.double) for p in paths]
    # dtaidistance's window w admits pairs of points less than w apart.
    window = int(np.floor(band * (paths.shape[1] - 1) + 1e-9)) + 1
    d = np.asarray(dtw_ndim.distance_matrix_fast(series, window=window, parallel=False,
                                                 only_triu=False), dtype=float)
    np.fill_diagonal(d, 0.0)
    return d / np.sqrt(paths.shape[1])


def embedded(distances, variance: float = VARIANCE_KEPT, min_components: int = 1):
    """(coordinates (n, q), the share of the spread each holds (q,)): classical multidimensional
    scaling of ``distances`` (n, n), the leading q components that hold ``variance`` of the
    spread (at least ``min_components``, at most n - 1 and the positive eigenvalues). A warped
    distance need not be Euclidean; the negative eigenvalues it leaves are dropped, and the
    spread is that of the positive ones. Each coordinate's sign is fixed (its largest entry
    positive), so that a LAPACK's choice of sign does not move them (a repeated eigenvalue
    leaves its coordinates a rotation to choose, which the mixture does not see)."""
    d2 = np.asarray(distances, dtype=float) ** 2
    n = len(d2)
    centred = d2 - d2.mean(axis=0) - d2.mean(axis=1)[:, None] + d2.mean()
    values, vectors = np.linalg.eigh(-0.5 * centred)
    values, vectors = values[::-1], vectors[:, ::-1]
    positive = values > 1e-12 * max(values[0], 1e-300)
    values, vectors = values[positive], vectors[:, positive]
    if not len(values):
        return np.zeros((n, 1)), np.ones(1)
    ratio = values / values.sum()
    q = int(np.searchsorted(np.cumsum(ratio), variance - 1e-12) + 1)
    q = max(1, min(max(q, min_components), n - 1, len(values)))
    vectors = vectors[:, :q]
    signs = np.sign(vectors[np.argmax(np.abs(vectors), axis=0), np.arange(q)])
    return vectors * signs * np.sqrt(values[:q]), ratio[:q]


class PatternSpace:
    """The coordinates patterns are told apart in (see the module docstring).

    ``n_observed``: DOFs of the observed agent (the first ``n_observed`` weight blocks), the
    rest are the controlled agent's. ``min_components``: at least this many coordinates (K
    patterns need K - 1 directions between their means, which need not hold 10 % of the spread
    when two patterns are close). ``translation``: groups of DOFs whose common offset is no
    part of a pattern (core.patterns.translation_for). Fitted attributes: ``scale_`` (D,) per
    DOF (one value per agent), ``distances_`` (n, n) the warped distances,
    ``explained_variance_ratio_`` (q,).
    """

    def __init__(self, n_basis: int, n_observed: int, variance: float = VARIANCE_KEPT,
                 min_components: int = 1, translation=()):
        self.n_basis = n_basis
        self.n_observed = n_observed
        self.variance = variance
        self.min_components = min_components
        self.translation = translation

    def fit_transform(self, W) -> np.ndarray:
        """(n, q) coordinates of the demonstrations with weights W (n, D N)."""
        if not np.all(np.isfinite(W)):
            raise ValueError('the weights of every demonstration must be finite')
        if not 0 < self.variance <= 1:
            raise ValueError(f'variance must be in (0, 1], got {self.variance!r}')
        paths = sampled_paths(without_offsets(W, self.n_basis, self.translation), self.n_basis)
        n, _, D = paths.shape
        if not 0 < self.n_observed <= D:
            raise ValueError(f'n_observed must be in 1..{D}, got {self.n_observed!r}')
        if n < 2:
            raise ValueError(f'a pattern space needs at least 2 demonstrations, got {n}')
        dof_var = paths.var(axis=0).mean(axis=0)         # over demonstrations, mean over z
        scale = np.empty(D)
        for agent in (slice(0, self.n_observed), slice(self.n_observed, D)):
            scale[agent] = np.sqrt(max(dof_var[agent].sum(), 1e-300))
        self.scale_ = scale
        self.distances_ = warped_distances(paths / scale)
        X, self.explained_variance_ratio_ = embedded(self.distances_, self.variance,
                                                     self.min_components)
        return X
