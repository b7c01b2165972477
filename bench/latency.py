"""End-to-end latency of observer_node -> estimator_node, and the mocap rate they sustain.

Latency: wall time (time.perf_counter, this process) from publishing a wrist
geometry_msgs/PoseStamped on /mocap/wrist to the probe's callback receiving the
trajectory_msgs/JointTrajectory that this pose triggered. The probe is a node of this script:
it publishes the poses (sensor-data QoS, paced by sleeping in the main thread) and subscribes
to the trajectories. No sim and no /joint_states, so plans are never shortened by catch-up.

Set-up: a model trained on box_assembly(seed=0) (3 components, 15 basis functions, 3 + 7
DOFs); parameters from config/observer.yaml and config/estimator.yaml. The latency runs
override min_interval = 0 (every observation used) and replan_rate_hz = 200 (above the
100 Hz pose rate, so every observation replans in its own callback; the node's wall-clock
replan timer then also runs at 200 Hz). The stream replays demos' recorded 100 Hz wrist samples
(positions in 'world' = robot base) at their timing plus 0.3 s of extra rest, 0.5 s apart;
stamps are a synthetic clock from 1000 s, so segmentation and estimation are deterministic. A
short demo is replayed first as warm-up (not measured).

Which pose triggered a trajectory: the estimator publishes /estimator/predicted_wrist (stamped
onset + t_now, t_now = the observation that triggered the replan) just after each trajectory,
and after the commit every replan sends both, so the i-th last trajectory of an interaction
pairs with its i-th last path (read raw: only the stamp is parsed). Cross-check: for plans with
several points, trigger = header.stamp + first time_from_start - lookahead (disagreements and
unmatched trajectories are counted in trigger_mismatches). Per pose the first trajectory
counts. The observer's segmentation is replayed offline on the published poses (core
MotionSegmenter, same parameters) to know, per interaction:
  * the pose that confirmed the onset: the estimator then absorbs the samples it held since the
    back-dated onset, a slice per callback, and commits the robot only once they are in; a
    trajectory replanned when the onset callback itself finished them is an onset sample
    (onset_ms_*); trajectories triggered by earlier poses would be n_backlog_trajectories;
  * the pose that confirmed the end: forwarded like every pose (its own replan is a sample),
    then 'end' brings the final plan: the interaction's last trajectory (end_plan_ms_max).
Trajectories whose trigger the node's replanning rule, replayed offline, does not name (the
wall-clock timer, or the callback that finished the held samples when the rate would not
have replanned) are counted apart (n_timer_trajectories).

Keys (ms unless named otherwise):
  e2e_ms_median, e2e_ms_p99, e2e_ms_max   in-process: observer, estimator and probe nodes, each
                      spun by its own SingleThreadedExecutor in its own thread; the samples of
                      --repeats runs (each a fresh pipeline) pooled, and e2e_ms_*_per_run
  e2e_ms_p99_live     without the onset-confirming poses; e2e_ms_*_steady: only poses at least
                      STEADY_AFTER_S after the onset confirmation; e2e_ms_max_transient: the
                      earlier ones (absorbing the samples held before the onset)
  *_deployed          in-process with config/estimator.yaml unchanged (observations used every
                      min_interval, replans at replan_rate_hz): the poses that trigger a replan
  *_cross_process     observer_node and estimator_node executables as subprocesses (params
                      files + the latency overrides), probe here
  estimator_update_us_mean/max, estimator_plan_us_mean/max   the node's own LatencyStats (it
                      keeps last, mean and max, no median); *_cross_process: its last
                      /diagnostics (since start, warm-up included)
  estimator_rejected* observations the estimator rejected, by reason
  sustained_hz        highest tried rate such that it and every lower one passed: no pose lost
                      (all accepted by the observer, none dropped), every observation the
                      observer published received and none rejected by the estimator,
                      >= 95 % of the rate published, lag bounded (see
                      sustained_mode); sustained_runs: per rate
  sustained_hz_replan_every_obs   the same with the latency overrides
Run: .venv/bin/python bench/latency.py [--demos 4] [--repeats 3] [--rates 250,500,1000,2000]
(about 3 minutes). Timing only, no assertions.
"""

import argparse
import json
import os
import signal
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

import numpy as np  # noqa: E402
import rclpy  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile,  # noqa: E402
                       ReliabilityPolicy, qos_profile_sensor_data)
