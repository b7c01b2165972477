"""Time series in the ``.ts`` format of the UCR/UEA archive (as shipped by aeon and sktime).

A header of ``@key value`` lines (comments start with ``#``), then ``@data`` and one series per
line: comma-separated values per dimension, dimensions separated by ``:``, the class label last
(with ``@classLabel true``). Unequal lengths are allowed; ``?`` or ``NaN`` is a missing value.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np


class TsData(NamedTuple):
    """``series``: one (T_i, D) array per series; ``labels``: (n,) strings or None;
    ``header``: the @-keys (lower case) and the leading comment lines joined."""

    series: list
    labels: list
    header: dict
    comments: str


def read_ts(path) -> TsData:
    """Read a .ts file; ValueError naming the file and line for anything malformed."""
    path = Path(path)
    header, comments, series, labels = {}, [], [], []
    in_data = False
    with open(path, encoding='utf-8') as f:
        for line_no, raw in enumerate(f, start=1):
            line = raw.strip()
            if not line:
                continue
            if line.startswith('#'):
                if not in_data:
                    comments.append(line[1:])
                continue
            if not in_data:
                if not line.startswith('@'):
                    raise ValueError(f'{path}, line {line_no}: expected an @ header line before @data')
                key, _, value = line[1:].partition(' ')
                if key.lower() == 'data':
                    in_data = True
                else:
                    header[key.lower()] = value.strip()
                continue
            parts = line.split(':')
            has_label = header.get('classlabel', 'false').split()[0].lower() == 'true'
            if has_label:
                if len(parts) < 2:
                    raise ValueError(f'{path}, line {line_no}: no class label')
                labels.append(parts[-1].strip())
                parts = parts[:-1]
            dims = []
            for p in parts:
                try:
                    dims.append(np.array([np.nan if v.strip() in ('?', 'NaN', 'nan') else float(v)
                                          for v in p.strip().rstrip(',').split(',')]))
                except ValueError as e:
                    raise ValueError(f'{path}, line {line_no}: not a number ({e})') from None
            if len({len(d) for d in dims}) != 1:
                raise ValueError(f'{path}, line {line_no}: dimensions of unequal length')
            series.append(np.column_stack(dims))
    if not in_data:
        raise ValueError(f'{path}: no @data section')
    if not series:
        raise ValueError(f'{path}: no series after @data')
    return TsData(series, labels or None, header, '\n'.join(comments))
