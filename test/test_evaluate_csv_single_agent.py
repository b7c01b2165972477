"""`mixture-ip evaluate --csv` without --controlled: a single-agent model (as --help says), its
recognition measured like a two-agent one's, and no partner to predict."""

import json

import numpy as np

from mixture_ip_ros.app.cli import main

from test_summaries import assert_documented


def _write_recordings(root, per_label=5, n_samples=20):
    """Two labels of two-DOF curves, each recording its own speed and amplitude: 'arc' goes up
    and comes back, 'line' keeps rising."""
    rng = np.random.default_rng(0)
    (root / 'csv').mkdir()
    labels = {}
    for label in ('arc', 'line'):
        for i in range(per_label):
            t = np.linspace(0.0, rng.uniform(1.0, 1.5), n_samples)
            z = t / t[-1]
            a = rng.uniform(0.9, 1.1)
            y = a * np.sin(np.pi * z) if label == 'arc' else a * z
            rows = '\n'.join(f'{ti:.4f},{zi:.4f},{yi:.4f}' for ti, zi, yi in zip(t, z, y))
            name = f'{label}_{i}'
            (root / 'csv' / f'{name}.csv').write_text(f't,x,y\n{rows}\n')
            labels[name] = label
    (root / 'labels.json').write_text(json.dumps(labels))


def test_evaluate_csv_without_a_controlled_agent_measures_recognition(tmp_path, capsys):
    _write_recordings(tmp_path)
    out = tmp_path / 'out'
    assert main(['evaluate', '--csv', str(tmp_path / 'csv'), '--labels',
                 str(tmp_path / 'labels.json'), '--observed', 'x,y', '--out', str(out),
                 '--quick', '--json', str(tmp_path / 'metrics.json')]) == 0
    metrics = json.loads((out / 'metrics.json').read_text())
    assert json.loads((tmp_path / 'metrics.json').read_text()) == metrics
    printed = capsys.readouterr().out
    assert 'recognised (%) from' in printed and 'partner' not in printed
    assert_documented(metrics)
    assert metrics['n_recordings'] == 10 and metrics['interactions'] == ['arc', 'line']
    for key in ('recognition_accuracy_by_fraction', 'baseline_nn_accuracy_by_fraction'):
        accuracy = metrics[key]
        assert set(accuracy) == {'0.3', '0.5', '0.7', '1'}
        assert all(0.0 <= a <= 1.0 for a in accuracy.values())
    # The whole movement tells a rising line from an arc.
    assert metrics['recognition_accuracy_by_fraction']['1'] == 1.0
    assert not any(key.startswith('partner_') or '_partner_' in key for key in metrics)
