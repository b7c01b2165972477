"""`mixture-ip demo --scenario interactions`: the robot takes a person's part.

NuiSI's two-person interactions (scenarios.interactions): the arm in the partner's place learns
from the training recordings (person 1's hand observed, the arm's joints retargeted from the
partner's hand controlled), then each held-out recording's person 1 is replayed from a rosbag2
bag through the running nodes (bag_player -> observer -> estimator -> sim, on simulated time),
and the arm answers. Per interaction: the interaction chosen and when, the flange's distance to
where the partner's hand was (in the base frame) from the commitment to the end of the
movement (RMS) and once all is over, beside the same model's offline prediction of the same
(OnlineEstimator fed the movement up to the same fraction, phase unknown); the flange's
distance from person 1's hand at the recorded contact (where the two people's hands were
closest) beside the people's own distance there; the tracking error,
refused trajectories, commanded points beyond the arm's limits and non-finite commands.
"""

from __future__ import annotations

import logging
import os
import time
from pathlib import Path

import numpy as np

from mixture_ip_ros.app.demo import demo_folders
from mixture_ip_ros.app.progress import text_progress
from mixture_ip_ros.app.summary import demo_summary, write_json
from mixture_ip_ros.app.training import train_to_file
from mixture_ip_ros.core.online import OnlineEstimator
from mixture_ip_ros.core.playback import played_to
from mixture_ip_ros.io.bags import read_bag
from mixture_ip_ros.io.dataset import (NoRecordedInterval, load_dataset, load_demonstration,
                                       segment_recording)
from mixture_ip_ros.robot.description import DEFAULT_ROBOT, load_description
from mixture_ip_ros.scenarios import interactions, nuisi
from mixture_ip_ros.scenarios.folders import read_labels, read_scenario_robot

log = logging.getLogger('mixture_ip_ros.app.interactions')
SPLITS = ('train', 'test')


def default_paths(robot) -> tuple:
    """(bag folder, output folder): out/interactions/{bags,demo} for the default robot,
    out/<name>/interactions/{bags,demo} for another."""
    name = load_description(robot).name
    root = (Path('out') if name == DEFAULT_ROBOT else Path('out') / name) / 'interactions'
    return root / 'bags', root / 'demo'


def loading(scene, cut: str = 'recorded') -> dict:
    """How the scenario's bags become demonstrations: in the base frame, the robot's joints, at
    the recordings' rate; cut where NuiSI's authors cut the interaction (``'recorded'``, for
    training: the observer's ends, which only set a training demonstration's duration, come up
    to a second early where a person slows down before the annotated end, and with them the
    rocket fist bumps split in two), or where the observer finds the
    movement with the scenario's settings (``'detected'``: what the nodes see online)."""
    robot = scene.robot
    return {'transform': robot.world_to_base(), 'joint_names': robot.joint_names,
            'segmentation': interactions.segmentation(scene.config), 'cut': cut,
            'dt': 1.0 / nuisi.VERSIONS[scene.config.data].rate}


def prepare_interactions_demo(data_dir: Path, out_dir: Path, robot=None, n_components=None,
                              supervised: bool = False):
    """The scene, the bags of both splits (written if missing), a model trained on the
    training split (K = ``n_components``, or chosen; ``supervised``: one component per
    interaction, the labels read, a reference for benches and tests) and its training summary:
    (scene, model path, info)."""
    robot = load_description(robot)
    scene = interactions.scene(robot)
    for split in SPLITS:
        folder = data_dir / split
        if not folder.is_dir() or not any(folder.iterdir()):
            log.info('retargeting NuiSI %s %s to %s into %s', scene.config.data, split,
                     robot.name, folder)
            interactions.write_bags(scene, split, folder)
        made_for = read_scenario_robot(folder)
        if made_for != robot.name:
            raise ValueError(f'{folder} holds demonstrations of {made_for!r}, not '
                             f'{robot.name!r}; give another --data folder')
    try:
        demos, _ = load_dataset(data_dir / 'train', on_error='raise', **loading(scene))
    except NoRecordedInterval as exc:
        raise ValueError(f'{exc}: these bags were written before bags recorded their '
                         f'interval; remove {data_dir} to write them again') from None
    model_path = out_dir / 'model.npz'
    if supervised:
        kwargs = {'labels': [d.label for d in demos]}
    elif n_components:
        kwargs = {'n_components': n_components}
    else:
        kwargs = {'progress': text_progress()}
    t0 = time.monotonic()
    _, info = train_to_file(demos, model_path, robot=robot, **kwargs)
    info['train_seconds'] = time.monotonic() - t0
    info['start_posture'] = np.mean([d.controlled[0] for d in demos], axis=0).tolist()
    return scene, model_path, info


