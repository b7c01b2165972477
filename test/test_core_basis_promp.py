"""Basis, ridge regression (eq. 14), ProMP EM (eqs. 21-30) against independent oracles."""

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from mixture_ip_ros.core.basis import GaussianBasis
from mixture_ip_ros.core.promp import (ObservationStats, ProMP, cho_inverse, log_evidence,
                                       observation_stats, ridge_weights, stack_stats,
                                       weight_posterior)
from scipy import linalg

from mixture_ip_ros.scenarios.synthetic import random_spd, sample_trajectory


def test_basis_is_normalized_and_derivatives_match_finite_differences():
    b = GaussianBasis(12)
    z = np.linspace(0.02, 0.98, 50)
    psi, dpsi, ddpsi = b.evaluate(z)
    assert np.allclose(psi.sum(axis=1), 1.0)
    h = 1e-5
    assert np.allclose(dpsi, (b(z + h) - b(z - h)) / (2 * h), atol=1e-5)
    assert np.allclose(ddpsi, (b.evaluate(z + h, 1)[1] - b.evaluate(z - h, 1)[1]) / (2 * h),
                       atol=1e-3)


def test_basis_clamps_outside_the_movement():
    b = GaussianBasis(10)
    psi, dpsi, ddpsi = b.evaluate([1.0, 1.3, -0.2, 0.0])
    assert np.allclose(psi[1], psi[0]) and np.allclose(psi[2], psi[3])
    assert np.all(dpsi[[1, 2]] == 0) and np.all(ddpsi[[1, 2]] == 0)


@pytest.mark.parametrize('bad', [0, 1, 2.5])
def test_basis_rejects_bad_sizes(bad):
    with pytest.raises(ValueError, match='n_basis'):
        GaussianBasis(bad)


def test_ridge_weights_match_least_squares_per_dof():
    rng = np.random.default_rng(1)
    b = GaussianBasis(10)
    z = np.sort(rng.uniform(0, 1, 200))
    Y = rng.standard_normal((200, 3))
    Y[5:9] = np.nan
    w = ridge_weights(b, z, Y, ridge=0.0)
    ok = ~np.isnan(Y[:, 0])
    for j in range(3):
        ref = np.linalg.lstsq(b(z[ok]), Y[ok, j], rcond=None)[0]
        assert np.allclose(w[j * 10:(j + 1) * 10], ref, atol=1e-8)


def test_marginal_likelihood_matches_dense_gaussian():
    """eq. 21 through the sufficient statistics vs. the dense N(A mu, R + A Sigma A^T)."""
    rng = np.random.default_rng(2)
    b = GaussianBasis(6)
    D, N = 2, 6
    mean = rng.standard_normal(D * N)
    cov = random_spd(rng, D * N)
    noise = np.array([0.05, 0.2])
    z = np.sort(rng.uniform(0, 1, 30))
    Y = rng.standard_normal((30, D))
    Y[3:7, 1] = np.nan
    post_mean, post_cov, ll = weight_posterior(observation_stats(b, z, Y), mean,
                                               linalg.cho_factor(cov, lower=True), noise)
    rows = [(j, t) for j in range(D) for t in range(30) if not np.isnan(Y[t, j])]
    A = np.zeros((len(rows), D * N))
    for r, (j, t) in enumerate(rows):
        A[r, j * N:(j + 1) * N] = b(z[t:t + 1])[0]
    y = np.array([Y[t, j] for j, t in rows])
    R = np.diag([noise[j] for j, _ in rows])
    S = R + A @ cov @ A.T
    assert ll == pytest.approx(multivariate_normal(A @ mean, S).logpdf(y), rel=1e-10)
    K = cov @ A.T @ np.linalg.inv(S)
    assert np.allclose(post_mean, mean + K @ (y - A @ mean), atol=1e-8)
    assert np.allclose(post_cov, cov - K @ A @ cov, atol=1e-8)


def test_observation_stats_are_the_per_dof_sums_over_observed_samples():
    rng = np.random.default_rng(3)
    b = GaussianBasis(5)
    z = np.sort(rng.uniform(0, 1, 40))
    Y = rng.standard_normal((40, 4))
    Y[5:12, :2] = np.nan                # two DOFs missing together, one alone, one complete
    Y[20:23, 2] = np.nan
    st = observation_stats(b, z, Y)
    for j in range(4):
        rows = ~np.isnan(Y[:, j])
        A = b(z[rows])
        assert np.allclose(st.G[j], A.T @ A, rtol=1e-13, atol=1e-15)
        assert np.allclose(st.b[j], A.T @ Y[rows, j], rtol=1e-13, atol=1e-15)
        assert st.yy[j] == pytest.approx(Y[rows, j] @ Y[rows, j], rel=1e-13)
        assert st.m[j] == rows.sum()


