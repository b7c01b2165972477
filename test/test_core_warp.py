"""The monotone phase warp (core.warp, thesis eq. 34) against independent oracles: the integral
by quadrature, the MAP of a Gaussian evidence in closed form, a warp recovered from a path
sampled at a known one, and numpy's weighted moments."""

import numpy as np
import pytest
from scipy import integrate, linalg

from mixture_ip_ros.core.basis import GaussianBasis
from mixture_ip_ros.core.demonstration import Demonstration
from mixture_ip_ros.core.promp import observation_stats, weight_posterior
from mixture_ip_ros.core.warp import (CENTERS, N_WARP, WIDTH, map_warp, registered, warp,
                                      warp_prior)


def quad_warp(u, b):
    """g(u) = int_0^u r / int_0^1 r by adaptive quadrature (the oracle of the trapezoids)."""
    def rate(s):
        return np.exp(np.exp(-0.5 * ((s - CENTERS) / WIDTH) ** 2) @ b)
    total = integrate.quad(rate, 0.0, 1.0)[0]
    return np.array([integrate.quad(rate, 0.0, x)[0] / total for x in u])


def test_warp_is_the_normalised_integral_of_its_rate_monotone_with_fixed_ends():
    rng = np.random.default_rng(0)
    u = np.linspace(0.0, 1.0, 41)
    for _ in range(5):
        b = rng.normal(0.0, 0.8, N_WARP)
        z = warp(u, b)
        assert np.allclose(z, quad_warp(u, b), atol=2e-5)
        assert z[0] == 0.0 and z[-1] == 1.0
        assert np.all(np.diff(z) > 0)
    assert np.allclose(warp(u, np.zeros(N_WARP)), u, atol=1e-12)      # b = 0: linear phase


def test_warp_keeps_times_outside_the_movement():
    b = np.linspace(-1.0, 1.0, N_WARP)
    assert np.array_equal(warp([-0.2, 1.3], b), [-0.2, 1.3])


def test_registered_restamps_to_the_warped_phase_and_keeps_the_samples():
    t = np.linspace(0.0, 2.5, 26)
    demo = Demonstration(t, np.sin(t), np.cos(t)[:, None], label='a', name='d')
    b = np.array([0.5, -0.3, 0.2, 0.0, -0.6])
    out = registered(demo, b)
    assert np.allclose(out.t, 2.5 * quad_warp(t / 2.5, b), atol=1e-4)
    assert out.duration == demo.duration and out.t[0] == 0.0
    assert np.array_equal(out.observed, demo.observed)
    assert np.array_equal(out.controlled, demo.controlled)
    assert (out.label, out.name) == ('a', 'd')


def test_map_warp_of_a_gaussian_evidence_is_the_closed_form_posterior_mode():
    rng = np.random.default_rng(1)
    A = rng.normal(size=(N_WARP, N_WARP))
    A = A @ A.T + np.eye(N_WARP)
    c = rng.normal(size=N_WARP)
    mean, sd = rng.normal(0, 0.2, N_WARP), rng.uniform(0.2, 0.6, N_WARP)
    b, good = map_warp(lambda x: -0.5 * (x - c) @ A @ (x - c), mean, sd)
    S_inv = np.diag(sd ** -2.0)
    expected = linalg.solve(A + S_inv, A @ c + S_inv @ mean)
    assert good
    assert np.allclose(b, expected, atol=1e-4)


def test_map_warp_recovers_the_warp_a_path_was_sampled_at():
    rng = np.random.default_rng(2)
    basis = GaussianBasis(12)
    w = rng.normal(0.0, 1.0, (2, 12))               # two DOFs, known weights
    b_true = np.array([0.8, 0.6, 0.0, -0.6, -0.8])     # fast, then slow
    u = np.linspace(0.0, 1.0, 120)
    Y = basis(warp(u, b_true)) @ w.T + rng.normal(0.0, 1e-3, (len(u), 2))
    mean, chol = w.ravel(), linalg.cho_factor(1e-6 * np.eye(24), lower=True)

    def log_evidence(b):
        return weight_posterior(observation_stats(basis, warp(u, b), Y), mean, chol,
                                np.full(2, 1e-6))[2]
    b, good = map_warp(log_evidence, np.zeros(N_WARP), 1.0)
    assert good
    off = np.max(np.abs(warp(u, b_true) - u))
    assert off > 0.05                                            # far from the linear phase
    assert np.max(np.abs(warp(u, b) - warp(u, b_true))) < 0.05 * off


def test_map_warp_keeps_the_prior_mean_where_the_evidence_is_not_finite():
    mean = np.full(N_WARP, 0.1)
    b, good = map_warp(lambda x: np.nan, mean, 0.3)
    assert not good
    assert np.array_equal(b, mean)


@pytest.mark.parametrize('mean, sd', [(np.zeros(3), 0.3), (np.zeros(N_WARP), 0.0),
                                      (np.full(N_WARP, np.nan), 0.3)])
def test_map_warp_rejects_a_bad_prior(mean, sd):
    with pytest.raises(ValueError, match='prior over the warp'):
        map_warp(lambda x: 0.0, mean, sd)


def test_warp_prior_is_the_weighted_mean_and_floored_sd():
    rng = np.random.default_rng(3)
    b, w = rng.normal(size=(30, N_WARP)), rng.uniform(0.1, 1.0, 30)
    mean, sd = warp_prior(b, w, sd_floor=0.05)
    assert np.allclose(mean, np.average(b, axis=0, weights=w))
    var = np.diag(np.cov(b.T, aweights=w, bias=True))
    assert np.allclose(sd, np.sqrt(var + 0.05 ** 2))
    same = warp_prior(np.zeros((4, N_WARP)))
    assert np.array_equal(same[1], np.full(N_WARP, 0.05))


def test_warp_prior_rejects_misshaped_warps_and_zero_weights():
    with pytest.raises(ValueError, match='warps must be'):
        warp_prior(np.zeros((4, 3)))
    with pytest.raises(ValueError, match='warps must be'):
        warp_prior(np.zeros((4, N_WARP)), np.zeros(4))