import yaml  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402
from nav_msgs.msg import Path as PathMsg  # noqa: E402
from trajectory_msgs.msg import JointTrajectory  # noqa: E402

from mixture_ip_ros.core.frames import FrameTransform  # noqa: E402
from mixture_ip_ros.core.segmentation import MotionSegmenter  # noqa: E402
from mixture_ip_ros.scenarios.generated import MOCAP_NOISE, box_assembly  # noqa: E402
from mixture_ip_ros.nodes.estimator_node import EstimatorNode  # noqa: E402
from mixture_ip_ros.nodes.observer_node import SEGMENTER_DEFAULTS, ObserverNode  # noqa: E402
from mixture_ip_ros.nodes.spinning import spin_in_thread  # noqa: E402
from mixture_ip_ros.core.share import config_path  # noqa: E402
from mixture_ip_ros.app.training import train_to_file  # noqa: E402

BIN = Path(sys.executable).parent
BASE_NS = 1000 * 1_000_000_000      # synthetic stamp clock starts at 1000 s
GAP_S = 0.5                         # stamp and wall pause between replayed interactions
REST_PAD_S = 0.3                    # extra rest after each demo so every end is confirmed
LAG_BOUND_MS = 50.0                 # sustained: steady-state lag and drain bound
STEADY_AFTER_S = 1.0                # poses this long after the onset confirmation: steady state
LATENCY_OVERRIDES = {'min_interval': 0.0, 'replan_rate_hz': 200.0}
OBSERVER_YAML = config_path('observer.yaml')
ESTIMATOR_YAML = config_path('estimator.yaml')


def yaml_params(path, node):
    with open(path) as f:
        return yaml.safe_load(f)[node]['ros__parameters']


OBSERVER_PARAMS = yaml_params(OBSERVER_YAML, 'observer_node')
ESTIMATOR_PARAMS = yaml_params(ESTIMATOR_YAML, 'estimator_node')


def as_parameters(d):
    return [Parameter(k, value=v) for k, v in d.items()]


def reliable(depth):
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


def ms_stats(seconds, prefix, suffix=''):
    a = np.asarray(seconds, dtype=float) * 1e3
    if a.size == 0:
        return {f'{prefix}_median{suffix}': None, f'{prefix}_p99{suffix}': None,
                f'{prefix}_max{suffix}': None}
    return {f'{prefix}_median{suffix}': round(float(np.median(a)), 3),
            f'{prefix}_p99{suffix}': round(float(np.percentile(a, 99)), 3),
            f'{prefix}_max{suffix}': round(float(a.max()), 3)}


# ---------------------------------------------------------------------------- streams
class Stream:
    """Poses to publish: wall offsets (s), stamps (ns), positions; segments = interactions."""

    def __init__(self, start_ns=BASE_NS):
        self.offsets, self.stamps, self.xyz, self.segments = [], [], [], []
        self.start_ns = start_ns

    def add(self, t, xyz):
        """One interaction's samples, ``t`` seconds from its first sample, after a pause."""
        start = self.offsets[-1] + GAP_S if self.offsets else 0.0
        lo = len(self.stamps)
        for ti, p in zip(t.tolist(), xyz.tolist()):
            self.offsets.append(start + ti)
            self.stamps.append(self.start_ns + round((start + ti) * 1e9))
            self.xyz.append(p)
        self.segments.append((lo, len(self.stamps)))

    @property
    def end_ns(self):
        return self.stamps[-1]

    def messages(self):
        msgs = []
        for ns, (x, y, z) in zip(self.stamps, self.xyz):
            m = PoseStamped()
            m.header.frame_id = 'world'
            m.header.stamp.sec, m.header.stamp.nanosec = divmod(ns, 1_000_000_000)
            m.pose.position.x, m.pose.position.y, m.pose.position.z = x, y, z
            m.pose.orientation.w = 1.0
            msgs.append(m)
        return msgs


def padded_wrist(g, seed, rate=None):
    """A demo's wrist samples (from its recording start) plus REST_PAD_S of rest (noise seeded
    by ``seed``); resampled to ``rate`` Hz (linear interpolation) if given."""
    rng = np.random.default_rng(seed)
    t, xyz = g.wrist_t, g.wrist_xyz
    dt = float(np.median(np.diff(t)))
    n = int(round(REST_PAD_S / dt))
    t = np.concatenate([t, t[-1] + dt * np.arange(1, n + 1)])
    rest = xyz[-10:].mean(axis=0) + rng.normal(0.0, MOCAP_NOISE, (n, 3))
    xyz = np.vstack([xyz, rest])
    if rate is not None:
        tr = np.arange(0.0, t[-1], 1.0 / rate)
        xyz = np.column_stack([np.interp(tr, t, xyz[:, j]) for j in range(3)])
        t = tr
    return t, xyz


