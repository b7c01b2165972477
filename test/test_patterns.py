"""Pattern discovery (core.patterns): the mixture's EM against scikit-learn's, the
leave-one-out curve against the straightforward loop, and the patterns found where weights
hide them."""

import numpy as np
import pytest

from mixture_ip_ros.core.basis import GaussianBasis
from mixture_ip_ros.core.mixture import MixtureIProMP
from mixture_ip_ros.core.patterns import (PatternMixture, adjusted_rand_index, heldout_curve,
                                          partition_stability)
from mixture_ip_ros.core.selection import selection_curve
from mixture_ip_ros.scenarios.synthetic import mixture_demos


def test_the_gram_matrix_is_the_integral_of_the_basis_products():
    basis = GaussianBasis(15)
    z = (np.arange(200_000) + 0.5) / 200_000              # midpoint rule
    psi = basis(z)
    assert np.allclose(basis.gram(), psi.T @ psi / len(z), atol=1e-9)


def test_without_shrinkage_the_normal_mixture_is_scikit_learns_em():
    """Normal components (dof = inf), shrinkage and floor off, the same starting parameters:
    the EM converges to scikit-learn's full-covariance GaussianMixture, and scores samples as
    it does."""
    from sklearn.mixture import GaussianMixture
    rng = np.random.default_rng(2)
    X = np.vstack([rng.normal([0, 0], [1.0, 0.5], (40, 2)),
                   rng.normal([4, 1], [0.6, 1.2], (30, 2)),
                   rng.normal([1, 5], [0.8, 0.8], (30, 2))])
    start = np.eye(3)[np.repeat([0, 1, 2], [40, 30, 30])]
    first = PatternMixture(3, prior_strength=0.0, floor=0.0, max_iter=1,
                           dof=np.inf).fit(X, resp=start)
    ours = PatternMixture(3, prior_strength=0.0, floor=0.0, tol=1e-14, max_iter=1000,
                          dof=np.inf).fit(X, resp=start)
    sk = GaussianMixture(3, covariance_type='full', reg_covar=0.0, tol=1e-14, max_iter=1000,
                         weights_init=first.weights_, means_init=first.means_,
                         precisions_init=np.linalg.inv(first.covariances_)).fit(X)
    assert np.allclose(ours.means_, sk.means_, atol=1e-6)
    assert np.allclose(ours.covariances_, sk.covariances_, atol=1e-6)
    assert np.allclose(ours.weights_, sk.weights_, atol=1e-6)
    assert np.allclose(ours.score_samples(X), sk.score_samples(X), atol=1e-6)
    assert np.array_equal(ours.predict(X), sk.predict(X))


def test_the_t_mixture_recovers_sampled_parameters_and_scores_as_scipy():
    """Two t components of 4 degrees of freedom sampled with known parameters: EM without
    shrinkage recovers weights, means and scale matrices, and the mixture's density is
    scipy's multivariate t's."""
    from scipy.stats import multivariate_t
    rng = np.random.default_rng(7)
    means = np.array([[0.0, 0.0, 0.0], [6.0, -2.0, 1.0]])
    scales = np.array([[[1.0, 0.3, 0.0], [0.3, 0.5, 0.1], [0.0, 0.1, 0.8]],
                       [[0.6, -0.2, 0.0], [-0.2, 1.2, 0.0], [0.0, 0.0, 0.4]]])
    n = (30000, 20000)
    X = np.vstack([multivariate_t(means[k], scales[k], df=4).rvs(n[k], random_state=rng)
                   for k in range(2)])
    fit = PatternMixture(2, prior_strength=0.0, floor=0.0, n_init=3, tol=1e-12).fit(X)
    order = np.argsort(fit.means_[:, 0])
    assert np.allclose(fit.weights_[order], [0.6, 0.4], atol=0.01)
    assert np.allclose(fit.means_[order], means, atol=0.03)
    assert np.allclose(fit.covariances_[order], scales, atol=0.05)
    dense = np.log(sum(w * multivariate_t(m, c, df=4).pdf(X[:50]) for w, m, c in
                       zip(fit.weights_, fit.means_, fit.covariances_)))
    assert np.allclose(fit.score_samples(X[:50]), dense, rtol=1e-10, atol=1e-10)
    with pytest.raises(ValueError, match='dof'):
        PatternMixture(2, dof=0.0).fit(X)


