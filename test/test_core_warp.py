"""The monotone phase warp (core.warp, thesis eq. 34) against independent oracles: the integral
by quadrature, derivatives by finite differences, the MAP of a Gaussian evidence in closed form,
warps recovered from paths sampled at known ones, numpy's weighted moments, the mixture's
warped posterior against the dense Gaussian formula and its linear special case."""

import copy

import numpy as np
import pytest
from scipy import integrate, linalg
from scipy.special import logsumexp
from scipy.stats import multivariate_normal, norm

from mixture_ip_ros.core.basis import GaussianBasis
from mixture_ip_ros.core.demonstration import Demonstration
from mixture_ip_ros.core.mixture import MixtureIProMP
from mixture_ip_ros.core.noise import decimated_rows
from mixture_ip_ros.core.promp import observation_stats, weight_posterior
from mixture_ip_ros.core import warped as warped_module
from mixture_ip_ros.core.warped import PhaseWarps, WarpEvidence, warp_spacing
from mixture_ip_ros.core.warp import (CENTERS, FLAT, N_WARP, SD_FLOOR, START_SD, WIDTH,
                                      laplace, learn_warp_priors, map_warp, registered, warp,
                                      warp_jacobian, warp_prior)


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


def test_warp_prior_is_the_mean_and_the_expected_squared_deviation():
    rng = np.random.default_rng(3)
    b, var = rng.normal(size=(30, N_WARP)), rng.uniform(0.0, 0.1, (30, N_WARP))
    mean, sd = warp_prior(b, var, sd_floor=0.05)
    assert np.allclose(mean, b.mean(axis=0))
    assert np.allclose(sd ** 2, np.var(b, axis=0) + var.mean(axis=0) + 0.05 ** 2)
    same = warp_prior(np.zeros((4, N_WARP)))
    assert np.array_equal(same[1], np.full(N_WARP, 0.05))


def test_warp_prior_rejects_misshaped_or_no_warps():
    for bad in (np.zeros((4, 3)), np.zeros((0, N_WARP))):
        with pytest.raises(ValueError, match='warps must be'):
            warp_prior(bad)


def test_laplace_is_exact_for_a_gaussian_evidence():
    """int exp(-(b - c)^T A (b - c) / 2) N(b; m, S) db = (2 pi)^(d/2) |A|^(-1/2) N(c; m, S + A^-1),
    and the posterior covariance (A + S^-1)^-1."""
    rng = np.random.default_rng(8)
    A = rng.normal(size=(N_WARP, N_WARP))
    A = A @ A.T + np.eye(N_WARP)
    c, m, sd = rng.normal(size=N_WARP), rng.normal(0, 0.2, N_WARP), rng.uniform(0.2, 0.6, N_WARP)

    def evidence(x):
        return -0.5 * (x - c) @ A @ (x - c), -A @ (x - c)
    b, good = map_warp(evidence, m, sd, gradient=True)
    log_z, cov = laplace(evidence, b, m, sd)
    S = np.diag(sd ** 2)
    expected = (0.5 * N_WARP * np.log(2 * np.pi) - 0.5 * np.linalg.slogdet(A)[1]
                + multivariate_normal(m, S + np.linalg.inv(A)).logpdf(c))
    assert good and abs(log_z - expected) < 1e-6
    assert np.allclose(cov, np.linalg.inv(A + np.linalg.inv(S)), atol=1e-6)


def test_warp_jacobian_is_the_derivative_of_warp():
    rng = np.random.default_rng(4)
    u = np.r_[-0.1, np.linspace(0.0, 1.0, 37), 1.2]
    b = rng.normal(0.0, 0.5, N_WARP)
    z, J = warp_jacobian(u, b)
    assert np.array_equal(z, warp(u, b))
    h = 1e-6
    fd = np.stack([(warp(u, b + h * e) - warp(u, b - h * e)) / (2 * h) for e in np.eye(N_WARP)],
                  axis=1)
    assert np.allclose(J, fd, atol=1e-7)
    assert np.all(J[[0, -1]] == 0) and np.allclose(J[[1, -2]], 0.0)      # ends fixed


