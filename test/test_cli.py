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
    (['train', '{tmp}', '--out', '{tmp}/m.npz', '--jobs', '0'], '--jobs: 0 is not >= 1'),
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
    _exits_2_in_one_line_and_creates_nothing(tmp_path, capsys, argv, message)


def _exits_2_in_one_line_and_creates_nothing(tmp_path, capsys, argv, message):
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


# -- combinations of options: each contradiction is found before any data is read -------------
def _inputs(tmp):
    (tmp / 'csv').mkdir()
    (tmp / 'csv' / 'a.csv').write_text('t,x,y,q\n0,1,2,3\n0.1,2,3,4\n')
    (tmp / 'labels.json').write_text('{"a": "reach"}')
    (tmp / 'list.json').write_text('["a", "reach"]')
    (tmp / 'bad.json').write_text('{"a": ')


TRAIN_CSV = ['train', '--csv', '{tmp}/csv', '--out', '{tmp}/m.npz']
EVALUATE_CSV = ['evaluate', '--csv', '{tmp}/csv', '--labels', '{tmp}/labels.json', '--out',
                '{tmp}/eval']


@pytest.mark.parametrize('argv, message', [
    (['train', '--out', '{tmp}/m.npz'], 'give a folder of bags or --csv DIR (one of them)'),
    (TRAIN_CSV + ['{tmp}', '--observed', 'x'], 'give a folder of bags or --csv DIR'),
    (['train', '{tmp}', '--out', '{tmp}/m.npz', '--observed', 'x,y'],
     '--observed: for --csv DIR only'),
    (['train', '{tmp}', '--out', '{tmp}/m.npz', '--controlled-units', 'm', '--time', 's'],
     '--controlled-units, --time: for --csv DIR only'),
    (TRAIN_CSV, '--csv needs --observed NAME'),
    (TRAIN_CSV + ['--observed', 'x,y', '--observed-units', 'm,m,m'],
     '3 observed units for 2 observed DOFs'),
    (TRAIN_CSV + ['--observed', 'x,y', '--controlled-units', 'rad'],
     '1 controlled units for 0 controlled DOFs'),
    (TRAIN_CSV + ['--observed', 'x,y', '--controlled', 'y'], "names in both agents: ['y']"),
    (TRAIN_CSV + ['--observed', 'x,x'], "observed DOF names repeat: ['x', 'x']"),
    (TRAIN_CSV + ['--observed', 'x,'], "--observed: empty name in 'x,'"),
    (TRAIN_CSV + ['--observed', 'x,y', '--time', 'x'], "--time 'x' names the time column"),
    (TRAIN_CSV + ['--observed', 'x', '--cut', 'recorded'],
     '--cut: for a folder of bags only, not --csv'),
    (TRAIN_CSV + ['--observed', 'x', '--controlled', 'q', '--components', '2', '--criterion',
                  'loo'], '--components gives K and --criterion chooses it'),
    (TRAIN_CSV + ['--observed', 'x', '--criterion', 'loo'],
     '--criterion loo measures how well the controlled agent is predicted: it needs '
     '--controlled'),
    (TRAIN_CSV + ['--observed', 'x', '--observation-noise', '0.1,abc'],
     "argument --observation-noise: 'abc' is not a number"),
    (TRAIN_CSV + ['--observed', 'x', '--observation-noise', '-0.1'],
     'argument --observation-noise: -0.1 is not >= 0.0'),
    (TRAIN_CSV + ['--observed', 'x,y', '--observation-noise', '0.1,0.2,0.3'],
     '--observation-noise: 3 numbers for 2 observed DOFs (x, y)'),
    (['train', '{tmp}', '--out', '{tmp}/m.npz', '--observation-noise', '0.1,0.2'],
     '--observation-noise: 2 numbers for 3 observed DOFs (wrist_x, wrist_y, wrist_z)'),
    (['evaluate', '--out', '{tmp}/eval'], 'give --scenario NAME or --csv DIR (one of them)'),
    (EVALUATE_CSV + ['--observed', 'x', '--scenario', 'pole'],
     'give --scenario NAME or --csv DIR (one of them)'),
    (['evaluate', '--scenario', 'pole', '--out', '{tmp}/eval', '--labels', '{tmp}/labels.json'],
     '--labels: for --csv DIR only'),
    (['evaluate', '--scenario', 'gestures', '--out', '{tmp}/eval', '--observed', 'x'],
     '--observed: for --csv DIR only'),
    (['evaluate', '--csv', '{tmp}/csv', '--observed', 'x', '--out', '{tmp}/eval'],
     '--csv needs --labels FILE'),
    (EVALUATE_CSV, '--csv needs --observed NAME'),
    (EVALUATE_CSV + ['--observed', 'x,y', '--controlled', 'q', '--controlled-units', 'm,m'],
     '2 controlled units for 1 controlled DOFs'),
    (EVALUATE_CSV + ['--observed', 'x', '--robot', 'iiwa14'],
     '--robot: for --scenario box_assembly or pole only, not --csv'),
    (['evaluate', '--scenario', 'gestures', '--out', '{tmp}/eval', '--bags', '{tmp}'],
     '--bags: for --scenario box_assembly or pole only, not --scenario gestures'),
    (['evaluate', '--scenario', 'interactions', '--out', '{tmp}/eval', '--robot', 'iiwa14'],
     '--robot: for --scenario box_assembly or pole only, not --scenario interactions'),
    (['evaluate', '--scenario', 'pole', '--out', '{tmp}/eval', '--bags', '{tmp}', '--seed', '3'],
     '--seed: the demonstrations it would generate are not used with --bags'),
])
def test_contradicting_options_fail_in_one_line_before_reading_any_data(
        tmp_path, capsys, nothing_runs, argv, message):
    _inputs(tmp_path)
    _exits_2_in_one_line_and_creates_nothing(tmp_path, capsys, argv, message)