# ------------------------------------------------------------------------------ metrics

def replay_offset(record, scene, recording) -> float:
    """Simulated time minus replay time of a played recording: the bag player publishes each
    sample at the simulated time its offset in the bag says, and the observer passes the
    stamps on. Found at the observed sample farthest from the first one (a moving hand is
    unique along the recording; the rests are not)."""
    t, xyz = interactions.person1_stream(recording, scene)
    base = scene.robot.world_to_base().apply_array(xyz)
    seen = np.asarray(record.wrist)
    j = int(np.argmax(np.linalg.norm(seen - seen[0], axis=1)))
    k = int(np.argmin(np.linalg.norm(base - seen[j], axis=1)))
    return float(record.wrist_t[j] - t[k])


def _partner_at(times, partner_t, partner) -> np.ndarray:
    """The partner's hand at ``times`` (s, replay time base), linear between its samples; NaN
    next to a sample the tracker lost."""
    idx = np.interp(times, partner_t, np.arange(len(partner_t)))
    lo = np.clip(np.floor(idx).astype(int), 0, len(partner_t) - 1)
    hi = np.clip(lo + 1, 0, len(partner_t) - 1)
    w = (idx - lo)[:, None]
    return (1 - w) * partner[lo] + w * partner[hi]


def _rms_cm(d) -> float | None:
    d = np.asarray(d, dtype=float)
    d = d[np.isfinite(d)]
    return float(100 * np.sqrt(np.mean(d ** 2))) if d.size else None


def _last(path) -> np.ndarray:
    """The last position of a path (n, 3) whose rows may be NaN."""
    return path[np.flatnonzero(~np.isnan(path).any(axis=1))[-1]]


def loop_errors(record, scene, recording) -> dict:
    """The flange's distance from where the partner's hand was, from the commitment to the end
    of the movement (the observer's 'end', else the recording's last frame), and from the
    onset (the robot may move before it commits: PlannerSettings.hedge): RMS; once the run
    is over against the partner's last position; at the recorded contact
    (scenarios.interactions.contact) from person 1's hand, beside the two people's own distance
    there (cm), and how long before the contact the robot committed (s; negative: after it,
    when the arm can only catch up); with the replay's offset (s)."""
    offset = replay_offset(record, scene, recording)
    pt, partner = interactions.partner_hand(recording, scene)
    before, _ = interactions.replay_frames(recording, scene.config)
    end = (record.end_time - offset if record.end_time is not None
           else pt[before + len(recording.t) - 1])
    t_contact, person1, person2 = interactions.contact(recording, scene)
    flange = np.asarray(record.flange, dtype=float)
    at_contact = np.array([np.interp(t_contact + offset, record.t, flange[:, j])
                           for j in range(3)])
    out = {'offset': offset,
           'end_cm': float(100 * np.linalg.norm(record.flange[-1] - _last(partner))),
           'contact_cm': float(100 * np.linalg.norm(at_contact - person1)),
           'people_contact_cm': float(100 * np.linalg.norm(person2 - person1))}
    t = np.asarray(record.t) - offset
    d = np.linalg.norm(flange - _partner_at(t, pt, partner), axis=1)
    out['onset_rms_cm'] = (None if record.onset_time is None else
                           _rms_cm(d[(t >= record.onset_time - offset) & (t <= end)]))
    if record.commit_time is None:
        return {**out, 'rms_cm': None, 'commit_before_contact_s': None}
    out['commit_before_contact_s'] = float(t_contact - (record.commit_time - offset))
    return {**out, 'rms_cm': _rms_cm(d[(t >= record.commit_time - offset) & (t <= end)])}


def offline_errors(model, scene, recording, bag, fraction: float) -> dict:
    """The same model offline: OnlineEstimator (the nodes' settings: 50 alphas, 20 Hz) fed the
    replayed movement up to ``fraction`` of it, phase unknown; the controlled agent it predicts
    for the rest (MAP component, phase speed marginalised, as the nodes plan) as flange
    positions (FK) against where the partner's hand was: RMS over the rest of the movement, and
    at its end (every speed's z = 1) against the partner's last position (cm). The movement is
    the one the observer finds (the bag segmented as training segments it)."""
    opts = loading(scene, cut='detected')
    demo = load_demonstration(bag, **opts)
    _, t_onset, _ = segment_recording(read_bag(bag, joint_names=scene.robot.joint_names),
                                      transform=opts['transform'],
                                      segmentation=opts['segmentation'])
    est = OnlineEstimator(model, n_alpha=50, min_interval=0.05)
    played_to(est, demo, fraction * demo.duration)
    rest = demo.t >= fraction * demo.duration
    # the expected path as the nodes plan it; at t = inf every speed hypothesis has ended
    q = est.expected_controlled(np.r_[demo.t[rest], np.inf])[1]
    flange = scene.kin.fk_positions(q)
    pt, partner = interactions.partner_hand(recording, scene)
    d = np.linalg.norm(flange[:-1] - _partner_at(t_onset + demo.t[rest], pt, partner), axis=1)
    return {'rms_cm': _rms_cm(d),
            'end_cm': float(100 * np.linalg.norm(flange[-1] - _last(partner)))}