def test_map_warp_with_the_gradient_finds_the_same_mode():
    rng = np.random.default_rng(5)
    A = rng.normal(size=(N_WARP, N_WARP))
    A = A @ A.T + np.eye(N_WARP)
    c = rng.normal(size=N_WARP)
    b, good = map_warp(lambda x: (-0.5 * (x - c) @ A @ (x - c), -A @ (x - c)), np.zeros(N_WARP),
                       0.4, gradient=True)
    expected = linalg.solve(A + np.eye(N_WARP) / 0.16, A @ c)
    assert good and np.allclose(b, expected, atol=1e-5)


def test_learn_warp_priors_recovers_the_gaussian_the_warps_were_drawn_from():
    """Sampled data with known parameters: each demonstration's evidence sharply peaked at its
    own warp, drawn from its component's Gaussian; one whose evidence is not finite is left
    out and reported."""
    rng = np.random.default_rng(6)
    true_mean = np.array([[0.5, 0.2, 0.0, -0.2, -0.5], [-0.3, 0.0, 0.4, 0.0, -0.3]])
    true_sd = np.array([0.15, 0.25])
    comp = np.repeat([0, 1], 200)
    drawn = true_mean[comp] + true_sd[comp, None] * rng.normal(size=(400, N_WARP))
    evidences = [lambda x, c=c: (-0.5e4 * np.sum((x - c) ** 2), -1e4 * (x - c)) for c in drawn]
    evidences[7] = lambda x: (np.nan, np.zeros(N_WARP))
    means, sds, good = learn_warp_priors(evidences, comp, 3)
    assert not good[7] and good.sum() == 399
    for k in range(2):
        mine = drawn[(comp == k) & good]
        assert np.allclose(means[k], mine.mean(axis=0), atol=0.01)
        assert np.allclose(sds[k], np.sqrt(mine.var(axis=0) + SD_FLOOR ** 2), rtol=0.05)
        assert np.all(np.abs(sds[k] - true_sd[k]) < 0.05)
    assert np.array_equal(means[2], np.zeros(N_WARP))                    # no member: its start
    assert np.array_equal(sds[2], np.full(N_WARP, START_SD))


# ------------------------------------------------------------------ in the mixture

def recordings_at_warps(spread, seed=7):
    """Two interactions, each recording made at its own warp drawn from N(0, spread^2 I)."""
    rng = np.random.default_rng(seed)
    shapes = [np.array([[0.0, 1.0], [0.5, -0.5], [1.0, 1.0]]),
              np.array([[1.0, -0.5], [0.0, 0.6], [-0.5, 0.5]])]       # (DOF, start / end)
    demos = []
    for k in range(2):
        for _ in range(14):
            T = rng.uniform(1.5, 2.0)
            t = np.arange(0.0, T + 1e-9, 0.02)
            z = warp(t / t[-1], spread * rng.normal(size=N_WARP))
            start, end = shapes[k][:, 0], shapes[k][:, 1]
            Y = start + np.outer(z, end - start) + 0.1 * np.sin(np.pi * z)[:, None]
            Y += 0.002 * rng.normal(size=Y.shape)
            demos.append(Demonstration(t, Y[:, :2], Y[:, 2:], label=str(k)))
    return demos


@pytest.fixture(scope='module')
def warped_mixture():
    """The mixture learned from recordings at warps of spread 0.3, and the recordings."""
    demos = recordings_at_warps(0.3)
    return with_warps(MixtureIProMP(n_components=2, n_basis=8).fit(demos), demos), demos


def with_warps(model, demos, **config):
    """``model`` with its PhaseWarps fitted to ``demos``, as training gives them."""
    model.warps_ = PhaseWarps(**config).fit(model, demos)
    return model


def test_phase_warps_learn_how_much_the_pace_varies(warped_mixture):
    """Warps are relative to each component's mean path (a warp common to every recording is
    part of that path): drawn around 0, the learned mean warp is about the linear phase; the
    learned spread is about the one the recordings were made at (EM with each warp's posterior
    variance: the MAP warps alone, shrunk to the prior, would shrink it round by round)."""
    model, demos = warped_mixture
    warps = model.warps_
    assert warps.failed_ == []
    u = np.linspace(0.0, 1.0, 101)
    for k in range(2):
        assert np.max(np.abs(warp(u, warps.mean_[k]) - u)) < 0.05
    steady = recordings_at_warps(0.05)
    calm = PhaseWarps().fit(MixtureIProMP(n_components=2, n_basis=8).fit(steady), steady)
    assert 0.15 < warps.sd_.mean() < 0.45                       # drawn at 0.3
    assert np.all(calm.sd_ < 0.12)                              # drawn at 0.05 (floor 0.05)
    assert warps.sd_.mean() > 2 * calm.sd_.mean()


