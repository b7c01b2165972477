"""What the commands say when they finish: `train`, `evaluate` and `demo` print a few lines a
person reads and write the full JSON to a file (--json); `info` summarises a model file;
`evaluate --model` scores a trained model without retraining; every key of the JSON is
described in docs/metrics.md."""

import contextlib
import io
import json
from pathlib import Path
import re

import numpy as np
import pytest

from mixture_ip_ros.app.cli import main
from mixture_ip_ros.app.summary import demo_summary, evaluate_summary, train_summary
from mixture_ip_ros.core.demonstration import Layout
from mixture_ip_ros.core.online import OnlineEstimator
from mixture_ip_ros.io.csv_files import load_csv_dataset, write_csv_demonstration
from mixture_ip_ros.io.model_file import load_model
from mixture_ip_ros.scenarios.synthetic import mixture_demos

ROOT = Path(__file__).resolve().parents[1]
LAYOUT = Layout(('hx', 'hy', 'hz'), ('px', 'py', 'pz'), ('m',) * 3, ('m',) * 3)
# a row of the pattern table: pattern, members, weight, duration, name
ROW = re.compile(r'^\s+(\d+)\s+(\d+|-)\s+([\d.]+)\s+([\d.]+) s\s+(\S+)$')


def documented_keys() -> set:
    """Every `key` docs/metrics.md names (a{b,c}d stands for abd and acd)."""
    keys = set()
    for word in re.findall(r'`([a-z0-9_{},]+)`', (ROOT / 'docs' / 'metrics.md').read_text()):
        m = re.fullmatch(r'(.*)\{([^}]*)\}(.*)', word)
        keys |= {m[1] + x + m[3] for x in m[2].split(',')} if m else {word}
    return keys


def assert_documented(metrics):
    missing = sorted(set(metrics) - documented_keys())
    assert not missing, f'not described in docs/metrics.md: {missing}'