def test_shrinkage_pulls_every_covariance_towards_the_pooled_one():
    rng = np.random.default_rng(3)
    X = np.vstack([rng.normal(0, [1.0, 0.1], (8, 2)), rng.normal(5, [0.1, 1.0], (8, 2))])
    free = PatternMixture(2, prior_strength=0.0, n_init=3).fit(X)
    shrunk = PatternMixture(2, prior_strength=1e6, n_init=3).fit(X)
    assert not np.allclose(free.covariances_[0], free.covariances_[1], rtol=0.5)
    assert np.allclose(shrunk.covariances_[0], shrunk.covariances_[1], rtol=1e-4)


def test_the_leave_one_out_curve_is_the_loop_of_one_fit_per_demonstration():
    rng = np.random.default_rng(4)
    X = np.vstack([rng.normal(0, 1, (8, 2)), rng.normal(6, 1, (8, 2))])
    held = heldout_curve(X, [1, 2])
    whole = {K: PatternMixture(K).fit(X) for K in (1, 2)}
    for a, K in enumerate((1, 2)):
        for i in range(len(X)):
            keep = np.arange(len(X)) != i
            m = PatternMixture(K).fit(X[keep], resp=whole[K].resp_[keep])
            assert held.loglik[a, i] == pytest.approx(m.score_samples(X[i:i + 1])[0], abs=1e-12)
    eps = 1 / len(X)
    assert np.allclose(held.robust, np.log((1 - eps) * np.exp(held.loglik)
                                           + eps * np.exp(held.loglik[0])))
    assert held.robust[1].mean() > held.robust[0].mean()      # two clusters: K = 2 is better


def test_an_outlier_does_not_decide_the_number_of_patterns():
    """Two tight clusters and one recording half-way between them. Under normal components
    that one, held out, is hundreds of nats less likely under two patterns than under one
    broad Gaussian, more than every other demonstration gains; under the t components its
    cost is bounded, and the robust score bounds it by log n in any case."""
    rng = np.random.default_rng(5)
    X = np.vstack([rng.normal(0, 0.1, (10, 2)), rng.normal(3, 0.1, (10, 2)), [[1.5, 1.5]]])
    rest = X[:-1]
    normal = [PatternMixture(K, dof=np.inf).fit(rest).score_samples(X[-1:])[0] for K in (1, 2)]
    assert normal[1] - normal[0] < -100
    held = heldout_curve(X, [1, 2])
    gain = held.loglik[1] - held.loglik[0]
    assert np.all(gain[:-1] > 0) and -50 < gain[-1] < 0 and gain.mean() > 0.5
    robust_gain = held.robust[1] - held.robust[0]
    assert robust_gain[-1] >= -np.log(len(X)) - 1e-9
    assert robust_gain.mean() > 0.5


@pytest.mark.decision
def test_one_atypical_demonstration_does_not_take_a_component_of_its_own():
    """Two close patterns, a far one and one atypical member of the far one. Under normal
    components the highest likelihood puts the atypical one alone and merges the close two
    (the spurious maximum); the mixture keeps the best partition whose every component holds
    two demonstrations, and the t components find the patterns even without that rule."""
    for seed in range(3):
        rng = np.random.default_rng(seed)
        X = np.vstack([rng.normal([0, 0], 0.5, (10, 2)), rng.normal([3, 0], 0.5, (10, 2)),
                       rng.normal([0, 10], 0.5, (10, 2)), [[6.0, 16.0]]])
        truth = np.repeat([0, 1, 2, 2], [10, 10, 10, 1])
        spurious = PatternMixture(3, min_members=1, dof=np.inf).fit(X)
        assert sorted(np.bincount(spurious.predict(X))) == [1, 10, 20]
        kept = PatternMixture(3, dof=np.inf).fit(X)
        assert adjusted_rand_index(truth, kept.predict(X)) == 1.0
        assert spurious.log_likelihood_ > kept.log_likelihood_
        t_alone = PatternMixture(3, min_members=1).fit(X)
        assert adjusted_rand_index(truth, t_alone.predict(X)) == 1.0
    with pytest.raises(ValueError, match='min_members'):
        PatternMixture(2, min_members=0).fit(X)