def segmentation_events(probe, stream):
    """Per segment of ``stream``: stamp of the pose that confirmed the onset and of the one that
    confirmed the end (None if none), from the observer's own gate replayed offline on every
    pose the probe published (same parameters; the observer's stream time is seconds since the
    first pose it accepted)."""
    seg = MotionSegmenter(
        **{name: OBSERVER_PARAMS.get(name, d) for name, d in SEGMENTER_DEFAULTS.items()})
    tf = FrameTransform(OBSERVER_PARAMS['mocap_to_base_xyz'],
                        OBSERVER_PARAMS['mocap_to_base_xyzw'])
    t_ref = probe.published_stamps[0]
    events = []
    for ns, xyz in zip(probe.published_stamps, probe.published_xyz):
        for ev in seg.update((ns - t_ref) * 1e-9, tf.apply(*xyz)):
            if ev.kind in ('onset', 'end'):
                events.append((ev.kind, ns))
    out = []
    for lo, hi in stream.segments:
        s_lo, s_hi = stream.stamps[lo], stream.stamps[hi - 1]
        inside = [(k, ns) for k, ns in events if s_lo <= ns <= s_hi]
        out.append((next((ns for k, ns in inside if k == 'onset'), None),
                    next((ns for k, ns in inside if k == 'end'), None)))
    return out


# ---------------------------------------------------------------------------- probe
class Probe(Node):
    """Publishes the mocap poses; records trajectories and predicted-path stamps on arrival."""

    def __init__(self, diagnostics=False, **kwargs):
        super().__init__('latency_probe', **kwargs)
        self.pose_pub = self.create_publisher(PoseStamped, '/mocap/wrist', qos_profile_sensor_data)
        self.traj_sub = self.create_subscription(
            JointTrajectory, '/iiwa/joint_trajectory', self._on_traj, reliable(1000))
        self.path_sub = self.create_subscription(
            PathMsg, '/estimator/predicted_wrist', self._on_path, reliable(1000), raw=True)
        self.diagnostics = None
        if diagnostics:
            self.create_subscription(DiagnosticArray, '/diagnostics', self._on_diag, reliable(10))
        self.pub_times = {}     # stamp ns -> perf_counter just before publish
        self.published_stamps, self.published_xyz = [], []   # every pose, in order
        self.trajs = []         # (t_recv, onset ns, first time_from_start ns, n points)
        self.paths = []         # (t_recv, stamp ns)

    def _on_traj(self, msg):
        t = time.perf_counter()
        s = msg.header.stamp
        p0 = msg.points[0].time_from_start if msg.points else None
        self.trajs.append((t, s.sec * 1_000_000_000 + s.nanosec,
                           None if p0 is None else p0.sec * 1_000_000_000 + p0.nanosec,
                           len(msg.points)))

    def _on_path(self, raw):
        t = time.perf_counter()
        sec, nanosec = struct.unpack_from('<iI', raw, 4)   # CDR header, then header.stamp
        self.paths.append((t, sec * 1_000_000_000 + nanosec))

    def _on_diag(self, msg):
        for st in msg.status:
            if st.name.startswith('estimator_node'):
                self.diagnostics = {kv.key: kv.value for kv in st.values}

    def publish_stream(self, stream, msgs, rate_scale=1.0):
        """Publish at the stream's timing (sleep pacing: releases the GIL); returns the wall
        times of the first and last publish."""
        self.published_stamps.extend(stream.stamps)
        self.published_xyz.extend(stream.xyz)
        t0 = time.perf_counter() + 0.02
        first = last = None
        for off, ns, msg in zip(stream.offsets, stream.stamps, msgs):
            wait = t0 + off * rate_scale - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
            last = time.perf_counter()
            self.pose_pub.publish(msg)
            self.pub_times[ns] = last
            if first is None:
                first = last
        return first, last

    def wait_quiet(self, quiet=0.4, timeout=10.0, caught_up=None):
        """Until ``caught_up()`` (if given) and then no trajectory or path for ``quiet`` s."""
        deadline = time.monotonic() + timeout
        while caught_up is not None and not caught_up() and time.monotonic() < deadline:
            time.sleep(0.01)
        n = -1
        while time.monotonic() < deadline:
            m = len(self.trajs) + len(self.paths)
            if m == n:
                return
            n = m
            time.sleep(quiet)


