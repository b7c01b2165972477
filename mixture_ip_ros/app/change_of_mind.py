"""`mixture-ip demo --scenario change_of_mind`: the box assembly's person reaches toward one
part and turns to another mid-reach (issue 50), through the real nodes.

As the box demo (app.demo): the bags generated if missing, ``--held-out`` interactions held out
per pattern, a model trained on the rest (K by leave-one-out, its switch rate calibrated on
held-out folds: app.training). The held-out bags are replayed unchanged first, then spliced
(scenarios.change_of_mind: A's reach up to a share of it, then B's from the same share of its
own, reached within core.splice.BLEND s): for every ordered pair of patterns (P, Q), the i-th
held-out of P turning into the i-th of Q, at a share drawn from SHARES. The spliced bags go
to ``<out>/change_of_mind_bags``. Each is replayed through bag_player -> observer ->
estimator -> sim as the box demo replays its bags; its target is where the robot's hand ended
in B's demonstration. Per spliced interaction: the patterns, the share, the pattern of the
last plan the arm got (none when the estimator stopped it: the movement unexplained), of the
commit and of the estimator's last belief, the hand's distance from the target at the end
beside the unchanged interactions', the switches of plan the estimator recorded after it
committed, how long after the change its belief settled on B, the points of the commands
beyond the arm's limits, the plans the estimator refused and the commands the arm refused.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from mixture_ip_ros.app.demo import (demo_folders, finish_demo, interaction_line, loop_latency,
                                     make_report, prepare_box_demo, replay_bag, report_row)
from mixture_ip_ros.app.summary import demo_summary
from mixture_ip_ros.io.bags import read_bag
from mixture_ip_ros.robot.description import DEFAULT_ROBOT, load_description
from mixture_ip_ros.robot.kinematics import RobotKinematics
from mixture_ip_ros.core.splice import SHARES
from mixture_ip_ros.scenarios.change_of_mind import (CHANGE_KEY, read_splices,
                                                     splice_name, write_change_of_mind_bags)

BAGS = 'change_of_mind_bags'


def default_paths(robot) -> tuple:
    """(bag folder, output folder): the box demo's bags (out/box_assembly_bags) and
    out/change_of_mind for the default robot, out/<name>/... for another."""
    name = load_description(robot).name
    root = Path('out') if name == DEFAULT_ROBOT else Path('out') / name
    return root / 'box_assembly_bags', root / 'change_of_mind'


def splice_plan(held, labels: dict, seed: int = 0) -> list:
    """[(bag A, bag B, share)]: for every ordered pair of patterns (P, Q), P != Q, the i-th of
    the ``held`` bags of P into the i-th of Q (i up to the fewer of the two), at a share drawn
    from SHARES."""
    by_pattern = {}
    for name in sorted(held):
        by_pattern.setdefault(labels[name], []).append(name)
    pairs = [(a, b) for p in sorted(by_pattern) for q in sorted(by_pattern) if p != q
             for a, b in zip(by_pattern[p], by_pattern[q])]
    shares = np.random.default_rng(seed).choice(SHARES, size=len(pairs))
    return [(a, b, float(s)) for (a, b), s in zip(pairs, shares)]


def prepare_splices(data_dir: Path, plan, folder: Path, joint_names) -> dict:
    """The spliced bags of ``plan`` in ``folder`` (written if it is missing or empty, reused if
    it holds exactly these): their recipes (scenarios.change_of_mind.read_splices)."""
    if folder.is_dir() and any(folder.iterdir()):
        recipe = read_splices(folder)
        if set(recipe) != {splice_name(a, b, s) for a, b, s in plan}:
            raise ValueError(f'{folder} holds other change-of-mind bags than this split; remove '
                             'it (it is rebuilt from the held-out bags)')
        return recipe
    write_change_of_mind_bags([(data_dir / a, data_dir / b, s) for a, b, s in plan], folder,
                              joint_names=joint_names)
    return read_splices(folder)


def _replay_offset(rec, bag, robot):
    """(replay stamps minus bag time, the bag as read): at the observed wrist sample farthest
    from the first one (a reach passes each place once), against the bag's nearest sample."""
    raw = read_bag(bag, joint_names=robot.joint_names)
    xyz = robot.world_to_base().apply_array(raw.wrist_xyz)
    seen = np.asarray(rec.wrist)
    j = int(np.argmax(np.linalg.norm(seen - seen[0], axis=1)))
    k = int(np.nanargmin(np.linalg.norm(xyz - seen[j], axis=1)))
    return float(rec.wrist_t[j] - raw.wrist_t[k]), raw


