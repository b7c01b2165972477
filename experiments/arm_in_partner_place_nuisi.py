"""Does a user's own CSV folder of two people drive the arm as the interactions demo does?

NuiSI v2 exported as a user would have it: one CSV per recording, person 1's right hand
observed (hx, hy, hz), person 2's right hand controlled (px, py, pz), each in their own body
frame, t = frame / rate. Trained with the command line and the shipped placement
(config/partner_placement.yaml, the interactions scenario's values):

    mixture-ip train --csv DIR/train --observed hx,hy,hz --controlled px,py,pz \\
        --arm-in-partner-place config/partner_placement.yaml --robot iiwa14 --out DIR/model.npz

then each held-out recording's person 1 replayed through the running nodes exactly as
`mixture-ip demo --scenario interactions` replays them (app.interactions.replay: the same bags,
node settings and figures). The model's components have no names (the CSV folder has no
labels); for scoring, each is named by the majority label of the training recordings it
explains best (person 1's whole movement, phase known), as the demo names its components from
its bags' labels. With ``--demo REPORT`` (the demo's --json) the figures are set side by side;
a report.json already in --out is scored again without replaying.

    OPENBLAS_NUM_THREADS=1 ROS_DOMAIN_ID=77 python experiments/arm_in_partner_place_nuisi.py \\
        --out /tmp/nuisi_csv [--demo demo.json]
"""

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

import numpy as np  # noqa: E402

from mixture_ip_ros.core.demonstration import Demonstration, Layout  # noqa: E402
from mixture_ip_ros.core.share import config_path  # noqa: E402
from mixture_ip_ros.io.csv_files import load_csv_dataset, write_csv_demonstration  # noqa: E402
from mixture_ip_ros.core.named import majority_names  # noqa: E402
from mixture_ip_ros.io.model_file import load_model  # noqa: E402
from mixture_ip_ros.robot import partner_place  # noqa: E402
from mixture_ip_ros.scenarios import interactions, nuisi  # noqa: E402

LAYOUT = Layout(('hx', 'hy', 'hz'), ('px', 'py', 'pz'), ('m',), ('m',))
FIGURES = ('right', 'n', 'commit_fraction_mean', 'flange_to_partner_rms_cm_mean',
           'flange_to_partner_from_onset_rms_cm_mean', 'flange_to_partner_end_cm_mean',
           'flange_to_person1_at_touch_cm_mean', 'offline_rms_cm_mean', 'refused_trajectories',
           'points_beyond_limits')


def export(version: str, out: Path):
    """One CSV per recording of each split, and each split's labels.json (kept for scoring)."""
    v = nuisi.VERSIONS[version]
    j = v.joints.index(v.hand)
    for split in ('train', 'test'):
        labels = {}
        for r in nuisi.recordings(version, split):
            write_csv_demonstration(out / split / f'{r.name}.csv',
                                    Demonstration(r.t, r.person1[:, j], r.person2[:, j]), LAYOUT)
            labels[f'{r.name}.csv'] = r.label
        (out / split / 'labels.json').write_text(json.dumps(labels, indent=1))


def train(out: Path, placement: Path, robot: str) -> Path:
    model = out / 'model.npz'
    subprocess.run([str(Path(sys.executable).parent / 'mixture-ip'), 'train', '--csv',
                    str(out / 'train'), '--observed', 'hx,hy,hz', '--controlled', 'px,py,pz',
                    '--observed-units', 'm', '--controlled-units', 'm',
                    '--arm-in-partner-place', str(placement), '--robot', robot,
                    '--out', str(model)], check=True)
    return model


def component_names(model, demos, labels) -> list:
    """Each component's majority label among the training recordings it explains best."""
    best = [int(np.argmax(model.component_posterior(d.phase, d.observed))) for d in demos]
    return majority_names(best, [labels[d.name] for d in demos], model.n_components)


def scored(report, names) -> dict:
    """``report`` with each interaction's chosen component ('component_k') named."""
    rows = [{**r, 'chosen_pattern': (names[int(r['chosen_pattern'].split('_')[-1])]
                                     if str(r['chosen_pattern']).startswith('component_')
                                     else r['chosen_pattern'])} for r in report['interactions']]
    return {**report, 'interactions': rows, 'component_names': names,
            'right': int(sum(r['chosen_pattern'] == r['true_pattern'] for r in rows))}


def main():
    p = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    p.add_argument('--out', type=Path, required=True)
    p.add_argument('--robot', default='iiwa14')
    p.add_argument('--demo', type=Path, default=None, help="the interactions demo's --json")
    args = p.parse_args()
    placement = config_path('partner_placement.yaml')
    config = interactions.load_config()
    if not (args.out / 'test' / 'labels.json').is_file():
        export(config.data, args.out)
    model_path = args.out / 'model.npz'
    if not model_path.is_file():
        train(args.out, placement, args.robot)
    model, meta = load_model(model_path)
    recorded = partner_place.PartnerPlace.from_metadata(meta['extra']['partner_place'])
    # The demo's scene: the same placement, the same reach scale, so the same held-out bags.
    scene = interactions.scene(args.robot)
    assert recorded.placement == scene.placement, (recorded.placement, scene.placement)
    bags = args.out / 'bags'
    if not (bags / 'test').is_dir():
        interactions.write_bags(scene, 'test', bags / 'test')
    # The arm's start as the demo's: the mean first posture of the training demonstrations.
    _, demos, _ = partner_place.arm_demonstrations(
        args.robot, partner_place.load_placement(placement),
        load_csv_dataset(args.out / 'train', LAYOUT))
    training = meta['extra']['training']
    info = {**training, 'start_posture': np.mean([d.controlled[0] for d in demos],
                                                 axis=0).tolist()}
    report_path = args.out / 'report.json'
    if report_path.is_file():
        report = json.loads(report_path.read_text())
    else:
        from mixture_ip_ros.app.interactions import replay
        _, report = replay(scene, model_path, info, bags)
        report['reach_scale'] = scene.placement.scale
        report_path.write_text(json.dumps(report, indent=1, default=str))
    labels = json.loads((args.out / 'train' / 'labels.json').read_text())
    report = scored(report, component_names(model, demos, labels))
    for r in report['interactions']:
        print(f'{r["name"]}: {r["true_pattern"]:<18s} chose {r["chosen_pattern"]}')
    demo = json.loads(args.demo.read_text()) if args.demo else {}
    print(f'{"figure":42s} {"csv + placement":>16s} {"interactions demo":>18s}')
    for key in FIGURES:
        a, b = report.get(key), demo.get(key)
        ratio = '' if not (isinstance(a, float) and isinstance(b, float) and b) else \
            f'  {100 * (a / b - 1):+.1f} %'
        print(f'{key:42s} {a!s:>16.16s} {b!s:>18.18s}{ratio}')
    print(f'K = {report["n_components"]} (demo: {demo.get("n_components")})')


if __name__ == '__main__':
    main()