def triggering_observations(stamps, onset_ns, min_interval, replan_period, live_after=None):
    """Stamps of the observations whose callback replans (estimator_node's rule, replayed):
    used when >= min_interval after the last used one (1 ns slack, as OnlineEstimator), and,
    if stamped after ``live_after`` (the held ones are absorbed outside the rule), replanning
    when its time since onset >= the previous such replan's + replan_period."""
    out, t_used, next_replan = set(), None, None
    for ns in stamps:
        t = (ns - onset_ns) * 1e-9
        if t < 0:
            continue
        if t_used is not None and t - t_used < min_interval - 1e-9:
            continue
        t_used = t
        if live_after is not None and ns <= live_after:
            continue
        if next_replan is None or t >= next_replan:
            next_replan = t + replan_period
            out.add(ns)
    return out


def analyse(stream, probe, seg_events, est_params, skip=0):
    """Per-pose latencies for the stream's segments from ``skip`` on (see module notes)."""
    res = {'lat': [], 'live': [], 'onset': [], 'end': [], 'timer': [], 'steady': [],
           'transient': [], 'n_traj': 0,
           'backlog': 0, 'repeat': 0, 'mismatch': 0, 'unmatched': 0, 'interactions': 0}
    lookahead_ns = round(float(est_params['lookahead']) * 1e9)
    stamps = np.array(stream.stamps)
    for si, (lo, hi) in enumerate(stream.segments):
        if si < skip:
            continue
        s_lo, s_hi = stream.stamps[lo], stream.stamps[hi - 1]
        T = [r for r in probe.trajs if s_lo <= r[1] <= s_hi]
        P = [p for p in probe.paths if s_lo <= p[1] <= s_hi]
        onset_pose, end_pose = seg_events[si]
        res['n_traj'] += len(T)
        if not T:
            continue
        res['interactions'] += 1
        if len(P) < len(T):
            res['unmatched'] += len(T)
            continue
        forwarded = [ns for ns in stream.stamps[lo:hi] if end_pose is None or ns <= end_pose]
        triggers = triggering_observations(forwarded, T[0][1], float(est_params['min_interval']),
                                           1.0 / float(est_params['replan_rate_hz']),
                                           live_after=onset_pose)
        seen = set()
        for j, (tr, path) in enumerate(zip(T, P[len(P) - len(T):])):
            trig = path[1]
            if tr[3] > 1 and abs(tr[1] + tr[2] - lookahead_ns - trig) > 2000:
                res['mismatch'] += 1
            k = int(np.argmin(np.abs(stamps - trig)))
            if abs(int(stamps[k]) - trig) > 2000 or int(stamps[k]) not in probe.pub_times:
                res['unmatched'] += 1
                continue
            trig = int(stamps[k])
            lat = tr[0] - probe.pub_times[trig]
            if j == len(T) - 1 and trig == end_pose:
                res['end'].append(lat)      # the final plan, on 'end'
            if onset_pose is not None and trig < onset_pose:
                res['backlog'] += 1
                continue
            if trig not in triggers:
                res['timer'].append(lat)
                continue
            if trig in seen:
                res['repeat'] += 1
                continue
            seen.add(trig)
            res['lat'].append(lat)
            if onset_pose is not None:
                late = trig - onset_pose >= STEADY_AFTER_S * 1e9
                res['steady' if late else 'transient'].append(lat)
            if trig == onset_pose:
                res['onset'].append(lat)
            else:
                res['live'].append(lat)
    return res


def pooled(results):
    """The samples and counts of several ``analyse`` results together."""
    out = {k: ([] if isinstance(v, list) else 0) for k, v in results[0].items()}
    for r in results:
        for k, v in r.items():
            out[k] += v
    return out


