"""The interactions demo for every shipped arm and three models: NuiSI v2's 11 held-out
recordings replayed through the nodes (app.interactions.replay, as `mixture-ip demo --scenario
interactions` does), with
- 'chosen': K as training chooses it (unsupervised: the demo's model);
- 'k4': K = 4 given (one per interaction), unsupervised;
- 'supervised': one component per interaction, the labels read (a reference: what the loop
  does once discovery finds the interactions; the demo never reads labels).
One JSON object per (arm, model) as each finishes, then the summary rows; about 4 minutes per
(arm, model) on 2 cores. ``--render DIR``: a small GIF and contact sheet of every interaction
(400 x 300, 10 frames per second: the README's docs/interactions_*).

    OPENBLAS_NUM_THREADS=1 python bench/interactions.py [--robots iiwa14,panda,ur5]
        [--models chosen,k4,supervised] [--out out/bench_interactions] [--render DIR]
"""

import argparse
import json
import os
from pathlib import Path

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

from mixture_ip_ros.app import interactions as app  # noqa: E402

SUMMARY = ('right', 'n', 'commit_fraction_mean', 'flange_to_partner_rms_cm_mean',
           'flange_to_partner_from_onset_rms_cm_mean',
           'offline_rms_cm_mean', 'flange_to_partner_end_cm_mean', 'offline_end_cm_mean',
           'flange_to_person1_at_contact_cm_mean', 'people_at_contact_cm_mean',
           'flange_to_person1_at_touch_cm_mean', 'people_at_touch_cm_mean',
           'committed_after_contact',
           'tracking_rms_mrad_max', 'refused_trajectories', 'points_beyond_limits',
           'non_finite_commands', 'n_components')


MODELS = {'chosen': {}, 'k4': {'n_components': 4}, 'supervised': {'supervised': True}}


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument('--robots', default='iiwa14,panda,ur5')
    parser.add_argument('--models', default='chosen,k4,supervised')
    parser.add_argument('--out', default='out/bench_interactions')
    parser.add_argument('--render', default=None)
    args = parser.parse_args()
    rows = []
    for robot in args.robots.split(','):
        data_dir = Path(args.out) / robot / 'bags'
        for model in args.models.split(','):
            out_dir = Path(args.out) / robot / model
            out_dir.mkdir(parents=True, exist_ok=True)
            scene, model_path, info = app.prepare_interactions_demo(data_dir, out_dir, robot,
                                                                    **MODELS[model])
            records, report = app.replay(scene, model_path, info, data_dir)
            if args.render:
                from mixture_ip_ros.viz.animation import render_interaction
                for rec in records:
                    render_interaction(rec, Path(args.render) / robot / model, fps=10,
                                       width=400, height=300)
            report['model'] = model
            (out_dir / 'report.json').write_text(json.dumps(report, indent=1) + '\n')
            row = {'robot': robot, 'model': model, 'reach_scale': report['reach_scale'],
                   **{k: report[k] for k in SUMMARY}}
            rows.append(row)
            print(json.dumps(row), flush=True)
    print(json.dumps({'rows': rows}))


if __name__ == '__main__':
    main()
