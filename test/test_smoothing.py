"""The weights' curvature penalty and its empirical-Bayes strength (core.promp): the evidence is
the dense restricted marginal likelihood, the weights the dense penalised solve, and gaps and
noise are bridged and filtered as the recordings' own smoothness says."""

import numpy as np
import pytest

from mixture_ip_ros.core.basis import GaussianBasis
from mixture_ip_ros.core.promp import (empirical_bayes_smoothing, observation_stats,
                                       penalised_weights, ridge_weights, second_difference_penalty,
                                       smoothing_evidence, stack_stats)


def _recordings(rng, n=4, N=8):
    basis = GaussianBasis(N)
    Phis, Ys, stats = [], [], []
    for i in range(n):
        m = int(rng.integers(12, 30))
        z = np.sort(rng.random(m))
        z[0], z[-1] = 0.0, 1.0
        Y = np.column_stack([np.sin(3 * z + i) + 0.1 * rng.standard_normal(m),
                             z ** 2 + 0.05 * rng.standard_normal(m)])
        Phis.append(basis(z))
        Ys.append(Y)
        stats.append(observation_stats(basis, z, Y))
    return Phis, Ys, stack_stats(stats)


def _dense_reml(Phis, ys, lam, K):
    """The restricted log-likelihood of samples y_i = Phi_i w_i + e, w_i = N0 beta_i + U gamma_i
    with a flat prior on beta_i (K's null space), gamma_i ~ N(0, s2 / (lam d)) (d: K's positive
    eigenvalues) and e ~ N(0, s2 I), s2 shared and profiled out: the textbook dense form
    (Harville 1974) with every matrix built."""
    eig, vec = np.linalg.eigh(K)
    pos = eig > 1e-9 * eig.max()
    N0, U, d = vec[:, ~pos], vec[:, pos], eig[pos]
    terms = quad = dof = 0.0
    for Phi, y in zip(Phis, ys):
        X, Z = Phi @ N0, Phi @ U
        H = np.eye(len(y)) + Z @ np.diag(1 / (lam * d)) @ Z.T
        Hi = np.linalg.inv(H)
        XtHiX = X.T @ Hi @ X
        P = Hi - Hi @ X @ np.linalg.solve(XtHiX, X.T @ Hi)
        terms += np.linalg.slogdet(H)[1] + np.linalg.slogdet(XtHiX)[1]
        quad += y @ P @ y
        dof += len(y) - X.shape[1]
    s2 = quad / dof
    return -0.5 * (dof * np.log(2 * np.pi * s2) + terms + dof)


def test_the_evidence_is_the_dense_restricted_likelihood_up_to_a_constant():
    Phis, Ys, stats = _recordings(np.random.default_rng(0))
    grid = [1e-3, 1e-2, 1e-1, 1.0, 10.0]
    ev = smoothing_evidence(stats, grid)
    K = second_difference_penalty(8)
    for j in range(2):
        dense = np.array([_dense_reml(Phis, [Y[:, j] for Y in Ys], lam, K) for lam in grid])
        assert np.allclose(ev[:, j] - ev[0, j], dense - dense[0], rtol=0, atol=1e-8)
    chosen = empirical_bayes_smoothing(stats, grid)
    assert list(chosen) == [grid[int(np.argmax(ev[:, j]))] for j in range(2)]


def test_penalised_weights_are_the_dense_penalised_least_squares_solve():
    Phis, Ys, stats = _recordings(np.random.default_rng(1))
    K = second_difference_penalty(8)
    lam = np.array([0.3, 0.01])
    W = penalised_weights(stats, lam, ridge=1e-6)
    for i, (Phi, Y) in enumerate(zip(Phis, Ys)):
        for j in range(2):
            w = np.linalg.solve(Phi.T @ Phi + lam[j] * K + 1e-6 * np.eye(8), Phi.T @ Y[:, j])
            assert np.allclose(W[i, 8 * j:8 * (j + 1)], w, rtol=1e-9, atol=1e-12)
    # One trajectory's statistics give its weights alone; a smoothing of 0 is eq. 14.
    st = observation_stats(GaussianBasis(8), np.linspace(0, 1, 20), Ys[0][:1].repeat(20, 0))
    assert penalised_weights(st, 0.0, 1e-6).shape == (16,)


