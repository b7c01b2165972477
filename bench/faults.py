"""Process faults in the closed loop (issue 51), with the nodes as separate processes started as
`mixture-ip run` starts them (simulated time, a held-out box-assembly bag replayed); one JSON
object on stdout.

Cases (bench/_fault_loop.py runs the nodes and measures, in simulated time):

- ``kill_<node>_<phase>``: SIGKILL of estimator_node, observer_node or sim_node while the arm
  follows the interaction's plans: ``first_plan`` 0.3 s after the first plan arrived, ``mid``
  halfway from the first plan to the end of the movement (the bag's annotated end, dated from
  the observer's onset, plus the estimator's settle_time), ``late`` after that once the arm has
  slowed to 30 % of its peak speed (near the end of its own movement).
  Measured after the kill: the arm's speed then, when it came to rest for good (every joint
  < 1e-3 rad/s), the flange's travel (cm, RobotKinematics), the trajectories received on the
  command topic (plans; holds: empty ones) and what the sim and the estimator counted. The sim's
  kill stops /clock (simulated time stops for every node): what happens is watched on the wall
  clock for 3 s, then across its restart (whose clock starts at 0 again) until the old
  simulated time is passed. Then the killed node is restarted with its command and the next
  held-out bag replayed (``next``): the right pattern, the hand error (the demo's), points of
  its plans beyond the limits, commands the sim rejected or refused.
- ``drop_<percent>``: the held-out bags with that share of their wrist messages dropped in bursts
  of up to 1 s (written with io.bags), each share through a fresh set of nodes, the bags in the
  same order; right pattern and hand error per bag, beside ``drop_0``.
- ``stray``: a second node (bench/_fault_stray.py) publishes 10 trajectories on the arm's
  command topic during an interaction; the sim's counts while it is there.

Each case: ``trials``, ``failures`` (runs that could not go on), a list per measure (one value
per trial) with its ``_median``, the ``aim_*`` counts of trials meeting the issue's aims, and
``rows`` (everything measured, the log folder of each run). ``run_failures`` lists them all.

    ROS_DOMAIN_ID=150 OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/faults.py [--quick]
        [--model out/demo/model.npz --data out/box_assembly_bags]

Without the model file, the box-assembly bags (generated if missing) train one (K = 3) on all
but the demo's held-out interactions (3 per pattern, seed 0).
"""

import argparse
import json
import os
from pathlib import Path
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))   # the checkout: bench._fault_*

from bench._fault_loop import ROOT  # noqa: E402
from bench._fault_trials import (DROP_SHARES, KILLED, PHASES, drop_run,  # noqa: E402
                                 kill_trial, stray_trial)

# -- the table ---------------------------------------------------------------------------------
def _median(values):
    values = [v for v in values if v is not None]
    return float(np.median(values)) if values else None


def _column(rows, key, sub=None):
    return [((r.get(sub) or {}) if sub else r).get(key) for r in rows]


FEW_CM = 3.0        # cm: "the flange moves at most a few cm after the kill"


