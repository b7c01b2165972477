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
