"""Real human motion: PickupGestureWiimoteZ from the UCR time series archive.

Ten people each made the same "pick-up" gesture with a Nintendo Wiimote in the hand; the series
is the Z acceleration (in g), of unequal lengths, with rest before and after the gesture in most
recordings; the class is the person (10 classes, 50 train / 50 test, 5 per class each).
Data created by J. Guna, I. Humar and M. Pogacnik ("Intuitive gesture based user
identification system", TSP 2012), edited by H. A. Dau for the UCR archive.

It is fetched at run time from the aeon wheel on PyPI (``pip download aeon==1.6.0 --no-deps``
into a user cache; only the two .ts files are kept), so a fresh machine needs no manual step
and nothing of the archive is redistributed. The cache is io.cache's.

The archive gives no sample rate; times assume the Wiimote's usual 100 Hz report rate (it only
scales alpha and the online estimator's decimation interval, never the data). Each recording is
a single-agent demonstration (1 observed DOF, nothing controlled), whole, as the archive cut it:
t = 0 at its first sample. Cutting the rest off either end removes information the people
differ by (experiments/gesture_representation.py, docs/method.md): the end cut is wrong on
recordings that stop before the hand settles (the Wiimote rests at a new tilt, or never rests),
and how long a person waits before moving is part of how that person makes the gesture.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np

from mixture_ip_ros.core.demonstration import Demonstration, Layout
from mixture_ip_ros.io.cache import cache_dir
from mixture_ip_ros.io.ucr import read_ts

DATASET = 'PickupGestureWiimoteZ'
AEON_VERSION = '1.6.0'
RATE = 100.0                     # Hz (assumed, see the module docstring)
LAYOUT = Layout(('accel_z',), (), ('g',))
SOURCE = (f'{DATASET}, UCR time series archive (Guna, Humar, Pogacnik, TSP 2012; edited by '
          f'H. A. Dau), from the aeon {AEON_VERSION} wheel')


def fetch_ucr(name: str = DATASET, cache: Path | None = None) -> Path:
    """The folder holding ``{name}_TRAIN.ts`` and ``{name}_TEST.ts``, downloading the aeon wheel
    with pip the first time (a RuntimeError in one line if that fails)."""
    folder = Path(cache or cache_dir()) / 'ucr' / name
    files = [folder / f'{name}_{split}.ts' for split in ('TRAIN', 'TEST')]
    if all(f.is_file() for f in files):
        return folder
    folder.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=folder.parent) as tmp:
        cmd = [sys.executable, '-m', 'pip', 'download', '--no-deps', '--only-binary=:all:',
               '--disable-pip-version-check', '-q', '-d', tmp, f'aeon=={AEON_VERSION}']
        run = subprocess.run(cmd, capture_output=True, text=True)
        wheels = list(Path(tmp).glob('aeon-*.whl'))
        if run.returncode != 0 or not wheels:
            said = (run.stderr or run.stdout).strip().splitlines()
            raise RuntimeError(f'could not download aeon=={AEON_VERSION} from PyPI for the '
                               f'{name} data set: {said[-1] if said else "no wheel"}')
        staging = Path(tmp) / name
        staging.mkdir()
        with zipfile.ZipFile(wheels[0]) as whl:
            for f in files:
                member = f'aeon/datasets/data/{name}/{f.name}'
                try:
                    (staging / f.name).write_bytes(whl.read(member))
                except KeyError:
                    raise RuntimeError(f'the aeon {AEON_VERSION} wheel has no {member}') from None
        if folder.exists():
            shutil.rmtree(folder)
        staging.rename(folder)
    return folder


def gesture_demonstrations(split: str, cache: Path | None = None) -> list:
    """The ``split`` ('train' or 'test') recordings as labelled single-agent Demonstrations."""
    if split not in ('train', 'test'):
        raise ValueError(f"split must be 'train' or 'test', got {split!r}")
    data = read_ts(fetch_ucr(cache=cache) / f'{DATASET}_{split.upper()}.ts')
    demos = []
    for i, (y, label) in enumerate(zip(data.series, data.labels)):
        valid = np.flatnonzero(~np.isnan(y).all(axis=1))
        y = y[:valid[-1] + 1]              # padding of unequal lengths (the _eq files) only
        demos.append(Demonstration(np.arange(len(y)) / RATE, y, None, label=str(label),
                                   name=f'{split}_{i:02d}'))
    return demos