def settled_after(rec, label: str, t_change: float):
    """Seconds from ``t_change`` until the estimator's published belief (its most probable
    component) is ``label`` and stays so to its last message; None if it ends elsewhere."""
    if not len(rec.posterior):
        return None
    said = np.array(rec.component_labels, dtype=object)[np.argmax(rec.posterior, axis=1)]
    wrong = np.flatnonzero(said != label)
    if wrong.size and wrong[-1] == len(said) - 1:
        return None
    first = 0 if not wrong.size else wrong[-1] + 1
    return max(0.0, float(rec.posterior_t[first]) - t_change)


def replay_splice(loop, folder: Path, name: str, recipe: dict, data_dir: Path, kin):
    """One spliced bag through the running ``loop``: (record, report row). The target is
    where the robot's hand ended in B's demonstration."""
    r = recipe[name]
    rec = replay_bag(loop, folder / name, r['second'], kin, target_bag=data_dir / r['second_bag'])
    offset, raw = _replay_offset(rec, folder / name, kin.description)
    change = (int(raw.custom_data[CHANGE_KEY]) - raw.start_time_ns) * 1e-9 + offset
    rec.extra['change_time'] = change
    inter = rec.extra['interaction'] or {}
    labels = rec.component_labels
    commit = inter.get('commit_component')
    row = {**report_row(rec), 'first_pattern': r['first'], 'share': r['share'],
           'change_after_onset_s': r['change_after_onset_s'],
           'commit_pattern': None if commit is None else labels[commit],
           # the pattern of the plan the arm got at the end (None: it got none, e.g. it held)
           'final_plan_pattern': rec.chosen_pattern if rec.extra['final_plan_received'] else None,
           'end_reason': inter.get('end_reason'),
           'unexplained': inter.get('unexplained'),      # the novelty test's latest reason
           'switches': [{'after_onset_s': s['elapsed'], 'phase': s['phase'],
                         'from': labels[s['from_component']], 'to': labels[s['to_component']]}
                        for s in inter.get('switches', [])],
           'belief_settled_s': settled_after(rec, r['second'], change)}
    return rec, row


def summary(rows, unchanged: dict, info) -> dict:
    """The spliced interactions' totals beside the unchanged ones' (``unchanged``: app.demo's
    make_report of them)."""
    errors = [r['hand_error_cm'] for r in rows]
    settled = [r['belief_settled_s'] for r in rows]
    same = unchanged.get('hand_error_cm_mean')
    mean = float(np.mean(errors)) if rows else None
    # a belief that never settled on B counts as never (the median is None past half of them)
    median = (float(np.percentile([np.inf if s is None else s for s in settled], 50,
                                  method='inverted_cdf')) if rows else None)
    return {'interactions': rows, 'n': len(rows),
            'followed': float(np.mean([r['final_plan_pattern'] == r['true_pattern']
                                       for r in rows])) if rows else None,
            'belief_followed': float(np.mean([r['chosen_pattern'] == r['true_pattern']
                                              for r in rows])) if rows else None,
            'committed_to_first': int(sum(r['commit_pattern'] == r['first_pattern']
                                          for r in rows)),
            'hand_error_cm_mean': mean, 'hand_error_cm_max': max(errors, default=None),
            'hand_error_ratio': None if mean is None or not same else mean / same,
            'belief_settled_s_median': median if median is not None and np.isfinite(median)
            else None,
            'belief_never_settled': int(sum(s is None for s in settled)),
            'switches': int(sum(len(r['switches']) for r in rows)),
            'points_beyond_limits': int(sum(r['points_beyond_limits'] for r in rows)),
            'plans_refused': int(sum(r['plans_refused'] for r in rows)),
            'commands_refused': int(sum(r['commands_refused'] or 0 for r in rows)),
            'non_finite_commands': int(sum(r['non_finite_commands'] for r in rows)),
            'switch_rate': info.get('switch_rate'), 'unchanged': unchanged}