def beyond_limits(record, kin) -> int:
    """Commanded trajectory points outside the arm's position or speed limits."""
    count = 0
    for _, msg in record.extra.get('trajectories', []):
        for pt in msg.points:
            q, qd = np.asarray(pt.positions), np.asarray(pt.velocities)
            count += bool(np.any(q < kin.lower) or np.any(q > kin.upper)
                          or (qd.size and np.any(np.abs(qd) > kin.velocity_limit * (1 + 1e-9))))
    return count


# ------------------------------------------------------------------------------ the demo

def run(args):
    """The demo of this scenario (args of `mixture-ip demo`); returns the report."""
    robot, data_dir, out_dir = demo_folders(args, default_paths)
    scene, model_path, info = prepare_interactions_demo(data_dir, out_dir, robot,
                                                        n_components=args.components)
    print(f'{robot.name}: reach scale {scene.placement.scale:.3f}; trained on '
          f'{info["n_demonstrations"]} demonstrations: K = {info["n_components"]}'
          + (f' (leave-one-out RMS by K: {np.round(info["loo_rms_mean"], 4).tolist()})'
             if 'loo_rms_mean' in info else ''))
    records, report = replay(scene, model_path, info, data_dir)
    write_json(args.json, report)
    print(demo_summary(report, args.json))
    if args.render:
        from mixture_ip_ros.app.demo import render_all
        render_all(records, Path(args.render))
    return report


def replay(scene, model_path, info, data_dir: Path, names=None, real_time_factor=1.0,
           domain_id=None):
    """Every held-out recording of ``data_dir``/test (or those ``names``) replayed through the
    running nodes with the model: (records, report)."""
    from mixture_ip_ros.app.closed_loop import ClosedLoop   # rclpy only once the data is ready
    from mixture_ip_ros.io.model_file import load_model
    model = load_model(model_path)[0]
    start = info['start_posture']
    names = sorted(read_labels(data_dir / 'test')) if names is None else list(names)
    recordings = {r.name: r for r in nuisi.recordings(scene.config.data, 'test')}
    if domain_id is None:
        domain_id = int(os.environ.get('ROS_DOMAIN_ID', 42))
    loop = ClosedLoop(model_path, robot=scene.robot, home=start, domain_id=domain_id,
                      real_time_factor=real_time_factor,
                      sim_params={'table': False, 'stands': False,
                                  'initial_positions': list(start)},
                      observer_params=interactions.segmentation(scene.config),
                      estimator_params=interactions.estimator_settings(scene.config))
    records, rows = [], []
    try:
        for name in names:
            rec, row = run_one(loop, scene, model, data_dir / 'test' / name, recordings[name])
            records.append(rec)
            rows.append(row)
            print(_line(row), flush=True)
    finally:
        loop.close()
    report = summary(rows, info)
    report['robot'] = scene.robot.name
    report['reach_scale'] = scene.placement.scale
    return records, report


