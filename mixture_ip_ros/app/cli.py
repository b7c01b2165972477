"""`mixture-ip`: generate demonstrations, train, evaluate, and run the closed-loop demo."""

import argparse
import json
import logging
import math
import os
import sys
from functools import partial
from pathlib import Path

from mixture_ip_ros.nodes.launch import set_process_defaults


# -- argument types: every option is checked before any work starts -----------------------------
def _bounded(kind, low=None, high=None, name='a number'):
    def parse(text):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'{text!r} is not {name}') from None
        if kind is float and not math.isfinite(value):
            raise argparse.ArgumentTypeError(f'{text!r} is not a finite number')
        if (low is not None and value < low) or (high is not None and value > high):
            bounds = (f'>= {low}' if high is None else f'<= {high}' if low is None
                      else f'in [{low}, {high}]')
            raise argparse.ArgumentTypeError(f'{value} is not {bounds}')
        return value
    return parse


def _noise_stds(text):
    """'0.01' -> 0.01, '0.01,0.02' -> [0.01, 0.02]: standard deviations, finite and >= 0."""
    one = _bounded(float, 0.0)
    values = [one(v) for v in text.split(',')]
    return values[0] if len(values) == 1 else values


def _existing_dir(text):
    if not Path(text).is_dir():
        raise argparse.ArgumentTypeError(f'{text} is not a folder')
    return text


def _new_file(text):
    """A file to write: not a folder, and in a folder that exists or can be made (nothing is
    created now)."""
    path = Path(text)
    if path.is_dir():
        raise argparse.ArgumentTypeError(f'{text} is a folder: name the file to write')
    _writable_parent(path, text)
    return text


def _out_dir(text):
    path = Path(text)
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f'{text} is a file, not a folder')
    _writable_parent(path, text)
    return text


def _writable_parent(path, text):
    parent = path.resolve().parent
    while not parent.exists():
        parent = parent.parent
    if not (parent.is_dir() and os.access(parent, os.W_OK)):
        raise argparse.ArgumentTypeError(f'cannot write {text}: {parent} is not writable')


def _generate(args):
    from mixture_ip_ros.scenarios.folders import write_scenario_bags
    bags = write_scenario_bags(args.scenario, Path(args.out), seed=args.seed,
                               occlusion=args.occlusion, storage=args.storage, robot=args.robot)
    print(f'wrote {len(bags)} {args.scenario} demonstrations ({args.storage} bags, '
          f'{args.robot}) to {args.out}')


def _train(args):
    from mixture_ip_ros.app.progress import Stages, text_progress, text_stages
    from mixture_ip_ros.app.training import train_to_file
    from mixture_ip_ros.robot.description import load_description
    robot = load_description(args.robot)
    kwargs = {'n_basis': args.n_basis, 'method': args.method, 'criterion': args.criterion,
              'noise': args.noise, 'n_jobs': args.jobs}
    if args.observation_noise is not None:
        kwargs['observation_noise'] = args.observation_noise
    if args.csv is not None:
        from mixture_ip_ros.io.csv_files import load_csv_dataset
        layout = _csv_layout(args)
        demos = load_csv_dataset(args.csv, layout, time=args.time)
        kwargs['observed_frame'] = args.frame or ''
        kwargs['translation'] = _translation(args, layout)
    else:
        from mixture_ip_ros.io.dataset import load_dataset
        demos, skipped = load_dataset(args.bag_dir, on_error=args.on_error,
                                      joint_names=robot.joint_names,
                                      transform=robot.world_to_base(), cut=args.cut)
        for s in skipped:
            print(f'skipped {s.path}: {s.reason}', file=sys.stderr)
        layout = None
        if args.frame:
            kwargs['observed_frame'] = args.frame
    if args.components is not None:
        kwargs['n_components'] = args.components
    else:
        kwargs['candidates'] = range(1, args.max_components + 1)
        kwargs['progress'] = text_progress(what='held-out fits')
    model, info = train_to_file(demos, args.out, layout=layout, robot=robot,
                                stages=Stages(text_stages()), **kwargs)
    sel = info.get('selection')
    if sel is not None and not sel['clear_optimum']:
        print(f"warning: K = {sel['chosen']} by {sel['criterion']}: {sel['note']}",
              file=sys.stderr)
    if info.get('seconds'):
        print('where the time went: ' + ', '.join(f'{name} {s:.1f} s'
                                                 for name, s in info['seconds'].items()),
              file=sys.stderr)
    print(json.dumps({'model': str(args.out), **info}))


