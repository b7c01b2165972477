"""Option types and options shared by `mixture-ip`'s subcommands: every option is checked
before any work starts."""

import argparse
import math
import os
from pathlib import Path


def bounded(kind, low=None, high=None, name='a number'):
    def parse(text):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'{text!r} is not {name}') from None
        if kind is float and not math.isfinite(value):
            raise argparse.ArgumentTypeError(f'{text!r} is not a finite number')
        if (low is not None and value < low) or (high is not None and value > high):
            bounds = (f'>= {low}' if high is None else f'<= {high}' if low is None
                      else f'in [{low}, {high}]')
            raise argparse.ArgumentTypeError(f'{value} is not {bounds}')
        return value
    return parse


def noise_stds(text):
    """'0.01' -> 0.01, '0.01,0.02' -> [0.01, 0.02]: standard deviations, finite and >= 0."""
    one = bounded(float, 0.0)
    values = [one(v) for v in text.split(',')]
    return values[0] if len(values) == 1 else values


def existing_dir(text):
    if not Path(text).is_dir():
        raise argparse.ArgumentTypeError(f'{text} is not a folder')
    return text


def existing_file(text):
    if not Path(text).is_file():
        raise argparse.ArgumentTypeError(f'{text} is not a file')
    return text


def new_file(text):
    """A file to write: not a folder, and in a folder that exists or can be made (nothing is
    created now)."""
    path = Path(text)
    if path.is_dir():
        raise argparse.ArgumentTypeError(f'{text} is a folder: name the file to write')
    _writable_parent(path, text)
    return text


def out_dir(text):
    path = Path(text)
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f'{text} is a file, not a folder')
    _writable_parent(path, text)
    return text


def _writable_parent(path, text):
    parent = path.resolve().parent
    while not parent.exists():
        parent = parent.parent
    if not (parent.is_dir() and os.access(parent, os.W_OK)):
        raise argparse.ArgumentTypeError(f'cannot write {text}: {parent} is not writable')


def add_robot(parser):
    from mixture_ip_ros.robot.description import DEFAULT_ROBOT, shipped_robots
    parser.add_argument('--robot', default=DEFAULT_ROBOT,
                        help=f'the arm: a shipped name ({", ".join(shipped_robots())}) or the '
                             'path of a robot description file (docs/robots.md); default '
                             f'{DEFAULT_ROBOT}')


# Combinations of options are checked right after parsing, before any data is read, so that a
# run that cannot succeed fails in a second, not after minutes of training.
def given(args, parser, *dests):
    """The options among ``dests`` set to something other than their defaults, as spelled on
    the command line."""
    return ['--' + d.replace('_', '-') for d in dests
            if getattr(args, d) != parser.get_default(d)]
