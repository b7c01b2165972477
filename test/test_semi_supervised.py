"""Labels when a user has some: every recording named (the supervised mixture), a few named and
the rest learned (semi-supervised EM), through the estimator, training, the model file and
`mixture-ip train --labels`."""

from dataclasses import replace
import json

import numpy as np
import pytest
from scipy.stats import multivariate_normal, norm
from sklearn.metrics import adjusted_rand_score

from mixture_ip_ros.app.cli import main
from mixture_ip_ros.app.evaluation.interactions import (fold_metrics, fold_tasks,
                                                        interactions_config)
from mixture_ip_ros.app.training import train
from mixture_ip_ros.core.demonstration import Layout
from mixture_ip_ros.core.mixture import MixtureIProMP
from mixture_ip_ros.core.named import matched_components
from mixture_ip_ros.core.patterns import PatternMixture
from mixture_ip_ros.io.csv_files import write_csv_demonstration
from mixture_ip_ros.io.model_file import load_model
from mixture_ip_ros.scenarios.synthetic import mixture_demos

NAMES = np.array(['c', 'a', 'b'])          # pattern k is called NAMES[k]


@pytest.fixture(scope='module')
def three_patterns():
    """Three sampled Gaussian patterns (known parameters), two recordings of each named."""
    demos, labels, _, _ = mixture_demos(seed=0, n_obs=2, n_ctrl=1, n_basis=8)
    rng = np.random.default_rng(0)
    named = np.concatenate([rng.choice(np.flatnonzero(labels == k), 2, replace=False)
                            for k in range(3)])
    partial = [NAMES[k] if i in named else None for i, k in enumerate(labels)]
    return demos, NAMES[labels], partial


def _fingerprint(model):
    return [model.weights_, model.means_, model.covariances_, model.noise_var_,
            model.alpha_mean_, model.alpha_std_, model.resp_, np.array(model.log_likelihood_)]


def _monotone(model):
    """The penalised log-likelihood never decreases, up to rounding (a relative 1e-12)."""
    ll = np.array(model.log_likelihood_)
    return bool(np.all(np.diff(ll) >= -1e-12 * np.abs(ll[1:])))


def _same_to_the_bit(a, b):
    return all(np.array_equal(x, y) for x, y in zip(_fingerprint(a), _fingerprint(b)))


def test_semi_supervised_em_finds_the_unnamed_recordings_patterns_and_names_them(
        three_patterns):
    demos, truth, partial = three_patterns
    model = MixtureIProMP(3, n_basis=8).fit(demos, labels=partial)
    assert model.classes_ == ['a', 'b', 'c']
    free = np.array([p is None for p in partial])
    comp = np.argmax(model.resp_, axis=1)
    assert adjusted_rand_score(truth[free], comp[free]) == 1.0
    # every unnamed recording in the component its pattern's name names
    assert np.array_equal(np.array(model.classes_)[comp], truth)
    # the named ones' responsibilities are their names', exactly
    named = ~free
    assert np.array_equal(model.resp_[named],
                          np.eye(3)[[model.classes_.index(p) for p in np.array(partial)[named]]])
    assert _monotone(model)


def test_semi_supervised_em_of_latent_weights_never_decreases_the_penalised_likelihood(
        three_patterns):
    """method 'em' (the weights latent, eqs. 27-30): soft responsibilities, many iterations."""
    demos, truth, partial = three_patterns
    model = MixtureIProMP(3, n_basis=8, method='em', max_iter=30).fit(demos, labels=partial)
    assert model.n_iter_ > 3 and _monotone(model)
    named = np.array([p is not None for p in partial])
    assert np.array_equal(model.resp_[named], np.eye(3)[[model.classes_.index(p)
                                                         for p in np.array(partial)[named]]])
    assert np.array_equal(np.array(model.classes_)[np.argmax(model.resp_, axis=1)], truth)