def pooled_stats(stats):
    """The node statistics of several in-process runs: means averaged, maxima and counts over
    all of them."""
    out = {}
    for k in stats[0]:
        values = [st[k] for st in stats]
        if k.endswith('_mean'):
            out[k] = round(float(np.mean(values)), 1)
        elif k.endswith('_max'):
            out[k] = max(values)
        elif isinstance(values[0], dict):
            out[k] = {r: sum(v.get(r, 0) for v in values) for r in set().union(*values)}
        else:
            out[k] = sum(values)
    return out


def latency_keys(res, suffix):
    out = ms_stats(res['lat'], 'e2e_ms', suffix)
    out[f'e2e_ms_p99_live{suffix}'] = ms_stats(res['live'], 'x')['x_p99']
    st = ms_stats(res['steady'], 'x')
    out[f'e2e_ms_median_steady{suffix}'] = st['x_median']
    out[f'e2e_ms_p99_steady{suffix}'] = st['x_p99']
    out[f'e2e_ms_max_transient{suffix}'] = ms_stats(res['transient'], 'x')['x_max']
    o = ms_stats(res['onset'], 'x')
    out[f'onset_ms_median{suffix}'] = o['x_median']
    out[f'onset_ms_max{suffix}'] = o['x_max']
    out[f'end_plan_ms_max{suffix}'] = ms_stats(res['end'], 'x')['x_max']
    out.update({f'n_samples{suffix}': len(res['lat']), f'n_trajectories{suffix}': res['n_traj'],
                f'n_backlog_trajectories{suffix}': res['backlog'],
                f'n_timer_trajectories{suffix}': len(res['timer']),
                f'n_repeat_trajectories{suffix}': res['repeat'],
                f'trigger_mismatches{suffix}': res['mismatch'] + res['unmatched'],
                f'interactions{suffix}': res['interactions']})
    return out


# ---------------------------------------------------------------------------- in-process
class InProcess:
    def __init__(self, ctx, model_path, overrides):
        self.observer = ObserverNode(context=ctx, parameter_overrides=as_parameters(
            OBSERVER_PARAMS))
        self.estimator = EstimatorNode(context=ctx, parameter_overrides=as_parameters(
            {**ESTIMATOR_PARAMS, 'model_path': str(model_path), **overrides}))
        self.probe = Probe(context=ctx)
        # One SingleThreadedExecutor per node in its own thread, as system.ClosedLoop.
        self.executors, self.threads = zip(*(spin_in_thread(n) for n in (
            self.observer, self.estimator, self.probe)))

    def caught_up(self):
        """Every published pose handled by the observer and each of its observations received
        by the estimator."""
        ob = self.observer
        return (ob.accepted + sum(ob.drop_counts.values()) >= len(self.probe.published_stamps)
                and self.estimator.planner.received >= ob.published['observations'])

    def close(self):
        for ex in self.executors:
            ex.shutdown(timeout_sec=5.0)
        for t in self.threads:
            t.join(timeout=5.0)
        for n in (self.probe, self.estimator, self.observer):
            n.destroy_node()


def estimator_params(overrides):
    return {**ESTIMATOR_PARAMS, **overrides}


def warm_stream(g, k):
    """The k-th warm-up replay of demo ``g``, stamped well before the measured stream."""
    s = Stream(BASE_NS - 60_000_000_000 + k * 10_000_000_000)
    s.add(*padded_wrist(g, seed=100 + k))
    return s


def run_latency_in_process(domain, model_path, warm, stream, overrides):
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain)
    try:
        p = InProcess(ctx, model_path, overrides)
        try:
            time.sleep(0.3)   # matching in one participant is quick, but asynchronous
            for s in (warm, stream):
                p.probe.publish_stream(s, s.messages())
                p.probe.wait_quiet(caught_up=p.caught_up)
            res = analyse(stream, p.probe, segmentation_events(p.probe, stream),
                          estimator_params(overrides))
            est = p.estimator
            stats = {'estimator_update_us_mean': round(est.latency.mean_us, 1),
                     'estimator_update_us_max': round(est.latency.max_us, 1),
                     'estimator_plan_us_mean': round(est.plan_latency.mean_us, 1),
                     'estimator_plan_us_max': round(est.plan_latency.max_us, 1),
                     'lost_poses': len(p.probe.published_stamps) - p.observer.accepted,
                     'estimator_rejected': {k: v for k, v in est.planner.rejected.items() if v},
                     'estimator_uncommitted_interactions': sum(
                         1 for r in est.interactions if r['commit_phase'] is None)}
            return res, stats
        finally:
            p.close()
    finally:
        rclpy.try_shutdown(context=ctx)


