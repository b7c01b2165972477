"""estimator_node over real DDS in-process: observations and events in, trajectory, predicted
path, posterior and diagnostics out, checked against the OnlineEstimator run directly."""

import os
import subprocess
import sys
import time

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped
from nav_msgs.msg import Path
from rosgraph_msgs.msg import Clock
import numpy as np
import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import Float64MultiArray, Header
from trajectory_msgs.msg import JointTrajectory

from mixture_ip_ros.core.mixture import MixtureIProMP
from mixture_ip_ros.core.online import OnlineEstimator
from mixture_ip_ros.io.model_file import load_model, save_model
from mixture_ip_ros.nodes.estimator_node import EstimatorNode
from mixture_ip_ros.app.training import train_to_file
from mixture_ip_ros.robot.description import JOINT_NAMES

from conftest import private_domain_id
from mixture_ip_ros.scenarios.synthetic import mixture_demos

HELD_OUT = (0, 13, 30)
ONSET_NS = 1_000_000_000_000          # observation stamps: onset + t
FRAME = 'iiwa_link_0'
# Timers that never fire during a test: replans and diagnostics are driven by hand.
MANUAL = {'replan_rate_hz': 1e-3, 'diagnostics_period': 1e3, 'replan_on_observation': False}


@pytest.fixture(scope='module')
def trained(tmp_path_factory):
    demos = mixture_demos(seed=0, n_obs=3, n_ctrl=7, n_basis=8)[0]
    path = tmp_path_factory.mktemp('model') / 'model.npz'
    train_to_file([d for i, d in enumerate(demos) if i not in HELD_OUT], path,
                  n_components=3, n_basis=8)
    return path, [demos[i] for i in HELD_OUT]


def _ns(t):
    return int(round(t * 1e9))


def _stamp(ns):
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def _seconds(d):
    return d.sec + d.nanosec * 1e-9


class Harness:
    """The estimator node plus a peer node publishing its inputs and recording its outputs."""

    def __init__(self, ctx, **params):
        overrides = [Parameter(k, value=v) for k, v in params.items()]
        self.node = EstimatorNode(context=ctx, parameter_overrides=overrides)
        self.peer = Node('estimator_test_peer', context=ctx)
        qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        self.obs_pub = self.peer.create_publisher(PointStamped, '/observer/wrist', qos)
        self.event_pub = self.peer.create_publisher(Header, '/observer/event', qos)
        self.got = {'trajectory': [], 'path': [], 'posterior': [], 'diagnostics': []}
        for key, typ, topic in (('trajectory', JointTrajectory, '/iiwa/joint_trajectory'),
                                ('path', Path, '/estimator/predicted_wrist'),
                                ('posterior', Float64MultiArray, '/estimator/posterior'),
                                ('diagnostics', DiagnosticArray, '/diagnostics')):
            self.peer.create_subscription(typ, topic, self.got[key].append, qos)
        self.executor = SingleThreadedExecutor(context=ctx)
        self.executor.add_node(self.node)
        self.executor.add_node(self.peer)
        pubs = [self.obs_pub, self.event_pub, self.node._traj_pub, self.node._path_pub,
                self.node._post_pub, self.node._diag_pub]
        self.spin_until(lambda: all(p.get_subscription_count() > 0 for p in pubs),
                        what='discovery')

    def spin_until(self, predicate, timeout=10.0, what='condition'):
        deadline = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > deadline:
                raise AssertionError(f'timed out waiting for {what}')
            self.executor.spin_once(timeout_sec=0.01)

    def event(self, kind, ns):
        self.event_pub.publish(Header(frame_id=kind, stamp=_stamp(ns)))

    def observation(self, ns, xyz, frame=FRAME):
        msg = PointStamped()
        msg.header.stamp = _stamp(ns)
        msg.header.frame_id = frame
        msg.point.x, msg.point.y, msg.point.z = (float(v) for v in xyz)
        self.obs_pub.publish(msg)

    def feed(self, demo, indices, onset_ns=ONSET_NS):
        n0 = self.node.planner.received
        for i in indices:
            self.observation(onset_ns + _ns(demo.t[i]), demo.observed[i])
        self.spin_until(lambda: self.node.planner.received == n0 + len(indices),
                        what='observations')

    def wait_for(self, key, n):
        self.spin_until(lambda: len(self.got[key]) >= n, what=f'{n} {key} messages')
        return self.got[key][n - 1]

    def close(self):
        self.executor.shutdown()
        self.node.destroy_node()
        self.peer.destroy_node()


