"""K selection's cross-validation reuses what does not change between folds (per-demonstration
statistics and weights, each fold's k-means start across covariance floors, batched evidences):
its curves must be the ones the straightforward loop gives, one fit per fold from the
demonstrations, with the same folds and seeds."""

import numpy as np
import pytest

from conftest import heldout_loglik
from mixture_ip_ros.app.training import train
from mixture_ip_ros.core.demonstration import Demonstration
from mixture_ip_ros.core.kmeans import kmeans
from mixture_ip_ros.core.mixture import MixtureIProMP
from mixture_ip_ros.core.crossval import (cv_folds, fold_scores, k_folds, leave_one_out,
                                          prepare_for_cv)
from mixture_ip_ros.core.scores import controlled_rms
from mixture_ip_ros.core.selection import loo_rms_by_components
from mixture_ip_ros.scenarios.synthetic import mixture_demos


def plain_kmeans(X, n_clusters, random_state=0, n_init=10, max_iter=100):
    """k-means++ and Lloyd, one run after another, every distance summed directly."""
    rng = np.random.default_rng(random_state)
    best, best_inertia = None, np.inf
    for _ in range(n_init):
        centers = [X[rng.integers(len(X))]]
        for _ in range(1, n_clusters):
            d2 = np.min([np.sum((X - c) ** 2, axis=1) for c in centers], axis=0)
            p = d2 / d2.sum() if d2.sum() > 0 else np.full(len(X), 1 / len(X))
            centers.append(X[rng.choice(len(X), p=p)])
        C = np.array(centers)
        for _ in range(max_iter):
            labels = np.argmin(((X[:, None, :] - C[None]) ** 2).sum(-1), axis=1)
            newC = np.array([X[labels == k].mean(0) if np.any(labels == k) else C[k]
                             for k in range(n_clusters)])
            if np.allclose(newC, C):
                break
            C = newC
        inertia = np.sum((X - C[labels]) ** 2)
        if inertia < best_inertia:
            best, best_inertia = labels, inertia
    return best


def set_smoothing(demos, **params):
    """The weights' smoothing of the whole set (core.promp.empirical_bayes_smoothing): chosen
    once for the demonstrations cross-validation prepares and shared by its folds, so a plain
    loop that fits each fold from scratch is given it."""
    return prepare_for_cv(demos, params).smoothing


def plain_heldout(demos, candidates, scales, n_folds=5, **params):
    params = {'smoothing': set_smoothing(demos, **params), **params}
    fold = cv_folds(len(demos), n_folds, 0)
    out = np.empty((len(scales), len(candidates), len(demos)))
    for b, scale in enumerate(scales):
        for a, K in enumerate(candidates):
            for f in range(fold.max() + 1):
                train_set = [d for d, g in zip(demos, fold) if g != f]
                test = np.flatnonzero(fold == f)
                model = MixtureIProMP(K, prior_scale=scale, **params).fit(train_set)
                out[b, a, test] = model.score_demonstrations([demos[i] for i in test])
    return out


def plain_loo(demos, candidates, **params):
    params = {'smoothing': set_smoothing(demos, **params), **params}
    return np.array([[controlled_rms(MixtureIProMP(K, **params).fit(demos[:i] + demos[i + 1:]),
                                     test) for i, test in enumerate(demos)]
                     for K in candidates])