# ---------------------------------------------------------------------------- sustained
def run_sustained(domain, model_path, warm, g, rates, overrides):
    """One pipeline; after a warm-up, per rate one interaction (demo ``g`` resampled)."""
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain)
    runs = []
    params = estimator_params(overrides)
    try:
        p = InProcess(ctx, model_path, overrides)
        try:
            time.sleep(0.3)
            p.probe.publish_stream(warm, warm.messages())
            p.probe.wait_quiet(caught_up=p.caught_up)
            next_ns = BASE_NS
            for rate in rates:
                s = Stream(next_ns)
                s.add(*padded_wrist(g, seed=1, rate=rate))
                next_ns = s.end_ns + round(2 * GAP_S * 1e9)
                msgs = s.messages()
                p.probe.trajs.clear()
                p.probe.paths.clear()
                p.probe.pub_times.clear()
                ob, es = p.observer, p.estimator.planner
                acc0, obs0 = ob.accepted, ob.published['observations']
                drop0, rec0 = sum(ob.drop_counts.values()), es.received
                rej0 = sum(es.rejected.values())
                first, last = p.probe.publish_stream(s, msgs)
                n = len(msgs)
                done_at = None
                deadline = time.perf_counter() + 3.0
                while time.perf_counter() < deadline:
                    handled = ob.accepted - acc0 + sum(ob.drop_counts.values()) - drop0
                    if (handled >= n
                            and es.received - rec0 >= ob.published['observations'] - obs0):
                        done_at = time.perf_counter()
                        break
                    time.sleep(0.0005)
                p.probe.wait_quiet(quiet=0.3, timeout=2.0)
                accepted = ob.accepted - acc0
                dropped = sum(ob.drop_counts.values()) - drop0
                published_obs = ob.published['observations'] - obs0
                received = es.received - rec0
                rejected = sum(es.rejected.values()) - rej0
                achieved = (n - 1) / (last - first) if last > first else float('nan')
                drain_ms = None if done_at is None else (done_at - last) * 1e3
                res = analyse(s, p.probe, segmentation_events(p.probe, s), params)
                steady_p99 = ms_stats(res['steady'], 'x')['x_p99']
                ok = (accepted == n and dropped == 0 and received == published_obs
                      and rejected == 0
                      and achieved >= 0.95 * rate and drain_ms is not None
                      and drain_ms <= LAG_BOUND_MS and steady_p99 is not None
                      and steady_p99 <= LAG_BOUND_MS)
                runs.append({'rate_hz': rate, 'published': n, 'achieved_hz': round(achieved, 1),
                             'observer_accepted': accepted, 'observer_dropped': dropped,
                             'lost_poses': n - accepted - dropped,
                             'observations_published': published_obs,
                             'estimator_received': received,
                             'lost_observations': published_obs - received,
                             'estimator_rejected': rejected,
                             'drain_ms': None if drain_ms is None else round(drain_ms, 2),
                             'trajectories': res['n_traj'],
                             'e2e_ms_median': ms_stats(res['lat'], 'x')['x_median'],
                             'e2e_ms_p99_steady': steady_p99,
                             'e2e_ms_max_transient': ms_stats(res['transient'], 'x')['x_max'],
                             'ok': bool(ok)})
                time.sleep(GAP_S)
        finally:
            p.close()
    finally:
        rclpy.try_shutdown(context=ctx)
    best = 0
    for r in runs:
        if not r['ok']:
            break
        best = r['rate_hz']
    return best, runs


