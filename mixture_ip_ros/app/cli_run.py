"""`mixture-ip run`: the nodes started together on a bag or on live mocap (app.bringup)."""

from mixture_ip_ros.app.cli_options import add_robot, bounded, existing_file


def add_run_parser(sub):
    r = sub.add_parser('run', help='start the nodes (sim, observer, estimator, bag player) as '
                                   'separate processes and print the interaction as it happens')
    r.add_argument('--model', required=True, type=existing_file,
                   help='trained model file (.npz from mixture-ip train)')
    source = r.add_mutually_exclusive_group(required=True)
    source.add_argument('--bag', default=None,
                        help='rosbag2 folder to replay as the wrist (on the simulated clock); '
                             'the run stops once its last interaction is reported')
    source.add_argument('--live', action='store_true',
                        help='no bag: the wrist comes from live mocap on /mocap/wrist (wall '
                             'clock); runs until Ctrl-C')
    add_robot(r)
    r.add_argument('--no-sim', dest='sim', action='store_false',
                   help='do not start sim_node (a real arm takes its place)')
    r.add_argument('--domain', type=bounded(int, 0, 232, name='a whole number'), default=None,
                   help="ROS_DOMAIN_ID of the nodes (default: the caller's, else 0)")
    r.add_argument('--log-dir', default=None,
                   help="the nodes' log files go here (default: a new temporary folder)")
    r.add_argument('--end-timeout', type=bounded(float, 0.0), default=15.0, metavar='S',
                   help='with --bag: s to wait after the bag ends for its last interaction to '
                        'be reported (default 15)')
    r.set_defaults(func=_run)


def _run(args):
    from mixture_ip_ros.app.bringup import run
    code = run(args.model, args.robot, bag=args.bag, live=args.live, sim=args.sim,
               domain=args.domain, log_dir=args.log_dir, end_timeout=args.end_timeout)
    if code:
        raise ValueError('a node exited on its own (its log says why)')
