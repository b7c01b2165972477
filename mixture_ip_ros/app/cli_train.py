"""`mixture-ip train`: its options, the checks of their combinations, and the run."""

import sys
from functools import partial

from mixture_ip_ros.app.cli_csv import (add_csv_columns, add_translation, check_csv_columns,
                                        csv_layout, read_labels, translation_groups)
from mixture_ip_ros.app.cli_options import (add_robot, bounded, existing_dir, existing_file,
                                            given, new_file, noise_stds)


def add_train_parser(sub):
    t = sub.add_parser('train', help='learn a Mixture of Interaction ProMPs from a folder of bags '
                                     'or of CSV files (one per demonstration)')
    t.add_argument('bag_dir', nargs='?', default=None, type=existing_dir,
                   help='folder of demonstration bags')
    t.add_argument('--csv', default=None, metavar='DIR', type=existing_dir,
                   help='folder of CSV files instead: a time column and named columns; each file '
                        'is one movement, its first row the onset')
    add_csv_columns(t)
    t.add_argument('--frame', default=None,
                   help='frame the observed agent is expressed in (recorded in the model; bags: '
                        'iiwa_link_0)')
    t.add_argument('--arm-in-partner-place', default=None, metavar='FILE', type=existing_file,
                   help="--csv recordings of two people, the observed columns person 1's hand "
                        "and the controlled ones the partner's (x,y,z): the arm (--robot) takes "
                        "the partner's place as FILE sets it (config/partner_placement.yaml), "
                        "and the model controls its joints")
    t.add_argument('--out', required=True, type=new_file, help='model file (.npz)')
    t.add_argument('--json', default=None, type=new_file, metavar='PATH',
                   help='also write the full training summary as JSON here (stdout has a '
                        'short one)')
    t.add_argument('--components', type=bounded(int, 1, name='a whole number'), default=None,
                   help='number of components (default: chosen over 1..--max-components)')
    t.add_argument('--labels', default=None, metavar='FILE',
                   help='JSON object, file name or stem -> label: one component per label, '
                        'named by it; recordings absent or null are learned without labels '
                        '(the rest of K chosen, at least one component per label)')
    t.add_argument('--criterion', choices=['auto', 'patterns', 'loo'], default='auto',
                   help="how K is chosen: 'patterns' the leave-one-out likelihood of held-out "
                        "demonstrations in the space where patterns are found (both agents' "
                        "paths), 'loo' the leave-one-out RMS of the controlled agent given the "
                        "final observed position (the thesis); 'auto' = patterns")
    add_translation(t)
    t.add_argument('--noise', choices=['tied', 'per_component'], default='tied',
                   help='observation noise per DOF shared by all components (tied) or per component')
    t.add_argument('--observation-noise', default=None, type=noise_stds,
                   help='extra online sensor noise std, one number or one per observed DOF, in '
                        'their units (default: 0.01 for a wrist in m from bags, else 0)')
    t.add_argument('--max-components', type=bounded(int, 1, name='a whole number'), default=9,
                   help='without --components: the largest number of components tried '
                        '(K = 1..this; default 9)')
    t.add_argument('--n-basis', type=bounded(int, 2, name='a whole number'), default=15,
                   help='Gaussian basis functions per DOF over the phase (more: finer detail, '
                        'more parameters; default 15)')
    t.add_argument('--method', choices=['regression', 'em'], default='regression',
                   help="'em' learns from demonstrations with missing data (occlusions)")
    t.add_argument('--on-error', choices=['skip', 'raise'], default=None,
                   help="a demonstration that cannot be read (a bag or a CSV file): 'skip' "
                        "leaves it out with one logged line naming it and why, 'raise' stops "
                        "at the first with its error (default: skip for a folder of bags, "
                        "raise for --csv)")
    t.add_argument('--jobs', type=bounded(int, 1, name='a whole number'), default=None,
                   help='threads for the held-out folds (default: every core this process may '
                        'use; the model is the same for any number)')
    t.add_argument('--cut', choices=['detected', 'recorded'], default='detected',
                   help="bags: each demonstration from the onset to the end the observer finds, "
                        "or ('recorded') the ones its bag records (mixture_ip_ros.onset_ns / "
                        "end_ns in its metadata custom_data: an annotated data set)")
    add_robot(t)
    t.set_defaults(func=run_train, check=partial(check_train_args, parser=t))