def _evaluate(args):
    if args.csv is None:
        from mixture_ip_ros.app.evaluation import evaluate
        metrics = evaluate(args.scenario, Path(args.out), seed=args.seed, quick=args.quick,
                           bag_dir=args.bags, robot=args.robot)
    else:
        from mixture_ip_ros.app.evaluation import evaluate_csv
        layout = _csv_layout(args)
        metrics = evaluate_csv(args.csv, _labels(args.labels), layout, Path(args.out),
                               time_column=args.time, seed=args.seed, quick=args.quick,
                               translation=_translation(args, layout))
    print(json.dumps(metrics, indent=1))


def _csv_layout(args):
    """The layout --observed/--controlled (and their units) name; ValueError if they name none
    or contradict each other or --time."""
    from mixture_ip_ros.core.demonstration import Layout
    from mixture_ip_ros.io.csv_files import parse_names
    observed = parse_names(args.observed, '--observed')
    if not observed:
        raise ValueError('--csv needs --observed NAME[,NAME...] (the observed columns)')
    controlled = parse_names(args.controlled, '--controlled')
    layout = Layout(observed, controlled, parse_names(args.observed_units, '--observed-units')
                    or None, parse_names(args.controlled_units, '--controlled-units') or None)
    if args.time in observed + controlled:
        raise ValueError(f'--time {args.time!r} names the time column: it cannot also be an '
                         f'observed or controlled column')
    return layout


def _translation(args, layout):
    """The translation groups --translation names for ``layout`` (core.patterns); ValueError
    where they cannot apply."""
    from mixture_ip_ros.core.patterns import translation_for
    groups = translation_for(args.translation, len(layout.observed), len(layout.controlled))
    units = layout.observed_units + layout.controlled_units
    for g in groups:
        if len({units[j] for j in g} - {''}) > 1:          # '' is a unit not given
            raise ValueError(f'--translation {args.translation}: '
                             f'{" and ".join((layout.observed + layout.controlled)[j] for j in g)}'
                             f' move together but have units {[units[j] for j in g]}')
    return groups


def _labels(path):
    """The --labels file: a JSON object, file name or stem -> label."""
    try:
        labels = json.loads(Path(path).read_text())
    except (OSError, ValueError) as error:
        raise ValueError(f'--labels {path}: not a readable JSON file ({error})') from None
    if not isinstance(labels, dict):
        raise ValueError(f'--labels {path}: must be a JSON object, file name -> label')
    return labels


# -- combinations of options: checked right after parsing, before any data is read, so that a
# run that cannot succeed fails in a second, not after minutes of training --------------------
def _given(args, parser, *dests):
    """The options among ``dests`` set to something other than their defaults, as spelled on
    the command line."""
    return ['--' + d.replace('_', '-') for d in dests
            if getattr(args, d) != parser.get_default(d)]


def _check_csv_columns(args, parser):
    """--observed, --controlled, their units and --time name CSV columns: with --csv they must
    make a layout, without it they have nothing to name. The layout, or None without --csv."""
    columns = _given(args, parser, 'observed', 'controlled', 'observed_units',
                     'controlled_units', 'time', 'translation')
    if args.csv is None:
        if columns:
            parser.error(f'{", ".join(columns)}: for --csv DIR only (they name the columns of '
                         f'its files)')
        return None
    try:
        layout = _csv_layout(args)
        _translation(args, layout)
    except ValueError as error:
        parser.error(str(error))
    return layout


def _check_train_args(args, parser):
    """`train`'s options together: exit 2 with one line on the first contradiction."""
    if (args.bag_dir is None) == (args.csv is None):
        parser.error('give a folder of bags or --csv DIR (one of them)')
    layout = _check_csv_columns(args, parser)
    bag_options = _given(args, parser, 'cut', 'on_error')
    if args.csv is not None and bag_options:
        parser.error(f'{", ".join(bag_options)}: for a folder of bags only, not --csv')
    if args.components is not None and args.criterion != parser.get_default('criterion'):
        parser.error('--components gives K and --criterion chooses it: give one of them')
    if args.method == 'em' and args.translation != 'none':
        parser.error("--translation: with --method regression only (EM from missing data "
                     "does not take the offsets out)")
    if args.criterion == 'loo' and layout is not None and not layout.controlled:
        parser.error("--criterion loo measures how well the controlled agent is predicted: it "
                     "needs --controlled (without one, use --criterion patterns)")
    if isinstance(args.observation_noise, list):
        if layout is None:
            from mixture_ip_ros.io.dataset import bag_layout
            layout = bag_layout()
        if len(args.observation_noise) != len(layout.observed):
            parser.error(f'--observation-noise: {len(args.observation_noise)} numbers for '
                         f'{len(layout.observed)} observed DOFs ({", ".join(layout.observed)}); '
                         f'give one for all or one per DOF')


