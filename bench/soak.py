"""Soak: minutes of 500 Hz mocap through observer_node and estimator_node (the executables, as
separate processes), a person reaching, holding, returning the hand to rest, resting, reaching
again, now and then with an outlier pose among them.

The wrist stream: box-assembly reaches (generated, seed 1: not the training seed) resampled to
the rate, each followed by a hold at the goal, a return to rest along the reach reversed, a rest,
and sometimes a second reach straight after the first (no rest between). Every 2 s one pose is a
marker glitch 100 m away. Stamps are the present when each pose is published.

Keys: poses_published, observer_accepted, observer_dropped (by reason), estimator_received
(diagnostics), rss_mb_{start,end}_{observer,estimator}, reaches, returns, transitions (second
reaches without rest), commits_on_{reaches,returns,transitions} (commitments: the first plan
after an onset, by the window its stamp falls in), {returns,transitions}_with_plans (windows in
which any plan went out, e.g. the plans of the reach before a transition until the robot holds),
trajectories, points_beyond_limits (points
of every published trajectory outside the iiwa's position or velocity limits), holds (from
diagnostics), soak_s, load (busy processes beside the nodes, --load N: each
`python -c 'while True: pass'`, started once the nodes are up, killed at the end) and
loadavg_1min at the end.
Run: .venv/bin/python bench/soak.py [--minutes 3] [--rate 500] [--load 2]
"""

import argparse
import json
import os
from pathlib import Path
import signal
import subprocess
import sys
import tempfile
import time

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

import numpy as np  # noqa: E402
import rclpy  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.node import Node  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402
from std_msgs.msg import Header  # noqa: E402
from trajectory_msgs.msg import JointTrajectory  # noqa: E402

from mixture_ip_ros.app.training import train_to_file  # noqa: E402
from mixture_ip_ros.core.share import config_path  # noqa: E402
from mixture_ip_ros.core.stamps import ns_to_parts, stamp_to_ns  # noqa: E402
from mixture_ip_ros.nodes import qos  # noqa: E402
from mixture_ip_ros.nodes.spinning import spin_in_thread  # noqa: E402
from mixture_ip_ros.scenarios.box_assembly import box_assembly  # noqa: E402
from mixture_ip_ros.scenarios.recording import MOCAP_NOISE  # noqa: E402

BIN = Path(sys.executable).parent
HOLD_S, REST_S = 0.6, 1.0
GLITCH_EVERY_S = 2.0


def segments(rng, gen, total_s, rate):
    """(kind, positions (n, 3)) until total_s of stream: rest, reach, hold, return, rest, ...;
    one reach in four is followed at once by a second one (a transition)."""
    out, t = [], 0.0
    rest = np.array([1.22, 0.24, 0.08])

    def add(kind, xyz):
        nonlocal t
        out.append((kind, xyz))
        t += len(xyz) / rate

    def still(p, seconds):
        return p + rng.normal(0.0, MOCAP_NOISE, (int(seconds * rate), 3))

    def movement(g, start):
        s, e = g.onset, g.end
        ok = ~np.isnan(g.wrist_xyz).any(axis=1) & (g.wrist_t >= s) & (g.wrist_t <= e)
        ts = np.arange(s, e, 1.0 / rate)
        xyz = np.column_stack([np.interp(ts, g.wrist_t[ok], g.wrist_xyz[ok, j])
                               for j in range(3)])
        return xyz - xyz[0] + start
    add('rest', still(rest, REST_S))
    while t < total_s:
        g = gen[rng.integers(len(gen))]
        reach = movement(g, rest)
        add('reach', reach)
        end = reach[-1]
        if rng.uniform() < 0.25:                   # a second reach without a rest
            g2 = gen[rng.integers(len(gen))]
            second = movement(g2, end)
            add('transition', second)
            end = second[-1]
        add('hold', still(end, HOLD_S))
        back = movement(g, rest)[::-1]             # the way back: the reach reversed, ...
        s = np.linspace(0.0, 1.0, len(back))[:, None]
        add('return', back + (end - back[0]) * (1 - s) + (rest - back[-1]) * s)  # ... end to rest
        add('rest', still(rest, REST_S))
    return out


