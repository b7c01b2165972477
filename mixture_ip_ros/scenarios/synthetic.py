"""Sampled interaction demonstrations with known generating parameters: the oracle the learners
are tested and benchmarked against."""

import numpy as np

from mixture_ip_ros.core.basis import GaussianBasis
from mixture_ip_ros.core.demonstration import Demonstration


def random_spd(rng, d, scale=1.0, rank=None):
    A = rng.standard_normal((d, rank or d))
    return scale * (A @ A.T / (rank or d) + 0.05 * np.eye(d))


def sample_trajectory(basis, w, n_dofs, T, dt=0.01, noise=0.0, rng=None):
    t = np.arange(0.0, T + 1e-9, dt)
    z = t / t[-1]
    Y = basis(z) @ w.reshape(n_dofs, -1).T
    if noise:
        Y = Y + noise * rng.standard_normal(Y.shape)
    return t, Y


def mixture_demos(seed=0, counts=(12, 14, 10), n_obs=3, n_ctrl=4, n_basis=8, noise=0.002,
                  durations=((1.2, 1.8), (1.5, 2.4), (1.0, 1.6)), spread=0.002):
    """Three interaction patterns: distinct mean weights, a within-pattern covariance of scale
    ``spread`` (small by default: well separated patterns), durations varying within each
    pattern. Returns (demos, labels, basis, generating means)."""
    rng = np.random.default_rng(seed)
    basis = GaussianBasis(n_basis)
    D = n_obs + n_ctrl
    d = D * n_basis
    means = []
    for k in range(len(counts)):
        # smooth, well separated mean paths: offsets per DOF plus a gentle random shape
        offset = rng.uniform(-1, 1, D) * 0.6
        slope = rng.uniform(-1, 1, D) * 0.5
        z = basis.centers
        means.append(np.concatenate([offset[j] + slope[j] * z for j in range(D)]))
    demos, labels = [], []
    for k, c in enumerate(counts):
        cov = random_spd(rng, d, spread, rank=6)
        for _ in range(c):
            w = rng.multivariate_normal(means[k], cov, method="cholesky")
            T = rng.uniform(*durations[k])
            t, Y = sample_trajectory(basis, w, D, T, noise=noise, rng=rng)
            demos.append(Demonstration(t, Y[:, :n_obs], Y[:, n_obs:], label=str(k)))
            labels.append(k)
    return demos, np.array(labels), basis, means