def _run(argv):
    """main(argv) with its stdout and stderr captured: (exit code, out, err)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in argv])
    return code, out.getvalue(), err.getvalue()


@pytest.fixture(scope='module')
def recordings(tmp_path_factory):
    """Three well separated patterns of six CSV recordings each (a hand observed, a partner's
    hand controlled, in metres) and their labels."""
    root = tmp_path_factory.mktemp('summaries')
    demos, labels, _, _ = mixture_demos(seed=3, n_obs=3, n_ctrl=3, n_basis=8, counts=(6, 6, 6))
    (root / 'csv').mkdir()
    names = {}
    for i, (d, lbl) in enumerate(zip(demos, labels)):
        write_csv_demonstration(root / 'csv' / f'rec_{i:02d}.csv', d, LAYOUT)
        names[f'rec_{i:02d}'] = f'pattern_{lbl}'
    (root / 'labels.json').write_text(json.dumps(names))
    return root, names


@pytest.fixture(scope='module')
def trained(recordings):
    """`mixture-ip train` on the recordings: (model path, stdout, the --json file's summary)."""
    root, _ = recordings
    code, out, err = _run(['train', '--csv', root / 'csv', '--observed', 'hx,hy,hz',
                           '--controlled', 'px,py,pz', '--observed-units', 'm',
                           '--controlled-units', 'm', '--n-basis', '8', '--max-components', '4',
                           '--out', root / 'model.npz', '--json', root / 'train.json'])
    assert code == 0, err
    return root / 'model.npz', out, json.loads((root / 'train.json').read_text())


def _table(text):
    return [ROW.match(line).groups() for line in text.splitlines() if ROW.match(line)]


def test_train_prints_the_patterns_found_and_writes_the_full_summary_with_json(trained,
                                                                              recordings):
    path, out, summary = trained
    root, names = recordings
    lines = out.splitlines()
    assert len(lines) <= 12 and '{' not in out
    assert lines[0] == f'{path}: 3 patterns in 18 recordings'
    assert 'K = 3 chosen over 1..4 by the held-out likelihood of the patterns: a clear optimum' \
        in out
    model, _ = load_model(path)
    rows = _table(out)
    assert [int(r[0]) for r in rows] == [0, 1, 2]
    # Each generated pattern's six recordings in one component of their own.
    assert [int(r[1]) for r in rows] == summary['component_sizes'] == [6, 6, 6]
    assert [float(r[2]) for r in rows] == list(np.round(model.weights_, 2))
    # A component's mean duration: the harmonic mean of its members' (alpha = 1/T each).
    demos = load_csv_dataset(root / 'csv', LAYOUT)
    harmonic = sorted(round(1.0 / np.mean([1.0 / d.duration for d in demos
                                           if names[Path(d.name).stem] == lbl]), 2)
                      for lbl in sorted(set(names.values())))
    assert sorted(float(r[3]) for r in rows) == harmonic
    assert all(r[4] == '-' for r in rows)                 # unlabelled recordings: no names
    assert summary['model'] == str(path) and summary['selection']['chosen'] == 3
    assert_documented(summary)


def test_a_flat_k_curve_says_what_to_try():
    info = {'n_components': 1, 'n_demonstrations': 7, 'component_sizes': [7],
            'selection': {'criterion': 'patterns', 'candidates': [1, 2, 3],
                          'mean': [0.5, 0.6, 0.4], 'chosen': 1, 'clear_optimum': False,
                          'note': 'no clear optimum: the curve is flat', 'stability': {}},
            'phase': {'chosen': 'linear', 'held_out_gain': -0.5}, 'speed_weight': 1.0,
            'prior_scale': 1.0}
    text = train_summary(info, 'm.npz', [1.0], None, [2.0])
    assert 'NO clear optimum' in text and 'give --components K' in text
    assert 'record more of each pattern (7 recordings now)' in text
    assert '1: 0.5*  2: 0.6  3: 0.4' in text
    info['selection']['clear_optimum'] = True
    assert '--components' not in train_summary(info, 'm.npz', [1.0])


def test_info_summarises_a_model_file(trained, capsys):
    from mixture_ip_ros import __version__
    path, train_out, _ = trained
    assert main(['info', str(path)]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f'{path}: model file format 4, written by mixture_ip_ros {__version__}')
    assert 'observed (frame not given): hx [m], hy [m], hz [m]' in out
    assert 'controlled: px [m], py [m], pz [m]' in out
    assert '3 patterns; 8 basis functions per DOF, noise tied' in out
    assert _table(out) == _table(train_out)            # the same patterns train reported
    assert 'training: 18 recordings' in out and 'K curve (nats per recording' in out
    assert 'novelty test: calibrated' in out and len(out.splitlines()) <= 16


def test_info_on_a_file_that_is_no_model_is_one_line_exit_1(tmp_path, capsys):
    (tmp_path / 'notes.npz').write_text('not a model')
    assert main(['info', str(tmp_path / 'notes.npz')]) == 1
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'not a model file' in err


def test_evaluate_model_scores_a_trained_model_without_retraining(trained, recordings,
                                                                  tmp_path):
    path, _, _ = trained
    root, names = recordings
    code, out, err = _run(['evaluate', '--model', path, '--csv', root / 'csv', '--labels',
                           root / 'labels.json', '--json', tmp_path / 'scores.json'])
    assert code == 0, err
    m = json.loads((tmp_path / 'scores.json').read_text())
    assert_documented(m)
    assert m['n_recordings'] == 18 and m['n_components'] == 3
    assert sorted(m['component_labels']) == ['pattern_0', 'pattern_1', 'pattern_2']
    assert m['ari'] == 1.0 and m['recognition_accuracy_by_fraction']['1'] == 1.0
    assert sorted(map(sorted, m['components_vs_labels']['counts'])) == [[0, 0, 6]] * 3
    assert m['chance_accuracy'] == pytest.approx(1 / 3)
    # The partner after half of each movement, played sample by sample through offer() here.
    model, _ = load_model(path)
    est = OnlineEstimator(model, n_alpha=50, min_interval=0.05)
    rms = []
    for d in load_csv_dataset(root / 'csv', LAYOUT):
        est.reset()
        half = 0.5 * d.duration
        for t, y in zip(d.t, d.observed):
            if t <= half + 1e-9:
                est.offer(t, y)
        k, _ = est.map_hypothesis()
        rest = d.t > half + 1e-9
        pred = est.expected_controlled(d.t[rest], component=k, derivatives=False)[1]
        rms.append(100 * np.sqrt(np.mean(np.sum((pred - d.controlled[rest]) ** 2, axis=1))))
    assert m['partner_rms_cm_by_fraction']['0.5'] == pytest.approx(np.mean(rms), rel=1e-9)
    assert m['partner_rms_cm_by_fraction']['1'] is None
    lines = out.splitlines()
    assert 'scored on' in lines[0] and '(no retraining)' in lines[0] and len(lines) <= 12
    assert '{' not in out and f'full metrics: {tmp_path / "scores.json"}' in out
    assert 'played 18/18 recordings' in err


@pytest.mark.parametrize('extra, code, message', [
    (['--observed', 'hx,hy'], 1, '--observed names 2 columns; the model has 3 observed DOFs '
                                 '(hx, hy, hz)'),
    (['--controlled-units', 'cm'], 1, '--controlled-units cm, cm, cm: the model was trained on '
                                      'm, m, m'),
    (['--quick'], 2, '--quick: not with --model'),
    (['--seed', '3'], 2, '--seed: not with --model'),
])
def test_evaluate_model_refuses_what_does_not_fit_the_model_in_one_line(
        trained, recordings, tmp_path, capsys, extra, code, message):
    path, _, _ = trained
    root, _ = recordings
    argv = [str(a) for a in ['evaluate', '--model', path, '--csv', root / 'csv', '--labels',
                             root / 'labels.json', '--out', tmp_path / 'eval'] + extra]
    if code == 2:                                   # before anything is read
        with pytest.raises(SystemExit) as exit_:
            main(argv)
        got = exit_.value.code
    else:
        got = main(argv)
    err = capsys.readouterr().err
    assert got == code and err.count('\n') == 1 and message in err, err
    assert not (tmp_path / 'eval').exists()


def test_evaluate_model_needs_recordings_to_score_it_on(trained, capsys):
    path, _, _ = trained
    with pytest.raises(SystemExit) as exit_:
        main(['evaluate', '--model', str(path), '--scenario', 'pole'])
    assert exit_.value.code == 2
    assert '--model: with --csv DIR and --labels FILE' in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(['evaluate', '--scenario', 'pole'])
    assert 'the following arguments are required: --out' in capsys.readouterr().err


def _cross_validated():
    fractions = {'0.3': 0.5, '0.5': 0.75, '0.7': 1.0, '1': 1.0}
    return {'scenario': 'csv', 'n_folds': 5, 'n_recordings': 44,
            'interactions': ['a', 'b', 'c', 'd'], 'n_components_selected': [4, 4, 5, 4, 4],
            'ari': 0.98, 'heldout_ari': 0.94, 'baseline_kmeans_ari': 0.79,
            'baseline_gmm_pca_ari': 0.87, 'recognition_accuracy_by_fraction': fractions,
            'baseline_nn_accuracy_by_fraction': fractions,
            'single_accuracy_by_fraction': dict.fromkeys(fractions, 0.227),
            'chance_accuracy': 0.273,
            'partner_rms_cm_by_fraction': {'0.3': 20.4, '0.5': 21.5, '0.7': 23.5, '1': None},
            'config': {'candidates': list(range(1, 10))}, 'plots': ['a.png'], 'runtime_s': 99.0}


def test_the_evaluate_summary_is_a_small_table_beside_the_baselines():
    text = evaluate_summary(_cross_validated(), ['eval/metrics.json'])
    lines = text.splitlines()
    assert len(lines) <= 16
    assert 'K per fold 4, 4, 5, 4, 4' in text
    assert 'training 0.98, held out 0.94 (k-means 0.79, GMM 0.87, given the true K)' in text
    assert re.search(r'mixture, online\s+50\s+75\s+100\s+100$', text, re.M)
    assert re.search(r'one ProMP \(K = 1\)\s+23\s+23\s+23\s+23$', text, re.M)
    assert re.search(r'chance \(largest label\)\s+27\s+27\s+27\s+27$', text, re.M)
    assert 'so it can score below chance: docs/metrics.md' in text
    assert re.search(r'^\s+mixture\s+20.4\s+21.5\s+23.5$', text, re.M)
    assert lines[-1] == 'full metrics: eval/metrics.json (every key: docs/metrics.md)'
    nuisi = evaluate_summary({'scenario': 'interactions', 'v1': _cross_validated(),
                              'v2': _cross_validated()})
    assert nuisi.count('K per fold') == 2 and 'v1:' in nuisi and 'v2:' in nuisi


def test_the_evaluate_summary_shows_which_pattern_is_taken_for_which():
    m = _cross_validated()
    m['recognition_confusion_by_fraction'] = {
        '0.5': {'a': {'a': 4, 'b': 7, 'component_4': 0}, 'b': {'a': 0, 'b': 11, 'component_4': 1}},
        '1': {'a': {'a': 11, 'b': 0, 'component_4': 0}, 'b': {'a': 0, 'b': 12, 'component_4': 0}}}
    text = evaluate_summary(m)
    assert re.search(r'recognised as, at 50 %\s+a\s+b\s+component_4$', text, re.M)
    assert re.search(r'^\s+a\s+4\s+7\s+0$', text, re.M)
    assert re.search(r'^\s+b\s+0\s+11\s+1$', text, re.M)
    # every recording right at half the movement: no table
    m['recognition_confusion_by_fraction']['0.5'] = m['recognition_confusion_by_fraction']['1']
    assert 'recognised as' not in evaluate_summary(m)


def test_a_scenario_without_a_table_prints_its_plain_numbers_only():
    text = evaluate_summary({'scenario': 'pole', 'n_components_selected': 2, 'rms_single': 0.25,
                             'side_accuracy_mixture': {'one_sided': 0.95, 'two_sided': None},
                             'rms_vs_k': {'1': [0.2, 0.01]}, 'config': {'n_basis': 10},
                             'plots': ['p.png'], 'units': {'rms': 'rad'}})
    assert text.splitlines() == ['pole:', '  n_components_selected: 2', '  rms_single: 0.25',
                                 '  side_accuracy_mixture: one_sided 0.95, two_sided -']


def test_the_demo_ends_with_a_few_lines_not_its_report():
    rows = [{'true_pattern': 'plate', 'chosen_pattern': 'plate'},
            {'true_pattern': 'screw', 'chosen_pattern': 'plate'}]
    text = demo_summary({'interactions': rows, 'commit_fraction_mean': 0.26,
                         'hand_error_cm_mean': 2.41, 'hand_error_cm_max': 3.02,
                         'tracking_rms_mrad_mean': 0.51,
                         'latency': {'update_us_mean': 120.0, 'update_us_max': 900.0},
                         'training': {'novelty': {'prefix': list(range(40))}}},
                        'out/report.json')
    assert text.splitlines() == [
        '1 of 2 interactions recognised; committed on average at 0.26 of the motion',
        'hand to the demonstrated target: 2.4 cm mean, 3.0 cm worst',
        'joint tracking RMS 0.51 mrad', 'estimator update 120 us mean, 900 us worst',
        'full report: out/report.json (every key: docs/metrics.md)']
