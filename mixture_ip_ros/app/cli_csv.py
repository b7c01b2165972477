"""The options that name the columns of --csv recordings and their labels file (`train` and
`evaluate`): how they are parsed, what they mean, and which combinations of them are refused."""

import argparse
import json
from pathlib import Path

from mixture_ip_ros.app.cli_options import given


def add_translation(parser):
    parser.add_argument('--translation', choices=['none', 'shared', 'observed'], default='none',
                        help="where a recording happened is not part of its pattern (--csv): "
                             "'shared' both agents are positions in one frame (observed column i "
                             "and controlled column i the same axis) and the pair may stand "
                             "anywhere; 'observed' the same for a single agent; default 'none'")


class OneList(argparse.Action):
    """An option whose value is one comma-separated list: several words after it (the list
    spelled with spaces) are refused saying how to write it, instead of being taken for the
    positional arguments that follow."""

    def __call__(self, parser, namespace, values, option_string=None):
        if len(values) > 1:
            parser.error(f'{option_string} takes one comma-separated list, not {len(values)} '
                         f'words: {option_string} {",".join(values)}')
        setattr(namespace, self.dest, values[0])


def add_csv_columns(parser):
    from mixture_ip_ros.io.csv_files import UNITS
    units = ', '.join(UNITS)
    parser.add_argument('--observed', default=None, nargs='+', action=OneList,
                        help='observed agent columns, e.g. x,y,z (--csv)')
    parser.add_argument('--controlled', default=None, nargs='+', action=OneList,
                        help='controlled agent columns (--csv; none: a single-agent model)')
    parser.add_argument('--time', default='t',
                        help="time column in seconds (--csv; default 't')")
    parser.add_argument('--observed-units', default=None, nargs='+', action=OneList,
                        help=f'unit of each observed column, or one for all: {units} '
                             '(recorded in the model)')
    parser.add_argument('--controlled-units', default=None, nargs='+', action=OneList,
                        help=f"unit of each controlled column, or one for all: {units} (all "
                             "'m': errors in cm)")


def csv_layout(args):
    """The layout --observed/--controlled (and their units) name; ValueError if they name none
    or contradict each other or --time."""
    from mixture_ip_ros.core.demonstration import Layout
    from mixture_ip_ros.io.csv_files import parse_names, parse_units
    observed = parse_names(args.observed, '--observed')
    if not observed:
        raise ValueError('--csv needs --observed NAME[,NAME...] (the observed columns)')
    controlled = parse_names(args.controlled, '--controlled')
    layout = Layout(observed, controlled, parse_units(args.observed_units, '--observed-units')
                    or None, parse_units(args.controlled_units, '--controlled-units') or None)
    if args.time in observed + controlled:
        raise ValueError(f'--time {args.time!r} names the time column: it cannot also be an '
                         f'observed or controlled column')
    return layout


def translation_groups(args, layout):
    """The translation groups --translation names for ``layout`` (core.patterns); ValueError
    where they cannot apply."""
    from mixture_ip_ros.core.patterns import translation_for
    groups = translation_for(args.translation, len(layout.observed), len(layout.controlled))
    units = layout.observed_units + layout.controlled_units
    for g in groups:
        if len({units[j] for j in g} - {''}) > 1:          # '' is a unit not given
            raise ValueError(f'--translation {args.translation}: '
                             f'{" and ".join((layout.observed + layout.controlled)[j] for j in g)}'
                             f' move together but have units {[units[j] for j in g]}')
    return groups


def read_labels(path):
    """The --labels file: a JSON object, file name or stem -> label."""
    try:
        labels = json.loads(Path(path).read_text())
    except (OSError, ValueError) as error:
        raise ValueError(f'--labels {path}: not a readable JSON file ({error})') from None
    if not isinstance(labels, dict):
        raise ValueError(f'--labels {path}: must be a JSON object, file name -> label')
    return labels


def check_csv_columns(args, parser):
    """--observed, --controlled, their units and --time name CSV columns: with --csv they must
    make a layout, without it they have nothing to name. The layout, or None without --csv."""
    columns = given(args, parser, 'observed', 'controlled', 'observed_units',
                    'controlled_units', 'time', 'translation')
    if args.csv is None:
        if columns:
            parser.error(f'{", ".join(columns)}: for --csv DIR only (they name the columns of '
                         f'its files)')
        return None
    try:
        layout = csv_layout(args)
        translation_groups(args, layout)
    except ValueError as error:
        parser.error(str(error))
    return layout