def test_train_options_that_agree_reach_training_as_given(tmp_path, capsys, monkeypatch):
    import mixture_ip_ros.app.training as training
    calls = []
    monkeypatch.setattr(training, 'train_to_file',
                        lambda demos, out, **kwargs: calls.append((demos, out, kwargs))
                        or (None, {}))
    _inputs(tmp_path)
    assert main(['train', '--csv', str(tmp_path / 'csv'), '--out', str(tmp_path / 'm.npz'),
                 '--observed', 'x,y', '--observed-units', 'm', '--observation-noise', '0.1,0.2',
                 '--criterion', 'patterns']) == 0
    ((demos, out, kwargs),) = calls
    assert [d.name for d in demos] == ['a.csv'] and out == str(tmp_path / 'm.npz')
    assert kwargs['layout'].observed == ('x', 'y')
    assert kwargs['layout'].observed_units == ('m', 'm')
    assert kwargs['observation_noise'] == [0.1, 0.2] and kwargs['criterion'] == 'patterns'


def test_evaluate_options_that_agree_reach_the_evaluation_as_given(tmp_path, capsys,
                                                                   monkeypatch):
    import mixture_ip_ros.app.evaluation as evaluation
    calls = []
    monkeypatch.setattr(evaluation, 'evaluate_csv',
                        lambda *args, **kwargs: calls.append((args, kwargs)) or {})
    _inputs(tmp_path)
    assert main(['evaluate', '--csv', str(tmp_path / 'csv'), '--labels',
                 str(tmp_path / 'labels.json'), '--observed', 'x,y', '--out',
                 str(tmp_path / 'eval'), '--quick']) == 0
    ((args, kwargs),) = calls
    assert args[1] == {'a': 'reach'} and args[2].observed == ('x', 'y')
    assert args[2].controlled == () and kwargs['quick'] is True


@pytest.mark.parametrize('labels, message', [
    ('none.json', '--labels {tmp}/none.json: not a readable JSON file'),
    ('bad.json', '--labels {tmp}/bad.json: not a readable JSON file'),
    ('list.json', '--labels {tmp}/list.json: must be a JSON object, file name -> label'),
])
def test_a_bad_labels_file_is_a_run_time_error_found_before_reading_the_recordings(
        tmp_path, capsys, nothing_runs, labels, message):
    _inputs(tmp_path)
    assert main(['evaluate', '--csv', str(tmp_path / 'csv'), '--labels', str(tmp_path / labels),
                 '--observed', 'x', '--out', str(tmp_path / 'eval')]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f'mixture-ip evaluate: error: {message.format(tmp=tmp_path)}'), err
    assert err.count('\n') == 1 and not (tmp_path / 'eval').exists()
