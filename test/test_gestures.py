"""Real human motion: PickupGestureWiimoteZ (fetched from the aeon wheel) through the gesture
evaluation, on a CI-sized subset (4 of the 10 people), with its baselines; the evaluation's
K = 10 reference on all ten people; the .ts reader on its own."""

import json

import numpy as np
import pytest

from mixture_ip_ros.app.evaluation import evaluate
from mixture_ip_ros.app.evaluation.common import (online_component_given_end,
                                                  phase_known_components)
from mixture_ip_ros.core.mixture import MixtureIProMP
from mixture_ip_ros.core.noise import decimated_rows
from mixture_ip_ros.core.online import OnlineEstimator
from mixture_ip_ros.scenarios.synthetic import mixture_demos
from mixture_ip_ros.io.ucr import read_ts

from test_evaluation import assert_real_pngs
from test_summaries import assert_documented

KEYS = ('n_components_selected', 'unsupervised_accuracy_by_fraction',
        'unsupervised_accuracy_phase_known_by_fraction', 'supervised_accuracy_by_fraction',
        'baseline_promp_accuracy_by_fraction', 'baseline_sklearn_gmm_accuracy',
        'baseline_dtw_accuracy')


@pytest.fixture(scope='module')
def quick_gestures(tmp_path_factory):
    out = tmp_path_factory.mktemp('gestures')
    return out, evaluate('gestures', out, quick=True)


@pytest.mark.decision
def test_gesture_evaluation_reports_every_method_on_the_same_split(quick_gestures):
    out, m = quick_gestures
    assert all(k in m for k in KEYS)
    assert m['n_train'] == 20 and m['n_test'] == 20 and m['n_classes'] == 4
    assert m['source'].startswith('PickupGestureWiimoteZ')
    for key in KEYS[1:5]:
        assert set(m[key]) == {'0.3', '0.5', '0.7', '1'}, key
        assert all(0 <= v <= 1 for v in m[key].values()), key
    # Accuracies are multiples of 1/20 (20 test gestures): numbers, not placeholders.
    assert np.allclose(np.array(list(m['supervised_accuracy_by_fraction'].values())) * 20 % 1, 0)
    # The DTW baseline is far above chance on real data (a sanity check of the data and split).
    assert m['baseline_dtw_accuracy'] > 2 * m['chance_accuracy']
    # The choice of K is training's, with its curve and a verdict on it.
    sel = m['k_selection']
    assert sel['criterion'] == 'patterns' and len(sel['mean']) == len(sel['candidates']) == 6
    assert sel['chosen'] == m['n_components_selected'] and sel['prior_scale'] == m['prior_scale']
    assert isinstance(sel['clear_optimum'], bool) and sel['note']
    assert len(m['component_labels']) == m['n_components_selected']
    ref = m['reference_k_classes']
    assert ref['n_components'] == 4 and set(ref['unsupervised_accuracy_by_fraction']) == set(
        m['supervised_accuracy_by_fraction'])
    assert set(m['supervised_accuracy_phase_known_without_duration_by_fraction']) == set(
        m['supervised_accuracy_by_fraction'])
    # Once the end time is known each component reads the recording at its own warp (the
    # linear phase's case: test_online_component_given_the_end_is_the_phase_known_component_
    # of_the_whole_movement).
    for who in ('supervised', 'unsupervised'):
        assert 0 <= m[f'{who}_accuracy_given_end'] <= 1
    assert 0 <= ref['unsupervised_accuracy_given_end'] <= 1
    # The per-class ProMP baseline's ridge is chosen by cross-validation on the training set.
    assert m['baseline_promp_shrinkage'] in (1e-4, 1e-3, 1e-2, 1e-1, 1.0)
    # Labels never reach the unsupervised fit: every training gesture is in one component.
    assert np.sum(m['clusters_vs_labels']['counts']) == 20
    assert json.loads((out / 'metrics.json').read_text()) == m
    assert_real_pngs(out, m['plots'])
    assert_documented(m)


def test_ts_reader_reads_unequal_lengths_and_labels(tmp_path):
    (tmp_path / 'x.ts').write_text('# comment\n@problemName X\n@univariate true\n'
                                   '@classLabel true a b\n@data\n1,2,3:a\n4,5:b\n')
    d = read_ts(tmp_path / 'x.ts')
    assert [s.ravel().tolist() for s in d.series] == [[1, 2, 3], [4, 5]]
    assert d.labels == ['a', 'b'] and d.header['problemname'] == 'X'
    (tmp_path / 'y.ts').write_text('@classLabel true a\n@data\n1,x:a\n')
    with pytest.raises(ValueError, match=r'y\.ts, line 3: not a number'):
        read_ts(tmp_path / 'y.ts')


def test_phase_known_sees_the_samples_the_online_estimator_absorbs():
    demos = mixture_demos(seed=3, n_obs=1, n_ctrl=0, n_basis=6)[0]
    model = MixtureIProMP(3, n_basis=6).fit(demos)
    t = np.sort(np.random.default_rng(0).uniform(0, 1.5, 200))
    for min_interval in (0.0, 0.05, 0.13):
        est = OnlineEstimator(model, min_interval=min_interval)
        used = [i for i, ti in enumerate(t) if est.update(ti, [0.0])]
        assert decimated_rows(t, min_interval).tolist() == used


def test_online_component_given_the_end_is_the_phase_known_component_of_the_whole_movement():
    demos = mixture_demos(seed=4, n_obs=1, n_ctrl=0, n_basis=6)[0]
    model = MixtureIProMP(3, n_basis=6).fit(demos[::2])
    for d in demos[1::2]:
        for min_interval in (0.0, 0.05):
            assert online_component_given_end(model, d, 20, min_interval) == \
                phase_known_components(model, d, [1.0], min_interval)[0]


@pytest.mark.decision
def test_ten_components_started_from_the_patterns_name_the_ten_people_online():
    """All ten people, K = 10 given (the evaluation's reference): the mixture's EM starts from
    the pattern space's clusters, so how it treats when a person moves shows here. With the
    alignment unconstrained it forgave that and named 24-32 % of the held-out gestures online;
    within the band (core.pattern_space.BAND) 32-48 %, as at equal phases (36-44 %)."""
    from mixture_ip_ros.app.evaluation.common import majority_labels, named_online
    from mixture_ip_ros.app.evaluation.gestures import GESTURE_FRACTIONS, gesture_config
    from mixture_ip_ros.scenarios.gestures import gesture_demonstrations
    config = gesture_config()
    train, test = gesture_demonstrations('train'), gesture_demonstrations('test')
    model = MixtureIProMP(n_components=10, random_state=0, **config.model).fit(train)
    names = majority_labels(model, train)
    said = named_online(model, names, test, GESTURE_FRACTIONS, config.n_alpha,
                        config.min_interval)
    right = np.mean(said == np.array([d.label for d in test])[:, None], axis=0)
    assert right.mean() >= 0.35, right
