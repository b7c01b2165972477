"""The core layer's fast paths against the plain code they replace: SIMD lanes and the
lane-group layout (the estimator's results against batch conditioning: test_core_online)."""

import numba
import numpy as np

from mixture_ip_ros.core._fast import (LANES, compact_lanes, from_lanes, to_lanes, tri_index,
                                       vload, vsplat, vsqrt, vstore)


@numba.njit(fastmath={'contract'})
def _lane_expression(a, b, out, i):
    x, y = vload(a, i), vload(b, 0)
    vstore(out, 0, (x * y + vsplat(2.0)) / vsqrt(y) - x)


def test_lane_operations_match_numpy_at_any_offset():
    rng = np.random.default_rng(0)
    a, b = rng.uniform(-3, 3, 3 * LANES), rng.uniform(0.5, 4, LANES)
    for i in (0, 3, 2 * LANES):
        out = np.full(LANES, np.nan)
        _lane_expression(a, b, out, i)
        x = a[i:i + LANES]
        np.testing.assert_allclose(out, (x * b + 2.0) / np.sqrt(b) - x, rtol=1e-15, atol=1e-15)


def test_lane_groups_round_trip_and_pack_the_lower_triangle():
    rng = np.random.default_rng(1)
    columns = rng.standard_normal((3 * LANES, 5))
    groups = to_lanes(columns)
    assert groups.shape == (3, 5 * LANES)
    assert groups[1, 2 * LANES + 3] == columns[LANES + 3, 2]          # entry 2 of column LANES + 3
    np.testing.assert_array_equal(from_lanes(groups), columns)
    d = 4
    i, j = np.tril_indices(d)
    sym = rng.standard_normal((d, d))
    sym = sym + sym.T
    np.testing.assert_array_equal(sym[i, j][tri_index(d)], sym)


def test_compact_lanes_moves_the_kept_columns_to_the_front_in_order():
    rng = np.random.default_rng(2)
    columns = rng.standard_normal((4 * LANES, 7))
    keep = rng.random(4 * LANES) < 0.4
    keep[[0, 5, 4 * LANES - 1]] = [False, True, True]
    groups = to_lanes(columns)
    src = np.flatnonzero(keep)
    compact_lanes(groups, src)
    out = from_lanes(groups)
    np.testing.assert_array_equal(out[:len(src)], columns[src])
    np.testing.assert_array_equal(out[len(src):], columns[len(src):])   # left as they were



def test_expected_trajectory_is_the_speed_weighted_sum_of_the_plain_trajectories():
    """expected_trajectory against interaction.trajectory_distribution's means, one per speed
    hypothesis, weighted and summed; before, inside and after [0, 1] (held there); and its
    positions alone, without the derivatives, the same."""
    from mixture_ip_ros.core._fast import expected_trajectory
    from mixture_ip_ros.core.basis import GaussianBasis
    from mixture_ip_ros.core.interaction import trajectory_distribution
    rng = np.random.default_rng(3)
    basis = GaussianBasis(9)
    M, n = 4, 3
    weights = rng.standard_normal((M, n, basis.n_basis))
    alphas, probs = rng.uniform(0.2, 1.5, M), rng.dirichlet(np.ones(M))
    times = np.linspace(-0.2, 4.0, 57)
    pos, vel, acc = expected_trajectory(weights, alphas, alphas, probs, times, basis.centers,
                                        basis.width, True)
    ref = [np.zeros((len(times), n)) for _ in range(3)]
    for w, a, p in zip(weights, alphas, probs):
        d = trajectory_distribution(w.ravel(), None, basis, a * times, a)
        for r, key in zip(ref, ('position', 'velocity', 'acceleration')):
            r += p * d[key]
    for got, want in zip((pos, vel, acc), ref):
        assert np.allclose(got, want, rtol=1e-10, atol=1e-12 * np.abs(want).max())
    only, none_v, none_a = expected_trajectory(weights, alphas, alphas, probs, times,
                                               basis.centers, basis.width, False)
    assert np.array_equal(only, pos) and none_v.shape == none_a.shape == (0, n)
    # one path at given phases
    from mixture_ip_ros.core._fast import mean_trajectory
    z = np.linspace(-0.3, 1.3, 41)
    d = trajectory_distribution(weights[0].ravel(), None, basis, z, alphas[0])
    for got, key in zip(mean_trajectory(weights[0], z, basis.centers, basis.width, alphas[0]),
                        ('position', 'velocity', 'acceleration')):
        assert np.allclose(got, d[key], rtol=1e-10, atol=1e-12 * np.abs(d[key]).max())