# ---------------------------------------------------------------------------- cross-process
def run_cross_process(domain, model_path, warm_demo, stream, logdir, overrides):
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
    procs, logs = [], []
    try:
        for exe, params in (
                ('observer_node', ['--params-file', str(OBSERVER_YAML)]),
                ('estimator_node', ['--params-file', str(ESTIMATOR_YAML),
                                    '-p', f'model_path:={model_path}'] + [
                    x for k, v in overrides.items() for x in ('-p', f'{k}:={v}')])):
            log = open(Path(logdir) / f'{exe}.log', 'w')
            logs.append(log)
            procs.append(subprocess.Popen([str(BIN / exe), '--ros-args', *params], env=env,
                                          stdout=log, stderr=subprocess.STDOUT))
        ctx = Context()
        rclpy.init(context=ctx, domain_id=domain)
        try:
            probe = Probe(diagnostics=True, context=ctx)
            ex, th = spin_in_thread(probe)
            try:
                t0 = time.monotonic()
                # Matched with the probe, the estimator spinning (diagnostics), and the
                # observer -> estimator topic in the graph on both sides.
                while not (probe.pose_pub.get_subscription_count() >= 1
                           and probe.traj_sub.get_publisher_count() >= 1
                           and probe.path_sub.get_publisher_count() >= 1
                           and probe.diagnostics is not None
                           and probe.count_publishers('/observer/wrist') >= 1
                           and probe.count_subscribers('/observer/wrist') >= 1):
                    if time.monotonic() - t0 > 30.0:
                        raise RuntimeError('discovery timed out (30 s)')
                    if any(pr.poll() is not None for pr in procs):
                        raise RuntimeError('a node exited during start-up')
                    time.sleep(0.05)
                discovery_s = time.monotonic() - t0
                # Warm-up replays until one yields a trajectory: then the whole chain
                # (observer -> estimator included) is matched.
                warm_tries = 0
                for k in range(3):
                    warm_tries += 1
                    w = warm_stream(warm_demo, k)
                    probe.publish_stream(w, w.messages())
                    probe.wait_quiet()
                    if any(w.stamps[0] <= r[1] <= w.end_ns for r in probe.trajs):
                        break
                else:
                    raise RuntimeError('no trajectory after 3 warm-up interactions')
                probe.publish_stream(stream, stream.messages())
                probe.wait_quiet(quiet=1.0)
                time.sleep(1.1)    # one more /diagnostics period
                res = analyse(stream, probe, segmentation_events(probe, stream),
                              estimator_params(overrides))
                d = probe.diagnostics or {}
                stats = {'discovery_s': round(discovery_s, 2), 'warm_up_replays': warm_tries,
                         'estimator_update_us_mean_cross_process':
                             float(d.get('update_latency_mean_us', 'nan')),
                         'estimator_update_us_max_cross_process':
                             float(d.get('update_latency_max_us', 'nan')),
                         'estimator_plan_us_max_cross_process':
                             float(d.get('plan_latency_max_us', 'nan')),
                         'estimator_rejected_cross_process': {
                             k[len('rejected_'):]: int(v) for k, v in d.items()
                             if k.startswith('rejected_') and v not in ('', '0')}}
                return res, stats
            finally:
                ex.shutdown(timeout_sec=2.0)
                th.join(timeout=2.0)
                probe.destroy_node()
        finally:
            rclpy.try_shutdown(context=ctx)
    finally:
        for pr in procs:
            if pr.poll() is None:
                pr.send_signal(signal.SIGINT)
        for pr in procs:
            try:
                pr.wait(timeout=5)
            except subprocess.TimeoutExpired:
                pr.kill()
                pr.wait()
        for log in logs:
            log.close()