@pytest.fixture
def harness(ros_context, trained):
    made = []

    def make(**params):
        h = Harness(ros_context, model_path=str(trained[0]), **params)
        made.append(h)
        return h
    yield make
    for h in made:
        h.close()


def _oracle(model_path, demo, indices):
    model, _ = load_model(model_path)
    est = OnlineEstimator(model)
    for i in indices:
        est.update(_ns(demo.t[i]) * 1e-9, demo.observed[i])
    return est


def test_interaction_commits_then_replans_and_ends_with_a_final_plan(harness, trained):
    model_path, held = trained
    demo = held[1]
    h = harness(**MANUAL)
    assert h.node.state == 'idle'
    h.event('onset', ONSET_NS)
    h.spin_until(lambda: h.node.state == 'observing', what='onset')

    # 2 observations used (< min_observations = 3): posterior and path, no trajectory yet
    h.feed(demo, [0, 5])
    h.node.replan()
    post = h.wait_for('posterior', 1)
    h.wait_for('path', 1)
    oracle = _oracle(model_path, demo, [0, 5])
    assert np.allclose(post.data[:3], oracle.component_posterior(), atol=1e-12)
    assert h.node.state == 'observing' and h.got['trajectory'] == []

    # up to about 40 % of the movement: committed, first trajectory
    n = int(np.searchsorted(demo.t, 0.4 * demo.duration))
    idx = list(range(6, n))
    h.feed(demo, idx)
    h.node.replan()
    traj = h.wait_for('trajectory', 1)
    post = h.wait_for('posterior', 2)
    path = h.wait_for('path', 2)
    oracle = _oracle(model_path, demo, [0, 5] + idx)
    k, alpha = oracle.map_hypothesis()
    t_now = _ns(demo.t[n - 1]) * 1e-9
    p = oracle.component_posterior()

    assert traj.joint_names == list(JOINT_NAMES)
    assert (traj.header.stamp.sec, traj.header.stamp.nanosec) == (ONSET_NS // 10**9, 0)
    assert len(traj.points) == 25
    tfs = np.array([_seconds(pt.time_from_start) for pt in traj.points])
    assert np.all(np.diff(tfs) > 0)
    assert tfs[0] == pytest.approx(t_now + 0.1, abs=2e-9)           # lookahead
    phases = np.linspace(alpha * (t_now + 0.1), 1.0, 25)
    assert np.allclose(tfs, phases / alpha, atol=2e-9)                # z / alpha*
    ref = oracle.predict(phases)['controlled']
    pos = np.array([pt.positions for pt in traj.points])
    vel = np.array([pt.velocities for pt in traj.points])
    acc = np.array([pt.accelerations for pt in traj.points])
    assert np.allclose(pos, ref['position'], atol=1e-12)
    assert np.allclose(vel[:-1], ref['velocity'][:-1], atol=1e-12)
    assert np.allclose(acc[:-1], ref['acceleration'][:-1], atol=1e-12)
    assert not vel[-1].any() and not acc[-1].any()
    assert np.all(np.isfinite(pos)) and np.all(np.isfinite(vel)) and np.all(np.isfinite(acc))

    assert post.layout.dim[0].label == 'p0,p1,p2,alpha,phase,confidence,component'
    assert np.allclose(post.data, list(p) + [alpha, alpha * t_now, p[k], k], atol=1e-12)

    assert path.header.frame_id == FRAME and len(path.poses) == 25
    wrist = np.array([[q.pose.position.x, q.pose.position.y, q.pose.position.z]
                      for q in path.poses])
    z = np.linspace(0, 1, 25)
    assert np.allclose(wrist, oracle.predict(z)['observed']['position'], atol=1e-12)
    stamps = np.array([(q.header.stamp.sec * 10**9 + q.header.stamp.nanosec - ONSET_NS) * 1e-9
                       for q in path.poses])
    assert np.allclose(stamps, z / alpha, atol=2e-9)

    rec = h.node.interactions[-1]
    assert h.node.state == 'committed'
    assert rec['commit_phase'] == pytest.approx(alpha * t_now, abs=1e-12)
    t_commit = t_now
    assert rec['component'] == k and rec['label'] == demo.label
    assert rec['n_observations'] == oracle.n_observations

    # the rest of the movement, then 'end': a last plan at the predicted final posture
    rest = list(range(n, len(demo.t)))
    h.feed(demo, rest)
    h.event('end', ONSET_NS + _ns(demo.t[-1]))
    final = h.wait_for('trajectory', 2)
    h.spin_until(lambda: h.node.state == 'done', what='done')
    oracle = _oracle(model_path, demo, [0, 5] + idx + rest)
    k, alpha = oracle.map_hypothesis()
    assert np.allclose(final.points[-1].positions,
                       oracle.predict_at_rest(demo.observed[-1])[0], atol=1e-12)
    # the held-out demonstration's own final posture (independent of the estimator)
    assert np.abs(np.array(final.points[-1].positions) - demo.controlled[-1]).max() < 0.1
    assert not np.any(final.points[-1].velocities)
    assert _seconds(final.points[-1].time_from_start) >= _ns(demo.t[-1]) * 1e-9
    assert rec['end_reason'] == 'end' and rec['alpha'] == alpha and rec['plans'] == 2
    assert rec['final_component'] == k and rec['final_label'] == demo.label
    assert rec['commit_time'] == pytest.approx(ONSET_NS * 1e-9 + t_commit, abs=1e-6)
    assert rec['n_observations'] == oracle.n_observations
    assert abs(rec['alpha'] - 1 / demo.duration) < 0.1 / demo.duration
    # nothing new after the end: the timer's replan publishes nothing
    h.node.replan()
    h.node.publish_diagnostics()
    h.wait_for('diagnostics', 1)
    assert len(h.got['trajectory']) == 2


def test_timers_replan_and_publish_diagnostics(harness, trained):
    _, held = trained
    demo = held[2]
    h = harness(replan_rate_hz=20.0, diagnostics_period=0.2)
    h.event('onset', ONSET_NS)
    h.feed(demo, list(range(len(demo.t) // 2)))
    traj = h.wait_for('trajectory', 1)
    assert traj.joint_names == list(JOINT_NAMES) and len(traj.points) >= 1
    n = len(demo.t) // 2

    def complete():   # a diagnostics message issued after every observation was handled
        return [d for d in h.got['diagnostics']
                if {kv.key: kv.value for kv in d.status[0].values}['observations_received']
                == str(n)]
    h.spin_until(complete, what='diagnostics')
    values = {kv.key: kv.value for kv in complete()[0].status[0].values}
    assert values['state'] == 'committed'
    assert int(values['observations_used']) == h.node.planner.used
    assert int(values['observations_used']) + int(values['observations_skipped']) == n
    assert float(values['update_latency_max_us']) >= float(values['update_latency_mean_us']) > 0
    assert values['label'] == demo.label
    assert 0 < float(values['commit_phase']) < 1


def test_observations_before_the_onset_event_are_absorbed_in_slices(harness, trained):
    """As the observer sends them: the samples come first, the back-dated onset later. They
    are absorbed a slice per callback; the robot is committed only once all are in, and the
    plan is the oracle's on every observation in time order."""
    model_path, held = trained
    demo = held[1]
    h = harness(**{**MANUAL, 'backlog_budget': 1e-6, 'confidence_threshold': 0.5})
    n = len(demo.t) // 3
    h.feed(demo, list(range(n)))
    assert h.node.planner.n_held == n and h.node.state == 'idle'
    h.event('onset', ONSET_NS)
    h.spin_until(lambda: h.node.state == 'observing', what='onset')
    backlog = h.node.planner.n_backlog
    assert backlog == h.node.interactions[-1]['n_observations'] - 1 > 2  # one slice taken
    assert h.got['trajectory'] == []
    h.feed(demo, list(range(n, n + backlog)))    # each live one brings a slice
    assert h.node.planner.n_backlog == 0 and h.node.state == 'committed'
    first = h.wait_for('trajectory', 1)           # sent when the last slice was absorbed
    assert h.node.interactions[-1]['commit_observations'] == _oracle(
        model_path, demo, range(n + backlog)).n_observations
    assert len(first.points) >= 1
    h.feed(demo, [n + backlog])
    h.node.replan()
    traj = h.wait_for('trajectory', 2)
    oracle = _oracle(model_path, demo, range(n + backlog + 1))
    _, alpha = oracle.map_hypothesis()
    phases = np.array([_seconds(pt.time_from_start) for pt in traj.points]) * alpha
    assert np.allclose([pt.positions for pt in traj.points],
                       oracle.predict(phases)['controlled']['position'], atol=1e-9)


def test_bad_input_is_counted_and_the_node_keeps_working(harness, trained):
    model_path, held = trained
    demo = held[0]
    h = harness(**MANUAL)
    h.observation(ONSET_NS - _ns(1.0), demo.observed[0])           # held, rest before the onset
    h.spin_until(lambda: h.node.planner.received == 1, what='stray observation')
    h.event('onset', ONSET_NS)
    h.spin_until(lambda: h.node.state == 'observing', what='onset')
    h.observation(ONSET_NS + _ns(0.01), demo.observed[1], frame='world')      # wrong frame
    h.observation(ONSET_NS + _ns(0.02), [np.nan, 0.0, 0.0])                   # NaN
    h.observation(ONSET_NS - _ns(0.5), demo.observed[0])                       # before onset
    h.spin_until(lambda: h.node.planner.received == 4, what='bad observations')
    idx = list(range(0, 40))
    h.feed(demo, idx)
    h.observation(ONSET_NS + _ns(demo.t[10]), demo.observed[10])               # time backwards
    h.event('bogus', ONSET_NS)
    h.spin_until(lambda: h.node.planner.received == 45 and h.node.events['unknown'] == 1,
                 what='late observation')
    rec = h.node.interactions[-1]
    assert (rec['n_received'], rec['n_rejected']) == (44, 4)
    assert h.node.planner.rejected == {
        'wrong_frame': 1, 'non_finite': 1, 'before_onset': 1, 'time_backwards': 1,
        'exception': 0, 'bad_joint_state': 0}
    h.node.replan()
    traj = h.wait_for('trajectory', 1)
    oracle = _oracle(model_path, demo, idx)
    _, alpha = oracle.map_hypothesis()
    phases = np.array([_seconds(pt.time_from_start) for pt in traj.points]) * alpha
    assert np.allclose([pt.positions for pt in traj.points],
                       oracle.predict(phases)['controlled']['position'], atol=1e-9)
    h.node.publish_diagnostics()
    diag = h.wait_for('diagnostics', 1)
    st = diag.status[0]
    values = {kv.key: kv.value for kv in st.values}
    assert st.level == st.WARN and values['rejected_wrong_frame'] == '1'
    assert values['rejected_time_backwards'] == '1' and values['rejected_non_finite'] == '1'
    h.node.publish_diagnostics()                      # nothing new rejected since: OK again
    st = h.wait_for('diagnostics', 2).status[0]
    assert st.level == st.OK and {kv.key: kv.value for kv in st.values}[
        'rejected_wrong_frame'] == '1'


def test_replanning_runs_on_the_node_clock_with_sim_time(harness, trained):
    _, held = trained
    demo = held[1]
    h = harness(use_sim_time=True, replan_rate_hz=10.0, diagnostics_period=1e3,
                replan_on_observation=False)
    clock_pub = h.peer.create_publisher(Clock, '/clock', 10)
    h.spin_until(lambda: clock_pub.get_subscription_count() > 0, what='/clock discovery')
    h.event('onset', ONSET_NS)
    h.feed(demo, list(range(30)))
    # simulated time stands still (no /clock yet): the replan timer does not fire
    end = time.monotonic() + 0.3
    while time.monotonic() < end:
        h.executor.spin_once(timeout_sec=0.01)
    assert h.got['trajectory'] == [] and h.got['posterior'] == []
    sim_ns = [5 * 10**9]

    def tick():
        sim_ns[0] += 10_000_000
        clock_pub.publish(Clock(clock=_stamp(sim_ns[0])))
        return len(h.got['trajectory']) > 0
    h.spin_until(tick, what='a trajectory after simulated time advanced')
    assert h.node.get_clock().now().nanoseconds >= 5 * 10**9
    assert h.got['trajectory'][0].header.stamp == _stamp(ONSET_NS)   # stamps from the messages


def _refusal(ctx, match, **params):
    overrides = [Parameter(k, value=v) for k, v in params.items()]
    with pytest.raises(ValueError, match=match):
        EstimatorNode(context=ctx, parameter_overrides=overrides)


def test_refuses_to_start_without_a_usable_model(ros_context, trained, tmp_path):
    model_path, _ = trained
    _refusal(ros_context, 'model_path is empty')
    _refusal(ros_context, 'does not exist', model_path=str(tmp_path / 'missing.npz'))
    corrupt = tmp_path / 'corrupt.npz'
    corrupt.write_bytes(b'PK\x03\x04 this is not a model')
    _refusal(ros_context, f'{corrupt}.*not a readable', model_path=str(corrupt))
    _refusal(ros_context, 'controlled_names .* do not match', model_path=str(model_path),
             joint_names=[f'lbr_joint_{i}' for i in range(1, 8)])
    _refusal(ros_context, "frame 'iiwa_link_0'.*'world'", model_path=str(model_path),
             observed_frame='world')
    _refusal(ros_context, 'confidence_threshold', model_path=str(model_path),
             confidence_threshold=1.5)
    # a model whose observed agent is not a 3-D point
    demos = mixture_demos(seed=3, n_obs=2, n_ctrl=7, n_basis=8)[0]
    two_d = save_model(tmp_path / 'planar.npz', MixtureIProMP(3, n_basis=8).fit(demos),
                       observed_names=['x', 'y'], controlled_names=JOINT_NAMES)
    _refusal(ros_context, '2 DOFs', model_path=str(two_d))


def test_main_exits_non_zero_with_a_message_and_no_traceback(tmp_path):
    env = dict(os.environ, ROS_DOMAIN_ID=str(private_domain_id()))
    proc = subprocess.run(
        [sys.executable, '-m', 'mixture_ip_ros.nodes.estimator_node', '--ros-args',
         '-p', f'model_path:={tmp_path / "missing.npz"}'],
        capture_output=True, text=True, timeout=60, env=env)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 1
    assert 'refusing to start' in out and 'missing.npz: does not exist' in out
    assert 'Traceback' not in out


def test_config_file_declares_the_defaults(ros_context, trained):
    """config/estimator.yaml loads as a params file and documents exactly the defaults."""
    import yaml
    from mixture_ip_ros.core.share import config_path
    path = config_path('estimator.yaml')
    values = yaml.safe_load(path.read_text())['estimator_node']['ros__parameters']
    assert values['model_path'] == ''
    model = Parameter('model_path', value=str(trained[0]))

    def parameters(**kwargs):
        node = EstimatorNode(context=ros_context, parameter_overrides=[model], **kwargs)
        try:
            names = set(node.list_parameters([], 0).names) - {
                'use_sim_time', 'start_type_description_service', 'model_path'}
            return {n: node.get_parameter(n).value for n in names}
        finally:
            node.destroy_node()
    from_file = parameters(cli_args=['--ros-args', '--params-file', str(path)])
    defaults = parameters()
    expected = {k: v for k, v in values.items() if k != 'model_path'}
    # Not written in the file: the robot's description gives them (the file says so).
    from mixture_ip_ros.robot.kinematics import RobotKinematics
    robot = RobotKinematics(values['robot'])
    derived = {'joint_names': list(robot.joint_names),
               'observed_frame': robot.description.base_frame,
               'catch_up_velocity': (0.5 * robot.velocity_limit).tolist()}
    assert set(defaults) == set(expected) | set(derived)
    for name, value in {**expected, **derived}.items():
        for got in (from_file[name], defaults[name]):
            assert (list(got) if isinstance(value, list) else got) == value, name


def test_observations_trigger_replans_at_the_configured_rate(harness, trained):
    """With replan_on_observation, a used observation replans at once, at most every
    1/replan_rate_hz on the stamps' clock."""
    _, held = trained
    demo = held[2]
    h = harness(replan_rate_hz=5.0, diagnostics_period=1e3)
    h.event('onset', ONSET_NS)
    n = int(np.searchsorted(demo.t, 0.6 * demo.duration))
    for i in range(n):            # at the recorded pace: replans are also limited on the wall clock
        h.feed(demo, [i])
        end = time.monotonic() + 0.01
        while time.monotonic() < end:
            h.executor.spin_once(timeout_sec=0.002)
    h.spin_until(lambda: len(h.got['posterior']) >= int(demo.t[n - 1] / 0.2) - 1, what='replans')
    assert h.got['trajectory'], 'no trajectory from observation-triggered replans'
    # The timer only covers pauses: it does not double the replans while observations flow
    # (it did, before it skipped periods in which an observation had replanned).
    assert len(h.got['posterior']) <= int(demo.t[n - 1] / 0.2) + 2