def _check_evaluate_args(args, parser):
    """`evaluate`'s options together: exit 2 with one line on the first contradiction;
    ValueError if the --labels file is not a JSON object."""
    if (args.scenario is None) == (args.csv is None):
        parser.error('give --scenario NAME or --csv DIR (one of them)')
    _check_csv_columns(args, parser)
    if args.csv is None:
        if args.labels is not None:
            parser.error('--labels: for --csv DIR only (it labels its files)')
    elif args.labels is None:
        parser.error('--csv needs --labels FILE (a JSON object: file name -> label)')
    else:
        # A labels file that cannot be read is bad input, as a bad CSV file is (exit 1), but
        # reading it costs nothing: it fails here, not after the recordings are loaded.
        _labels(args.labels)
    robot_options = _given(args, parser, 'bags', 'robot')
    if robot_options and args.scenario not in ('box_assembly', 'pole'):
        what = '--csv' if args.csv is not None else f'--scenario {args.scenario}'
        parser.error(f'{", ".join(robot_options)}: for --scenario box_assembly or pole only, '
                     f'not {what}')
    if args.bags is not None and _given(args, parser, 'seed'):
        parser.error('--seed: the demonstrations it would generate are not used with --bags')


def _demo(args):
    if args.scenario == 'interactions':
        from mixture_ip_ros.app.interactions import run
        run(args)
    else:
        from mixture_ip_ros.app.demo import run_demo
        run_demo(args)


NODE_SCHEMAS = {'estimator_node': 'mixture_ip_ros.nodes.estimator_node:EstimatorParameters',
                'observer_node': 'mixture_ip_ros.nodes.observer_node:ObserverParameters',
                'sim_node': 'mixture_ip_ros.nodes.sim_node:SimParameters',
                'bag_player': 'mixture_ip_ros.nodes.bag_player:BagPlayerParameters'}


def _params(args):
    import importlib
    import re
    from mixture_ip_ros.io.files import write_text_atomic
    from mixture_ip_ros.nodes.params import markdown_table
    nodes = sorted(NODE_SCHEMAS) if args.node == 'all' else [args.node]
    tables = {}
    for node in nodes:
        module, name = NODE_SCHEMAS[node].split(':')
        tables[node] = markdown_table(getattr(importlib.import_module(module), name))
    if args.update is None:
        print('\n\n'.join(tables.values()))
        return
    path = Path(args.update)
    text = path.read_text()
    for node, table in tables.items():
        block = re.compile(rf'(<!-- parameters: {node} -->\n).*?(\n<!-- end -->)', re.S)
        if not block.search(text):
            raise ValueError(f'{path} has no block <!-- parameters: {node} --> ... <!-- end -->')
        text = block.sub(lambda m: m.group(1) + table + m.group(2), text)
    write_text_atomic(path, text)
    print(f'updated the parameter tables of {", ".join(nodes)} in {path}')


def _lifecycle(args):
    import rclpy
    from mixture_ip_ros.nodes.lifecycle_client import LifecycleClient
    rclpy.init()
    node = rclpy.create_node('mixture_ip_lifecycle')
    try:
        client = LifecycleClient(node, args.node)
        if args.transition != 'get':
            if not client.change(args.transition, timeout=args.timeout):
                raise ValueError(f'{args.node} refused to {args.transition} (its log says why)')
        print(f'{args.node}: {client.state(timeout=args.timeout)}')
    except TimeoutError as exc:
        raise ValueError(str(exc)) from None
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def _add_robot(parser):
    from mixture_ip_ros.robot.description import DEFAULT_ROBOT, shipped_robots
    parser.add_argument('--robot', default=DEFAULT_ROBOT,
                        help=f'the arm: a shipped name ({", ".join(shipped_robots())}) or the '
                             'path of a robot description file (docs/robots.md); default '
                             f'{DEFAULT_ROBOT}')