def kill_summary(rows, baseline) -> dict:
    """A kill case's columns (one value per trial) and medians; ``baseline``: {bag: hand error
    without a fault} for the next interaction's comparison."""
    ok = [r for r in rows if 'failure' not in r]
    out = {'trials': len(rows), 'failures': [r['failure'] for r in rows if 'failure' in r]}
    keys = ('speed_at_kill', 'rest_after_kill_s', 'flange_travel_cm', 'flange_path_cm',
            'stopping_time_s', 'plans_after_kill', 'holds_after_kill',
            'sim_accepted_after_kill', 'estimator_ends_wrist_silent',
            'joint_states_while_dead', 'estimator_reports_while_dead',
            'estimator_ends_clock_reset', 'first_sim_time_seen_after_restart',
            'old_player_alive_after_restart', 'old_player_done_after_clock_passed',
            'plans_after_restart_before_next')
    for key in keys:
        values = _column(ok, key)
        if any(v is not None for v in values):
            out[key] = [round(v, 3) if isinstance(v, float) else v for v in values]
            if all(isinstance(v, (int, float)) and not isinstance(v, bool) or v is None
                   for v in values):
                out[f'{key}_median'] = _median(values)
    for key in ('hand_error_cm', 'points_beyond_limits', 'sim_rejected', 'sim_refused_sender',
                'plans'):
        values = _column(ok, key, 'next')
        out[f'next_{key}'] = [round(v, 2) if isinstance(v, float) else v for v in values]
        out[f'next_{key}_median'] = _median(values)
    nexts = [r.get('next') or {} for r in ok]
    out['next_right'] = sum(bool(n.get('right')) for n in nexts)
    out['next_hand_error_vs_no_fault_cm'] = [
        round(n['hand_error_cm'] - baseline[n['bag']], 2) if n.get('bag') in baseline
        and n.get('hand_error_cm') is not None else None for n in nexts]
    if ok and ok[0]['node'] != 'sim_node':
        rest = _column(ok, 'rest_after_kill_s')
        out['aim_at_rest_within_1s'] = sum(v is not None and v <= 1.0 for v in rest)
        out['aim_travel_within_few_cm'] = sum(v <= FEW_CM for v in _column(ok, 'flange_travel_cm'))
        out['aim_no_command_after_kill'] = sum(r['plans_after_kill'] == 0 for r in ok)
    return out


def drop_summary(rows, clean) -> dict:
    ok = [r for r in rows if 'failure' not in r]
    base = {r['bag']: r['hand_error_cm'] for r in clean if 'failure' not in r}
    deltas = [r['hand_error_cm'] - base[r['bag']] for r in ok if r['bag'] in base]
    return {'trials': len(rows), 'failures': [r['failure'] for r in rows if 'failure' in r],
            'right': sum(r['right'] for r in ok), 'bags': [r['bag'] for r in ok],
            'hand_error_cm': [round(r['hand_error_cm'], 2) for r in ok],
            'hand_error_cm_median': _median([r['hand_error_cm'] for r in ok]),
            'hand_error_vs_no_drops_cm': [round(d, 2) for d in deltas],
            'hand_error_vs_no_drops_cm_max': max(deltas) if deltas else None,
            'longest_burst_s': [(r.get('dropped') or {}).get('longest_burst_s') for r in ok]}


def held_out_bags(data: Path):
    from mixture_ip_ros.app.demo import split_held_out
    from mixture_ip_ros.scenarios.folders import read_labels
    labels = read_labels(data)
    held = split_held_out(labels, 3, seed=0)[1]
    # one pattern after another: consecutive trials replay different patterns
    by = {}
    for name in held:
        by.setdefault(labels[name], []).append(name)
    order = [n for group in zip(*by.values()) for n in group]
    return labels, [data / n for n in order + [n for n in held if n not in order]]