@pytest.mark.decision
def test_real_interactions_are_found_in_the_path_metric():
    """NuiSI v2 (four interactions of two people, where the user cache has it): the mixture's
    start finds the interactions (k-means of the standardised weights, the start before the
    path metric, got an adjusted Rand index of 0.35-0.50)."""
    from sklearn.metrics import adjusted_rand_score
    from mixture_ip_ros.io.cache import cache_dir
    from mixture_ip_ros.scenarios import nuisi
    if not (cache_dir() / 'nuisi' / nuisi.VERSIONS['v2'].file).is_file():
        pytest.skip('NuiSI v2 is not in the user cache (./dev seeds it)')
    demos = nuisi.demonstrations('v2', 'train') + nuisi.demonstrations('v2', 'test')
    labels = [d.label for d in demos]
    for seed in (0, 1, 2):
        model = MixtureIProMP(4, random_state=seed)
        found = model.initial_clusters(model.prepare(demos))
        assert adjusted_rand_score(labels, found) == 1.0, seed


@pytest.mark.decision
def test_the_number_of_real_interactions_is_chosen():
    """NuiSI v2 (where the user cache has it): training chooses the four interactions, and
    its components are they. With t components three patterns (the two fist-bumps merged) are
    more than two standard errors worse held out than four, and four is reproduced exactly in
    most subsample pairs (median agreement 1), more than any larger K (each of which splits
    one interaction where the subsample puts it)."""
    from sklearn.metrics import adjusted_rand_score
    from mixture_ip_ros.app.training import train
    from mixture_ip_ros.io.cache import cache_dir
    from mixture_ip_ros.scenarios import nuisi
    if not (cache_dir() / 'nuisi' / nuisi.VERSIONS['v2'].file).is_file():
        pytest.skip('NuiSI v2 is not in the user cache (./dev seeds it)')
    demos = nuisi.demonstrations('v2', 'train') + nuisi.demonstrations('v2', 'test')
    model, info = train(demos, candidates=range(1, 8))
    assert info['n_components'] == 4
    stability = info['selection']['stability']
    assert 3 not in stability and stability[4] == 1.0 == max(stability.values())
    assert sorted(stability)[0] == 4 and all(stability[K] < 1.0 for K in stability if K > 4)
    assert adjusted_rand_score([d.label for d in demos], np.argmax(model.resp_, axis=1)) == 1.0


@pytest.mark.decision
def test_sampled_patterns_are_found_and_their_number_chosen():
    from mixture_ip_ros.app.training import train
    from sklearn.metrics import adjusted_rand_score
    demos, labels, _, _ = mixture_demos(seed=2, n_obs=2, n_ctrl=2)
    model, info = train(demos, candidates=range(1, 6), n_basis=8)
    assert info['n_components'] == 3 and info['selection']['clear_optimum']
    assert adjusted_rand_score(labels, model.resp_.argmax(axis=1)) == 1.0


def test_the_adjusted_rand_index_is_scikit_learns():
    from sklearn.metrics import adjusted_rand_score
    rng = np.random.default_rng(0)
    for n, ka, kb in [(30, 3, 4), (12, 2, 2), (50, 6, 1), (7, 1, 1), (20, 5, 5)]:
        a, b = rng.integers(ka, size=n), rng.integers(kb, size=n)
        for x, y in [(a, b), (a, a), (a, (a + 1) % ka)]:
            assert adjusted_rand_index(x, y) == pytest.approx(adjusted_rand_score(x, y),
                                                              abs=1e-12)


