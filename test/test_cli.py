"""`mixture-ip`: every option is checked before any work starts, with one line saying what is
wrong; nothing is created on bad input."""

import pytest

from mixture_ip_ros.app.cli import main


@pytest.mark.parametrize('argv, message', [
    (['train', '{tmp}', '--out', '{tmp}/m.npz', '--components', '0'],
     'argument --components: 0 is not >= 1'),
    (['train', '{tmp}', '--out', '{tmp}'], 'argument --out: {tmp} is a folder'),
    (['train', '{tmp}/none', '--out', '{tmp}/m.npz'], 'bag_dir: {tmp}/none is not a folder'),
    (['train', '{tmp}', '--out', '{tmp}/m.npz', '--n-basis', '1'], '--n-basis: 1 is not >= 2'),
    (['train', '{tmp}', '--out', '{tmp}/m.npz', '--max-components', 'six'],
     "--max-components: 'six' is not a whole number"),
    (['train', '{tmp}', '--out', '{tmp}/m.npz', '--cut', 'manual'],
     "--cut: invalid choice: 'manual'"),
    (['evaluate', '--scenario', 'pole', '--out', '{tmp}/eval', '--bags', '{tmp}/none'],
     '--bags: {tmp}/none is not a folder'),
    (['evaluate', '--scenario', 'pole', '--out', '{tmp}/file.txt'], 'is a file, not a folder'),
    (['generate', '--scenario', 'pole', '--out', '{tmp}/bags', '--occlusion', 'nan'],
     "--occlusion: 'nan' is not a finite number"),
    (['demo', '--held-out', '0', '--out', '{tmp}/demo'], '--held-out: 0 is not >= 1'),
    (['demo', '--scenario', 'dance', '--out', '{tmp}/demo'], "--scenario: invalid choice: 'dance'"),
    (['demo', '--scenario', 'interactions', '--components', '0', '--out', '{tmp}/demo'],
     '--components: 0 is not >= 1'),
    (['lifecycle', 'estimator_node', 'activate', '--timeout', '-1'], '--timeout: -1.0 is not'),
])
def test_bad_options_are_one_line_exit_2_and_create_nothing(tmp_path, capsys, argv, message):
    (tmp_path / 'file.txt').write_text('not a folder\n')
    before = sorted(p.name for p in tmp_path.iterdir())
    with pytest.raises(SystemExit) as exit_:
        main([a.format(tmp=tmp_path) for a in argv])
    err = capsys.readouterr().err
    assert exit_.value.code == 2
    assert err.count('\n') == 1 and message.format(tmp=tmp_path) in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_a_run_time_error_is_one_line_and_exit_1(tmp_path, capsys):
    (tmp_path / 'empty').mkdir()
    assert main(['train', str(tmp_path / 'empty'), '--out', str(tmp_path / 'm.npz')]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith('mixture-ip train: error:') and not (tmp_path / 'm.npz').exists()


def test_training_on_the_recorded_cut_needs_bags_that_record_it(tmp_path, capsys):
    import numpy as np
    from mixture_ip_ros.io.bags import write_demonstration_bag
    t = np.arange(0.0, 2.0, 0.01)
    wrist = np.column_stack([0.5 + 0.2 * np.sin(t), 0.1 * t, 0.3 + 0 * t])
    write_demonstration_bag(tmp_path / 'bags' / 'one', t, wrist, t, np.zeros((t.size, 7)))
    assert main(['train', str(tmp_path / 'bags'), '--cut', 'recorded',
                 '--out', str(tmp_path / 'm.npz')]) == 1
    err = capsys.readouterr().err
    assert 'no recorded movement interval' in err and not (tmp_path / 'm.npz').exists()