def run_train(args):
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
        layout = csv_layout(args)
        demos = load_csv_dataset(args.csv, layout, time=args.time,
                                 on_error=args.on_error or 'raise')
        kwargs['observed_frame'] = args.frame or ''
        kwargs['translation'] = translation_groups(args, layout)
        if args.arm_in_partner_place is not None:
            from mixture_ip_ros.app.arm_in_partner_place import arm_demonstrations
            demos, kwargs['extra'] = arm_demonstrations(demos, layout,
                                                        args.arm_in_partner_place, robot)
            # the bags' layout (the wrist, the arm's joints) in the robot's base frame
            layout = None
            del kwargs['observed_frame']
    else:
        from mixture_ip_ros.io.dataset import load_dataset
        # A bag left out is logged by load_dataset, in one line naming it and why.
        demos, _ = load_dataset(args.bag_dir, on_error=args.on_error or 'skip',
                                joint_names=robot.joint_names,
                                transform=robot.world_to_base(), cut=args.cut)
        layout = None
        if args.frame:
            kwargs['observed_frame'] = args.frame
    if args.labels is not None:
        kwargs['labels'] = train_labels(args.labels, demos)
    if args.components is not None:
        kwargs['n_components'] = args.components
    else:
        kwargs['candidates'] = range(1, args.max_components + 1)
        kwargs['progress'] = text_progress(what='held-out fits')
    model, info = train_to_file(demos, args.out, layout=layout, robot=robot,
                                stages=Stages(text_stages()), **kwargs)
    if info.get('seconds'):
        print('where the time went: ' + ', '.join(f'{name} {s:.1f} s'
                                                 for name, s in info['seconds'].items()),
              file=sys.stderr)
    from mixture_ip_ros.app.summary import train_report, write_json
    write_json(args.json, {'model': str(args.out), **info})
    print(train_report(model, info, demos, args.out, args.csv))


def train_labels(path, demos) -> list:
    """Each recording's label in the `train --labels` file (None: not in it, or null);
    ValueError if it names none of them."""
    from mixture_ip_ros.app.naming import recording_labels
    labels = recording_labels(read_labels(path), demos)
    if all(label is None for label in labels):
        raise ValueError(f'--labels {path}: names none of the {len(demos)} recordings (first: '
                         f'{demos[0].name!r}); it maps file names or stems to labels')
    named = sum(label is not None for label in labels)
    if named < len(labels):
        print(f'--labels: {named} of {len(labels)} recordings labelled, the other '
              f'{len(labels) - named} learned without labels', file=sys.stderr)
    return labels


def check_train_args(args, parser):
    """`train`'s options together: exit 2 with one line on the first contradiction;
    ValueError if the --labels file is not a JSON object."""
    if (args.bag_dir is None) == (args.csv is None):
        parser.error('give a folder of bags or --csv DIR (one of them)')
    if args.labels is not None:
        read_labels(args.labels)            # before the recordings are loaded, as for evaluate
    layout = check_csv_columns(args, parser)
    _check_arm_in_partner_place(args, parser, layout)
    bag_options = given(args, parser, 'cut')
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


def _check_arm_in_partner_place(args, parser, layout):
    if args.arm_in_partner_place is not None:
        from mixture_ip_ros.app.arm_in_partner_place import options_problem
        problem = options_problem(args.arm_in_partner_place, layout,
                                  given(args, parser, 'translation', 'frame'))
        if problem:
            parser.error(problem)
