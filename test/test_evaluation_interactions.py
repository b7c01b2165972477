"""`mixture-ip evaluate` on real interactions and on your own labelled recordings: patterns
found without labels against the labels, online recognition and the partner predicted, each
against baselines on the same folds."""

import json

import numpy as np
import pytest

from mixture_ip_ros.app.cli import main
from mixture_ip_ros.app.evaluation.interactions import (_at_contact, confusion, contact_row,
                                                        stratified_folds)
from mixture_ip_ros.core.demonstration import Layout
from mixture_ip_ros.io.csv_files import write_csv_demonstration
from mixture_ip_ros.scenarios.synthetic import mixture_demos

from test_evaluation import assert_real_pngs
from test_summaries import assert_documented

KEYS = ('n_components_selected', 'ari', 'heldout_ari', 'recognition_accuracy_by_fraction',
        'partner_rms_cm_by_fraction', 'partner_final_cm_by_fraction', 'baseline_kmeans_ari',
        'baseline_gmm_pca_ari', 'baseline_nn_accuracy_by_fraction',
        'baseline_nn_partner_rms_cm_by_fraction', 'single_partner_rms_cm_by_fraction',
        'supervised_partner_rms_cm_by_fraction', 'supervised_accuracy_by_fraction',
        'true_k_accuracy_by_fraction', 'phase_known_accuracy_by_fraction',
        'recognition_accuracy_by_interaction', 'partner_contact_cm_by_fraction',
        'baseline_nn_partner_contact_cm_by_fraction', 'phase_error_by_fraction',
        'people_contact_distance_cm')


def test_folds_hold_every_label_in_proportion():
    labels = np.repeat(['a', 'b', 'c'], [12, 10, 7])
    fold = stratified_folds(labels, 5, seed=0)
    for lbl in 'abc':
        counts = np.bincount(fold[labels == lbl], minlength=5)
        assert counts.max() - counts.min() <= 1
    assert np.array_equal(fold, stratified_folds(labels, 5, seed=0))


def _write(root, demos, layout):
    (root / 'csv').mkdir()
    labels = {}
    for i, d in enumerate(demos):
        write_csv_demonstration(root / 'csv' / f'rec_{i:02d}.csv', d, layout)
        labels[f'rec_{i:02d}'] = str(d.label)
    (root / 'labels.json').write_text(json.dumps(labels))


@pytest.mark.decision
def test_your_own_labelled_csv_recordings(tmp_path, capsys):
    demos, labels, _, _ = mixture_demos(seed=3, n_obs=3, n_ctrl=3, n_basis=8)
    for d, lbl in zip(demos, labels):
        d.label = f'pattern_{lbl}'
    layout = Layout(('hx', 'hy', 'hz'), ('px', 'py', 'pz'), ('m',) * 3, ('m',) * 3)
    _write(tmp_path, demos, layout)
    out = tmp_path / 'out'
    assert main(['evaluate', '--csv', str(tmp_path / 'csv'), '--labels',
                 str(tmp_path / 'labels.json'), '--observed', 'hx,hy,hz', '--controlled',
                 'px,py,pz', '--observed-units', 'm', '--controlled-units', 'm', '--out',
                 str(out), '--quick', '--json', str(tmp_path / 'm.json')]) == 0
    m = json.loads((out / 'metrics.json').read_text())
    assert json.loads((tmp_path / 'm.json').read_text()) == m
    printed = capsys.readouterr()
    assert 'K per fold 3, 3, 3, 3, 3' in printed.out and len(printed.out.splitlines()) < 25
    assert printed.err.count(': fold ') == 5
    assert all(k in m for k in KEYS)
    assert_documented(m)
    assert m['n_components_selected'] == [3] * 5
    assert m['ari'] == 1.0 and m['heldout_ari'] == 1.0 and m['baseline_kmeans_ari'] == 1.0
    assert m['recognition_accuracy_by_fraction']['1'] == 1.0
    # which interaction was recognised for which: at the end, every recording its own
    names = [f'pattern_{k}' for k in range(3)]
    sizes = {c: int(np.sum(labels == k)) for k, c in enumerate(names)}
    confusion = m['recognition_confusion_by_fraction']
    assert set(confusion) == {'0.5', '1'}
    assert confusion['1'] == {c: {d: sizes[c] if c == d else 0 for d in names} for c in names}
    assert {c: sum(row.values()) for c, row in confusion['0.5'].items()} == sizes
    assert set(m['partner_rms_cm_by_fraction']) == {'0.3', '0.5', '0.7', '1'}
    assert m['partner_rms_cm_by_fraction']['1'] is None           # nothing left to predict
    for f in ('0.3', '0.5', '0.7'):
        assert m['partner_rms_cm_by_fraction'][f] < m['single_partner_rms_cm_by_fraction'][f]
    assert_real_pngs(out, m['plots'])


