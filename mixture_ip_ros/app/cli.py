"""`mixture-ip`: generate demonstrations, train, evaluate, and run the closed-loop demo."""

import argparse
import json
import logging
import sys
from pathlib import Path


def _generate(args):
    from mixture_ip_ros.scenarios.generated import write_scenario_bags
    bags = write_scenario_bags(args.scenario, Path(args.out), seed=args.seed,
                               occlusion=args.occlusion, storage=args.storage, robot=args.robot)
    print(f'wrote {len(bags)} {args.scenario} demonstrations ({args.storage} bags, '
          f'{args.robot}) to {args.out}')


def _train(args):
    from mixture_ip_ros.io.dataset import load_dataset
    from mixture_ip_ros.app.training import text_progress, train_to_file
    from mixture_ip_ros.robot.description import load_description
    robot = load_description(args.robot)
    demos, skipped = load_dataset(args.bag_dir, on_error=args.on_error,
                                  joint_names=robot.joint_names, transform=robot.world_to_base())
    for s in skipped:
        print(f'skipped {s.path}: {s.reason}', file=sys.stderr)
    kwargs = {'n_basis': args.n_basis, 'method': args.method}
    if args.components:
        kwargs['n_components'] = args.components
    else:
        kwargs['candidates'] = range(1, args.max_components + 1)
        kwargs['progress'] = text_progress()
    model, info = train_to_file(demos, args.out, robot=robot, **kwargs)
    print(json.dumps({'model': str(args.out), **info}))


def _evaluate(args):
    from mixture_ip_ros.app.evaluation import evaluate
    metrics = evaluate(args.scenario, Path(args.out), seed=args.seed, quick=args.quick,
                       bag_dir=args.bags)
    print(json.dumps(metrics, indent=1))


def _demo(args):
    from mixture_ip_ros.app.demo import run_demo
    run_demo(args)


def _add_robot(parser):
    from mixture_ip_ros.robot.description import DEFAULT_ROBOT, shipped_robots
    parser.add_argument('--robot', default=DEFAULT_ROBOT,
                        help=f'the arm: a shipped name ({", ".join(shipped_robots())}) or the '
                             'path of a robot description file (docs/robots.md); default '
                             f'{DEFAULT_ROBOT}')


def build_parser():
    p = argparse.ArgumentParser(prog='mixture-ip', description=__doc__)
    sub = p.add_subparsers(dest='command', required=True)

    g = sub.add_parser('generate', help='write a scenario as a folder of rosbag2 bags')
    g.add_argument('--scenario', required=True, choices=['box_assembly', 'pole'])
    g.add_argument('--out', required=True)
    g.add_argument('--seed', type=int, default=0)
    g.add_argument('--occlusion', type=float, default=0.0,
                   help='probability that a demonstration has an occlusion gap in the wrist stream')
    g.add_argument('--storage', choices=['mcap', 'sqlite3'], default='mcap')
    _add_robot(g)
    g.set_defaults(func=_generate)

    t = sub.add_parser('train', help='learn a Mixture of Interaction ProMPs from a folder of bags')
    t.add_argument('bag_dir')
    t.add_argument('--out', required=True, help='model file (.npz)')
    t.add_argument('--components', type=int, default=None,
                   help='number of components (default: leave-one-out over 1..--max-components)')
    t.add_argument('--max-components', type=int, default=6)
    t.add_argument('--n-basis', type=int, default=15)
    t.add_argument('--method', choices=['regression', 'em'], default='regression',
                   help="'em' learns from demonstrations with missing data (occlusions)")
    t.add_argument('--on-error', choices=['skip', 'raise'], default='skip')
    _add_robot(t)
    t.set_defaults(func=_train)

    e = sub.add_parser('evaluate', help="reproduce the thesis's experiments: plots + metrics.json")
    e.add_argument('--scenario', required=True,
                   choices=['box_assembly', 'pole', 'phase', 'missing_data'])
    e.add_argument('--out', required=True)
    e.add_argument('--seed', type=int, default=0)
    e.add_argument('--quick', action='store_true', help='fewer components/folds (for smoke runs)')
    e.add_argument('--bags', default=None,
                   help='evaluate on this folder of bags (with labels.json) instead of generating')
    e.set_defaults(func=_evaluate)

    d = sub.add_parser('demo', help='closed loop: bags -> observer -> estimator -> MuJoCo arm')
    _add_robot(d)
    d.add_argument('--data', default=None,
                   help='folder of demonstration bags, generated if missing (default: '
                        'out/box_assembly_bags for the iiwa14, out/<robot>/box_assembly_bags '
                        'for another robot)')
    d.add_argument('--out', default=None, help='model, plots and report go here (default: '
                                               'out/demo, out/<robot>/demo for another robot)')
    d.add_argument('--json', default=None, help='also write the report as JSON here')
    d.add_argument('--render', default=None, help='write videos and contact sheets here')
    d.add_argument('--held-out', type=int, default=3, help='interactions replayed per pattern')
    d.add_argument('--seed', type=int, default=0)
    d.set_defaults(func=_demo)
    return p


def main(argv=None):
    logging.basicConfig(level=logging.INFO, format='%(levelname)s %(name)s: %(message)s')
    args = build_parser().parse_args(argv)
    try:
        args.func(args)
    except (ValueError, FileNotFoundError) as e:
        print(f'mixture-ip {args.command}: error: {e}', file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