def test_a_partition_the_data_hold_is_reproducible_and_an_arbitrary_one_is_not():
    """Three equidistant clusters: three components find them from every subsample; two must
    merge a pair of them, and which pair each subsample merges is arbitrary; four split one of
    them where its members happen to fall."""
    rng = np.random.default_rng(3)
    centres = 4 * np.array([[0, 0], [1, 0], [0.5, np.sqrt(0.75)]])
    X = np.vstack([c + rng.normal(0, 0.3, (15, 2)) for c in centres])
    S = partition_stability(X, [1, 2, 3, 4], n_pairs=20)
    assert S.shape == (4, 20)
    assert np.all(S[0] == 1) and np.all(S[2] == 1)
    assert S[1].mean() < 0.8 and S[3].mean() < 0.95


@pytest.mark.decision
def test_the_plateau_keeps_the_smallest_k_whose_partition_is_as_reproducible():
    """Held-out scores that cannot tell K = 2..4 apart: by default the smallest; with a second
    criterion, its choice among those three only."""
    rng = np.random.default_rng(0)
    base = rng.normal(0, 1, 40)
    scores = np.vstack([base - 5, base, base, base, base - 5])
    assert selection_curve(scores, True, paired=True)['index'] == 1
    seen = []
    curve = selection_curve(scores, True, paired=True,
                            choose=lambda plateau: seen.append(plateau) or plateau[-1])
    assert seen == [[1, 2, 3]] and curve['index'] == 3
    with pytest.raises(ValueError):
        selection_curve(scores, True, paired=True, choose=lambda plateau: 0)


def _plain_ecm(X, R, prior_strength, floor, dof, tol, max_iter):
    """One ECM run of PatternMixture written out per component from the formulas (scipy's
    multivariate t for the densities): (log-likelihood, weights, means, scales, the
    responsibilities they came from, iteration) of its best iteration."""
    from scipy.special import logsumexp
    from scipy.stats import multivariate_t
    n, q = X.shape
    K = R.shape[1]
    tiny = 10 * np.finfo(float).eps
    U, prev, best = np.ones_like(R), -np.inf, None
    for it in range(1, max_iter + 1):
        nk = R.sum(axis=0) + tiny
        RU = R * U
        means = np.array([RU[:, k] @ X / (RU[:, k].sum() + tiny) for k in range(K)])
        scatter = [(RU[:, k, None] * (X - means[k])).T @ (X - means[k]) for k in range(K)]
        pooled = sum(scatter) / n
        covs = np.array([(scatter[k] + prior_strength * pooled) / (nk[k] + prior_strength)
                         + np.diag(floor) for k in range(K)])
        lp = np.log(nk / n) + np.column_stack(
            [multivariate_t(means[k], covs[k], df=dof).logpdf(X) for k in range(K)])
        norm = logsumexp(lp, axis=1)
        ll = norm.sum()
        if best is None or ll > best[0]:
            best = (ll, nk / n, means, covs, R, it)
        R = np.exp(lp - norm[:, None])
        dist = np.column_stack([np.sum((X - means[k]) @ np.linalg.inv(covs[k]) * (X - means[k]),
                                       axis=1) for k in range(K)])
        U = (dof + q) / (dof + dist)
        if ll - prev <= tol * max(1.0, abs(ll)):
            break
        prev = ll
    return best


