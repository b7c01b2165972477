"""`mixture-ip demo`: the closed loop end to end (``--scenario interactions``: app.interactions;
``--scenario change_of_mind``: app.change_of_mind).

Generate the box-assembly demonstrations as bags for the chosen robot (if the folder is missing),
hold out some interactions per pattern, train on the rest (K by leave-one-out), then replay the
held-out human demonstrations through the real nodes (bag_player -> observer -> estimator -> sim)
on simulated time, and report per interaction the true and chosen pattern, when the robot
committed, how far its hand ended from the target, how closely it tracked its commands, what
the simulated controller did with them (refused, re-timed when late, points beyond the limits),
and the estimator's latency. ``--command-delay S`` holds every command S s of simulated time on
its way to the arm.
"""

import logging
import os
import sys
import time
from pathlib import Path

import numpy as np

from mixture_ip_ros.io.bags import read_bag
from mixture_ip_ros.io.dataset import load_demonstration
from mixture_ip_ros.scenarios.folders import read_labels, read_scenario_robot, write_scenario_bags
from mixture_ip_ros.robot.description import DEFAULT_ROBOT, load_description
from mixture_ip_ros.robot.kinematics import RobotKinematics
from mixture_ip_ros.app.progress import text_progress
from mixture_ip_ros.app.summary import demo_summary, write_json
from mixture_ip_ros.app.training import train_to_file

log = logging.getLogger('mixture_ip_ros.app.demo')


def split_held_out(labels: dict, per_pattern: int, seed: int = 0):
    """(training bag names, held-out bag names): ``per_pattern`` held out of every pattern."""
    rng = np.random.default_rng(seed)
    held = []
    for pattern in sorted(set(labels.values())):
        names = sorted(n for n, lbl in labels.items() if lbl == pattern)
        held += list(rng.choice(names, size=min(per_pattern, len(names) - 1), replace=False))
    return sorted(n for n in labels if n not in held), sorted(held)


def demonstrated_target(bag, kinematics):
    """Where the robot's hand ended in the demonstration (FK of its last recorded posture) and
    where the human's wrist ended, both in the robot's base frame."""
    robot = kinematics.description
    rec = read_bag(bag, joint_names=robot.joint_names)
    wrist = rec.wrist_xyz[~np.isnan(rec.wrist_xyz).any(axis=1)][-1]
    return kinematics.fk(rec.joint_q[-1])[0], robot.world_to_base().apply_array(wrist)


def default_paths(robot) -> tuple:
    """(bag folder, output folder) of ``mixture-ip demo`` for a robot: out/box_assembly_bags and
    out/demo for the default robot, out/<name>/box_assembly_bags and out/<name>/demo otherwise."""
    name = load_description(robot).name
    root = Path('out') if name == DEFAULT_ROBOT else Path('out') / name
    return root / 'box_assembly_bags', root / 'demo'


def demo_folders(args, paths):
    """(robot description, data folder, output folder, made) of a demo's ``args``;
    ``paths(robot)`` gives the default folders."""
    robot = load_description(args.robot)
    default_data, default_out = paths(robot)
    data_dir = Path(args.data) if args.data else default_data
    out_dir = Path(args.out) if args.out else default_out
    out_dir.mkdir(parents=True, exist_ok=True)
    return robot, data_dir, out_dir


def prepare_box_demo(data_dir: Path, out_dir: Path, held_out: int, seed: int,
                     n_components=None, robot=None):
    """Bags for ``robot`` (generated if missing), the held-out split and a trained model file."""
    robot = load_description(robot)
    if not data_dir.is_dir() or not any(data_dir.iterdir()):
        log.info('generating the box-assembly demonstrations for %s in %s', robot.name, data_dir)
        write_scenario_bags('box_assembly', data_dir, seed=seed, robot=robot)
    made_for = read_scenario_robot(data_dir)
    if made_for != robot.name:
        raise ValueError(f'{data_dir} holds demonstrations of {made_for!r}, not {robot.name!r}; '
                         'give another --data folder')
    labels = read_labels(data_dir)
    train_names, held_names = split_held_out(labels, held_out, seed)
    demos = [load_demonstration(data_dir / n, joint_names=robot.joint_names,
                                transform=robot.world_to_base()) for n in train_names]
    model_path = out_dir / 'model.npz'
    kwargs = {'n_components': n_components} if n_components else {
        'progress': text_progress()}
    t0 = time.monotonic()
    model, info = train_to_file(demos, model_path, robot=robot, **kwargs)
    info['train_seconds'] = time.monotonic() - t0
    return labels, held_names, model_path, info