def test_warp_evidence_gradient_matches_finite_differences(warped_mixture):
    model, demos = warped_mixture
    d = demos[3]
    Y = d.observed.copy()
    Y[5:9] = np.nan                                           # a gap the gradient must skip
    Y[12:15, 1] = np.nan                                      # and one DOF missing alone
    evidence = WarpEvidence(model, 0, d.phase, Y, 0.05)
    b = np.array([0.2, -0.4, 0.1, 0.3, -0.1])
    value, grad = evidence(b)
    fd = [(evidence(b + 1e-6 * e)[0] - evidence(b - 1e-6 * e)[0]) / 2e-6 for e in np.eye(N_WARP)]
    assert np.allclose(grad, fd, rtol=1e-4, atol=1e-4 * np.abs(grad).max())


def test_warped_posterior_is_the_linear_one_when_the_warp_is_pinned(warped_mixture):
    """The linear phase is the special case b = 0: with every component's Gaussian over b
    pinned at 0, eq. 11 with the phase z = t / T."""
    model, demos = warped_mixture
    pinned = copy.copy(model.warps_)
    pinned.mean_ = np.zeros_like(model.warps_.mean_)
    pinned.sd_ = np.full_like(model.warps_.sd_, 1e-6)
    d = demos[20]
    p, b = pinned.component_posterior(model, d.phase[::3], d.observed[::3], 1 / d.duration)
    assert np.allclose(b, 0.0, atol=1e-6)
    assert np.allclose(p, model.component_posterior(d.phase[::3], d.observed[::3],
                                                    1 / d.duration), atol=1e-6)


def test_warped_posterior_integrates_each_components_warp_out(warped_mixture):
    """p(k | D) ~ p(k) int p(D | k, b) N(b; m_k, s_k^2) db: the evidence at the returned b is
    the dense Gaussian formula, and the integral agrees with importance sampling from the
    Laplace Gaussian (an estimate that does not assume the posterior is Gaussian)."""
    model, demos = warped_mixture
    d = demos[2]
    u, Y = d.phase[::2], d.observed[::2]
    warps = model.warps_
    p, b = warps.component_posterior(model, u, Y, interval=0.04)
    basis, N = model.basis_, model.n_basis
    log_joint = []
    for k in range(2):
        A = np.kron(np.eye(2), basis(warp(u, b[k])))             # (2 m, 2 N): eq. 15's rows
        dense_cov = A @ model.covariances_[k][:2 * N, :2 * N] @ A.T
        noise = np.repeat(model.observed_noise(k, 0.04), len(u))
        dense = multivariate_normal(A @ model.means_[k][:2 * N],
                                    dense_cov + np.diag(noise)).logpdf(Y.T.ravel())
        evidence = WarpEvidence(model, k, u, Y, 0.04)
        assert np.isclose(evidence(b[k])[0], dense, rtol=1e-10, atol=1e-8)
        prior = norm(warps.mean_[k], warps.sd_[k])
        log_z, cov = laplace(evidence, b[k], warps.mean_[k], warps.sd_[k])
        q = multivariate_normal(b[k], cov)
        draws = q.rvs(400, random_state=k)
        w = [evidence(x)[0] + prior.logpdf(x).sum() - q.logpdf(x) for x in draws]
        assert abs(log_z - (logsumexp(w) - np.log(len(w)))) < 0.1
        log_joint.append(np.log(model.weights_[k]) + log_z)
    log_joint = np.array(log_joint)
    assert np.allclose(p, np.exp(log_joint - logsumexp(log_joint)), atol=1e-9)


def test_phase_warps_read_each_recording_as_the_estimator_does(warped_mixture, monkeypatch):
    """At samples no closer than the estimator's decimation (the recordings here are at 50 Hz
    with white residuals, min_interval 0.05 s), under its component's weights made once for
    every member (the same evidence as made per recording)."""
    model, demos = warped_mixture
    seen = []

    def spy(model, k, u, Y, interval, prior=None):
        assert prior is not None                          # made once for every member
        seen.append((len(u), interval))
        alone = WarpEvidence(model, k, u, Y, interval)
        shared = WarpEvidence(model, k, u, Y, interval, prior)
        b = np.linspace(-0.3, 0.3, N_WARP)
        assert alone(b)[0] == shared(b)[0] and np.array_equal(alone(b)[1], shared(b)[1])
        return shared
    monkeypatch.setattr(warped_module, 'WarpEvidence', spy)
    PhaseWarps().fit(model, demos)
    assert warp_spacing(model) < 0.05
    assert seen == [(len(decimated_rows(d.t, 0.05)), 0.05) for d in demos]
    with pytest.raises(ValueError, match='min_interval must be'):
        PhaseWarps(min_interval=-1.0).fit(model, demos)


