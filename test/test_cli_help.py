"""`mixture-ip`: every option says what it is for, units come from a known list, and a column
list spelled with spaces is refused saying how to write it."""

import argparse

import pytest

from mixture_ip_ros.app.cli import build_parser, main
from mixture_ip_ros.io.csv_files import UNITS


def _subcommands(parser):
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return sub.choices


def test_every_option_of_every_subcommand_has_help_text():
    missing = []
    for name, parser in _subcommands(build_parser()).items():
        for action in parser._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            if not (action.help or '').strip():
                missing.append(f'{name} {"/".join(action.option_strings) or action.dest}')
    assert missing == []


def test_every_subcommand_has_help_text():
    parser = build_parser()
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    assert sorted(a.dest for a in sub._choices_actions if a.help) == sorted(_subcommands(parser))


def _exit_2(capsys, argv):
    with pytest.raises(SystemExit) as exit_:
        main(argv)
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and err.count('\n') == 1, err
    return err


@pytest.mark.parametrize('option', ['--observed-units', '--controlled-units'])
def test_a_unit_not_in_the_list_is_refused_naming_the_accepted_ones(tmp_path, capsys,
                                                                     nothing_runs, option):
    (tmp_path / 'csv').mkdir()
    err = _exit_2(capsys, ['train', '--csv', str(tmp_path / 'csv'), '--observed', 'hx,hy,hz',
                           '--controlled', 'px,py,pz', option, 'metres',
                           '--out', str(tmp_path / 'm.npz')])
    assert f"{option}: unknown unit 'metres'; give one of m (metres), cm" in err
    assert all(f'{unit} (' in err for unit in ('m', 'cm', 'mm', 'rad', 'deg', 's'))
    assert not (tmp_path / 'm.npz').exists()


def test_known_units_reach_the_model_as_spelled(tmp_path, monkeypatch):
    import mixture_ip_ros.app.training as training
    calls = []
    monkeypatch.setattr(training, 'train_to_file',
                        lambda demos, out, **kwargs: calls.append(kwargs) or (None, {}))
    monkeypatch.setattr('mixture_ip_ros.app.summary.train_report', lambda *a, **k: '')
    (tmp_path / 'csv').mkdir()
    (tmp_path / 'csv' / 'a.csv').write_text('t,x,q\n0,1,2\n0.1,2,3\n')
    assert main(['train', '--csv', str(tmp_path / 'csv'), '--observed', 'x', '--controlled',
                 'q', '--observed-units', 'mm', '--controlled-units', 'deg',
                 '--out', str(tmp_path / 'm.npz')]) == 0
    layout = calls[0]['layout']
    assert (layout.observed_units, layout.controlled_units) == (('mm',), ('deg',))
    assert set(UNITS) >= {'m', 'cm', 'mm', 'rad', 'deg', 's'}


@pytest.mark.parametrize('argv', [
    ['train', '--csv', '{tmp}', '--observed', 'hx', 'hy', 'hz', '--out', '{tmp}/m.npz'],
    ['train', '--csv', '{tmp}', '--observed', 'hx,hy,hz', '--controlled', 'px', 'py', 'pz',
     '--out', '{tmp}/m.npz'],
    ['evaluate', '--csv', '{tmp}', '--labels', '{tmp}/l.json', '--observed', 'hx', 'hy', 'hz',
     '--out', '{tmp}/eval'],
])
def test_a_column_list_spelled_with_spaces_is_refused_saying_how_to_write_it(
        tmp_path, capsys, nothing_runs, argv):
    err = _exit_2(capsys, [a.format(tmp=tmp_path) for a in argv])
    option = 'observed' if argv.count('hx') else 'controlled'
    spelled = 'hx,hy,hz' if option == 'observed' else 'px,py,pz'
    assert (f'--{option} takes one comma-separated list, not 3 words: --{option} {spelled}'
            in err)
    assert 'bag_dir' not in err and 'unrecognized' not in err


def test_the_usage_shows_a_column_list_as_one_value():
    usage = _subcommands(build_parser())['train'].format_usage()
    assert '[--observed OBSERVED]' in usage and 'OBSERVED ...' not in usage