def run_demo(args):
    """The box-assembly demo (`mixture-ip demo`); the interactions demo is app.interactions."""
    # rclpy only once the data is ready
    from mixture_ip_ros.app.closed_loop import ClosedLoop

    robot, data_dir, out_dir = demo_folders(args, default_paths)
    labels, held, model_path, info = prepare_box_demo(
        data_dir, out_dir, args.held_out, args.seed, n_components=args.components, robot=robot)
    print(f"{robot.name}: trained on {info['n_demonstrations']} demonstrations: "
          f"K = {info['n_components']}"
          + (f" (leave-one-out RMS by K: {np.round(info['loo_rms_mean'], 4).tolist()})"
             if 'loo_rms_mean' in info else ''))
    kin = RobotKinematics(robot)
    loop = ClosedLoop(model_path, robot=robot,
                      domain_id=int(os.environ.get('ROS_DOMAIN_ID', 42)),
                      command_delay=args.command_delay)
    records = []
    try:
        for name in held:
            records.append(replay_bag(loop, data_dir / name, labels[name], kin))
            print(interaction_line(records[-1]), flush=True)
        latency = loop_latency(loop)
    finally:
        loop.close()
    report = make_report(records, info, latency)
    report['robot'] = robot.name
    report['command_delay'] = args.command_delay
    return finish_demo(records, report, demo_summary(report, args.json), args, out_dir)


def finish_demo(records, report, summary: str, args, out_dir):
    """A box-assembly demo's end: the report to ``args.json``, its ``summary`` printed, the
    plots in ``out_dir``, the videos with ``args.render``; returns the report."""
    write_json(args.json, report)
    print(summary)
    plot_demo(records, out_dir)
    print(f'plots in {out_dir}')
    if args.render:
        render_all(records, Path(args.render))
    return report


def replay_bag(loop, bag, true_pattern, kin, target_bag=None):
    """One bag replayed through the running ``loop`` from the robot's home posture: its record,
    the target where the robot's hand ended in ``target_bag``'s demonstration (default: the
    bag's own) with where the human's wrist ended there, the points of its commands beyond the
    arm's limits and the plans the estimator refused to send (``plans_refused``)."""
    from mixture_ip_ros.app.closed_loop import points_beyond_limits
    loop.go_home()
    target, wrist_end = demonstrated_target(target_bag or bag, kin)
    refusals = loop.estimator.planner.counts.plan_refusals
    before = dict(refusals)
    rec = loop.run_interaction(bag, true_pattern=true_pattern, target=target)
    rec.extra['wrist_end'] = wrist_end
    rec.extra['points_beyond_limits'] = points_beyond_limits(rec.extra['commands'], kin)
    rec.extra['plans_refused'] = int(sum(refusals[k] - before.get(k, 0) for k in refusals))
    return rec


def loop_latency(loop) -> dict:
    """The estimator's update and plan times so far (us)."""
    return {'update_us_mean': loop.estimator.latency.mean_us,
            'update_us_max': loop.estimator.latency.max_us,
            'plan_us_mean': loop.estimator.plan_latency.mean_us,
            'plan_us_max': loop.estimator.plan_latency.max_us}


def hand_error_cm(rec):
    return float(100 * np.linalg.norm(rec.flange[-1] - rec.target)) if len(rec.flange) else None


def tracking_mrad(rec):
    """(RMS, max) joint tracking error of the interaction in mrad (None if it never moved)."""
    tracking = rec.extra.get('tracking') or {}
    if tracking.get('rms') is None:
        return None, None
    return 1e3 * tracking['rms'], 1e3 * tracking['max']


def interaction_line(rec) -> str:
    """The line the demo prints for one interaction's record."""
    he = hand_error_cm(rec)
    wrist = rec.extra.get('wrist_end')
    to_wrist = (100 * np.linalg.norm(rec.flange[-1] - wrist)) if wrist is not None else np.nan
    commit = '-' if rec.commit_fraction is None else f'{rec.commit_fraction:.2f}'
    rms, _ = tracking_mrad(rec)
    track = '-' if rms is None else f'{rms:.3f}'
    late = rec.extra.get('sim_retimed', 0)
    refused = rec.extra.get('sim_rejections', 0)
    return (f'{rec.name:>16s}: true {rec.true_pattern:<12s} chosen {str(rec.chosen_pattern):<12s}'
            f' committed at {commit} of the motion; hand {he:5.1f} cm from target, '
            f'{to_wrist:5.1f} cm from the wrist; tracking RMS {track} mrad'
            + (f'; {late} commands late (re-timed)' if late else '')
            + (f'; {refused} refused: {rec.extra["last_rejection"]}' if refused else ''))