def test_bad_labels_are_one_line_errors(tmp_path, capsys):
    demos, labels, _, _ = mixture_demos(seed=3, n_obs=1, n_ctrl=1, n_basis=8)
    layout = Layout(('x',), ('y',))
    for d, lbl in zip(demos, labels):
        d.label = str(lbl)
    _write(tmp_path, demos, layout)
    (tmp_path / 'partial.json').write_text(json.dumps({'rec_00': 'a'}))
    (tmp_path / 'list.json').write_text('[1, 2]')
    for labels_file, message in (('partial.json', 'no label for'), ('list.json', 'JSON object'),
                                 ('missing.json', 'not a readable JSON file')):
        assert main(['evaluate', '--csv', str(tmp_path / 'csv'), '--labels',
                     str(tmp_path / labels_file), '--observed', 'x', '--controlled', 'y',
                     '--out', str(tmp_path / 'o')]) == 1
        err = capsys.readouterr().err.strip()
        assert message in err and len(err.splitlines()) == 1, err
    with pytest.raises(SystemExit) as exit_:        # options that contradict: argparse's 2
        main(['evaluate', '--scenario', 'pole', '--csv', str(tmp_path / 'csv'),
              '--out', str(tmp_path / 'o')])
    assert exit_.value.code == 2 and 'one of them' in capsys.readouterr().err


@pytest.fixture(scope='module')
def nuisi_v2(tmp_path_factory):
    from mixture_ip_ros.app.evaluation.interactions import evaluate_nuisi, interactions_config
    from mixture_ip_ros.io.cache import cache_dir
    from mixture_ip_ros.scenarios import nuisi
    if not (cache_dir() / 'nuisi' / nuisi.VERSIONS['v2'].file).is_file():
        pytest.skip('NuiSI v2 is not in the user cache (./dev seeds it)')
    out = tmp_path_factory.mktemp('nuisi')
    return out, evaluate_nuisi(out, interactions_config(quick=True), versions=('v2',))['v2']


def test_the_contact_is_where_the_two_agents_are_closest():
    """Two hands moving towards each other along x meet at t = 0.5 (sample 5); with that
    sample of the partner lost, the closest recorded one is the first of its neighbours. The
    error there counts only if the contact is still to come."""
    from mixture_ip_ros.core.demonstration import Demonstration
    t = np.linspace(0.0, 1.0, 11)
    zero = np.zeros_like(t)
    observed, controlled = np.column_stack([t, zero, zero]), np.column_stack([1 - t, zero, zero])
    assert contact_row(Demonstration(t, observed, controlled)) == 5
    controlled[5] = np.nan
    assert contact_row(Demonstration(t, observed, controlled)) == 4
    assert contact_row(Demonstration(t, observed, controlled[:, :2])) is None
    rest = np.arange(3, 11)
    pred = controlled[rest] + [0.0, 0.03, 0.04]
    assert _at_contact(pred, rest, 4, controlled) == pytest.approx(0.05)
    assert np.isnan(_at_contact(pred[2:], rest[2:], 4, controlled))