def _add_translation(parser):
    parser.add_argument('--translation', choices=['none', 'shared', 'observed'], default='none',
                        help="where a recording happened is not part of its pattern (--csv): "
                             "'shared' both agents are positions in one frame (observed column i "
                             "and controlled column i the same axis) and the pair may stand "
                             "anywhere; 'observed' the same for a single agent; default 'none'")


def _add_csv_columns(parser):
    parser.add_argument('--observed', default=None,
                        help='observed agent columns, e.g. x,y,z (--csv)')
    parser.add_argument('--controlled', default=None,
                        help='controlled agent columns (--csv; none: a single-agent model)')
    parser.add_argument('--time', default='t',
                        help="time column in seconds (--csv; default 't')")
    parser.add_argument('--observed-units', default=None,
                        help='unit of each observed column, or one for all, e.g. m (recorded in '
                             'the model)')
    parser.add_argument('--controlled-units', default=None,
                        help="unit of each controlled column (all 'm': errors in cm)")


class _Parser(argparse.ArgumentParser):
    """Wrong arguments: one line saying what is wrong (and where the help is), exit code 2."""

    def error(self, message):
        self.exit(2, f'{self.prog}: error: {message} (see {self.prog} --help)\n')


def build_parser():
    p = _Parser(prog='mixture-ip', description=__doc__)
    sub = p.add_subparsers(dest='command', required=True)

    g = sub.add_parser('generate', help='write a scenario as a folder of rosbag2 bags')
    g.add_argument('--scenario', required=True, choices=['box_assembly', 'pole'])
    g.add_argument('--out', required=True, type=_out_dir)
    g.add_argument('--seed', type=int, default=0)
    g.add_argument('--occlusion', type=_bounded(float, 0.0, 1.0), default=0.0,
                   help='probability that a demonstration has an occlusion gap in the wrist stream')
    g.add_argument('--storage', choices=['mcap', 'sqlite3'], default='mcap')
    _add_robot(g)
    g.set_defaults(func=_generate)

    t = sub.add_parser('train', help='learn a Mixture of Interaction ProMPs from a folder of bags '
                                     'or of CSV files (one per demonstration)')
    t.add_argument('bag_dir', nargs='?', default=None, type=_existing_dir,
                   help='folder of demonstration bags')
    t.add_argument('--csv', default=None, metavar='DIR', type=_existing_dir,
                   help='folder of CSV files instead: a time column and named columns; each file '
                        'is one movement, its first row the onset')
    _add_csv_columns(t)
    t.add_argument('--frame', default=None,
                   help='frame the observed agent is expressed in (recorded in the model; bags: '
                        'iiwa_link_0)')
    t.add_argument('--out', required=True, type=_new_file, help='model file (.npz)')
    t.add_argument('--components', type=_bounded(int, 1, name='a whole number'), default=None,
                   help='number of components (default: chosen over 1..--max-components)')
    t.add_argument('--criterion', choices=['auto', 'patterns', 'loo'], default='auto',
                   help="how K is chosen: 'patterns' the leave-one-out likelihood of held-out "
                        "demonstrations in the space where patterns are found (both agents' "
                        "paths), 'loo' the leave-one-out RMS of the controlled agent given the "
                        "final observed position (the thesis); 'auto' = patterns")
    _add_translation(t)
    t.add_argument('--noise', choices=['tied', 'per_component'], default='tied',
                   help='observation noise per DOF shared by all components (tied) or per component')
    t.add_argument('--observation-noise', default=None, type=_noise_stds,
                   help='extra online sensor noise std, one number or one per observed DOF, in '
                        'their units (default: 0.01 for a wrist in m from bags, else 0)')
    t.add_argument('--max-components', type=_bounded(int, 1, name='a whole number'), default=9)
    t.add_argument('--n-basis', type=_bounded(int, 2, name='a whole number'), default=15)
    t.add_argument('--method', choices=['regression', 'em'], default='regression',
                   help="'em' learns from demonstrations with missing data (occlusions)")
    t.add_argument('--on-error', choices=['skip', 'raise'], default='skip')
    t.add_argument('--jobs', type=_bounded(int, 1, name='a whole number'), default=None,
                   help='threads for the held-out folds (default: every core this process may '
                        'use; the model is the same for any number)')
    t.add_argument('--cut', choices=['detected', 'recorded'], default='detected',
                   help="bags: each demonstration from the onset to the end the observer finds, "
                        "or ('recorded') the ones its bag records (mixture_ip_ros.onset_ns / "
                        "end_ns in its metadata custom_data: an annotated data set)")
    _add_robot(t)
    t.set_defaults(func=_train, check=partial(_check_train_args, parser=t))

    e = sub.add_parser('evaluate', help="the thesis's experiments, real recordings or your own "
                                        'labelled CSV recordings: plots + metrics.json')
    e.add_argument('--scenario', default=None,
                   choices=['box_assembly', 'pole', 'phase', 'missing_data', 'gestures',
                            'interactions'])
    e.add_argument('--csv', default=None, type=_existing_dir,
                   help='instead of a scenario: a folder of labelled CSV demonstrations (with '
                        '--labels, --observed, --controlled)')
    e.add_argument('--labels', default=None,
                   help='with --csv: a JSON file mapping each CSV file (name or stem) to its label')
    _add_csv_columns(e)
    _add_translation(e)
    e.add_argument('--out', required=True, type=_out_dir)
    e.add_argument('--seed', type=int, default=0)
    e.add_argument('--quick', action='store_true', help='fewer components/folds (for smoke runs)')
    e.add_argument('--bags', default=None, type=_existing_dir,
                   help='evaluate on this folder of bags (with labels.json) instead of generating')
    e.add_argument('--robot', default=None,
                   help='box_assembly and pole: the arm of the demonstrations, a shipped name or '
                        'the path of a robot description file (default: the iiwa14)')
    e.set_defaults(func=_evaluate, check=partial(_check_evaluate_args, parser=e))

    d = sub.add_parser('demo', help='closed loop: bags -> observer -> estimator -> MuJoCo arm')
    d.add_argument('--scenario', choices=['box_assembly', 'interactions'],
                   default='box_assembly',
                   help="box_assembly: generated human-robot demonstrations; interactions: "
                        "NuiSI's two people, the arm in person 2's place, person 1's held-out "
                        "recordings replayed (config/interactions.yaml)")
    _add_robot(d)
    d.add_argument('--data', default=None,
                   help='folder of demonstration bags, generated if missing (default: '
                        'out/box_assembly_bags or out/interactions/bags for the iiwa14, '
                        'out/<robot>/... for another robot)')
    d.add_argument('--out', default=None, type=_out_dir,
                   help='model, plots and report go here (default: out/demo or '
                        'out/interactions/demo, out/<robot>/... for another robot)')
    d.add_argument('--components', type=_bounded(int, 1, name='a whole number'), default=None,
                   help='number of components (default: chosen by leave-one-out)')
    d.add_argument('--json', default=None, type=_new_file,
                   help='also write the report as JSON here')
    d.add_argument('--render', default=None, type=_out_dir,
                   help='write videos and contact sheets here')
    d.add_argument('--held-out', type=_bounded(int, 1, name='a whole number'), default=3,
                   help='box_assembly: interactions replayed per pattern (interactions: the '
                        'upstream test split)')
    d.add_argument('--seed', type=int, default=0)
    d.add_argument('--command-delay', type=_bounded(float, 0.0, 60.0), default=None,
                   metavar='S', help='hold every command from the estimator S seconds of '
                                     'simulated time before the arm gets it (a slow link)')
    d.set_defaults(func=_demo)

    m = sub.add_parser('params', help="a node's parameters as the README's Markdown table")
    m.add_argument('node', choices=sorted(NODE_SCHEMAS) + ['all'])
    m.add_argument('--update', metavar='FILE', default=None,
                   help='rewrite the tables between <!-- parameters: NODE --> and <!-- end --> '
                        'in FILE (the README) instead of printing them')
    m.set_defaults(func=_params)

    lc = sub.add_parser('lifecycle', help='drive a managed node through its lifecycle services '
                                          '(like `ros2 lifecycle set`), or get its state')
    lc.add_argument('node', help='node name, e.g. estimator_node')
    lc.add_argument('transition', choices=['configure', 'activate', 'deactivate', 'cleanup',
                                           'shutdown', 'get'])
    lc.add_argument('--timeout', type=_bounded(float, 0.0), default=10.0,
                    help='s to wait for the service (discovery takes a few seconds)')
    lc.set_defaults(func=_lifecycle)
    return p


def main(argv=None):
    set_process_defaults()       # before the commands import numpy and numba
    logging.basicConfig(level=logging.INFO, format='%(levelname)s %(name)s: %(message)s')
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