def _line(row) -> str:
    settled = row['belief_settled_s']
    return (f"{row['name']:>34s}: {row['first_pattern']:<11s} -> {row['true_pattern']:<11s} "
            f"at {row['share']:.1f}; committed to {str(row['commit_pattern']):<11s} last plan "
            f"{str(row['final_plan_pattern']):<11s} ({len(row['switches'])} switches); belief "
            f"{str(row['chosen_pattern'])}, on B "
            f"{'never' if settled is None else f'{settled:.2f} s'} after the turn; hand "
            f"{row['hand_error_cm']:5.1f} cm from target; beyond limits "
            f"{row['points_beyond_limits']}, plans refused {row['plans_refused']}, commands "
            f"refused {row['commands_refused']}"
            + ('' if row['end_reason'] == 'end' else f"; ended: {row['end_reason']}"))


def replay(loop, data_dir: Path, labels: dict, held, folder: Path, recipe: dict, kin,
           info: dict, progress=print):
    """The ``held`` bags unchanged, then every spliced bag of ``recipe``, through the running
    ``loop``: (records, report)."""
    records = []
    for name in held:
        records.append(replay_bag(loop, data_dir / name, labels[name], kin))
        progress(interaction_line(records[-1]))
    unchanged = make_report(records, info, loop_latency(loop))
    del unchanged['training']                        # the report has it once, at the top
    rows = []
    for name in sorted(recipe):
        rec, row = replay_splice(loop, folder, name, recipe, data_dir, kin)
        records.append(rec)
        rows.append(row)
        progress(_line(row))
    report = summary(rows, unchanged, info)
    report['latency'] = loop_latency(loop)
    return records, report


def run(args):
    """The demo of this scenario (args of `mixture-ip demo`); returns the report."""
    from mixture_ip_ros.app.closed_loop import ClosedLoop   # rclpy only once the data is ready
    robot, data_dir, out_dir = demo_folders(args, default_paths)
    labels, held, model_path, info = prepare_box_demo(
        data_dir, out_dir, args.held_out, args.seed, n_components=args.components, robot=robot)
    print(f"{robot.name}: trained on {info['n_demonstrations']} demonstrations: "
          f"K = {info['n_components']}, switch rate {info.get('switch_rate')} per s")
    folder = out_dir / BAGS
    recipe = prepare_splices(data_dir, splice_plan(held, labels, args.seed), folder,
                             robot.joint_names)
    kin = RobotKinematics(robot)
    loop = ClosedLoop(model_path, robot=robot, domain_id=int(os.environ.get('ROS_DOMAIN_ID', 42)),
                      command_delay=args.command_delay)
    try:
        records, report = replay(loop, data_dir, labels, held, folder, recipe, kin, info,
                                 progress=lambda line: print(line, flush=True))
    finally:
        loop.close()
    report.update({'robot': robot.name, 'command_delay': args.command_delay,
                   'n_components': info['n_components'], 'training': info})
    return finish_demo(records, report, demo_summary(report['unchanged']) + '\n'
                       + change_summary(report, args.json), args, out_dir)


def change_summary(report, json_path=None) -> str:
    """The closing lines on the spliced interactions."""
    n = report['n']
    if not n:
        return 'changes of mind: none (the held-out bags hold one pattern)'
    right = round((report['followed'] or 0.0) * n)
    ratio = report['hand_error_ratio']
    settled = report['belief_settled_s_median']
    believed = round((report['belief_followed'] or 0.0) * n)
    lines = [f"changes of mind: the arm's last plan was the pattern turned to in {right} of {n} "
             f"(the estimator's last belief in {believed}; {report['committed_to_first']} had "
             f"committed to the first); belief settled "
             f"{'-' if settled is None else f'{settled:.2f} s'} after the turn (median), "
             f"{report['switches']} switches of plan",
             f"hand to the target of the pattern turned to: {report['hand_error_cm_mean']:.1f} "
             f"cm mean, {report['hand_error_cm_max']:.1f} cm worst"
             + ('' if ratio is None else f' ({ratio:.2f}x the unchanged interactions\')'),
             f"points beyond the limits {report['points_beyond_limits']}, plans refused "
             f"{report['plans_refused']}, commands refused {report['commands_refused']}"]
    if json_path:
        lines.append(f'full report: {json_path}')
    return '\n'.join(lines)