def ensure_model(model: Path, data: Path, scratch: Path) -> Path:
    if model.is_file():
        return model
    from mixture_ip_ros.app.demo import prepare_box_demo
    return prepare_box_demo(data, scratch, held_out=3, seed=0, n_components=3)[2]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--model', type=Path, default=ROOT / 'out' / 'demo' / 'model.npz')
    parser.add_argument('--data', type=Path, default=ROOT / 'out' / 'box_assembly_bags')
    parser.add_argument('--quick', action='store_true', help='a small subset')
    parser.add_argument('--domain', type=int, default=int(os.environ.get('ROS_DOMAIN_ID', 0)))
    parser.add_argument('--bags-per-kill', type=int, default=3)
    parser.add_argument('--cases', default='kill,drop,stray')
    parser.add_argument('--nodes', default=','.join(KILLED), help='the nodes killed')
    parser.add_argument('--phases', default=','.join(PHASES), help='when they are killed')
    parser.add_argument('--work', type=Path, default=None, help='logs and dropped bags')
    a = parser.parse_args()
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    work = a.work or Path(tempfile.mkdtemp(prefix='faults_'))
    start = time.monotonic()
    model = ensure_model(a.model, a.data, work / 'model')
    labels, bags = held_out_bags(a.data)
    cases = set(a.cases.split(','))
    out = {'model': str(model), 'data': str(a.data), 'quick': a.quick, 'work': str(work),
           'held_out': [b.name for b in bags], 'loadavg_at_start': os.getloadavg(),
           'cases': {}, 'run_failures': []}
    if a.quick:
        kills = [('estimator_node', 'first_plan', 0), ('observer_node', 'first_plan', 1),
                 ('sim_node', 'mid', 2)]
        drop_bags, shares = bags[:3], (0.0, 0.3)
    else:
        kills = [(node, phase, i) for node in a.nodes.split(',')
                 for phase in a.phases.split(',') for i in range(a.bags_per_kill)]
        drop_bags, shares = bags, DROP_SHARES
    trials = {}
    if 'kill' in cases:
        for n, (node, phase, i) in enumerate(kills):
            bag, next_bag = bags[i % len(bags)], bags[(i + 1) % len(bags)]
            row = kill_trial(model, a.domain, bag, next_bag, labels, node, phase,
                             work / f'kill_{n:02d}_{node}_{phase}')
            trials.setdefault(f'kill_{node}_{phase}', []).append(row)
            print(f"[{time.monotonic() - start:6.0f} s] kill {node} {phase} {bag.name}: "
                  f"rest {row.get('rest_after_kill_s')} travel {row.get('flange_travel_cm')} "
                  f"next {(row.get('next') or {}).get('right')} "
                  f"{(row.get('next') or {}).get('hand_error_cm')} {row.get('failure', '')}",
                  file=sys.stderr, flush=True)
    if 'drop' in cases:
        runs = {}
        for share in shares:
            runs[share] = drop_run(model, a.domain, drop_bags, labels, share, 0,
                                   work / 'drops')
            print(f'[{time.monotonic() - start:6.0f} s] drop {share}: '
                  f"{[(r.get('right'), r.get('hand_error_cm')) for r in runs[share]]}",
                  file=sys.stderr, flush=True)
        for share, rows in runs.items():
            out['cases'][f'drop_{round(100 * share)}'] = {**drop_summary(rows, runs[0.0]),
                                                          'rows': rows}
    # the hand error of each bag without a fault (the drop runs' first share, from the home
    # posture or the previous bag's end), beside the interaction after a restart
    baseline = {r['bag']: r['hand_error_cm'] for r in
                out['cases'].get('drop_0', {}).get('rows', []) if 'failure' not in r}
    for name, rows in trials.items():
        out['cases'][name] = {**kill_summary(rows, baseline), 'rows': rows}
    if 'stray' in cases:
        rows = [stray_trial(model, a.domain, bags[i], labels, work / f'stray_{i}')
                for i in range(1 if a.quick else 3)]
        ok = [r for r in rows if 'failure' not in r]
        out['cases']['stray'] = {
            'trials': len(rows), 'failures': [r['failure'] for r in rows if 'failure' in r],
            **{k: _column(ok, k) for k in ('stray_sent', 'stray_received_by_probe',
                                            'accepted_while_stray', 'refused_while_stray',
                                            'commands_in_window', 'refused_total',
                                            'other_publishers', 'accepted_after_stray_left')},
            'aim_no_stray_command_executed': sum(r['accepted_while_stray'] == 0 for r in ok),
            'rows': rows}
    for name, case in out['cases'].items():
        out['run_failures'] += [f'{name}: {f}' for f in case.get('failures', [])]
    out['seconds'] = round(time.monotonic() - start, 1)
    print(json.dumps(out, default=lambda o: o.tolist() if hasattr(o, 'tolist') else str(o)))


if __name__ == '__main__':
    main()