def test_fits_side_by_side_are_each_set_s_own_ecm():
    """fit_many runs every start of every data set in one batch, each stopping on its own:
    each set's fit is the plain ECM of its own data from its own start (written out per
    component, scipy's t density), and with k-means starts the start kept is the plain loop's
    best among those with two members per component."""
    from mixture_ip_ros.core.kmeans import kmeans
    rng = np.random.default_rng(8)
    X = np.vstack([c + rng.normal(0, 0.4, (10, 3)) for c in rng.normal(0, 2, (3, 3))])
    subsets = [np.sort(rng.choice(len(X), 24, replace=False)) for _ in range(4)]
    starts = [np.eye(3)[rng.integers(3, size=24)] for _ in subsets]
    mixture = PatternMixture(3, tol=1e-10)
    fits = mixture.fit_many([X[s] for s in subsets], starts)
    iterations = set()
    for s, R, fit in zip(subsets, starts, fits):
        ll, w, mu, cov, resp, it = _plain_ecm(X[s], R, 10.0, 1e-6 * X[s].var(axis=0), 4.0,
                                              1e-10, 200)
        iterations.add(it)
        assert fit.n_iter_ == it
        assert fit.log_likelihood_ == pytest.approx(ll, rel=1e-10)
        assert np.allclose(fit.weights_, w, rtol=1e-9, atol=1e-12)
        assert np.allclose(fit.means_, mu, rtol=1e-9, atol=1e-12)
        assert np.allclose(fit.covariances_, cov, rtol=1e-9, atol=1e-12)
        assert np.allclose(fit.resp_, resp, rtol=1e-9, atol=1e-12)
    assert len(iterations) > 1                  # the runs did stop at different iterations
    # k-means starts: the best of the plain runs.
    fit = PatternMixture(3, n_init=5, tol=1e-10).fit(X)
    seeds = np.random.default_rng(0).integers(2 ** 31, size=5)
    runs = [_plain_ecm(X, np.eye(3)[kmeans(X, 3, random_state=int(seed), n_init=1)], 10.0,
                       1e-6 * X.var(axis=0), 4.0, 1e-10, 200) for seed in seeds]
    ok = [r for r in runs if np.bincount(np.argmax(r[4], axis=1), minlength=3).min() >= 2]
    assert fit.log_likelihood_ == pytest.approx(max(r[0] for r in ok or runs), rel=1e-10)


def test_k_means_runs_side_by_side_are_each_seed_s_own_run():
    from mixture_ip_ros.core.kmeans import kmeans, kmeans_runs
    rng = np.random.default_rng(9)
    X = np.vstack([c + rng.normal(0, 0.8, (15, 2)) for c in ([0, 0], [3, 0], [1.5, 2.5])])
    seeds = [11, 5, 2 ** 30, 7]
    got = kmeans_runs(X, 4, seeds)
    assert np.array_equal(got, [kmeans(X, 4, random_state=s, n_init=1) for s in seeds])
    assert len({tuple(g) for g in got}) > 1     # the seeds found different partitions


def _pairs_of_patterns(seed, n_each=4):
    """(n, 2) points of four patterns in two pairs, ``n_each`` demonstrations each: within a
    pair the patterns are six standard deviations apart along the second coordinate, the pairs
    twenty along the first."""
    rng = np.random.default_rng(seed)
    centres = np.array([[0, 0], [0, 3], [10, 0], [10, 3]], dtype=float)
    return np.vstack([c + rng.normal(0, 0.5, (n_each, 2)) for c in centres])


@pytest.mark.decision
def test_four_recordings_of_each_pattern_are_enough_to_keep_patterns_apart(monkeypatch):
    """With four demonstrations of each pattern one paired standard error is as large as the
    held-out gain of splitting each pair, and parsimony alone merges the pairs (K = 2) in most
    draws; splitting them is as reproducible and strongly better held out (EVIDENCE_NATS), so
    four are kept. A split the observed agent's paths do not hold (here: its coordinates
    tell the pairs apart only) is not: the robot could not tell its parts apart online."""
    from mixture_ip_ros.core import selection
    from mixture_ip_ros.core.selection import patterns_in_space
    draws = [_pairs_of_patterns(seed) for seed in range(8)]
    chosen = [patterns_in_space(X, range(1, 7))['chosen'] for X in draws]
    unseen = [patterns_in_space(X, range(1, 7), observed=X[:, :1])['chosen'] for X in draws]
    monkeypatch.setattr(selection, 'EVIDENCE_NATS', np.inf)
    parsimony = [patterns_in_space(X, range(1, 7))['chosen'] for X in draws]
    # measured: 4 in 5 of 8 draws (one 5, two 2), by parsimony 4 in 3 (the others 2)
    assert parsimony.count(2) >= 4, parsimony
    assert all(c >= p for c, p in zip(chosen, parsimony)), (chosen, parsimony)
    assert chosen.count(4) > parsimony.count(4) and chosen.count(2) < parsimony.count(2), (
        chosen, parsimony)
    assert unseen == parsimony, (unseen, parsimony)
