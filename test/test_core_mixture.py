"""Interaction ProMP conditioning (eqs. 3-5), the mixture (eqs. 6-13), K by leave-one-out."""

import numpy as np
import pytest
from scipy.stats import multivariate_normal, norm
from sklearn.mixture import GaussianMixture

from mixture_ip_ros.core.basis import GaussianBasis
from mixture_ip_ros.core.demonstration import Demonstration
from mixture_ip_ros.core.kmeans import kmeans
from mixture_ip_ros.core.interaction import condition_on_observed, trajectory_distribution
from mixture_ip_ros.core.mixture import MixtureIProMP
from mixture_ip_ros.core.selection import loo_rms_by_components, select_n_components
from mixture_ip_ros.core.gmm import gmm_maximization, gmm_responsibilities
from mixture_ip_ros.core.promp import ProMP

from mixture_ip_ros.scenarios.synthetic import mixture_demos, random_spd


@pytest.fixture(scope='module')
def three_patterns():
    return mixture_demos(seed=0)


def test_conditioning_matches_dense_gaussian_conditioning_of_trajectories():
    """eqs. 3-5 vs. conditioning the joint Gaussian of all positions (observed + predicted)."""
    rng = np.random.default_rng(5)
    b = GaussianBasis(6)
    P, Q, N = 2, 3, 6
    d = (P + Q) * N
    mean, cov = rng.standard_normal(d), random_spd(rng, d)
    noise = np.array([0.01, 0.03])
    z_obs = np.array([0.1, 0.35, 0.6])
    Y_obs = rng.standard_normal((3, P))
    new_mean, new_cov = condition_on_observed(mean, cov, b, P, z_obs, Y_obs, noise)
    z_grid = np.linspace(0, 1, 7)
    got = trajectory_distribution(new_mean, new_cov, b, z_grid)

    def rows(z, dofs):
        A = np.zeros((len(z) * len(dofs), d))
        for a, j in enumerate(dofs):
            A[a * len(z):(a + 1) * len(z), j * N:(j + 1) * N] = b(z)
        return A
    Ao, Ag = rows(z_obs, range(P)), rows(z_grid, range(P + Q))
    So = Ao @ cov @ Ao.T + np.diag(np.repeat(noise, 3))
    Sgo = Ag @ cov @ Ao.T
    gain = Sgo @ np.linalg.inv(So)
    m_ref = Ag @ mean + gain @ (Y_obs.T.ravel() - Ao @ mean)
    C_ref = Ag @ cov @ Ag.T - gain @ Sgo.T
    assert np.allclose(got['position'].T.ravel(), m_ref, atol=1e-9)
    var_ref = np.diag(C_ref).reshape(P + Q, len(z_grid)).T
    assert np.allclose(np.einsum('tii->ti', got['position_cov']), var_ref, atol=1e-9)


def test_velocities_are_time_derivatives_of_positions():
    rng = np.random.default_rng(6)
    b = GaussianBasis(8)
    mean = rng.standard_normal(16)
    alpha, h = 0.5, 1e-5
    z = np.linspace(0.1, 0.9, 9)
    out = trajectory_distribution(mean, np.eye(16), b, z, alpha)
    fd = (trajectory_distribution(mean, np.eye(16), b, z + alpha * h, alpha)['position']
          - trajectory_distribution(mean, np.eye(16), b, z - alpha * h, alpha)['position']) / (2 * h)
    assert np.allclose(out['velocity'], fd, atol=1e-5)


def test_mixture_em_is_monotone_and_matches_direct_log_likelihood(three_patterns):
    demos = three_patterns[0]
    for method in ('regression', 'em'):
        m = MixtureIProMP(3, n_basis=8, method=method, tol=1e-9).fit(demos)
        ll = np.array(m.log_likelihood_)
        assert np.all(np.diff(ll) >= -1e-9 * np.abs(ll[:-1])), method
    # Direct evaluation of eq. 6 (plus the covariance priors) at the fitted parameters.
    m = MixtureIProMP(3, n_basis=8, tol=1e-9).fit(demos)
    # Eq. 14 with the fitted curvature penalty per DOF (core.promp.penalised_weights).
    curvature = np.diff(np.eye(8), 2, axis=0)
    W = np.array([np.concatenate([np.linalg.solve(
        m.basis_(d.t / d.duration).T @ m.basis_(d.t / d.duration)
        + lam * curvature.T @ curvature + 1e-6 * np.eye(8), m.basis_(d.t / d.duration).T @ y)
        for lam, y in zip(m.smoothing_, np.hstack([d.observed, d.controlled]).T)])
        for d in demos])
    # Each component is joint over shape and phase speed: p(w | k) p(alpha | k).
    alpha = np.array([1 / d.duration for d in demos])
    dens = sum(m.weights_[k] * multivariate_normal(m.means_[k], m.covariances_[k]).pdf(W)
               * norm(m.alpha_mean_[k], np.sqrt(m.alpha_var_[k])).pdf(alpha) for k in range(3))
    penalty = sum(-0.5 * m.prior_strength * (np.trace(m.prior_cov_ @ np.linalg.inv(C))
                                             + np.linalg.slogdet(C)[1]) for C in m.covariances_)
    penalty += sum(-0.5 * m.prior_strength * (m.alpha_prior_var_ / v + np.log(v))
                   for v in m.alpha_var_)
    assert m.log_likelihood_[-1] == pytest.approx(np.log(dens).sum() + penalty, rel=1e-8)