def report_row(r) -> dict:
    """The report's row of one interaction's record."""
    rms, worst = tracking_mrad(r)
    return {'name': r.name, 'true_pattern': r.true_pattern,
            'chosen_pattern': r.chosen_pattern, 'commit_fraction': r.commit_fraction,
            'hand_error_cm': hand_error_cm(r),
            'hand_to_wrist_cm': float(100 * np.linalg.norm(
                r.flange[-1] - r.extra['wrist_end'])) if 'wrist_end' in r.extra else None,
            'tracking_rms_mrad': rms, 'tracking_max_mrad': worst,
            'non_finite_commands': r.extra.get('non_finite_commands', 0),
            'commands': len(r.extra.get('commands', ())),
            'commands_retimed': r.extra.get('sim_retimed'),
            'last_retime_delay_s': r.extra.get('last_retime_delay'),
            'commands_refused': r.extra.get('sim_rejections'),
            'last_refusal': r.extra.get('last_rejection'),
            'plans_refused': r.extra.get('plans_refused'),
            'final_plan_received': r.extra.get('final_plan_received'),
            'points_beyond_limits': r.extra.get('points_beyond_limits')}


def make_report(records, info, latency):
    rows = [report_row(r) for r in records]
    correct = [r['true_pattern'] == r['chosen_pattern'] for r in rows]
    tracked = [r['tracking_rms_mrad'] for r in rows if r['tracking_rms_mrad'] is not None]
    return {'interactions': rows,
            'selection_accuracy': float(np.mean(correct)) if rows else None,
            'hand_error_cm_mean': float(np.mean([r['hand_error_cm'] for r in rows])) if rows else None,
            'commit_fraction_mean': float(np.mean([r['commit_fraction'] for r in rows
                                                   if r['commit_fraction'] is not None] or [np.nan])),
            'hand_error_cm_max': max(r['hand_error_cm'] for r in rows) if rows else None,
            'tracking_rms_mrad_mean': float(np.mean(tracked)) if tracked else None,
            'tracking_rms_mrad_max': float(np.max(tracked)) if tracked else None,
            'n_components': info['n_components'], 'training': info, 'latency': latency}


def render_all(records, render_dir: Path):
    try:
        from mixture_ip_ros.viz.animation import render_interaction
        from mixture_ip_ros.viz.offscreen import rendering_available
    except ImportError as e:
        print(f'rendering unavailable ({e}); no video', file=sys.stderr)
        return
    ok, why = rendering_available()
    if not ok:
        print(f'rendering unavailable ({why}); no video', file=sys.stderr)
        return
    render_dir.mkdir(parents=True, exist_ok=True)
    for rec in records:
        paths = render_interaction(rec, render_dir)
        print(f'rendered {rec.name}: ' + ', '.join(str(p) for p in paths.values()))


def plot_demo(records, out_dir: Path):
    """Per interaction: wrist and robot hand paths (top view and height over time) and the
    component posterior over time, with the onset, commit and end marked (and where the human
    turned to another part: ``extra['change_time']``, app.change_of_mind)."""
    from mixture_ip_ros.viz.plots import plt, save_figure   # matplotlib on the Agg backend
    for rec in records:
        fig, ax = plt.subplots(1, 3, figsize=(15, 4.2))
        t0 = rec.onset_time if rec.onset_time is not None else (rec.t[0] if len(rec.t) else 0.0)
        if len(rec.wrist):
            ax[0].plot(rec.wrist[:, 1], rec.wrist[:, 0], '.', ms=2, label='human wrist (observed)')
            ax[1].plot(rec.wrist_t - t0, rec.wrist[:, 2], '.', ms=2, label='wrist z')
        if len(rec.flange):
            ax[0].plot(rec.flange[:, 1], rec.flange[:, 0], '-', label='robot hand (sim)')
            ax[1].plot(rec.t - t0, rec.flange[:, 2], '-', label='robot hand z')
        if rec.target is not None:
            ax[0].plot(rec.target[1], rec.target[0], 'k*', ms=12, label='demonstrated target')
        ax[0].set(xlabel='y (m)', ylabel='x (m)', title='top view, robot base frame')
        ax[0].invert_xaxis()
        ax[0].legend(fontsize=7)
        ax[1].set(xlabel='time since onset (s)', ylabel='z (m)', title='height')
        for k, label in enumerate(rec.component_labels):
            if len(rec.posterior):
                ax[2].plot(rec.posterior_t - t0, rec.posterior[:, k], label=f'p({label} | D)')
        if len(rec.phase):
            ax[2].plot(rec.posterior_t - t0, rec.phase, 'k--', label='phase z')
        for a in ax[1:]:
            for when, colour, what in ((rec.commit_time, 'g', 'robot committed'),
                                       (rec.extra.get('change_time'), 'm', 'human turned'),
                                       (rec.end_time, 'r', 'human movement ended')):
                if when is not None:
                    a.axvline(when - t0, color=colour, ls=':', label=what)
        ax[2].set(xlabel='time since onset (s)', ylim=(-0.05, 1.05),
                  title=f'true {rec.true_pattern}, chosen {rec.chosen_pattern}')
        ax[1].legend(fontsize=7)
        ax[2].legend(fontsize=7)
        fig.tight_layout()
        save_figure(fig, out_dir / f'{rec.name}.png', dpi=90)
