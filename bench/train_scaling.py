"""How training's cost grows with the number of demonstrations. Prints one JSON object.

Generated box assembly (48 demonstrations a seed; N = 48, 96, 192, 384 from seeds 0, 1, ...)
and one layout of 10 DOFs (3 observed, 7 controlled) of 36 demonstrations of 300 samples,
each trained in a fresh process as `mixture-ip train` trains (app.training.train_to_file, K
chosen over 1..6): the time of every stage (app.progress.Stages: choosing K, the covariance
floor, the speed weight, the final fit, the novelty calibration, saving) and in all. The
exponent is the slope of log(total seconds) against log(N) over the box-assembly sizes.

    OPENBLAS_NUM_THREADS=1 python bench/train_scaling.py [--sizes 48,96,192,384]
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')


def box_demos(n):
    from mixture_ip_ros.scenarios.folders import generate
    from mixture_ip_ros.robot.kinematics import RobotKinematics
    kin = RobotKinematics(None)
    demos, seed = [], 0
    while len(demos) < n:
        demos += [g.to_demonstration() for g in generate('box_assembly', seed, kinematics=kin)]
        seed += 1
    return demos[:n]


def layout_demos():
    """36 demonstrations of 10 DOFs (3 observed, 7 controlled), 300 samples each."""
    from mixture_ip_ros.core.demonstration import Demonstration
    from mixture_ip_ros.scenarios.synthetic import mixture_demos
    demos = mixture_demos(seed=1, n_obs=3, n_ctrl=7, n_basis=15)[0]
    out = []
    for d in demos:
        t = np.linspace(0.0, d.duration, 300)
        Y = np.hstack([d.observed, d.controlled])
        Y = np.column_stack([np.interp(t, d.t, Y[:, j]) for j in range(Y.shape[1])])
        out.append(Demonstration(t, Y[:, :3], Y[:, 3:], d.label))
    return out


def one(kind: str, n: int) -> dict:
    """Train once in this process; the stages' seconds."""
    from mixture_ip_ros.app.training import train_to_file
    from mixture_ip_ros.core.demonstration import Layout
    demos = box_demos(n) if kind == 'box' else layout_demos()
    layout = None if kind == 'box' else Layout(tuple(f'o{i}' for i in range(3)),
                                               tuple(f'c{i}' for i in range(7)))
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        _, info = train_to_file(demos, Path(tmp) / 'model.npz', layout=layout,
                                candidates=range(1, 7))
        total = time.perf_counter() - t0
    return {'n': len(demos), 'seconds': round(total, 2), 'stages': info['seconds'],
            'K': info['n_components'], 'phase': info.get('phase', {}).get('chosen')}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--sizes', default='48,96,192,384')
    ap.add_argument('--worker', default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        kind, n = args.worker.split(':')
        print(json.dumps(one(kind, int(n))))
        return
    sizes = [int(s) for s in args.sizes.split(',')]
    runs = {}
    for job in [f'box:{n}' for n in sizes] + ['layout:36']:
        done = subprocess.run([sys.executable, __file__, '--worker', job], capture_output=True,
                              text=True, env=dict(os.environ, OPENBLAS_NUM_THREADS='1'))
        if done.returncode:
            raise SystemExit(f'{job} failed: {done.stderr.strip().splitlines()[-1:]}')
        runs[job] = json.loads(done.stdout.strip().splitlines()[-1])
    seconds = [runs[f'box:{n}']['seconds'] for n in sizes]
    exponent = (float(np.polyfit(np.log(sizes), np.log(seconds), 1)[0]) if len(sizes) > 1
                else None)
    print(json.dumps({'sizes': sizes, 'seconds': seconds, 'exponent': exponent,
                      'stages': [runs[f'box:{n}']['stages'] for n in sizes],
                      'K': [runs[f'box:{n}']['K'] for n in sizes],
                      'phase': [runs[f'box:{n}']['phase'] for n in sizes],
                      'layout_10_dofs_36x300': runs['layout:36']}))


if __name__ == '__main__':
    main()
