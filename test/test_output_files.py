"""Files the package writes get the user's umask (not the private mode of the temporary file
they are written through), and --on-error means the same for a folder of CSV files as for a
folder of bags."""

import contextlib
import logging
import os
import stat

import pytest

from mixture_ip_ros.app.cli import main
from mixture_ip_ros.core.demonstration import Layout
from mixture_ip_ros.io.csv_files import CsvError, load_csv_dataset
from mixture_ip_ros.io.files import write_text_atomic

GOOD = 't,x,y\n0,1,1\n0.1,2,2\n0.2,3,3\n'
BAD = 't,x,y\n0,1,1\n0.1,2,2\n0.2,3,?\n'


@contextlib.contextmanager
def umask(mask):
    old = os.umask(mask)
    try:
        yield
    finally:
        os.umask(old)


def _mode(path):
    return stat.S_IMODE(os.stat(path).st_mode)


def test_a_model_file_a_report_and_a_plot_are_written_with_the_users_umask(tmp_path):
    from mixture_ip_ros.core.mixture import MixtureIProMP
    from mixture_ip_ros.io.model_file import save_model
    from mixture_ip_ros.scenarios.synthetic import mixture_demos
    from mixture_ip_ros.viz.plots import plt, save_figure
    demos = mixture_demos(seed=2, n_obs=1, n_ctrl=1)[0]
    model = MixtureIProMP(1, n_basis=4).fit(demos)
    for mask, mode in ((0o022, 0o644), (0o077, 0o600), (0o002, 0o664)):
        with umask(mask):
            written = [save_model(tmp_path / f'model_{mask:o}.npz', model,
                                  observed_names=['o'], controlled_names=['c']),
                       write_text_atomic(tmp_path / f'metrics_{mask:o}.json', '{}\n')]
            fig, _ = plt.subplots()
            save_figure(fig, tmp_path / f'plot_{mask:o}.png')
            written.append(tmp_path / f'plot_{mask:o}.png')
        assert [oct(_mode(p)) for p in written] == [oct(mode)] * 3
    assert stat.filemode(os.stat(tmp_path / 'model_22.npz').st_mode) == '-rw-r--r--'
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith('.')) == []


def test_a_file_replaced_gets_the_umask_mode_not_its_old_one(tmp_path):
    path = tmp_path / 'metrics.json'
    path.write_text('old\n')
    os.chmod(path, 0o600)
    with umask(0o022):
        write_text_atomic(path, 'new\n')
    assert path.read_text() == 'new\n' and _mode(path) == 0o644


# -- --on-error for CSV folders ---------------------------------------------------------------
def _folder(tmp_path):
    folder = tmp_path / 'csv'
    folder.mkdir()
    (folder / 'a.csv').write_text(GOOD)
    (folder / 'b.csv').write_text(BAD)
    (folder / 'c.csv').write_text(GOOD)
    return folder


def test_skip_leaves_a_malformed_csv_out_with_one_line_naming_it_and_why(tmp_path, caplog):
    folder = _folder(tmp_path)
    with caplog.at_level(logging.WARNING, logger='mixture_ip_ros.io.csv_files'):
        demos = load_csv_dataset(folder, Layout(('x', 'y')), on_error='skip')
    assert [d.name for d in demos] == ['a.csv', 'c.csv']
    (record,) = caplog.records
    assert record.getMessage() == (f"skipping {folder / 'b.csv'}, line 4: column 'y' is not a "
                                   "number: '?'")


def test_raise_stops_at_the_first_malformed_csv_with_its_error(tmp_path):
    folder = _folder(tmp_path)
    with pytest.raises(CsvError, match=r"b\.csv, line 4: column 'y' is not a number"):
        load_csv_dataset(folder, Layout(('x', 'y')), on_error='raise')
    with pytest.raises(ValueError, match="on_error must be 'skip' or 'raise'"):
        load_csv_dataset(folder, Layout(('x', 'y')), on_error='ignore')


def test_skip_with_no_good_file_left_is_an_error_naming_the_first_problem(tmp_path):
    (tmp_path / 'b.csv').write_text(BAD)
    with pytest.raises(ValueError, match=r"none of the 1 CSV files .* could be read \(first: "
                                         r"b\.csv: .*line 4"):
        load_csv_dataset(tmp_path, Layout(('x', 'y')), on_error='skip')


@pytest.mark.parametrize('on_error, trained', [('skip', ['a.csv', 'c.csv']), ('raise', None),
                                               (None, None)])
def test_train_on_error_means_the_same_for_csv_files_as_for_bags(tmp_path, capsys, monkeypatch,
                                                                   on_error, trained):
    import mixture_ip_ros.app.training as training
    calls = []
    monkeypatch.setattr(training, 'train_to_file',
                        lambda demos, out, **kwargs: calls.append(demos) or (None, {}))
    monkeypatch.setattr('mixture_ip_ros.app.summary.train_report', lambda *a, **k: '')
    folder = _folder(tmp_path)
    argv = ['train', '--csv', str(folder), '--observed', 'x,y', '--out', str(tmp_path / 'm.npz')]
    code = main(argv + (['--on-error', on_error] if on_error else []))
    err = capsys.readouterr().err
    if trained is None:          # raise, the default for CSV files: exit 1 naming the file
        assert code == 1 and calls == []
        assert err.strip() == (f"mixture-ip train: error: {folder / 'b.csv'}, line 4: column "
                               "'y' is not a number: '?'")
    else:
        assert code == 0 and [d.name for d in calls[0]] == trained