@pytest.mark.filterwarnings('ignore::sklearn.exceptions.ConvergenceWarning')
def test_gmm_em_agrees_with_scikit_learn_from_the_same_initialisation():
    rng = np.random.default_rng(7)
    X = np.vstack([rng.multivariate_normal(mu, random_spd(rng, 4, 0.3), 80)
                   for mu in (np.zeros(4), np.full(4, 3.0), np.r_[3.0, -3, 0, 1])])
    labels = kmeans(X, 3, random_state=0)
    resp = np.eye(3)[labels]
    w, mu, C = gmm_maximization(X, resp, np.zeros(4), 0.0)
    sk = GaussianMixture(3, covariance_type='full', reg_covar=0.0, max_iter=25, tol=0.0,
                         weights_init=w, means_init=mu,
                         precisions_init=np.linalg.inv(C)).fit(X)
    for _ in range(25):
        resp, _ = gmm_responsibilities(X, w, mu, C)
        w, mu, C = gmm_maximization(X, resp, np.zeros(4), 0.0)
    assert np.allclose(w, sk.weights_, atol=1e-8)
    assert np.allclose(mu, sk.means_, atol=1e-8)
    assert np.allclose(C, sk.covariances_, atol=1e-8)


def test_regularised_components_stay_positive_definite_with_fewer_members_than_weights(
        three_patterns):
    demos = three_patterns[0]
    m = MixtureIProMP(3, n_basis=8).fit(demos)
    d = m.means_.shape[1]
    assert max(np.bincount(m.resp_.argmax(axis=1))) < d        # 56 weights, <= 14 members
    for C in m.covariances_:
        assert np.allclose(C, C.T)
        assert np.linalg.eigvalsh(C).min() > 0


