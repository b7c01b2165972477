"""`mixture-ip`: generate demonstrations, train, evaluate, and run the closed-loop demo."""

import argparse
import logging
import sys
from pathlib import Path

from mixture_ip_ros.app.cli_csv import OneList
from mixture_ip_ros.app.cli_evaluate import add_evaluate_parser
from mixture_ip_ros.app.cli_nodes import add_node_parsers
from mixture_ip_ros.app.cli_options import add_robot, bounded, existing_file, new_file, out_dir
from mixture_ip_ros.app.cli_run import add_run_parser
from mixture_ip_ros.app.cli_train import add_train_parser
from mixture_ip_ros.nodes.launch import set_process_defaults


def _generate(args):
    from mixture_ip_ros.scenarios.folders import write_scenario_bags
    bags = write_scenario_bags(args.scenario, Path(args.out), seed=args.seed,
                               occlusion=args.occlusion, storage=args.storage, robot=args.robot)
    print(f'wrote {len(bags)} {args.scenario} demonstrations ({args.storage} bags, '
          f'{args.robot}) to {args.out}')


def _info(args):
    from mixture_ip_ros.app.inspect_model import model_summary
    print(model_summary(args.model))


def _demo(args):
    if args.scenario == 'interactions':
        from mixture_ip_ros.app.interactions import run
        run(args)
    elif args.scenario == 'change_of_mind':
        from mixture_ip_ros.app.change_of_mind import run
        run(args)
    else:
        from mixture_ip_ros.app.demo import run_demo
        run_demo(args)


class _Formatter(argparse.HelpFormatter):
    """Shows a one-list option as taking one value (it takes more only to refuse them)."""

    def _format_args(self, action, default_metavar):
        if isinstance(action, OneList):
            return self._metavar_formatter(action, default_metavar)(1)[0]
        return super()._format_args(action, default_metavar)


class _Parser(argparse.ArgumentParser):
    """Wrong arguments: one line saying what is wrong (and where the help is), exit code 2."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault('formatter_class', _Formatter)
        super().__init__(*args, **kwargs)

    def error(self, message):
        self.exit(2, f'{self.prog}: error: {message} (see {self.prog} --help)\n')


def build_parser():
    p = _Parser(prog='mixture-ip', description=__doc__)
    sub = p.add_subparsers(dest='command', required=True)

    g = sub.add_parser('generate', help='write a scenario as a folder of rosbag2 bags')
    g.add_argument('--scenario', required=True, choices=['box_assembly', 'pole'],
                   help="box_assembly: 48 handovers of a plate, a screw or the screwdriver "
                        "(thesis 3.4.2); pole: 28 pointings past a pole, left or right (3.4.1)")
    g.add_argument('--out', required=True, type=out_dir,
                   help='folder to write the bags and labels.json into (new or empty)')
    g.add_argument('--seed', type=int, default=0,
                   help='random seed of the generated demonstrations (default 0)')
    g.add_argument('--occlusion', type=bounded(float, 0.0, 1.0), default=0.0,
                   help='probability that a demonstration has an occlusion gap in the wrist stream')
    g.add_argument('--storage', choices=['mcap', 'sqlite3'], default='mcap',
                   help="rosbag2 storage format of the bags (default 'mcap')")
    add_robot(g)
    g.set_defaults(func=_generate)

    add_train_parser(sub)
    add_evaluate_parser(sub)

    d = sub.add_parser('demo', help='closed loop: bags -> observer -> estimator -> MuJoCo arm')
    d.add_argument('--scenario', choices=['box_assembly', 'interactions', 'change_of_mind'],
                   default='box_assembly',
                   help="box_assembly: generated human-robot demonstrations; interactions: "
                        "NuiSI's two people, the arm in person 2's place, person 1's held-out "
                        "recordings replayed (config/interactions.yaml); change_of_mind: the "
                        "box assembly's held-out reaches, then pairs of them spliced where the "
                        "human turns from one part to another mid-reach")
    add_robot(d)
    d.add_argument('--data', default=None,
                   help='folder of demonstration bags, generated if missing (default: '
                        'out/box_assembly_bags (box_assembly, change_of_mind) or '
                        'out/interactions/bags for the iiwa14, out/<robot>/... for another '
                        'robot)')
    d.add_argument('--out', default=None, type=out_dir,
                   help='model, plots and report go here (default: out/demo, '
                        'out/interactions/demo or out/change_of_mind (with the spliced bags), '
                        'out/<robot>/... for another robot)')
    d.add_argument('--components', type=bounded(int, 1, name='a whole number'), default=None,
                   help='number of components (default: chosen by leave-one-out)')
    d.add_argument('--json', default=None, type=new_file,
                   help='also write the report as JSON here')
    d.add_argument('--render', default=None, type=out_dir,
                   help='write videos and contact sheets here')
    d.add_argument('--held-out', type=bounded(int, 1, name='a whole number'), default=3,
                   help='box_assembly, change_of_mind: interactions replayed per pattern '
                        '(interactions: the upstream test split)')
    d.add_argument('--seed', type=int, default=0,
                   help='box_assembly, change_of_mind: random seed of the generated '
                        'demonstrations, of the held-out draw and of the shares where the '
                        'human turns (default 0)')
    d.add_argument('--command-delay', type=bounded(float, 0.0, 60.0), default=None,
                   metavar='S', help='hold every command from the estimator S seconds of '
                                     'simulated time before the arm gets it (a slow link)')
    d.set_defaults(func=_demo)

    i = sub.add_parser('info', help='what a model file holds: its layout, patterns and '
                                    'training summary')
    i.add_argument('model', type=existing_file, help='model file (.npz)')
    i.set_defaults(func=_info)

    add_node_parsers(sub)
    add_run_parser(sub)
    return p


def main(argv=None):
    set_process_defaults()       # before the commands import numpy and numba
    # The package's own progress at INFO; other libraries' only when something is wrong
    # (dtaidistance announces every distance matrix at INFO).
    logging.basicConfig(level=logging.WARNING, format='%(levelname)s %(name)s: %(message)s')
    logging.getLogger('mixture_ip_ros').setLevel(logging.INFO)
    args = build_parser().parse_args(argv)
    try:
        if hasattr(args, 'check'):
            args.check(args)
        args.func(args)
    except (ValueError, OSError) as e:
        print(f'mixture-ip {args.command}: error: {e}', file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f'mixture-ip {args.command}: interrupted', file=sys.stderr)
        return 130
    return 0


if __name__ == '__main__':
    sys.exit(main())