def test_warp_gains_say_where_a_warp_predicts_held_out_recordings_better():
    """Recordings held out from the model: made at warps of spread 0.3, a warp predicts them
    better; made at the linear phase, the warp's freedom only spreads the prediction. Each gain
    is Laplace's marginal at N(0, START_SD^2 I) less the evidence at b = 0 under the component
    the linear phase finds most probable."""
    for spread, sign in ((0.3, 1.0), (0.0, -1.0)):
        demos = recordings_at_warps(spread, seed=11)
        held_out = recordings_at_warps(spread, seed=12)
        model = MixtureIProMP(n_components=2, n_basis=8).fit(demos)
        gains = PhaseWarps().gains(model, held_out)
        assert sign * gains.mean() > 0.5
        d = held_out[1]
        rows = decimated_rows(d.t, 0.05)
        start = np.zeros(N_WARP), np.full(N_WARP, START_SD)
        evidences = [WarpEvidence(model, j, d.phase[rows], d.observed[rows], 0.05)
                     for j in range(2)]
        k = int(np.argmax(np.log(model.weights_) + [f(start[0])[0] for f in evidences]
                          + norm(model.alpha_mean_, model.alpha_std_).logpdf(1 / d.duration)))
        evidence = evidences[k]
        b = map_warp(evidence, *start, gradient=True)[0]
        assert np.isclose(gains[1], laplace(evidence, b, *start)[0] - evidence(start[0])[0])


def test_phase_warps_need_the_demonstrations_the_model_was_fitted_to(warped_mixture):
    model, demos = warped_mixture
    with pytest.raises(ValueError, match='need the 28 Demonstrations'):
        PhaseWarps().fit(model, demos[:5])


def test_unfitted_warps_refuse_the_warped_posterior(warped_mixture):
    model, demos = warped_mixture
    with pytest.raises(ValueError, match='no phase warp'):
        PhaseWarps().component_posterior(model, demos[0].phase, demos[0].observed)


def test_a_warp_that_does_not_converge_is_named_and_left_out(warped_mixture, monkeypatch):
    model, demos = warped_mixture
    named = [Demonstration(d.t, d.observed, d.controlled, d.label, f'rec{i}')
             for i, d in enumerate(demos)]
    calls = []

    def failing_for_rec4(*args):
        calls.append(len(calls))
        evidence = WarpEvidence(*args)
        return (lambda b: (np.nan, np.zeros(N_WARP))) if len(calls) == 5 else evidence
    monkeypatch.setattr(warped_module, 'WarpEvidence', failing_for_rec4)
    refit = PhaseWarps().fit(model, named)
    assert refit.failed_ == ['rec4']
    assert np.all(np.isfinite(refit.mean_)) and np.all(refit.sd_ > 0)


def test_end_posterior_aligns_each_component_when_the_model_has_warps(warped_mixture):
    from mixture_ip_ros.core.online import OnlineEstimator
    from mixture_ip_ros.core.playback import played_to
    model, demos = warped_mixture
    model = copy.copy(model)
    model.noise_time_ = np.full_like(model.noise_time_, 0.2)  # residuals correlated over 0.2 s
    d = demos[25]
    est = OnlineEstimator(model, n_alpha=9)
    played_to(est, d, d.duration)
    t, Y = np.array(est._times), np.array(est._values)
    spacing = max(warp_spacing(model), est.min_interval)
    rows = decimated_rows(t, spacing)
    assert spacing == 0.2 and 5 < len(rows) < len(t) / 3    # read as training read the warps
    p = est.end_posterior(d.duration)
    expected = model.warps_.component_posterior(model, np.minimum(t[rows] / d.duration, 1.0),
                                                Y[rows], 1 / d.duration, spacing)[0]
    assert np.array_equal(p, expected)


