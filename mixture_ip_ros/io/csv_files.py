"""Demonstrations from CSV files: one file per demonstration, a header row, a time column and
one column per DOF, e.g.

    t,x,y,z,q1,q2
    0.00,0.41,0.02,0.30,0.1,-0.2
    0.01,0.42,0.02,0.31,0.1,-0.2

Each file is one movement: its first row is the onset (times are taken relative to it, in
seconds) and its last row the end. Every row is kept: an empty or NaN cell in every column of
an agent marks that agent's sample as missing (an occlusion), never dropped; anything else that
is not a number is an error. Errors name the file and the line (counted from 1 as a text editor
counts them, the header being line 1), in one line.
"""

from __future__ import annotations

import csv
import io
import logging
from pathlib import Path
from typing import Sequence

import numpy as np

from mixture_ip_ros.core.demonstration import Demonstration, Layout
from mixture_ip_ros.io.files import write_text_atomic

logger = logging.getLogger(__name__)


class CsvError(ValueError):
    """A CSV file that cannot be read as a demonstration."""


def _number(cell: str, path, line: int, column: str) -> float:
    cell = cell.strip()
    if cell == '' or cell.lower() == 'nan':
        return np.nan
    try:
        value = float(cell)
    except ValueError:
        raise CsvError(f'{path}, line {line}: column {column!r} is not a number: '
                       f'{cell!r}') from None
    if not np.isfinite(value):
        raise CsvError(f'{path}, line {line}: column {column!r} is {cell!r}, not a finite number')
    return value


def _numbered_rows(path) -> list:
    """(line, cells) of every row of ``path``, ``line`` the row's first line as a text editor
    numbers them (from 1, the header included; a quoted cell may span lines)."""
    # utf-8-sig: the byte-order mark a spreadsheet may write would otherwise become part of the
    # first column's name, and 't' would be reported missing from a header that shows it.
    with open(path, newline='', encoding='utf-8-sig') as f:
        reader = csv.reader(f)
        rows, line = [], 1
        try:
            for cells in reader:
                rows.append((line, cells))
                line = reader.line_num + 1
        except csv.Error as e:
            raise CsvError(f'{path}, line {reader.line_num}: {e}') from None
    return rows


def read_csv_demonstration(path, layout: Layout, time: str = 't') -> Demonstration:
    """One CSV file -> one Demonstration with ``layout``'s columns (see the module docstring).
    Raises CsvError with the file and line of the first problem."""
    path = Path(path)
    try:
        rows = _numbered_rows(path)
    except (OSError, UnicodeDecodeError) as e:
        raise CsvError(f'{path}: cannot be read ({e})') from None
    if not any(cells for _, cells in rows):
        raise CsvError(f'{path}: empty file')
    if not rows[0][1]:
        raise CsvError(f'{path}, line 1: empty; the first line is the header naming the columns')
    header = [h.strip() for h in rows[0][1]]
    wanted = [time, *layout.observed, *layout.controlled]
    missing = [c for c in wanted if c not in header]
    if missing:
        raise CsvError(f'{path}: no column {", ".join(map(repr, missing))} (columns: '
                       f'{", ".join(header)})')
    twice = [c for c in wanted if header.count(c) > 1]
    if twice:
        raise CsvError(f'{path}, line 1: the header names {", ".join(map(repr, twice))} more '
                       f'than once')
    index = [header.index(c) for c in wanted]
    data, lines = [], []
    for line, row in rows[1:]:
        if not row or all(not c.strip() for c in row):
            raise CsvError(f'{path}, line {line}: empty row')
        if len(row) != len(header):
            raise CsvError(f'{path}, line {line}: {len(row)} cells for {len(header)} columns')
        values = [_number(row[i], path, line, c) for i, c in zip(index, wanted)]
        if np.isnan(values[0]):
            what = 'empty' if not row[index[0]].strip() else 'NaN'
            raise CsvError(f'{path}, line {line}: time column {time!r} is {what} (every row '
                           f'needs a time)')
        data.append(values)
        lines.append(line)
    if len(data) < 2:
        raise CsvError(f'{path}: needs at least 2 rows of samples, got {len(data)}')
    a = np.array(data)
    t = a[:, 0]
    P = len(layout.observed)
    for k in range(1, len(t)):
        if t[k] <= t[k - 1]:
            raise CsvError(f'{path}, line {lines[k]}: time {t[k]:g} does not increase (previous '
                           f'{t[k - 1]:g}, line {lines[k - 1]})')
    for agent, block in (('observed', a[:, 1:1 + P]), ('controlled', a[:, 1 + P:])):
        partial = np.isnan(block).any(axis=1) & ~np.isnan(block).all(axis=1)
        if partial.any():
            k = int(np.argmax(partial))
            names = getattr(layout, agent)
            empty = [n for n, v in zip(names, block[k]) if np.isnan(v)]
            raise CsvError(f'{path}, line {lines[k]}: {agent} columns {", ".join(empty)} are '
                           f'empty but not the others (a missing sample is empty in every '
                           f'column)')
    if np.isnan(a[:, 1:1 + P]).all():
        raise CsvError(f'{path}: no observed sample (every observed cell is empty)')
    return Demonstration(t - t[0], a[:, 1:1 + P], a[:, 1 + P:], name=path.name)


