"""Training decides the same on every CPU: bench/cpu_kernels.py trains in one process per OpenBLAS
kernel the machine runs and compares every decision (K, partition, floor, speed weight)."""

import json
from pathlib import Path
import subprocess
import sys

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.decision
def test_every_blas_kernel_takes_the_same_decisions():
    # (1, 2) is the set whose K flipped between kernels when its data were sampled through an
    # SVD (numpy's multivariate_normal default): the samples themselves then differed.
    done = subprocess.run([sys.executable, str(ROOT / 'bench' / 'cpu_kernels.py'), '--cases',
                           'layouts-1-2,layouts-4-1'], cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    out = json.loads(done.stdout.strip().splitlines()[-1])
    assert {'Sandybridge', 'Prescott'} <= set(out['kernels'])
    assert out['same'], out['decisions']
    assert out['curve_max_relative_difference'] < 1e-9
    for decisions in out['decisions'].values():
        assert all(d['K'] == 3 for d in decisions.values())
