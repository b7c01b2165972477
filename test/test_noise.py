"""Residual correlation (core.noise): the integrated autocorrelation time against its value for
processes with a known one, and what the online estimator makes of it."""

import numpy as np
import pytest

from mixture_ip_ros.core.demonstration import Demonstration
from mixture_ip_ros.core.mixture import MixtureIProMP
from mixture_ip_ros.core.noise import correlation_time, noise_factor, residual_autocovariance


def _ar1(rng, n, phi):
    x = np.empty(n)
    x[0] = rng.normal() / np.sqrt(1 - phi ** 2)
    for t in range(1, n):
        x[t] = phi * x[t - 1] + rng.normal()
    return x


@pytest.mark.parametrize('phi', [0.0, 0.5, 0.9])
def test_the_correlation_time_of_a_first_order_autoregression(phi):
    """AR(1) with coefficient phi: integrated autocorrelation time (1 + phi) / (1 - phi)
    samples."""
    rng = np.random.default_rng(0)
    period = 0.01
    sums = counts = 0
    for _ in range(100):
        s, c = residual_autocovariance(_ar1(rng, 4000, phi)[:, None], 200)
        sums, counts = sums + s, counts + c
    tau = correlation_time(sums, counts, period)[0]
    assert tau == pytest.approx(period * (1 + phi) / (1 - phi), rel=0.1)


def test_missing_samples_are_left_out_of_the_pairs():
    r = np.array([1.0, np.nan, -1.0, 2.0])[:, None]
    sums, counts = residual_autocovariance(r, 2)
    assert np.allclose(sums[0], [1 + 1 + 4, -2, -1])
    assert np.allclose(counts[0], [3, 1, 1])


def test_white_residuals_leave_every_observation_its_variance():
    assert np.allclose(noise_factor([0.01, 0.3], 0.01, 0.05), [1.0, 6.0])
    assert np.allclose(noise_factor([0.2], 0.1, 0.05), [2.0])    # never closer than recorded


def test_a_model_of_wiggling_movements_counts_each_sample_for_less():
    """Demonstrations whose deviation from a smooth path lasts a fraction of a second: the
    fitted model measures it, and the online estimator's noise for samples 0.05 s apart is the
    variance times tau / 0.05 (unchanged for white residuals)."""
    from mixture_ip_ros.core.online import OnlineEstimator
    rng = np.random.default_rng(1)
    t = np.arange(0, 4.0, 0.01)
    demos = {}
    for kind, phi in (('white', 0.0), ('wiggling', 0.97)):
        demos[kind] = [Demonstration(t, np.sin(t)[:, None] + 0.01 * rng.normal()
                                     + 0.005 * _ar1(rng, t.size, phi)[:, None])
                       for _ in range(10)]
    white = MixtureIProMP(1).fit(demos['white'])
    wiggle = MixtureIProMP(1).fit(demos['wiggling'])
    assert white.noise_time_[0] < 0.02 and wiggle.noise_time_[0] > 5 * white.noise_time_[0]
    assert np.allclose(white.observed_noise_var_at(0.05), white.observed_noise_var_)
    factor = wiggle.observed_noise_var_at(0.05) / wiggle.observed_noise_var_
    assert factor[0] == pytest.approx(wiggle.noise_time_[0] / 0.05)
    est = OnlineEstimator(wiggle, min_interval=0.05)
    assert np.allclose(est._noise0.ravel()[0], wiggle.observed_noise_var_at(0.05)[0])