def run_one(loop, scene, model, bag, recording):
    """Replay one held-out recording through the running loop: (record, report row)."""
    from mixture_ip_ros.app.demo import tracking_mrad
    loop.go_home()
    pt, partner = interactions.partner_hand(recording, scene)
    refused_before = loop.sim.rejection_count
    rec = loop.run_interaction(bag, true_pattern=recording.label, target=_last(partner))
    snap = loop.recorder.snapshot()
    rec.extra['trajectories'] = [(t, m) for t, m in snap['trajectories'] if t >= rec.t[0]]
    errors = loop_errors(rec, scene, recording)
    rec.extra['partner'] = {'t': (pt + errors['offset']).tolist(), 'xyz': partner.tolist()}
    rec.extra['scene'] = {'table': False, 'stands': False}
    rec.extra['person1'] = [float(v) for v in np.r_[scene.person1_pose()[0],
                                                    scene.person1_pose()[1]]]
    rms, worst = tracking_mrad(rec)
    row = {'name': rec.name, 'true_pattern': rec.true_pattern,
           'chosen_pattern': rec.chosen_pattern, 'commit_fraction': rec.commit_fraction,
           'commit_s': (None if rec.commit_time is None or rec.onset_time is None
                        else rec.commit_time - rec.onset_time),
           'flange_to_partner_rms_cm': errors['rms_cm'],
           'flange_to_partner_from_onset_rms_cm': errors['onset_rms_cm'],
           'flange_to_partner_end_cm': errors['end_cm'],
           'flange_to_person1_at_contact_cm': errors['contact_cm'],
           'people_at_contact_cm': errors['people_contact_cm'],
           'commit_before_contact_s': errors['commit_before_contact_s'],
           'hedged_plans': (rec.extra['interaction'] or {}).get('hedged_plans', 0),
           'tracking_rms_mrad': rms, 'tracking_max_mrad': worst,
           'refused_trajectories': loop.sim.rejection_count - refused_before,
           'points_beyond_limits': beyond_limits(rec, scene.kin),
           'non_finite_commands': rec.extra.get('non_finite_commands', 0)}
    if rec.commit_fraction is not None:
        offline = offline_errors(model, scene, recording, bag, rec.commit_fraction)
        row['offline_rms_cm'], row['offline_end_cm'] = offline['rms_cm'], offline['end_cm']
    del rec.extra['trajectories']         # rclpy messages: not for the JSON report
    return rec, row


def _line(row) -> str:
    def num(v, fmt):
        return '-' if v is None else format(v, fmt)
    return (f'{row["name"]:>12s}: {row["true_pattern"]:<18s} chose '
            f'{str(row["chosen_pattern"]):<18s} at {num(row["commit_fraction"], ".2f")} '
            f'({num(row["commit_s"], ".2f")} s); flange to partner RMS '
            f'{num(row["flange_to_partner_rms_cm"], "5.1f")} cm (offline '
            f'{num(row.get("offline_rms_cm"), "5.1f")}), at the end '
            f'{num(row["flange_to_partner_end_cm"], "5.1f")} cm (offline '
            f'{num(row.get("offline_end_cm"), "5.1f")}); at the contact '
            f'{num(row["flange_to_person1_at_contact_cm"], "5.1f")} cm from person 1 (the '
            f'people {num(row["people_at_contact_cm"], "4.1f")}; committed '
            f'{num(row["commit_before_contact_s"], "+.2f")} s before it); tracking '
            f'{num(row["tracking_rms_mrad"], ".3f")} mrad; refused '
            f'{row["refused_trajectories"]}, beyond limits {row["points_beyond_limits"]}')


def summary(rows, info) -> dict:
    def mean(key, among=rows):
        v = [r[key] for r in among if r.get(key) is not None]
        return float(np.mean(v)) if v else None
    # where the hands meet (a wave's closest approach is no contact: the people stay apart)
    touching = [r for r in rows if r['true_pattern'] in interactions.CONTACT]
    right = lambda r: r['true_pattern'] == r['chosen_pattern']    # noqa: E731
    return {'interactions': rows, 'right': int(sum(right(r) for r in rows)), 'n': len(rows),
            'commit_fraction_mean': mean('commit_fraction'),
            'flange_to_partner_rms_cm_mean': mean('flange_to_partner_rms_cm'),
            'flange_to_partner_from_onset_rms_cm_mean': mean('flange_to_partner_from_onset_rms_cm'),
            'offline_rms_cm_mean': mean('offline_rms_cm'),
            'flange_to_partner_end_cm_mean': mean('flange_to_partner_end_cm'),
            'offline_end_cm_mean': mean('offline_end_cm'),
            'flange_to_person1_at_contact_cm_mean': mean('flange_to_person1_at_contact_cm'),
            'people_at_contact_cm_mean': mean('people_at_contact_cm'),
            'flange_to_person1_at_touch_cm_mean': mean('flange_to_person1_at_contact_cm',
                                                       touching),
            'people_at_touch_cm_mean': mean('people_at_contact_cm', touching),
            'committed_after_contact': int(sum((r['commit_before_contact_s'] or 0.0) < 0.0
                                               for r in rows)),
            'tracking_rms_mrad_max': max((r['tracking_rms_mrad'] for r in rows
                                          if r['tracking_rms_mrad'] is not None), default=None),
            'refused_trajectories': int(sum(r['refused_trajectories'] for r in rows)),
            'points_beyond_limits': int(sum(r['points_beyond_limits'] for r in rows)),
            'non_finite_commands': int(sum(r['non_finite_commands'] for r in rows)),
            'n_components': info['n_components'], 'training': info}
