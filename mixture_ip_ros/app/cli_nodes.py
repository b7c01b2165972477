"""`mixture-ip params` and `mixture-ip lifecycle`: the nodes' parameter tables and their
lifecycle transitions."""

from pathlib import Path

from mixture_ip_ros.app.cli_options import bounded


NODE_SCHEMAS = {'estimator_node': 'mixture_ip_ros.nodes.estimator_node:EstimatorParameters',
                'observer_node': 'mixture_ip_ros.nodes.observer_node:ObserverParameters',
                'sim_node': 'mixture_ip_ros.nodes.sim_node:SimParameters',
                'bag_player': 'mixture_ip_ros.nodes.bag_player:BagPlayerParameters'}


def add_node_parsers(sub):
    m = sub.add_parser('params', help="a node's parameters as the README's Markdown table")
    m.add_argument('node', choices=sorted(NODE_SCHEMAS) + ['all'],
                   help="the node whose parameters to show, or 'all'")
    m.add_argument('--update', metavar='FILE', default=None,
                   help='rewrite the tables between <!-- parameters: NODE --> and <!-- end --> '
                        'in FILE (the README) instead of printing them')
    m.set_defaults(func=_params)

    lc = sub.add_parser('lifecycle', help='drive a managed node through its lifecycle services '
                                          '(like `ros2 lifecycle set`), or get its state')
    lc.add_argument('node', help='node name, e.g. estimator_node')
    lc.add_argument('transition', choices=['configure', 'activate', 'deactivate', 'cleanup',
                                           'shutdown', 'get'],
                    help="the transition to trigger, or 'get' to print the node's state")
    lc.add_argument('--timeout', type=bounded(float, 0.0), default=10.0,
                    help='s to wait for the service (discovery takes a few seconds)')
    lc.set_defaults(func=_lifecycle)


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