def load_csv_dataset(folder, layout: Layout, time: str = 't', on_error: str = 'raise') -> list:
    """Every ``*.csv`` file in ``folder`` (sorted by name) as a Demonstration.

    ``on_error='raise'``: the first bad file raises its CsvError; ``'skip'``: a bad file is left
    out with one warning naming it and why (io.dataset.load_dataset does the same with bags).
    ValueError if there is no file, or no good one.
    """
    if on_error not in ('skip', 'raise'):
        raise ValueError(f"on_error must be 'skip' or 'raise', got {on_error!r}")
    folder = Path(folder)
    if not folder.is_dir():
        raise ValueError(f'CSV folder {folder} does not exist or is not a directory')
    files = sorted(folder.glob('*.csv'))
    if not files:
        raise ValueError(f'no .csv files in {folder}')
    demos, skipped = [], []
    for f in files:
        try:
            demos.append(read_csv_demonstration(f, layout, time))
        except CsvError as error:
            if on_error == 'raise':
                raise
            logger.warning('skipping %s', error)
            skipped.append(f'{f.name}: {error}')
    if not demos:
        raise ValueError(f'none of the {len(files)} CSV files in {folder} could be read '
                         f'(first: {skipped[0]})')
    return demos


def write_csv_demonstration(path, demo: Demonstration, layout: Layout, time: str = 't'):
    """The inverse of :func:`read_csv_demonstration` (missing samples as empty cells)."""
    layout.check([demo])
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    a = np.column_stack([demo.t, demo.observed, demo.controlled])
    text = io.StringIO(newline='')
    w = csv.writer(text)
    w.writerow([time, *layout.observed, *layout.controlled])
    for row in a:
        w.writerow(['' if np.isnan(v) else repr(float(v)) for v in row])
    return write_text_atomic(path, text.getvalue())


# The units a column may be given in (recorded in the model as spelled here): the evaluation
# reports errors of positions all in 'm' in cm, and --translation refuses to move columns of
# different units together, so a unit must be one name per quantity, not any spelling of it.
UNITS = {'m': 'metres', 'cm': 'centimetres', 'mm': 'millimetres', 'rad': 'radians',
         'deg': 'degrees', 's': 'seconds', 'g': 'standard gravities (an accelerometer)'}


def parse_units(text: str | None, what: str) -> Sequence[str]:
    """'m,m,rad' -> ('m', 'm', 'rad') for the command line, each one of UNITS; '' or None ->
    (). ValueError naming the accepted units otherwise."""
    units = parse_names(text, what)
    unknown = [u for u in units if u not in UNITS]
    if unknown:
        raise ValueError(f'{what}: unknown unit {unknown[0]!r}; give one of '
                         f'{", ".join(f"{u} ({name})" for u, name in UNITS.items())}')
    return units


def parse_names(text: str | None, what: str) -> Sequence[str]:
    """'x,y,z' -> ('x', 'y', 'z') for the command line; '' or None -> ()."""
    if not text:
        return ()
    names = tuple(n.strip() for n in text.split(','))
    if any(not n for n in names):
        raise ValueError(f'{what}: empty name in {text!r}')
    return names