class Probe(Node):

    def __init__(self, **kwargs):
        super().__init__('soak_probe', **kwargs)
        self.pose_pub = self.create_publisher(PoseStamped, '/mocap/wrist', qos.sensor_data(100))
        self.traj_sub = self.create_subscription(JointTrajectory, 'joint_trajectory',
                                                 self.on_traj, qos.reliable(1000))
        self.create_subscription(DiagnosticArray, '/diagnostics', self.on_diag, qos.reliable(10))
        self.create_subscription(Header, '/observer/event', self.on_event, qos.reliable(100))
        self.trajectories = []      # (receive wall time, message)
        self.commits = []           # stamp of the first plan after each onset: a commitment
        self._onset = False
        self.diagnostics = {}

    def on_traj(self, msg):
        self.trajectories.append((time.monotonic(), msg))
        if msg.points and self._onset:
            self.commits.append(stamp_to_ns(msg.header.stamp))
            self._onset = False

    def on_event(self, msg):
        if msg.frame_id == 'onset':
            self._onset = True

    def on_diag(self, msg):
        for st in msg.status:
            self.diagnostics[st.name.split(':')[0]] = {kv.key: kv.value for kv in st.values}


def rss_mb(pid):
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('VmRSS:'):
            return round(int(line.split()[1]) / 1024, 1)
    return None


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--minutes', type=float, default=3.0)
    ap.add_argument('--rate', type=float, default=500.0)
    ap.add_argument('--domain-id', type=int, default=None)
    ap.add_argument('--load', type=int, default=0,
                    help='busy processes competing for the CPUs during the soak')
    args = ap.parse_args()
    domain = args.domain_id if args.domain_id is not None else 10 + os.getpid() % 80
    rng = np.random.default_rng(7)
    t_start = time.monotonic()
    result = {}
    with tempfile.TemporaryDirectory(prefix='soak_') as tmp:
        model = Path(tmp) / 'model.npz'
        train_to_file([g.to_demonstration(0.01) for g in box_assembly(seed=0)], model,
                      n_components=3)
        plan = segments(rng, box_assembly(seed=1), args.minutes * 60.0, args.rate)
        env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
        procs = {}
        for exe, extra in (('observer_node', ['--params-file', str(config_path('observer.yaml'))]),
                           ('estimator_node', ['--params-file',
                                               str(config_path('estimator.yaml')),
                                               '-p', f'model_path:={model}'])):
            log = open(Path(tmp) / f'{exe}.log', 'w')
            procs[exe] = (subprocess.Popen([str(BIN / exe), '--ros-args', *extra], env=env,
                                           stdout=log, stderr=subprocess.STDOUT), log)
        ctx = Context()
        rclpy.init(context=ctx, domain_id=domain)
        probe = Probe(context=ctx)
        ex, th = spin_in_thread(probe)
        busy = []
        try:
            deadline = time.monotonic() + 60
            while not (probe.pose_pub.get_subscription_count() and
                       probe.traj_sub.get_publisher_count() and len(probe.diagnostics) == 2):
                if time.monotonic() > deadline:
                    raise RuntimeError('the nodes did not come up')
                time.sleep(0.05)
            rss0 = {exe: rss_mb(p.pid) for exe, (p, _) in procs.items()}
            busy = [subprocess.Popen([sys.executable, '-c', 'while True: pass'])
                    for _ in range(args.load)]
            windows = []                 # (kind, first stamp, last stamp)
            msg = PoseStamped()
            msg.header.frame_id = 'world'
            msg.pose.orientation.w = 1.0
            clock = probe.get_clock()
            period = 1.0 / args.rate
            t0 = time.perf_counter()
            k = 0
            published = glitches = 0
            next_glitch = GLITCH_EVERY_S
            for kind, xyz in plan:
                first = None
                for p in xyz:
                    wait = t0 + k * period - time.perf_counter()
                    if wait > 0:
                        time.sleep(wait)
                    k += 1
                    ns = clock.now().nanoseconds
                    if k * period >= next_glitch and kind == 'rest':
                        next_glitch += GLITCH_EVERY_S
                        p = p + 100.0                # a marker glitch
                        glitches += 1
                    msg.header.stamp.sec, msg.header.stamp.nanosec = ns_to_parts(ns)
                    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = p.tolist()
                    probe.pose_pub.publish(msg)
                    published += 1
                    first = ns if first is None else first
                windows.append((kind, first, ns))
            time.sleep(2.5)              # the last diagnostics and trajectories
            rss1 = {exe: rss_mb(p.pid) for exe, (p, _) in procs.items()}
            loadavg = os.getloadavg()[0]
        finally:
            for p in busy:
                p.kill()
                p.wait()
            ex.shutdown(timeout_sec=2.0)
            th.join(timeout=2.0)
            probe.destroy_node()
            rclpy.try_shutdown(context=ctx)
            for p, _ in procs.values():
                p.send_signal(signal.SIGINT)
            for p, log in procs.values():
                try:
                    p.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    p.kill()
                log.close()

    from mixture_ip_ros.robot.kinematics import RobotKinematics
    kin = RobotKinematics()
    # A commitment is the first plan after an onset (a new interaction), classified by the
    # stream window its trigger stamp falls in; the plans that continue a commitment into the
    # next window are counted apart (the robot finishing the reach it was committed to).
    committed = {w: 0 for w in ('reach', 'return', 'transition')}
    counts = {w: 0 for w in committed}
    plan_stamps = [stamp_to_ns(m.header.stamp) for _, m in probe.trajectories if m.points]
    carried = {w: 0 for w in committed}
    for kind, lo, hi in windows:
        if kind in counts:
            counts[kind] += 1
            committed[kind] += any(lo <= c <= hi for c in probe.commits)
            carried[kind] += any(lo <= c <= hi for c in plan_stamps)
    beyond = 0
    for _, m in probe.trajectories:
        for pt in m.points:
            q = np.array(pt.positions)
            v = np.array(pt.velocities) if len(pt.velocities) else np.zeros_like(q)
            beyond += bool(np.any(q < kin.lower) or np.any(q > kin.upper)
                           or np.any(np.abs(v) > kin.velocity_limit))
    obs = probe.diagnostics.get('observer_node', {})
    est = probe.diagnostics.get('estimator_node', {})
    result.update({
        'poses_published': published, 'glitches_injected': glitches,
        'observer_accepted': int(obs.get('accepted', -1)),
        'observer_dropped': {k[len('dropped_'):]: int(v) for k, v in obs.items()
                             if k.startswith('dropped_') and v != '0'},
        'estimator_received': int(est.get('observations_received', -1)),
        'reaches': counts['reach'], 'returns': counts['return'],
        'transitions': counts['transition'],
        'commits_on_reaches': committed['reach'], 'commits_on_returns': committed['return'],
        'commits_on_transitions': committed['transition'],
        'transitions_with_plans': carried['transition'],
        'returns_with_plans': carried['return'],
        'trajectories': len(probe.trajectories),
        'stops_sent': sum(1 for _, m in probe.trajectories if not m.points),
        'points_beyond_limits': beyond,
        'holds': int(est.get('holds_unexplained', -1)),
        **{f'rss_mb_start_{exe.split("_")[0]}': v for exe, v in rss0.items()},
        **{f'rss_mb_end_{exe.split("_")[0]}': v for exe, v in rss1.items()},
        'rate_hz': args.rate, 'load': args.load, 'loadavg_1min': round(loadavg, 2),
        'soak_s': round(time.monotonic() - t_start, 1)})
    print(json.dumps(result))


if __name__ == '__main__':
    main()