def test_batched_log_evidence_is_the_marginal_likelihood_of_every_trajectory():
    """promp.log_evidence (one bordered Cholesky per trajectory) vs weight_posterior's eq. 21,
    with missing samples, per-DOF noise and trajectories of different lengths."""
    rng = np.random.default_rng(4)
    b = GaussianBasis(6)
    D, N = 3, 6
    mean = rng.standard_normal(D * N)
    cov = random_spd(rng, D * N)
    noise = np.array([0.05, 0.2, 0.01])
    stats = []
    for i in range(7):
        T = int(rng.integers(8, 60))
        Y = rng.standard_normal((T, D)) * 3
        Y[:T // 3, i % D] = np.nan
        stats.append(observation_stats(b, np.sort(rng.uniform(0, 1, T)), Y))
    chol = linalg.cho_factor(cov, lower=True)
    want = [weight_posterior(st, mean, chol, noise)[2] for st in stats]
    assert np.allclose(log_evidence(stack_stats(stats), mean, cov, noise), want, rtol=1e-10)
    assert np.allclose(cho_inverse(chol), np.linalg.inv(cov), rtol=1e-9, atol=1e-12)
    one = stack_stats(stats[:1])
    assert isinstance(one, ObservationStats) and one.G.shape == (1, D, N, N)


def _sample_set(rng, n, b, mean, cov, D, noise):
    trajs = []
    for _ in range(n):
        w = rng.multivariate_normal(mean, cov)
        t, Y = sample_trajectory(b, w, D, rng.uniform(1.0, 2.0), dt=0.01, noise=noise, rng=rng)
        trajs.append((t / t[-1], Y))
    return trajs


def test_em_recovers_generating_mean_and_covariance():
    rng = np.random.default_rng(3)
    b = GaussianBasis(5)
    D, d = 2, 10
    mean = rng.standard_normal(d)
    cov = random_spd(rng, d, 0.05)
    trajs = _sample_set(rng, 400, b, mean, cov, D, noise=0.01)
    m = ProMP(n_basis=5, method='em', prior_strength=0.0, tol=1e-9).fit(trajs)
    assert np.allclose(m.mean_, mean, atol=4 * np.sqrt(np.diag(cov).max() / 400) + 1e-3)
    assert np.linalg.norm(m.cov_ - cov) / np.linalg.norm(cov) < 0.2
    assert np.sqrt(m.noise_var_) == pytest.approx([0.01, 0.01], rel=0.1)


def test_em_log_likelihood_rises_monotonically_and_converges_with_gaps():
    rng = np.random.default_rng(4)
    b = GaussianBasis(8)
    mean = rng.standard_normal(8)
    cov = random_spd(rng, 8, 0.1)
    trajs = []
    for z, Y in _sample_set(rng, 20, b, mean, cov, 1, noise=0.02):
        s = rng.integers(0, len(z) - 60)
        Y = Y.copy()
        Y[s:s + 60] = np.nan
        trajs.append((z, Y))
    m = ProMP(n_basis=8, method='em', tol=1e-8, max_iter=3000).fit(trajs)
    ll = np.array(m.log_likelihood_)
    assert len(ll) > 3
    assert np.all(np.diff(ll) >= -1e-9 * np.abs(ll[:-1]))
    assert m.n_iter_ < 3000 and ll[-1] - ll[-2] < 1e-8 * abs(ll[-1])


def test_promp_rejects_bad_input():
    b_ok = (np.linspace(0, 1, 10), np.zeros((10, 2)))
    with pytest.raises(ValueError, match='no trajectories'):
        ProMP().fit([])
    with pytest.raises(ValueError, match='strictly increasing'):
        ProMP().fit([b_ok, (np.zeros(10), np.zeros((10, 2)))])
    with pytest.raises(ValueError, match='DOFs'):
        ProMP().fit([b_ok, (np.linspace(0, 1, 10), np.zeros((10, 3)))])
    with pytest.raises(ValueError, match='NaN/Inf'):
        ProMP().fit([(np.linspace(0, 1, 10), np.full((10, 2), np.inf))])
    with pytest.raises(ValueError, match='shape'):
        ProMP().fit([(np.linspace(0, 1, 10), np.zeros((9, 2)))])
    with pytest.raises(ValueError, match="method='em'"):
        ProMP(method='regression').fit([(np.linspace(0, 1, 10), np.c_[np.zeros(10), np.full(10, np.nan)])])
