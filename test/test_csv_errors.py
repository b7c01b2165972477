"""A folder of CSV demonstrations with a bad file: the error names the file and, where a row is
at fault, its line as a text editor numbers it (the header is line 1), in one line."""

import numpy as np
import pytest

from mixture_ip_ros.app.cli import main
from mixture_ip_ros.core.demonstration import Layout
from mixture_ip_ros.io.csv_files import CsvError, load_csv_dataset

GOOD = 't,x,y\n0,1,1\n0.1,2,2\n0.2,3,3\n'


@pytest.mark.parametrize('text, message', [
    ('t,x,y\n0,1,1\n0.1,2,2\n0.2,abc,3\n', "b.csv, line 4: column 'x' is not a number: 'abc'"),
    ('t,x,y\n0,1,1\n0.1,2,2\n0.2,3\n', 'b.csv, line 4: 2 cells for 3 columns'),
    ('t,x,y\n0,1,1\n0.1,2,2,2\n', 'b.csv, line 3: 4 cells for 3 columns'),
    ('', 'b.csv: empty file'),
    ('\n\n', 'b.csv: empty file'),
    ('\nt,x,y\n0,1,1\n', 'b.csv, line 1: empty; the first line is the header'),
    ('t,x\n0,1\n0.1,2\n', "b.csv: no column 'y' (columns: t, x)"),
    ('x,y\n1,1\n2,2\n', "b.csv: no column 't' (columns: x, y)"),
    ('t,x,y,x\n0,1,1,1\n0.1,2,2,2\n', "b.csv, line 1: the header names 'x' more than once"),
    ('t,x,y\n0,1,1\n0.2,2,2\n0.2,3,3\n',
     'b.csv, line 4: time 0.2 does not increase (previous 0.2, line 3)'),
    ('t,x,y\n0,1,1\n0.2,2,2\n0.1,3,3\n', 'b.csv, line 4: time 0.1 does not increase'),
    ('t,x,y\n0,1,1\nnan,2,2\n0.2,3,3\n', "b.csv, line 3: time column 't' is NaN"),
    ('t,x,y\n0,1,1\n,2,2\n0.2,3,3\n', "b.csv, line 3: time column 't' is empty"),
    ('t,x,y\n0,1,1\ninf,2,2\n', "b.csv, line 3: column 't' is 'inf', not a finite number"),
    ('t,x,y\n0,1,1\n0.1,-Infinity,2\n',
     "b.csv, line 3: column 'x' is '-Infinity', not a finite number"),
    ('t,x,y\n0,1,1\n\n0.2,3,3\n', 'b.csv, line 3: empty row'),
    ('t,x,y\n0,1,1\n', 'b.csv: needs at least 2 rows of samples, got 1'),
    ('t,x,y\n0,1,1\n0.1,,2\n', 'b.csv, line 3: observed columns x are empty but not the others'),
])
def test_a_bad_file_in_a_folder_is_named_with_the_line_at_fault(tmp_path, text, message):
    (tmp_path / 'a.csv').write_text(GOOD)
    (tmp_path / 'b.csv').write_text(text)
    with pytest.raises(CsvError) as e:
        load_csv_dataset(tmp_path, Layout(('x', 'y')))
    assert message in str(e.value) and str(tmp_path / 'b.csv') in str(e.value), str(e.value)
    assert '\n' not in str(e.value)


def test_lines_are_counted_as_an_editor_counts_them_past_a_cell_spanning_lines(tmp_path):
    (tmp_path / 'a.csv').write_text('t,x,y,note\n0,1,1,"two\nlines"\n0.1,2,2,\n0.2,3,x,\n')
    with pytest.raises(CsvError, match=r"a\.csv, line 5: column 'y' is not a number: 'x'"):
        load_csv_dataset(tmp_path, Layout(('x', 'y')))


def test_a_byte_order_mark_before_the_header_is_not_part_of_the_first_column_name(tmp_path):
    (tmp_path / 'a.csv').write_bytes(b'\xef\xbb\xbf' + GOOD.encode())
    (d,) = load_csv_dataset(tmp_path, Layout(('x', 'y')))
    assert np.allclose(d.t, [0.0, 0.1, 0.2]) and np.allclose(d.observed[:, 0], [1, 2, 3])


def test_a_controlled_column_with_a_bad_cell_is_named_with_its_line(tmp_path):
    (tmp_path / 'a.csv').write_text('t,x,q1,q2\n0,1,0,0\n0.1,2,0.5,\n')
    with pytest.raises(CsvError, match=r'a\.csv, line 3: controlled columns q2 are empty'):
        load_csv_dataset(tmp_path, Layout(('x',), ('q1', 'q2')))


def test_train_names_the_bad_file_and_its_line_in_one_line_and_exit_1(tmp_path, capsys):
    (tmp_path / 'csv').mkdir()
    (tmp_path / 'csv' / 'a.csv').write_text(GOOD)
    (tmp_path / 'csv' / 'b.csv').write_text('t,x,y\n0,1,1\n0.1,2,2\n0.2,3,?\n')
    assert main(['train', '--csv', str(tmp_path / 'csv'), '--observed', 'x,y', '--out',
                 str(tmp_path / 'm.npz')]) == 1
    err = capsys.readouterr().err.strip()
    assert err == (f"mixture-ip train: error: {tmp_path / 'csv' / 'b.csv'}, line 4: column 'y' "
                   "is not a number: '?'")
    assert not (tmp_path / 'm.npz').exists()