def occluded(demos, seed=0):
    """The observed agent missing for a stretch of every other demonstration."""
    rng = np.random.default_rng(seed)
    out = []
    for i, d in enumerate(demos):
        obs = d.observed.copy()
        if i % 2:
            lo = int(rng.integers(1, len(d.t) // 2))
            obs[lo:lo + len(d.t) // 5] = np.nan
        out.append(Demonstration(d.t, obs, d.controlled, label=d.label))
    return out


def test_folds_hold_out_every_demonstration_once_and_train_on_the_rest():
    """k seeded folds and leave-one-out: each fold's held-out and training indices split the
    demonstrations, every demonstration is held out exactly once (leave-one-out: the ones
    asked for), and the fold loop gives each fold's and setting's score in that order, the
    same on any number of threads, a fold that cannot hold the model as None."""
    for n, n_folds in ((19, 5), (7, 5), (3, 5), (10, 10)):
        folds = k_folds(n, n_folds, 0)
        assert len(folds) == min(n, n_folds)
        assert np.array_equal(np.sort(np.concatenate([f.test for f in folds])), np.arange(n))
        for f, fold in enumerate(folds):
            assert np.array_equal(fold.test, np.flatnonzero(cv_folds(n, n_folds, 0) == f))
            assert np.array_equal(np.union1d(fold.train, fold.test), np.arange(n))
            assert not np.intersect1d(fold.train, fold.test).size
    loo = leave_one_out(6, [4, 1])
    assert [f.test.tolist() for f in loo] == [[4], [1]]
    assert [f.train.tolist() for f in loo] == [[0, 1, 2, 3, 5], [0, 2, 3, 4, 5]]

    def fit(fold, K):
        return None if len(fold.train) < K else (K, fold.train.sum())

    def score(model, fold, K):
        return model[1] * K + fold.test.sum()
    folds = k_folds(9, 3, 1)
    want = [None if len(f.train) < K else f.train.sum() * K + f.test.sum()
            for f in folds for K in (1, 7)]
    for n_jobs in (1, 3):
        assert fold_scores(folds, fit, score, (1, 7), n_jobs=n_jobs) == want
    assert want.count(None) == 3


def test_kmeans_gives_the_labels_of_the_plain_loop():
    rng = np.random.default_rng(1)
    for trial in range(60):
        n, dim = int(rng.integers(4, 50)), int(rng.integers(1, 60))
        X = rng.standard_normal((n, dim)) * rng.uniform(0.1, 10, dim)
        if trial % 3 == 0:
            X[:n // 2] += 3
        if trial % 4 == 0:
            X = np.round(X)                           # ties and repeated rows
        for K in range(1, min(6, n) + 1):
            assert np.array_equal(kmeans(X, K, trial), plain_kmeans(X, K, trial)), (trial, K)


@pytest.mark.parametrize('n_ctrl', [3, 0])
def test_heldout_curves_equal_the_straightforward_loop(n_ctrl):
    demos = occluded(mixture_demos(seed=5, n_obs=2, n_ctrl=n_ctrl, counts=(8, 9, 7))[0])
    candidates, scales = [1, 2, 3, 4], [1.0, 0.1, 0.01]
    plain = plain_heldout(demos, candidates, scales, n_basis=8)
    cal = heldout_loglik(demos, candidates, scales, n_basis=8)
    assert np.allclose(cal['mean_by_scale'], plain.mean(axis=2), rtol=1e-12, atol=0)
    best = np.argmax(plain.mean(axis=2), axis=0)
    assert cal['prior_scale'] == [scales[b] for b in best]
    assert np.allclose(cal['scores'], plain[best, range(len(candidates))], rtol=1e-12, atol=0)
    fixed = heldout_loglik(demos, candidates, [0.1], n_basis=8)['scores']
    assert np.allclose(fixed, plain[1], rtol=1e-12, atol=0)


def test_leave_one_out_curve_equals_the_straightforward_loop():
    # To round-off: the curve conditions on the final sample in the Kalman form (a P x P
    # innovation), controlled_rms in the information form.
    demos = occluded(mixture_demos(seed=5, n_obs=2, n_ctrl=3, counts=(6, 7, 5))[0])
    candidates = [1, 2, 3, 4]
    for params in ({'n_basis': 8}, {'n_basis': 8, 'prior_scale': 0.3, 'noise': 'per_component'}):
        assert np.allclose(loo_rms_by_components(demos, candidates, **params),
                           plain_loo(demos, candidates, **params), rtol=1e-9, atol=0)


def test_em_stops_when_the_responsibilities_repeat_with_the_parameters_of_the_full_loop():
    """An E step that gives the responsibilities of the last M step back means the next
    iteration repeats this one: the fit stops there with what two full iterations give."""
    demos = mixture_demos(seed=0)[0]
    short = MixtureIProMP(3, n_basis=8).fit(demos)
    full = MixtureIProMP(3, n_basis=8, tol=0.0, max_iter=2).fit(demos)   # no stopping rule
    assert short.n_iter_ == 2 and short.converged_
    assert short.log_likelihood_ == full.log_likelihood_
    for name in ('weights_', 'means_', 'covariances_', 'resp_', 'noise_var_', 'alpha_mean_',
                 'alpha_std_'):
        assert np.array_equal(getattr(short, name), getattr(full, name)), name


@pytest.mark.decision
def test_training_keeps_three_patterns_on_box_assembly():
    from mixture_ip_ros.io.dataset import WRIST_OBSERVATION_NOISE
    from mixture_ip_ros.scenarios.box_assembly import box_assembly
    demos = [g.to_demonstration(0.01) for g in box_assembly(0, occlusion=0.5)]
    for criterion in ('patterns', 'loo'):
        model, info = train(demos, candidates=range(1, 7), criterion=criterion,
                            observation_noise=WRIST_OBSERVATION_NOISE)
        sel = info['selection']
        assert sel['criterion'] == criterion and sel['chosen'] == 3 and sel['clear_optimum']
        assert model.n_components == 3 and model.prior_scale == sel['prior_scale']


def test_heldout_loglik_of_em_data_with_a_robot_never_observed():
    """The likelihood curve scores nothing of the controlled agent's prediction, so EM data
    where one demonstration never observed the controlled agent gives finite curves."""
    demos = mixture_demos(seed=5, n_obs=2, n_ctrl=2, counts=(6, 6, 6))[0]
    blind = demos[3]
    demos[3] = Demonstration(blind.t, blind.observed, np.full_like(blind.controlled, np.nan))
    cal = heldout_loglik(demos, [1, 2], [1.0], n_basis=6, method='em', max_iter=5)
    assert np.all(np.isfinite(cal['scores']))


def test_training_is_the_same_on_one_thread_or_several_and_its_folds_are_plain_fits(tmp_path):
    """Training's held-out folds run on threads (n_jobs) and take what each demonstration is
    on its own from one preparation: the same model and decisions on one thread or three,
    and the speed weight's and the novelty test's folds are the fits each fold's
    demonstrations give from scratch (with the set's smoothing, as every fold shares it)."""
    from mixture_ip_ros.app.training import train_to_file
    from mixture_ip_ros.core.demonstration import Layout
    from mixture_ip_ros.core.novelty import calibrate
    from mixture_ip_ros.core.calibration import SPEED_WEIGHTS, speed_log_scores
    demos = mixture_demos(seed=2, n_obs=2, n_ctrl=1, counts=(6, 7, 6))[0]
    layout = Layout(('x', 'y'), ('c',))
    runs = [train_to_file(demos, tmp_path / f'm{j}.npz', layout=layout, candidates=(1, 2, 3, 4),
                          n_basis=8, n_jobs=j) for j in (1, 3)]
    (one, info), (three, info3) = runs
    for key in ('selection', 'prior_scale', 'speed_weight', 'speed_scores', 'novelty'):
        assert info[key] == info3[key], key
    assert np.array_equal(one.means_, three.means_)
    assert np.array_equal(one.covariances_, three.covariances_)
    assert info['n_components'] == 3
    params = {'n_basis': 8, 'smoothing': set_smoothing(demos, n_basis=8),
              'prior_scale': one.prior_scale}
    fold = cv_folds(len(demos), 5, 0)
    total, n = np.zeros(len(SPEED_WEIGHTS)), 0
    for f in range(fold.max() + 1):
        model = MixtureIProMP(3, **params).fit([d for d, g in zip(demos, fold) if g != f])
        score, m = speed_log_scores(model, [d for d, g in zip(demos, fold) if g == f])
        total, n = total + score, n + m
    assert np.allclose([info['speed_scores'][f'{w:g}'] for w in SPEED_WEIGHTS], total / n,
                       rtol=1e-9, atol=0)
    plain = calibrate(demos, lambda i: MixtureIProMP(3, speed_weight=one.speed_weight,
                                                     switch_rate=one.switch_rate,
                                                     **params).fit([demos[j] for j in i]),
                      n_jobs=1)
    assert np.allclose(one.novelty_.prefix, plain.prefix, rtol=1e-9, atol=0)
    assert np.isclose(one.novelty_.window, plain.window, rtol=1e-9, atol=0)