@pytest.mark.decision
def test_the_four_interactions_of_real_people_are_found_without_labels(nuisi_v2):
    out, m = nuisi_v2
    assert all(k in m for k in KEYS)
    assert m['n_recordings'] == 44 and len(m['interactions']) == 4
    # K inside each fold, from its 35 training recordings (found: 4 in every fold, ARI 1.00,
    # held-out 0.94; recognised online 100 / 98 / 100 / 95 % at 30 / 50 / 70 / 100 % of the
    # movement, the supervised mixture 100 / 98 / 100 / 98, the nearest recording by DTW
    # 93 / 95 / 98 / 100; the partner at half the movement 22.0 cm off, the nearest
    # recording's 23.8). Discovery costs at most one recording against the supervised mixture
    # at any fraction; at 30-70 % the mixture is at least the nearest recording. At the end of
    # the movement (no 'end' given) it is two recordings below the nearest: a linear phase
    # reading the last of a movement whose pace changed (issue 49, item 2, open).
    assert sum(3 <= k <= 5 for k in m['n_components_selected']) == 5
    assert sum(k == 4 for k in m['n_components_selected']) >= 4
    assert m['ari'] >= 0.95 and m['heldout_ari'] >= 0.85
    nearest = m['baseline_nn_accuracy_by_fraction']
    supervised = m['supervised_accuracy_by_fraction']
    one = 1.0 / m['n_recordings'] + 1e-9
    for f, acc in m['recognition_accuracy_by_fraction'].items():
        assert acc >= supervised[f] - one and (f == '1' or acc >= nearest[f]), f
    assert m['recognition_accuracy_by_fraction']['0.5'] >= 0.9
    assert m['true_k_accuracy_by_fraction']['0.5'] >= 0.9
    assert m['supervised_accuracy_by_fraction']['0.5'] >= 0.9
    # the contact and the phase, measured (issue 32 sets the aims): finite where the contact
    # is still to come, and a phase within half a movement
    assert 0 < m['partner_contact_cm_by_fraction']['0.3'] < 100
    assert 0 < m['people_contact_distance_cm'] < 50
    assert all(0 <= e < 0.5 for e in m['phase_error_by_fraction'].values())
    rms = m['partner_rms_cm_by_fraction']['0.5']
    assert rms < m['single_partner_rms_cm_by_fraction']['0.5']
    assert rms < m['baseline_nn_partner_rms_cm_by_fraction']['0.5']
    # the accuracy per interaction averages, weighted by their recordings, to the overall one
    counts = {'handshake': 11, 'parachute_fistbump': 9, 'rocket_fistbump': 12, 'waving': 12}
    by = m['recognition_accuracy_by_interaction']
    assert set(by) == set(counts)
    assert np.isclose(sum(counts[c] * by[c]['0.5'] for c in counts) / 44,
                      m['recognition_accuracy_by_fraction']['0.5'])
    # the confusion table's diagonal is that accuracy, its rows the interactions' recordings
    half = m['recognition_confusion_by_fraction']['0.5']
    assert {c: sum(row.values()) for c, row in half.items()} == counts
    assert np.isclose(sum(half[c][c] for c in counts) / 44,
                      m['recognition_accuracy_by_fraction']['0.5'])
    assert_real_pngs(out, m['plots'])
    assert_documented(m)


def test_the_confusion_table_counts_each_label_by_the_name_recognised():
    truth = np.array(['a', 'a', 'b', 'b', 'b'])
    said = np.array(['a', 'b', 'b', 'b', 'component_2'], dtype=object)
    assert confusion(truth, said, ['a', 'b']) == {
        'a': {'a': 1, 'b': 1, 'component_2': 0}, 'b': {'a': 0, 'b': 2, 'component_2': 1}}