def test_the_fit_is_an_em_fixed_point_checked_against_scipy_densities(three_patterns):
    """The unnamed recordings' responsibilities are eq. 7 under the fitted parameters (scipy's
    Gaussian densities of the weights and of the phase speed), and the means are eq. 9 of
    the responsibilities."""
    demos, _, partial = three_patterns
    model = MixtureIProMP(3, n_basis=8).fit(demos, labels=partial)
    W = model.demonstration_weights(demos)
    alphas = np.array([1.0 / d.duration for d in demos])
    lp = np.column_stack([
        np.log(model.weights_[k]) + multivariate_normal(model.means_[k],
                                                        model.covariances_[k]).logpdf(W)
        + norm(model.alpha_mean_[k], np.sqrt(model.alpha_var_[k])).logpdf(alphas)
        for k in range(3)])
    post = np.exp(lp - lp.max(axis=1, keepdims=True))
    post /= post.sum(axis=1, keepdims=True)
    free = np.array([p is None for p in partial])
    assert np.allclose(model.resp_[free], post[free], atol=1e-9)
    nk = model.resp_.sum(axis=0)
    assert np.allclose(model.means_, model.resp_.T @ W / nk[:, None], atol=1e-9)


def test_a_named_recording_stays_with_its_name_where_its_pattern_says_otherwise(
        three_patterns):
    demos, truth, partial = three_patterns
    wrong = list(partial)
    i = next(j for j, p in enumerate(partial) if p is None and truth[j] == 'a')
    wrong[i] = 'b'
    model = MixtureIProMP(3, n_basis=8).fit(demos, labels=wrong)
    assert model.classes_[np.argmax(model.resp_[i])] == 'b'
    assert _monotone(model)


def test_every_recording_named_is_the_supervised_fit_to_the_bit(three_patterns):
    demos, truth, _ = three_patterns
    supervised = MixtureIProMP(3, n_basis=8).fit(demos, labels=truth)
    as_list = MixtureIProMP(3, n_basis=8).fit(demos, labels=[str(t) for t in truth])
    assert _same_to_the_bit(supervised, as_list)
    assert as_list.classes_ == ['a', 'b', 'c']
    # one class each: the means are the classes' mean weights (eq. 9 with labels)
    W = supervised.demonstration_weights(demos)
    assert np.allclose(supervised.means_, [W[truth == c].mean(axis=0) for c in 'abc'])


def test_no_recording_named_is_the_unsupervised_fit_to_the_bit(three_patterns):
    demos, _, _ = three_patterns
    unsupervised = MixtureIProMP(3, n_basis=8).fit(demos)
    unnamed = MixtureIProMP(3, n_basis=8).fit(demos, labels=[None] * len(demos))
    assert unnamed.classes_ is None
    assert _same_to_the_bit(unsupervised, unnamed)


def test_components_beyond_the_names_stay_unnamed_and_too_few_are_refused(three_patterns):
    demos, _, partial = three_patterns
    model = MixtureIProMP(4, n_basis=8).fit(demos, labels=partial)
    assert model.classes_ == ['a', 'b', 'c', None]
    assert _monotone(model)
    with pytest.raises(ValueError, match='more than n_components=2'):
        MixtureIProMP(2, n_basis=8).fit(demos, labels=partial)
    with pytest.raises(ValueError, match='one entry per demonstration'):
        MixtureIProMP(3, n_basis=8).fit(demos, labels=partial[:-1])


def test_names_take_the_discovered_pattern_holding_most_of_their_recordings():
    clusters = np.array([0, 0, 1, 1, 1, 2, 2])
    index = np.array([1, -1, 0, 0, -1, -1, 1])       # name 0 in pattern 1; name 1 in 0 and 2
    assert matched_components(clusters, index, 2, 3).tolist() == [1, 0, 2]


def test_pattern_mixture_holds_fixed_rows_and_learns_the_rest():
    rng = np.random.default_rng(1)
    X = np.vstack([rng.normal(0, 0.3, (10, 2)), rng.normal(4, 0.3, (10, 2))])
    start = np.eye(2)[np.r_[np.zeros(10, int), np.ones(10, int)]]
    start[0] = [0.0, 1.0]                   # a recording of the first blob named the second's
    fixed = np.zeros(20, dtype=bool)
    fixed[[0, 5, 15]] = True
    fit = PatternMixture(2, random_state=0).fit(X, resp=start, fixed=fixed)
    assert np.array_equal(fit.resp_[fixed], start[fixed])
    assert np.array_equal(np.argmax(fit.resp_[~fixed], axis=1),
                          np.argmax(start[~fixed], axis=1))


