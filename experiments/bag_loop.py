"""Does a bag replayed in a loop through the nodes give one committed, right interaction per pass?

The four nodes run as separate processes, started as `mixture-ip run` starts them
(app/bringup.py), with the bag player looping (``loop:=true``). Two ways to replay:
``--stamps rewritten`` (the default of `mixture-ip run`: the nodes on the sim's clock, the stamps
rewritten to it, so at each loop the wrist jumps back in space while the stamps go on) and
``--stamps recorded`` (the bag's own stamps and its /clock, ``publish_clock``, like `ros2 bag
play --clock`: every node on that clock, which jumps back at each loop). This process listens to
/observer/event, the estimator's log lines on /rosout and the observer's /diagnostics. Once
``--loops`` interactions have been reported (or after a timeout) it stops the player alone, as a
user would, and, 3 s later, the other nodes.

Printed (one JSON object): per interaction the estimator's log lines parsed into committed, the
label committed to, the final label, switches and commit phase, and ``right``: both labels are
the bag's (labels.json beside the bag); onsets, ends, the observer's drops by reason and stream
restarts, the errors the nodes logged (``errors``, also after the player stopped), the load
average at the start.
Run: ROS_DOMAIN_ID=56 .venv/bin/python experiments/bag_loop.py --model out/demo/model.npz
--bag out/box_assembly_bags/demo_000 [--loops 10] [--stamps rewritten|recorded]
"""

import argparse
import json
import os
from pathlib import Path
import re
import signal
import tempfile
import time

from mixture_ip_ros.app.bringup import Children, node_commands, node_parameters, run_environment

RESULT = re.compile(r'interaction done: component \d+ \((?P<label>[^)]*)\).*committed at phase '
                    r'(?P<phase>[-\d.]+).* (?P<switches>\d+) switches')
COMMIT = re.compile(r'committed to component \d+ \((?P<label>[^)]*)\)')


def parameters(model, bag, stamps: str) -> dict:
    nodes = node_parameters(model, 'iiwa14', bag)
    nodes['bag_player']['loop'] = True
    if stamps == 'recorded':
        # The sim follows the bag's clock at the wall clock's pace (it must not publish one).
        nodes['sim_node'].update(simulated_time=False, use_sim_time=True)
        nodes['bag_player'].update(rewrite_stamps=False, publish_clock=True, use_sim_time=False)
    return nodes


def measure(model, bag, loops: int, stamps: str, domain: int, timeout: float) -> dict:
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rcl_interfaces.msg import Log
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Header
    labels = json.loads((Path(bag).parent / 'labels.json').read_text())['labels']
    truth = labels[Path(bag).name]
    env = run_environment(domain)
    log_dir = Path(tempfile.mkdtemp(prefix='bag_loop_'))
    children = Children(env, log_dir)
    out = {'bag': str(bag), 'truth': truth, 'stamps': stamps, 'loops': loops,
           'loadavg_at_start': os.getloadavg(), 'log_dir': str(log_dir), 'events': {},
           'interactions': [], 'errors': [], 'observer': {}, 'estimator_lines': []}
    rclpy.init(domain_id=domain)
    node = rclpy.create_node('bag_loop_probe', enable_rosout=False)
    reliable = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    commits = []     # the label the interaction in progress was committed to

    def on_event(m):
        out['events'][m.frame_id] = out['events'].get(m.frame_id, 0) + 1

    def on_log(m):
        if m.level >= Log.ERROR:
            out['errors'].append(f'{m.name}: {m.msg}')
        if m.name != 'estimator_node':
            return
        if m.msg.startswith(('committed to', 'interaction', 'switching', 'onset before')):
            out['estimator_lines'].append(m.msg)
        if COMMIT.match(m.msg):
            commits.append(COMMIT.match(m.msg)['label'])
        if m.msg.startswith('interaction'):
            match, first = RESULT.match(m.msg), commits.pop() if commits else None
            out['interactions'].append(
                {'committed': match is not None, 'committed_to': first,
                 'label': match['label'] if match else None,
                 'switches': int(match['switches']) if match else None,
                 'right': match is not None and first == match['label'] == truth,
                 'commit_phase': float(match['phase']) if match else None})

    def on_diagnostics(m):
        for status in m.status:
            if status.name.startswith('observer_node'):
                values = {v.key: v.value for v in status.values}
                out['observer'] = {k: int(v) for k, v in values.items()
                                   if k.startswith('dropped_') and v != '0'
                                   or k in ('stream_restarts', 'accepted')}

    node.create_subscription(Header, '/observer/event', on_event, reliable)
    node.create_subscription(Log, '/rosout', on_log, QoSProfile(
        depth=1000, reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL))
    node.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, reliable)
    start = time.monotonic()
    try:
        for name, argv in node_commands(parameters(model, bag, stamps)):
            children.start(name, argv)
        while (len(out['interactions']) < loops and time.monotonic() - start < timeout
               and not children.exited()):
            rclpy.spin_once(node, timeout_sec=0.1)
        out['exited_early'] = children.exited()
        if 'bag_player' in children.procs:
            children.procs['bag_player'].send_signal(signal.SIGINT)
        end = time.monotonic() + 3.0     # what stopping the player does; the last diagnostics
        while time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.1)
    finally:
        out['exit_codes'] = children.stop()
        node.destroy_node()
        rclpy.try_shutdown()
    out['seconds'] = round(time.monotonic() - start, 1)
    done = out['interactions'][:loops]
    out['summary'] = {'reported': len(done), 'committed': sum(r['committed'] for r in done),
                      'right': sum(r['right'] for r in done)}
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--model', default='out/demo/model.npz')
    parser.add_argument('--bag', default='out/box_assembly_bags/demo_000')
    parser.add_argument('--loops', type=int, default=10)
    parser.add_argument('--stamps', choices=('rewritten', 'recorded'), default='rewritten')
    parser.add_argument('--domain', type=int, default=int(os.environ.get('ROS_DOMAIN_ID', 0)))
    parser.add_argument('--timeout', type=float, default=180.0, help='s')
    a = parser.parse_args()
    print(json.dumps(measure(a.model, a.bag, a.loops, a.stamps, a.domain, a.timeout)))


if __name__ == '__main__':
    main()