def test_warp_at_is_numpys_interpolation_of_the_normalised_integral():
    """WarpAt (the grid position found once) against np.interp of g over GRID: at 0, 1, just
    inside and outside, outside [0, 1] and at random points; NaN or a 2-D u is refused."""
    from mixture_ip_ros.core.warp import GRID, WarpAt, _cumulative, _rate
    rng = np.random.default_rng(14)
    u = np.concatenate([[0.0, 1e-17, 0.5, 1 - 1e-16, 1.0, 1 + 1e-16, -0.1, 2.0, -np.inf, np.inf],
                        rng.uniform(0, 1, 200)])
    for b in (np.zeros(N_WARP), rng.normal(0, 0.3, N_WARP), rng.normal(0, 3.0, N_WARP)):
        cum = _cumulative(_rate(b)[:, None])[:, 0]
        inside = (u >= 0) & (u <= 1)
        expected = np.where(inside, np.interp(u, GRID, cum / cum[-1]), u)
        z, J = WarpAt(u)(b)
        assert np.allclose(z, expected, rtol=0, atol=1e-15) and J.shape == (len(u), N_WARP)
        assert z[0] == 0.0 and z[4] == 1.0 and np.all(J[~inside] == 0.0)
    for bad in (np.array([0.2, np.nan]), np.zeros((2, 2))):
        with pytest.raises(ValueError, match='1-D array without NaN'):
            WarpAt(bad)


def test_warp_stays_finite_and_monotone_for_extreme_parameters():
    """An optimiser's line search tries huge b: the phase must stay a finite monotone warp."""
    u = np.linspace(0.0, 1.0, 51)
    for b in (np.full(N_WARP, 800.0), np.array([900.0, -900.0, 0.0, 700.0, -50.0])):
        z, J = warp_jacobian(u, b)
        assert np.all(np.isfinite(z)) and np.all(np.isfinite(J))
        assert np.array_equal(z, warp(u, b)) and np.all(np.diff(z) >= 0)
        assert z[0] == 0.0 and z[-1] == 1.0


def test_map_warp_treats_a_warp_the_evidence_refuses_as_impossible():
    def evidence(b):
        if b[0] > 0.5:
            raise np.linalg.LinAlgError('not positive definite')
        return -0.5 * np.sum((b - 1.0) ** 2), -(b - 1.0)
    b, good = map_warp(evidence, np.zeros(N_WARP), 1.0, gradient=True)
    assert np.all(np.isfinite(b)) and b[0] <= 0.5


def test_map_warp_takes_a_stop_where_the_posterior_is_flat_as_converged(monkeypatch):
    """L-BFGS-B's line search may give up at the mode (rounding, kinks between GRID points):
    a gradient below FLAT nats per prior sd is a mode; a steep one is not."""
    from scipy import optimize
    from mixture_ip_ros.core import warp as warp_module
    sd = np.full(N_WARP, 0.2)
    for jac, expected in ((np.full(N_WARP, 0.9 * FLAT / 0.2), True),
                          (np.full(N_WARP, 1.1 * FLAT / 0.2), False)):
        stopped = optimize.OptimizeResult(x=np.full(N_WARP, 0.1), fun=3.0, jac=jac,
                                          success=False, message='ABNORMAL: ')
        monkeypatch.setattr(warp_module.optimize, 'minimize', lambda *a, **k: stopped)
        b, good = map_warp(lambda x: (0.0, np.zeros(N_WARP)), np.zeros(N_WARP), sd,
                           gradient=True)
        assert good is expected and np.array_equal(b, stopped.x)


def test_end_posterior_falls_back_to_the_linear_phase_if_every_warp_fails(warped_mixture,
                                                                          monkeypatch):
    """A numerical failure at the end event must not leave the interaction without an answer
    (the node would send no final plan)."""
    from mixture_ip_ros.core.online import OnlineEstimator
    from mixture_ip_ros.core.playback import played_to
    model, demos = warped_mixture
    d = demos[5]
    est = OnlineEstimator(model, n_alpha=9)
    played_to(est, d, d.duration)

    def failing(*args, **kwargs):
        raise np.linalg.LinAlgError('not positive definite')
    monkeypatch.setattr(PhaseWarps, 'component_posterior', failing)
    t, Y = np.array(est._times), np.array(est._values)
    assert np.array_equal(est.end_posterior(d.duration), model.component_posterior(
        np.minimum(t / d.duration, 1.0), Y, alpha=1 / d.duration))