def test_training_with_some_labels_chooses_k_at_least_their_number(three_patterns):
    demos, truth, partial = three_patterns
    model, info = train(demos, labels=partial, candidates=(1, 2, 3, 4), n_basis=8, n_jobs=1)
    assert info['selection']['candidates'] == [3, 4]
    assert model.n_components == 3 and model.classes_ == ['a', 'b', 'c']
    assert info['labelled'] == {'demonstrations': 6, 'labels': ['a', 'b', 'c']}
    assert np.array_equal(np.array(model.classes_)[np.argmax(model.resp_, axis=1)], truth)
    with pytest.raises(ValueError, match='below the 3 labels'):
        train(demos, labels=partial, candidates=(1, 2), n_basis=8, n_jobs=1)
    with pytest.raises(ValueError, match='cannot hold the 3 labels'):
        train(demos, labels=truth, n_components=4, n_basis=8, n_jobs=1)


def test_train_labels_file_names_the_components_in_the_model_file(three_patterns, tmp_path):
    demos, _, partial = three_patterns
    layout = Layout(('x', 'y'), ('c',))
    labels = {}
    for i, (d, p) in enumerate(zip(demos, partial)):
        write_csv_demonstration(tmp_path / 'csv' / f'rec_{i:02d}.csv', d, layout)
        if p is not None:
            labels[f'rec_{i:02d}'] = str(p)
        elif i % 2:
            labels[f'rec_{i:02d}.csv'] = None              # null: no label, as absent
    (tmp_path / 'labels.json').write_text(json.dumps(labels))
    out = tmp_path / 'm.npz'
    assert main(['train', '--csv', str(tmp_path / 'csv'), '--observed', 'x,y', '--controlled',
                 'c', '--labels', str(tmp_path / 'labels.json'), '--components', '4',
                 '--n-basis', '8', '--out', str(out), '--jobs', '1']) == 0
    model, meta = load_model(out)
    assert meta['classes'] == ['a', 'b', 'c', None] and model.classes_ == meta['classes']
    assert meta['component_labels'] == ['a', 'b', 'c', 'component_3']
    assert meta['extra']['training']['labelled']['demonstrations'] == 6
    assert model.novelty_ is not None
    (tmp_path / 'nobody.json').write_text(json.dumps({'someone_else': 'a'}))
    assert main(['train', '--csv', str(tmp_path / 'csv'), '--observed', 'x,y', '--controlled',
                 'c', '--labels', str(tmp_path / 'nobody.json'), '--components', '3',
                 '--n-basis', '8', '--out', str(tmp_path / 'n.npz')]) == 1


def test_the_evaluation_names_one_recording_per_interaction_and_scores_the_others(tmp_path):
    """EvalConfig.labelled_per_class: each fold's mixture with K chosen is given one training
    recording of every interaction named (semi-supervised); ``unlabelled_ari`` is on the others,
    and the confusion table counts the held-out recordings by the name recognised."""
    demos, labels, _, _ = mixture_demos(seed=3, n_obs=3, n_ctrl=3, n_basis=8, counts=(6, 6, 6))
    for d, k in zip(demos, labels):
        d.label = f'p{k}'
    config = replace(interactions_config(quick=True), candidates=(1, 2, 3, 4),
                     labelled_per_class=1)
    result = fold_tasks(demos, config, 0)[0]()
    assert result['fold']['unlabelled_ari'] == 1.0
    assert result['fold']['component_labels'] == ['p0', 'p1', 'p2']
    m = fold_metrics(demos, [result], tmp_path, config, 'one_fold', cm=True)
    assert m['unlabelled_ari'] == 1.0 and m['config']['labelled_per_class'] == 1
    held = [demos[i].label for i in result['rows']]
    names = ['p0', 'p1', 'p2']
    assert m['recognition_confusion_by_fraction']['1'] == {
        c: {d: held.count(c) if c == d else 0 for d in names} for c in names}
