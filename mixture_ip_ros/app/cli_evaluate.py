"""`mixture-ip evaluate`: its options, the checks of their combinations, and the run."""

from functools import partial
from pathlib import Path

from mixture_ip_ros.app.cli_csv import (add_csv_columns, add_translation, check_csv_columns,
                                        csv_layout, read_labels, translation_groups)
from mixture_ip_ros.app.cli_options import existing_dir, existing_file, given, new_file, out_dir


def add_evaluate_parser(sub):
    e = sub.add_parser('evaluate', help="the thesis's experiments, real recordings or your own "
                                        'labelled CSV recordings: plots + metrics.json')
    e.add_argument('--scenario', default=None,
                   choices=['box_assembly', 'pole', 'phase', 'missing_data', 'gestures',
                            'interactions', 'change_of_mind'],
                   help="an experiment: box_assembly, pole (thesis 3.4.2, 3.4.1; generated "
                        "or --bags), phase, missing_data (generated letters, 4.3.1, 4.3.2), "
                        "gestures (UCR accelerometer gestures), interactions (NuiSI two-person "
                        "recordings), change_of_mind (NuiSI recordings spliced into changes "
                        "of mind); docs/method.md says what each asks")
    e.add_argument('--csv', default=None, type=existing_dir,
                   help='instead of a scenario: a folder of labelled CSV demonstrations (with '
                        '--labels, --observed, --controlled)')
    e.add_argument('--labels', default=None,
                   help='with --csv: a JSON file mapping each CSV file (name or stem) to its label')
    add_csv_columns(e)
    add_translation(e)
    e.add_argument('--model', default=None, type=existing_file,
                   help='score this trained model file on the labelled --csv recordings, '
                        "without retraining (the columns default to the model's)")
    e.add_argument('--out', default=None, type=out_dir,
                   help='folder for the plots and metrics.json, created if missing (optional '
                        'with --model)')
    e.add_argument('--json', default=None, type=new_file, metavar='PATH',
                   help='also write the full metrics as JSON here (stdout has a summary)')
    e.add_argument('--seed', type=int, default=0,
                   help='random seed of the generated demonstrations and of the folds '
                        '(default 0)')
    e.add_argument('--quick', action='store_true', help='fewer components/folds (for smoke runs)')
    e.add_argument('--bags', default=None, type=existing_dir,
                   help='evaluate on this folder of bags (with labels.json) instead of generating')
    e.add_argument('--robot', default=None,
                   help='box_assembly and pole: the arm of the demonstrations, a shipped name or '
                        'the path of a robot description file (default: the iiwa14)')
    e.set_defaults(func=run_evaluate, check=partial(check_evaluate_args, parser=e))


def run_evaluate(args):
    from mixture_ip_ros.app.progress import text_lines
    from mixture_ip_ros.app.summary import evaluate_summary, write_json
    if args.model is not None:
        metrics = _evaluate_model(args, text_lines())
    elif args.csv is None:
        from mixture_ip_ros.app.evaluation import evaluate
        metrics = evaluate(args.scenario, Path(args.out), seed=args.seed, quick=args.quick,
                           bag_dir=args.bags, robot=args.robot, progress=text_lines())
    else:
        from mixture_ip_ros.app.evaluation import evaluate_csv
        layout = csv_layout(args)
        metrics = evaluate_csv(args.csv, read_labels(args.labels), layout, Path(args.out),
                               time_column=args.time, seed=args.seed, quick=args.quick,
                               translation=translation_groups(args, layout),
                               progress=text_lines())
    written = [] if args.out is None else [Path(args.out) / 'metrics.json']
    written += [args.json] if write_json(args.json, metrics) else []
    print(evaluate_summary(metrics, written))


def _evaluate_model(args, progress):
    """`evaluate --model`: the model file scored on the labelled --csv recordings."""
    from mixture_ip_ros.app.evaluation import evaluate_model_csv
    from mixture_ip_ros.io.csv_files import parse_names
    columns = {key: parse_names(getattr(args, key), '--' + key.replace('_', '-')) for key in
               ('observed', 'controlled', 'observed_units', 'controlled_units')}
    return evaluate_model_csv(args.model, args.csv, read_labels(args.labels),
                              args.out and Path(args.out), time_column=args.time,
                              progress=progress, **columns)


def check_evaluate_args(args, parser):
    """`evaluate`'s options together: exit 2 with one line on the first contradiction;
    ValueError if the --labels file is not a JSON object."""
    if (args.scenario is None) == (args.csv is None):
        parser.error('give --scenario NAME or --csv DIR (one of them)')
    if args.model is not None:
        if args.csv is None:
            parser.error('--model: with --csv DIR and --labels FILE (the recordings it is '
                         'scored on)')
        fitting = given(args, parser, 'quick', 'translation', 'seed')
        if fitting:
            parser.error(f'{", ".join(fitting)}: not with --model (a trained model is scored '
                         'as it is: nothing is fitted)')
    elif args.out is None:
        parser.error('the following arguments are required: --out')
    else:
        check_csv_columns(args, parser)
    if args.csv is None:
        if args.labels is not None:
            parser.error('--labels: for --csv DIR only (it labels its files)')
    elif args.labels is None:
        parser.error('--csv needs --labels FILE (a JSON object: file name -> label)')
    else:
        # A labels file that cannot be read is bad input, as a bad CSV file is (exit 1), but
        # reading it costs nothing: it fails here, not after the recordings are loaded.
        read_labels(args.labels)
    robot_options = given(args, parser, 'bags', 'robot')
    if robot_options and args.scenario not in ('box_assembly', 'pole'):
        what = '--csv' if args.csv is not None else f'--scenario {args.scenario}'
        parser.error(f'{", ".join(robot_options)}: for --scenario box_assembly or pole only, '
                     f'not {what}')
    if args.bags is not None and given(args, parser, 'seed'):
        parser.error('--seed: the demonstrations it would generate are not used with --bags')
