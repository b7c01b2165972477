"""Do the decisions training takes depend on the CPU? Every decision of ``training.train`` (K,
its partition, the covariance floor, the speed weight) on small generated sets, taken in one
process per OpenBLAS kernel this CPU can run (OPENBLAS_CORETYPE: Haswell and Zen (AVX2),
Sandybridge (AVX), Prescott (SSE3), SkylakeX where it has AVX-512), and compared. Prints one
JSON object: per kernel the decisions, whether they are all the same, and how far apart the
curves behind them are (they differ by rounding only).

    OPENBLAS_NUM_THREADS=1 python bench/cpu_kernels.py [--cases layouts-1-2,...]
    OPENBLAS_NUM_THREADS=1 python bench/cpu_kernels.py --tests [--kernels Haswell,Sandybridge]

``--tests`` runs the tests marked ``decision`` (a chosen K or a recognition rate asserted) under
every kernel and reports each kernel's pass and fail counts: minutes per kernel.
"""

import argparse
import json
import os
from pathlib import Path
import subprocess
import sys

ROOT = Path(__file__).resolve().parents[1]
# kernel -> the CPU flag it needs
KERNELS = {'Haswell': 'avx2', 'Zen': 'avx2', 'Sandybridge': 'avx', 'Prescott': 'sse3',
           'SkylakeX': 'avx512f'}
# name -> (observed DOFs, controlled DOFs) of a generated set of three patterns (the layouts
# test's sets, seed 1)
CASES = {f"layouts-{p}-{q}": (p, q) for p, q in ((1, 0), (2, 0), (1, 2), (4, 1), (3, 7))}


def runnable_kernels():
    flags = set()
    cpuinfo = Path('/proc/cpuinfo')
    if cpuinfo.is_file():
        for line in cpuinfo.read_text().splitlines():
            if line.startswith('flags'):
                flags |= set(line.split(':', 1)[1].split())
    sse3 = 'pni' in flags                      # /proc/cpuinfo calls SSE3 pni
    return [k for k, f in KERNELS.items() if f in flags or (f == 'sse3' and sse3)]


def decisions(names) -> dict:
    """Every decision of training on each named case, and the curves behind them."""
    import numpy as np
    from mixture_ip_ros.app.training import train
    from mixture_ip_ros.scenarios.synthetic import mixture_demos
    out = {}
    for name in names:
        P, Q = CASES[name]
        demos = mixture_demos(seed=1, n_obs=P, n_ctrl=Q)[0]
        model, info = train(demos, candidates=(1, 2, 3, 4), n_basis=8)
        sel = info['selection']
        out[name] = {'K': info['n_components'], 'prior_scale': info['prior_scale'],
                     'speed_weight': info['speed_weight'],
                     'partition': np.argmax(model.resp_, axis=1).tolist(),
                     'smoothing': sel['smoothing'], 'curve': sel['mean'],
                     'stability': sel['stability']}
    return out


def run_kernels(args_for_worker, kernels):
    """{kernel: the worker's JSON} from one subprocess per kernel, two at a time."""
    procs = {}
    results = {}
    pending = list(kernels)
    while pending or procs:
        while pending and len(procs) < 2:
            k = pending.pop(0)
            env = dict(os.environ, OPENBLAS_CORETYPE=k, OPENBLAS_NUM_THREADS='1')
            procs[k] = subprocess.Popen([sys.executable, __file__, *args_for_worker], env=env,
                                        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                        text=True)
        k, p = next(iter(procs.items()))
        out, err = p.communicate()
        del procs[k]
        if p.returncode != 0:
            raise RuntimeError(f'{k}: worker failed: {err.strip().splitlines()[-1:]}')
        results[k] = out
    return results


def compare(per_kernel: dict) -> dict:
    """Whether every kernel took the same decisions, and how far apart the curves were."""
    import numpy as np
    kernels = list(per_kernel)
    first = per_kernel[kernels[0]]
    same, spread = True, 0.0
    for case, d in first.items():
        for k in kernels[1:]:
            other = per_kernel[k][case]
            for key in ('K', 'prior_scale', 'speed_weight', 'partition', 'smoothing',
                        'stability'):
                same &= other[key] == d[key]
            a, b = np.array(d['curve']), np.array(other['curve'])
            spread = max(spread, float(np.max(np.abs(a - b) / np.maximum(np.abs(a), 1.0))))
    return {'same': bool(same), 'curve_max_relative_difference': spread}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--cases', default=','.join(CASES))
    ap.add_argument('--tests', action='store_true', help='run the decision tests instead')
    ap.add_argument('--kernels', default=None,
                    help='comma-separated kernels (default: every one this CPU runs)')
    ap.add_argument('--worker', action='store_true', help=argparse.SUPPRESS)
    args = ap.parse_args()
    names = args.cases.split(',')
    if set(names) - set(CASES):
        raise SystemExit(f'unknown cases {sorted(set(names) - set(CASES))}; known: {list(CASES)}')
    if args.worker:
        print(json.dumps(decisions(names)))
        return
    kernels = runnable_kernels()
    if args.kernels:
        asked = args.kernels.split(',')
        if set(asked) - set(kernels):
            raise SystemExit(f'this CPU cannot run {sorted(set(asked) - set(kernels))}; it runs '
                             f'{kernels}')
        kernels = asked
    if args.tests:
        out = {}
        for k in kernels:      # one at a time: each run uses both cores
            env = dict(os.environ, OPENBLAS_CORETYPE=k, OPENBLAS_NUM_THREADS='1')
            done = subprocess.run([sys.executable, '-m', 'pytest', '-q', '-p', 'no:cacheprovider',
                                   '-m', 'decision', 'test'], env=env, cwd=ROOT,
                                  capture_output=True, text=True)
            out[k] = done.stdout.strip().splitlines()[-1] if done.stdout.strip() else done.stderr
        print(json.dumps({'kernels': kernels, 'decision_tests': out}))
        return
    raw = run_kernels(['--worker', '--cases', ','.join(names)], kernels)
    per_kernel = {k: json.loads(v.strip().splitlines()[-1]) for k, v in raw.items()}
    print(json.dumps({'kernels': kernels, **compare(per_kernel),
                      'decisions': {k: {c: {key: d[key] for key in ('K', 'prior_scale',
                                                                    'speed_weight')}
                                        for c, d in v.items()} for k, v in per_kernel.items()}}))


if __name__ == '__main__':
    main()