def test_a_gap_is_bridged_as_smoothly_as_the_recording_is_elsewhere():
    """Dropped frames leave eq. 14 free between the samples on either side: with a vanishing
    ridge its path swings there; the smoothed weights stay near the path the samples show."""
    rng = np.random.default_rng(2)
    N, basis = 15, GaussianBasis(15)
    stats, phases, gaps = [], [], []
    for i in range(20):
        z = np.linspace(0, 1, 25)                       # a sparse recording, 9 Hz-like
        keep = np.ones(25, dtype=bool)
        lo = int(rng.integers(5, 15))
        keep[lo:lo + 5] = False                         # a burst of five dropped frames
        y = 0.3 * np.sin(2 * np.pi * z + i) + 0.5 + 0.01 * rng.standard_normal(25)
        stats.append(observation_stats(basis, z[keep], y[keep, None]))
        phases.append(i)
        gaps.append((z[lo - 1], z[lo + 5]))
    stats = stack_stats(stats)
    smooth = penalised_weights(stats, empirical_bayes_smoothing(stats), 1e-6)
    rough = penalised_weights(stats, 0.0, 1e-6)
    zz = np.linspace(0, 1, 400)
    err_smooth, err_rough = [], []
    for w_s, w_r, i, (a, b) in zip(smooth, rough, phases, gaps):
        inside = (zz > a) & (zz < b)
        true = 0.3 * np.sin(2 * np.pi * zz[inside] + i) + 0.5
        err_smooth.append(np.max(np.abs(basis(zz[inside]) @ w_s - true)))
        err_rough.append(np.max(np.abs(basis(zz[inside]) @ w_r - true)))
    assert np.median(err_smooth) < 0.05                  # within 5 cm of a 30 cm swing
    assert np.median(err_rough) > 4 * np.median(err_smooth)


def test_a_trackers_noise_is_filtered_not_learned():
    """White noise of 2 cm on smooth paths sampled densely: the smoothed paths are nearer the
    true ones than eq. 14's (ridge 1e-6), which follow the noise with their basis functions."""
    rng = np.random.default_rng(3)
    basis = GaussianBasis(15)
    z, zz = np.linspace(0, 1, 60), np.linspace(0, 1, 300)
    samples = [0.2 * np.cos(np.pi * z * (1 + 0.1 * i)) + 0.02 * rng.standard_normal(60)
               for i in range(10)]
    stats = stack_stats([observation_stats(basis, z, y[:, None]) for y in samples])
    lam = empirical_bayes_smoothing(stats)
    assert lam[0] > 1e-4
    smooth = penalised_weights(stats, lam, 1e-6)
    rough = [ridge_weights(basis, z, y[:, None], 1e-6) for y in samples]

    def rms(W):
        return np.sqrt(np.mean([(basis(zz) @ w - 0.2 * np.cos(np.pi * zz * (1 + 0.1 * i))) ** 2
                                for i, w in enumerate(W)]))
    assert rms(smooth) < 0.8 * rms(rough)


def test_a_set_of_samples_too_few_to_score_takes_the_smoothest_line():
    basis = GaussianBasis(8)
    st = stack_stats([observation_stats(basis, np.array([0.0, 1.0]), np.array([[0.0], [1.0]]))])
    lam = empirical_bayes_smoothing(st, [0.01, 1.0, 100.0])
    assert lam[0] == 100.0
    w = penalised_weights(st, lam, 1e-6)[0]
    assert np.allclose(basis(np.array([0.0, 0.5, 1.0])) @ w, [0.0, 0.5, 1.0], atol=0.05)


@pytest.mark.parametrize('bad', [-1.0, np.nan, [[0.1, 0.2]]])
def test_a_bad_smoothing_is_refused_by_name(bad):
    from mixture_ip_ros.core.mixture import MixtureIProMP
    with pytest.raises(ValueError, match='smoothing'):
        MixtureIProMP(1, smoothing=bad)._check_params()


def test_a_smoothing_of_the_wrong_length_or_for_em_is_refused_by_name():
    from mixture_ip_ros.core.mixture import MixtureIProMP
    from mixture_ip_ros.scenarios.synthetic import mixture_demos
    demos = mixture_demos(seed=1, n_obs=1, n_ctrl=1, counts=(3, 3, 3))[0]
    with pytest.raises(ValueError, match='3 values for 2 DOFs'):
        MixtureIProMP(1, n_basis=8, smoothing=[0.1, 0.1, 0.1]).fit(demos)
    with pytest.raises(ValueError, match="smoothing is for method='regression'"):
        MixtureIProMP(1, n_basis=8, method='em', smoothing=0.1)._check_params()
    m = MixtureIProMP(1, n_basis=8, smoothing=0.1).fit(demos)
    assert np.array_equal(m.smoothing_, [0.1, 0.1])