# ---------------------------------------------------------------------------- main
def pick(lk, suffix, keys):
    return {f'{k}{suffix}': lk[f'{k}{suffix}'] for k in keys}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--demos', type=int, default=4, help='interactions replayed per latency run')
    ap.add_argument('--repeats', type=int, default=3,
                    help='in-process latency runs pooled for the headline numbers')
    ap.add_argument('--rates', default='250,500,1000,2000', help='sustained: mocap rates (Hz)')
    ap.add_argument('--domain-id', type=int, default=None,
                    help='ROS domain id (default: private, from the pid)')
    args = ap.parse_args()
    rates = [float(r) for r in args.rates.split(',')]
    domain = args.domain_id if args.domain_id is not None else 10 + os.getpid() % 80
    t_start = time.monotonic()
    result = {}
    errors = []
    every_pose = LATENCY_OVERRIDES
    with tempfile.TemporaryDirectory(prefix='latency_bench_') as tmp:
        gen = box_assembly(seed=0)
        model_path = Path(tmp) / 'box_model.npz'
        train_to_file([g.to_demonstration(0.01) for g in gen], model_path, n_components=3)
        # Warm-up: the shortest demo; measured: the first demo of each pattern, then more.
        warm_demo = min(gen, key=lambda g: g.duration)
        chosen = [next(g for g in gen if g.label == label and g is not warm_demo)
                  for label in ('plate', 'screw', 'screwdriver')]
        chosen += [g for g in gen if g is not warm_demo and g not in chosen]
        chosen = chosen[:args.demos]
        stream = Stream(BASE_NS)
        for i, g in enumerate(chosen):
            stream.add(*padded_wrist(g, seed=i))
        warm = warm_stream(warm_demo, 0)
        result['replayed'] = [f'{g.name}:{g.label}:{g.duration:.2f}s' for g in chosen]

        # Headline: in-process, one SingleThreadedExecutor per node, every pose replanned;
        # samples pooled over --repeats fresh pipelines (this machine's noise comes in spells
        # that can dominate the tail of one run).
        runs = [run_latency_in_process(domain, model_path, warm, stream, every_pose)
                for _ in range(args.repeats)]
        res, stats = pooled([r for r, _ in runs]), pooled_stats([st for _, st in runs])
        result.update(latency_keys(res, ''))
        result['e2e_ms_p99_per_run'] = [latency_keys(r, '')['e2e_ms_p99'] for r, _ in runs]
        result['e2e_ms_median_per_run'] = [latency_keys(r, '')['e2e_ms_median'] for r, _ in runs]
        result.update(stats)
        result['in_process_executor'] = ('one SingleThreadedExecutor per node (observer, '
                                         'estimator, probe), each spun in its own thread')
        # Deployed replanning (config/estimator.yaml: observations used at most every
        # min_interval, replans at replan_rate_hz): latency of the poses that trigger a replan.
        res, stats = run_latency_in_process(domain, model_path, warm, stream, {})
        lk = latency_keys(res, '_deployed')
        result.update(pick(lk, '_deployed', (
            'e2e_ms_median', 'e2e_ms_p99', 'e2e_ms_max', 'e2e_ms_p99_steady', 'n_samples',
            'n_trajectories', 'n_timer_trajectories', 'n_backlog_trajectories')))
        result['timer_plan_ms_median_deployed'] = ms_stats(res['timer'], 'x')['x_median']
        result['estimator_plan_us_mean_deployed'] = stats['estimator_plan_us_mean']

        try:
            res, stats = run_cross_process(domain, model_path, warm_demo, stream, tmp,
                                           every_pose)
            result.update(latency_keys(res, '_cross_process'))
            result.update(stats)
        except Exception as exc:  # report it, keep the other numbers
            errors.append(f'cross-process: {exc!r}')
            result.update({'e2e_ms_median_cross_process': None, 'e2e_ms_p99_cross_process': None})

        g_sus = next(g for g in chosen if g.label == 'plate')
        best, runs = run_sustained(domain, model_path, warm, g_sus, rates, {})
        result['sustained_hz'] = best
        result['sustained_mode'] = (
            'in-process, one SingleThreadedExecutor per node; config/*.yaml parameters '
            f'(estimator: min_interval {ESTIMATOR_PARAMS["min_interval"]} s, replan_rate_hz '
            f'{ESTIMATOR_PARAMS["replan_rate_hz"]}); one reach of {g_sus.duration:.2f} s '
            f'({g_sus.name}, with rest ~3.6 s) resampled to each rate; pass = no pose or '
            f'observation lost, >= 95 % of the rate published, lag bounded: e2e p99 of the '
            f'poses >= {STEADY_AFTER_S:.0f} s after the onset confirmation <= '
            f'{LAG_BOUND_MS:.0f} ms and everything delivered within {LAG_BOUND_MS:.0f} ms of '
            f'the last pose (the transient after an onset is reported, not judged)')
        result['sustained_runs'] = runs
        best, runs = run_sustained(domain, model_path, warm, g_sus, rates[:3], every_pose)
        result['sustained_hz_replan_every_obs'] = best
        result['sustained_runs_replan_every_obs'] = [
            {k: r[k] for k in ('rate_hz', 'achieved_hz', 'lost_poses', 'lost_observations',
                               'estimator_rejected', 'drain_ms', 'e2e_ms_median',
                               'e2e_ms_p99_steady', 'e2e_ms_max_transient', 'ok')}
            for r in runs]
    result['latency_config'] = {**every_pose, 'n_points': ESTIMATOR_PARAMS['n_points'],
                                'lookahead': ESTIMATOR_PARAMS['lookahead']}
    result['domain_id'] = domain
    result['bench_s'] = round(time.monotonic() - t_start, 1)
    if errors:
        result['errors'] = errors
    print(json.dumps(result))


if __name__ == '__main__':
    main()