def test_posterior_is_calibrated_leave_one_out(three_patterns):
    """Final controlled positions of held-out demos, standardised by the predicted variance
    (+ learned noise): mean squared z near 1 and about 95 % inside +-2 sigma."""
    demos = three_patterns[0]
    zs = []
    for i, test in enumerate(demos):
        m = MixtureIProMP(3, n_basis=8).fit(demos[:i] + demos[i + 1:])
        z = test.t / test.duration
        out = m.predict_controlled(z[-1:], test.observed[-1:], np.array([0.5, 1.0]))
        var = np.einsum('tii->ti', out['position_cov']) + m.noise_var_[m.n_observed_:]
        zs.append((test.controlled[[len(z) // 2, -1]] - out['position']) / np.sqrt(var))
    zs = np.concatenate(zs)
    assert 0.3 < np.mean(zs ** 2) < 3.0
    assert np.mean(np.abs(zs) < 2) > 0.85


def test_leave_one_out_selects_three_patterns():
    """One observed DOF: with three, the three pattern means are an affine function of the final
    wrist position, so a single Gaussian predicts them too and K would not matter."""
    demos = mixture_demos(seed=0, n_obs=1)[0]
    candidates = [1, 2, 3, 4, 5]
    rms = loo_rms_by_components(demos, candidates, n_basis=8)
    K = candidates[select_n_components(rms)]
    assert K == 3
    assert rms.mean(axis=1)[2] < 0.2 * rms.mean(axis=1)[0]


def test_component_posterior_picks_true_pattern_from_final_position(three_patterns):
    demos, labels = three_patterns[0], three_patterns[1]
    for i, test in enumerate(demos):
        train = demos[:i] + demos[i + 1:]
        m = MixtureIProMP(3, n_basis=8).fit(train)
        train_labels = np.delete(labels, i)
        # map components to labels by majority of the training members
        comp_label = [np.bincount(train_labels[m.resp_.argmax(1) == k], minlength=3).argmax()
                      for k in range(3)]
        post = m.component_posterior([1.0], test.observed[-1:])
        assert post.sum() == pytest.approx(1.0)
        assert comp_label[int(np.argmax(post))] == labels[i]


def test_missing_data_em_beats_regression_at_every_observed_fraction():
    """Thesis 4.3.2: 180-step gaps removed from every training trajectory."""
    rng = np.random.default_rng(8)
    b = GaussianBasis(10)
    D, N = 2, 10
    mean = np.concatenate([np.sin(np.linspace(0, 3, N)), np.cos(np.linspace(0, 3, N))])
    cov = random_spd(rng, D * N, 0.01, rank=5)

    def traj(n_steps):
        w = rng.multivariate_normal(mean, cov)
        z = np.arange(n_steps) / (n_steps - 1)
        return z, b(z) @ w.reshape(D, N).T + 0.005 * rng.standard_normal((n_steps, D))
    train = []
    for _ in range(20):
        z, Y = traj(int(rng.integers(355, 1130)))
        s = int(rng.integers(0, len(z) - 180))
        Y[s:s + 180] = np.nan
        train.append((z, Y))
    tests = [traj(int(rng.integers(355, 1130))) for _ in range(10)]
    em = ProMP(n_basis=10, method='em').fit(train)
    reg = ProMP(n_basis=10, method='regression').fit(train)
    for frac in (0.3, 0.5, 0.7):
        errs = {}
        for name, model in (('em', em), ('reg', reg)):
            e = []
            for z, Y in tests:
                n = int(frac * len(z))
                mu, C = condition_on_observed(model.mean_, model.cov_, b, D, z[:n:10], Y[:n:10],
                                              model.noise_var_ + 1e-6)
                pred = trajectory_distribution(mu, C, b, z[n:])['position']
                e.append(np.sqrt(np.mean((pred - Y[n:]) ** 2)))
            errs[name] = np.mean(e)
        assert errs['em'] < errs['reg'], (frac, errs)


def test_mixture_rejects_bad_input(three_patterns):
    demos = three_patterns[0]
    with pytest.raises(ValueError, match='fewer than n_components'):
        MixtureIProMP(5).fit(demos[:3])
    with pytest.raises(ValueError, match='Demonstration'):
        MixtureIProMP(1).fit([np.zeros((3, 3))])
    odd = Demonstration(demos[0].t, demos[0].observed[:, :2], demos[0].controlled)
    with pytest.raises(ValueError, match='disagree'):
        MixtureIProMP(1).fit([demos[0], odd])
    m = MixtureIProMP(3, n_basis=8).fit(demos)
    with pytest.raises(ValueError, match='empty observation'):
        m.component_posterior([], np.zeros((0, 3)))
    with pytest.raises(ValueError, match='shape'):
        m.component_posterior([1.0], np.zeros((1, 2)))
    with pytest.raises(ValueError, match='Inf'):
        m.component_posterior([1.0], np.full((1, 3), np.inf))
    with pytest.raises(ValueError, match='NaN'):
        m.component_posterior([np.nan], np.zeros((1, 3)))
    with pytest.raises(ValueError, match='strictly increasing'):
        Demonstration([0.0, 0.0], np.zeros((2, 3)), np.zeros((2, 2)))
    with pytest.raises(RuntimeError, match='not fitted'):
        MixtureIProMP(2).component_posterior([1.0], np.zeros((1, 3)))


def test_a_component_left_empty_keeps_a_finite_phase_prior():
    """K = 10 on 47 box-assembly demonstrations with a broad covariance floor: EM empties a
    component, whose phase prior must not be 0 / 0 (NaN priors make the online posterior NaN)."""
    from mixture_ip_ros.core.online import OnlineEstimator
    from mixture_ip_ros.scenarios.box_assembly import box_assembly
    demos = [g.to_demonstration(0.01) for g in box_assembly(0, occlusion=0.5)]
    m = MixtureIProMP(10, prior_scale=0.3).fit(demos[:1] + demos[2:])
    empty = m.resp_.sum(axis=0) < 1e-12
    assert empty.any()
    alphas = np.array([1.0 / d.duration for d in demos[:1] + demos[2:]])
    assert np.allclose(m.alpha_mean_[empty], alphas.mean())
    assert np.all(np.isfinite(m.alpha_std_)) and np.all(m.alpha_std_ > 0)
    est = OnlineEstimator(m)
    est.update(0.1, demos[1].observed[10])
    p = est.component_posterior()
    assert np.all(np.isfinite(p)) and p.sum() == pytest.approx(1.0)
