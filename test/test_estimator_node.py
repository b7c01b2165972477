"""estimator_node over real DDS in-process: observations and events in, trajectory, predicted
path, posterior, markers and diagnostics out, checked against the OnlineEstimator run directly;
its lifecycle, its parameters and its services."""

import os
import re
import subprocess
import sys

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped
from lifecycle_msgs.srv import GetState
from nav_msgs.msg import Path
import numpy as np
import pytest
from rcl_interfaces.msg import ParameterType
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, Header
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

from conftest import private_domain_id
from ros_harness import time_msg
from mixture_ip_ros.app.training import train_to_file
from mixture_ip_ros.core.mixture import MixtureIProMP
from mixture_ip_ros.core.online import OnlineEstimator
from mixture_ip_ros.core.stamps import stamp_to_ns
from mixture_ip_ros.io.model_file import load_model, save_model
from mixture_ip_ros.nodes.estimator_node import EstimatorNode
from mixture_ip_ros.nodes.lifecycle_client import LifecycleClient
from mixture_ip_ros.robot.description import JOINT_NAMES
from mixture_ip_ros.scenarios.synthetic import mixture_demos

HELD_OUT = (0, 13, 30)
ONSET_NS = 1_000_000_000_000          # observation stamps: onset + t
FRAME = 'iiwa_link_0'
# Timers that never fire during a test: replans and diagnostics are driven by hand.
# Replans by hand; trajectories are whole plans (horizon 0), checked against the estimator
# (test_a_trajectory_follows_the_plan_to_its_horizon_then_stops checks the cut).
MANUAL = {'replan_rate_hz': 0.01, 'diagnostics_period': 3600.0, 'replan_on_observation': False,
          'horizon': 0.0}
OUTPUTS = {'trajectory': (JointTrajectory, '/joint_trajectory'),
           'path': (Path, '/estimator/predicted_wrist'),
           'posterior': (Float64MultiArray, '/estimator/posterior'),
           'markers': (MarkerArray, '/estimator/markers'),
           'diagnostics': (DiagnosticArray, '/diagnostics')}


@pytest.fixture(scope='module')
def trained(tmp_path_factory):
    demos = mixture_demos(seed=0, n_obs=3, n_ctrl=7, n_basis=8)[0]
    path = tmp_path_factory.mktemp('model') / 'model.npz'
    train_to_file([d for i, d in enumerate(demos) if i not in HELD_OUT], path,
                  n_components=3, n_basis=8)
    return path, [demos[i] for i in HELD_OUT]


def _ns(t):
    return int(round(t * 1e9))


def _seconds(d):
    return stamp_to_ns(d) * 1e-9


class Estimator:
    """The node in the harness, with publishers of its inputs and recorders of its outputs."""

    def __init__(self, harness, model_path, start=True, **params):
        params.setdefault('max_clock_offset', 0.0)   # ONSET_NS is not the node's clock
        overrides = [Parameter(k, value=v) for k, v in {'model_path': str(model_path),
                                                         **params}.items()]
        self.h = harness
        self.node = harness.add(EstimatorNode(context=harness.context,
                                              parameter_overrides=overrides), start=start)
        self.obs_pub = harness.publisher(PointStamped, '/observer/wrist')
        self.event_pub = harness.publisher(Header, '/observer/event')
        self.got = {key: harness.subscribe(*typ_topic) for key, typ_topic in OUTPUTS.items()}
        if start:
            self.discover()

    def discover(self):
        n = self.node
        self.h.matched(self.obs_pub, self.event_pub, n.trajectory_pub, n.path_pub, n.posterior_pub,
                       n.diagnostics_pub, n.marker_pub)

    def event(self, kind, ns):
        self.event_pub.publish(Header(frame_id=kind, stamp=time_msg(ns)))

    def observation(self, ns, xyz, frame=FRAME):
        msg = PointStamped()
        msg.header.stamp = time_msg(ns)
        msg.header.frame_id = frame
        msg.point.x, msg.point.y, msg.point.z = (float(v) for v in xyz)
        self.obs_pub.publish(msg)

    def feed(self, demo, indices, onset_ns=ONSET_NS, clock=False):
        """Publish the demo's observations ``indices`` and spin until the node received them;
        with ``clock``, /clock follows the stamps (each observation is handled at its own
        simulated time)."""
        counts = self.node.planner.counts
        target = counts.received + len(indices)
        for i in indices:
            ns = onset_ns + _ns(demo.t[i])
            if clock:
                self.h.set_clock(ns)
            n0 = counts.received
            self.observation(ns, demo.observed[i])
            if clock:
                self.h.spin_until(lambda: counts.received > n0, what='the observation')
        self.h.spin_until(lambda: counts.received >= target, what='observations')

    def wait_for(self, key, n):
        self.h.spin_until(lambda: len(self.got[key]) >= n, what=f'{n} {key} messages')
        return self.got[key][n - 1]


@pytest.fixture
def estimator(harness, trained):
    def make(**params):
        return Estimator(harness, trained[0], **params)
    return make


def _oracle(model_path, demo, indices):
    model, _ = load_model(model_path)
    est = OnlineEstimator(model)
    for i in indices:
        est.update(_ns(demo.t[i]) * 1e-9, demo.observed[i])
    return est


def _absolute_times(traj):
    """header.stamp + time_from_start of every point, s since the onset."""
    base = stamp_to_ns(traj.header.stamp)
    return np.array([(base + stamp_to_ns(pt.time_from_start) - ONSET_NS) * 1e-9
                     for pt in traj.points])


def test_interaction_commits_then_replans_and_ends_with_a_final_plan(estimator, trained):
    model_path, held = trained
    demo = held[1]
    e = estimator(**MANUAL)
    assert e.node.state == 'idle'
    e.event('onset', ONSET_NS)
    e.h.spin_until(lambda: e.node.state == 'observing', what='onset')

    # 2 observations used (< min_observations = 3): posterior and path, no trajectory yet
    e.feed(demo, [0, 5])
    e.node.replan()
    post = e.wait_for('posterior', 1)
    e.wait_for('path', 1)
    oracle = _oracle(model_path, demo, [0, 5])
    assert np.allclose(post.data[:3], oracle.component_posterior(), atol=1e-12)
    assert e.node.state == 'observing' and e.got['trajectory'] == []

    # up to about 40 % of the movement: committed, first trajectory
    n = int(np.searchsorted(demo.t, 0.4 * demo.duration))
    idx = list(range(6, n))
    e.feed(demo, idx)
    e.node.replan()
    traj = e.wait_for('trajectory', 1)
    post = e.wait_for('posterior', 2)
    path = e.wait_for('path', 2)
    oracle = _oracle(model_path, demo, [0, 5] + idx)
    k, alpha = oracle.map_hypothesis()
    t_now = _ns(demo.t[n - 1]) * 1e-9
    p = oracle.component_posterior()

    assert traj.joint_names == list(JOINT_NAMES)
    # stamped with what triggered it: the latest observation's stamp
    assert stamp_to_ns(traj.header.stamp) == ONSET_NS + _ns(demo.t[n - 1])
    assert len(traj.points) == 25
    tfs = _absolute_times(traj)
    assert np.all(np.diff(tfs) > 0)
    assert tfs[0] == pytest.approx(t_now + 0.1, abs=2e-9)           # lookahead
    # to the end of the slowest phase speed that holds the posterior, the speed marginalised
    t_end = 1.0 / oracle.alphas[oracle.speed_hypotheses()[0]].min()
    assert np.allclose(tfs, np.linspace(t_now + 0.1, t_end, 25), atol=2e-9)
    _, *ref = oracle.expected_controlled(tfs)
    pos = np.array([pt.positions for pt in traj.points])
    vel = np.array([pt.velocities for pt in traj.points])
    acc = np.array([pt.accelerations for pt in traj.points])
    assert np.allclose(pos, ref[0], atol=1e-9)
    assert np.allclose(vel[:-1], ref[1][:-1], atol=1e-9)
    assert np.allclose(acc[:-1], ref[2][:-1], atol=1e-9)
    assert not vel[-1].any() and not acc[-1].any()
    assert np.all(np.isfinite(pos)) and np.all(np.isfinite(vel)) and np.all(np.isfinite(acc))

    assert post.layout.dim[0].label == 'p0,p1,p2,alpha,phase,confidence,component'
    assert np.allclose(post.data, list(p) + [alpha, alpha * t_now, p[k], k], atol=1e-12)

    assert path.header.frame_id == FRAME and len(path.poses) == 25
    wrist = np.array([[q.pose.position.x, q.pose.position.y, q.pose.position.z]
                      for q in path.poses])
    z = np.linspace(0, 1, 25)
    assert np.allclose(wrist, oracle.predict(z)['observed']['position'], atol=1e-12)
    stamps = np.array([(stamp_to_ns(q.header.stamp) - ONSET_NS) * 1e-9 for q in path.poses])
    assert np.allclose(stamps, z / alpha, atol=2e-9)

    rec = e.node.interactions[-1]
    assert e.node.state == 'committed'
    assert rec.commit_phase == pytest.approx(alpha * t_now, abs=1e-12)
    t_commit = t_now
    assert rec.component == k and rec.label == demo.label
    assert rec.n_observations == oracle.n_observations

    # the rest of the movement, then 'end': a last plan at the predicted final posture
    rest = list(range(n, len(demo.t)))
    e.feed(demo, rest)
    e.event('end', ONSET_NS + _ns(demo.t[-1]))
    final = e.wait_for('trajectory', 2)
    e.h.spin_until(lambda: e.node.state == 'done', what='done')
    assert stamp_to_ns(final.header.stamp) == ONSET_NS + _ns(demo.t[-1])   # the 'end' event
    oracle = _oracle(model_path, demo, [0, 5] + idx + rest)
    # With the end known the phase is too: the component of p(k | D, T), alpha = 1 / T.
    t_end = _ns(demo.t[-1]) * 1e-9
    k, alpha = int(np.argmax(oracle.end_posterior(t_end))), 1.0 / t_end
    assert np.allclose(final.points[-1].positions,
                       oracle.predict_at_rest(demo.observed[-1], component=k)[0], atol=1e-12)
    # the held-out demonstration's own final posture (independent of the estimator)
    assert np.abs(np.array(final.points[-1].positions) - demo.controlled[-1]).max() < 0.1
    assert not np.any(final.points[-1].velocities)
    assert _absolute_times(final)[-1] >= _ns(demo.t[-1]) * 1e-9
    assert rec.end_reason == 'end' and rec.alpha == alpha and rec.plans == 2
    assert rec.final_component == k and rec.final_label == demo.label
    assert rec.commit_time == pytest.approx(ONSET_NS * 1e-9 + t_commit, abs=1e-6)
    assert rec.n_observations == oracle.n_observations
    assert abs(rec.alpha - 1 / demo.duration) < 0.1 / demo.duration
    # nothing new after the end: a replan publishes nothing
    e.node.replan()
    e.node.publish_diagnostics()
    e.wait_for('diagnostics', 1)
    assert len(e.got['trajectory']) == 2


def test_a_trajectory_follows_the_plan_to_its_horizon_then_stops(estimator, trained):
    model_path, held = trained
    demo = held[1]
    e = estimator(**{**MANUAL, 'horizon': 0.3})
    e.event('onset', ONSET_NS)
    n = int(np.searchsorted(demo.t, 0.4 * demo.duration))
    e.feed(demo, list(range(n)))
    e.node.replan()
    traj = e.wait_for('trajectory', 1)
    oracle = _oracle(model_path, demo, range(n))
    t_now = _ns(demo.t[n - 1]) * 1e-9
    tfs = _absolute_times(traj)
    pos = np.array([pt.positions for pt in traj.points])
    vel = np.array([pt.velocities for pt in traj.points])
    t_end = 1.0 / oracle.alphas[oracle.speed_hypotheses()[0]].min()
    whole = np.linspace(t_now + 0.1, t_end, 25)
    before = whole[whole < t_now + 0.3]
    # the plan's own points up to the horizon, its state there, then at rest
    assert len(traj.points) == len(before) + 2
    assert np.allclose(tfs[:-1], np.r_[before, t_now + 0.3], atol=2e-9)
    assert np.allclose(pos[:len(before)], oracle.expected_controlled(before)[1], atol=1e-9)
    assert np.abs(vel[-2]).max() > 0.0 and not vel[-1].any()
    assert tfs[-1] < t_now + 0.3 + 0.5
    assert e.node.planner.counts.plans_uncut == 0


def test_markers_show_every_component_and_the_planned_hand(estimator, trained):
    from mixture_ip_ros.robot.kinematics import RobotKinematics
    model_path, held = trained
    demo = held[1]
    e = estimator(**MANUAL, marker_rate_hz=1000.0)
    e.event('onset', ONSET_NS)
    e.feed(demo, list(range(int(0.5 * len(demo.t)))))
    e.node.replan()
    traj = e.wait_for('trajectory', 1)
    markers = e.wait_for('markers', 1).markers
    oracle = _oracle(model_path, demo, range(int(0.5 * len(demo.t))))
    p = oracle.component_posterior()
    wrist = sorted((m for m in markers if m.ns == 'predicted_wrist'), key=lambda m: m.id)
    assert [m.id for m in wrist] == [0, 1, 2]
    assert all(m.header.frame_id == FRAME for m in markers)
    for m in wrist:                       # opacity = probability (never quite invisible)
        assert m.color.a == pytest.approx(max(0.1, p[m.id]), abs=1e-6)
        assert len(m.points) == 25
    k = int(np.argmax(p))
    joint = oracle.joint_posterior()
    alpha = oracle.alphas[np.argmax(joint[k])]
    expected = oracle.predict(np.linspace(0, 1, 25), component=k, alpha=alpha)['observed']
    got = np.array([[q.x, q.y, q.z] for q in wrist[k].points])
    assert np.allclose(got, expected['position'], atol=1e-9)
    hand = [m for m in markers if m.ns == 'planned_hand'][0]
    q = np.array([pt.positions for pt in traj.points])
    np.testing.assert_allclose([[v.x, v.y, v.z] for v in hand.points],
                               RobotKinematics().fk_positions(q), atol=1e-9)


def test_timers_replan_and_publish_diagnostics(estimator, trained):
    _, held = trained
    demo = held[2]
    e = estimator(replan_rate_hz=20.0, diagnostics_period=0.2)
    e.event('onset', ONSET_NS)
    e.feed(demo, list(range(len(demo.t) // 2)))
    traj = e.wait_for('trajectory', 1)
    assert traj.joint_names == list(JOINT_NAMES) and len(traj.points) >= 1
    n = len(demo.t) // 2

    def complete():   # a diagnostics message issued after every observation was handled
        return [d for d in e.got['diagnostics']
                if {kv.key: kv.value for kv in d.status[0].values}['observations_received']
                == str(n)]
    e.h.spin_until(complete, what='diagnostics')
    values = {kv.key: kv.value for kv in complete()[0].status[0].values}
    assert values['state'] == 'committed'
    assert int(values['observations_used']) == e.node.planner.counts.used
    assert int(values['observations_used']) + int(values['observations_skipped']) == n
    assert float(values['update_latency_max_us']) >= float(values['update_latency_mean_us']) > 0
    assert values['label'] == demo.label
    assert 0 < float(values['commit_phase']) < 1


def test_observations_before_the_onset_event_are_absorbed_in_slices(estimator, trained):
    """As the observer sends them: the samples come first, the back-dated onset later. They
    are absorbed a slice per callback; the robot is committed only once all are in, and the
    plan is the oracle's on every observation in time order."""
    model_path, held = trained
    demo = held[1]
    e = estimator(**{**MANUAL, 'backlog_slice': 1, 'confidence_threshold': 0.5})
    n = len(demo.t) // 3
    e.feed(demo, list(range(n)))
    assert e.node.planner.n_held == n and e.node.state == 'idle'
    e.event('onset', ONSET_NS)
    e.h.spin_until(lambda: e.node.state == 'observing', what='onset')
    backlog = e.node.planner.n_backlog
    assert backlog == e.node.interactions[-1].n_observations - 1 > 2   # one slice taken
    assert e.got['trajectory'] == []
    e.feed(demo, list(range(n, n + backlog)))    # each live one brings a slice
    assert e.node.planner.n_backlog == 0 and e.node.state == 'committed'
    first = e.wait_for('trajectory', 1)           # sent when the last slice was absorbed
    assert e.node.interactions[-1].commit_observations == _oracle(
        model_path, demo, range(n + backlog)).n_observations
    assert len(first.points) >= 1
    e.feed(demo, [n + backlog])
    e.node.replan()
    traj = e.wait_for('trajectory', 2)
    oracle = _oracle(model_path, demo, range(n + backlog + 1))
    assert np.allclose([pt.positions for pt in traj.points],
                       oracle.expected_controlled(_absolute_times(traj))[1], atol=1e-9)


def test_bad_input_is_counted_and_the_node_keeps_working(estimator, trained):
    model_path, held = trained
    demo = held[0]
    e = estimator(**MANUAL)
    counts = e.node.planner.counts
    e.observation(ONSET_NS - _ns(1.0), demo.observed[0])           # held, rest before the onset
    e.h.spin_until(lambda: counts.received == 1, what='stray observation')
    e.event('onset', ONSET_NS)
    e.h.spin_until(lambda: e.node.state == 'observing', what='onset')
    e.observation(ONSET_NS + _ns(0.01), demo.observed[1], frame='world')      # wrong frame
    e.observation(ONSET_NS + _ns(0.02), [np.nan, 0.0, 0.0])                   # NaN
    e.observation(ONSET_NS - _ns(0.5), demo.observed[0])                       # before onset
    e.h.spin_until(lambda: counts.received == 4, what='bad observations')
    idx = list(range(0, 40))
    e.feed(demo, idx)
    e.observation(ONSET_NS + _ns(demo.t[10]), demo.observed[10])               # time backwards
    e.event('bogus', ONSET_NS)
    e.h.spin_until(lambda: counts.received == 45 and e.node.events['unknown'] == 1,
                   what='late observation')
    rec = e.node.interactions[-1]
    assert (rec.n_received, rec.n_rejected) == (44, 4)
    assert counts.rejected == {
        'wrong_frame': 1, 'non_finite': 1, 'before_onset': 1, 'time_backwards': 1,
        'exception': 0, 'bad_joint_state': 0}
    e.node.replan()
    traj = e.wait_for('trajectory', 1)
    oracle = _oracle(model_path, demo, idx)
    assert np.allclose([pt.positions for pt in traj.points],
                       oracle.expected_controlled(_absolute_times(traj))[1], atol=1e-9)
    e.node.publish_diagnostics()
    diag = e.wait_for('diagnostics', 1)
    st = diag.status[0]
    values = {kv.key: kv.value for kv in st.values}
    assert st.level == st.WARN and values['rejected_wrong_frame'] == '1'
    assert values['rejected_time_backwards'] == '1' and values['rejected_non_finite'] == '1'
    e.node.publish_diagnostics()                      # nothing new rejected since: OK again
    st = e.wait_for('diagnostics', 2).status[0]
    assert st.level == st.OK and {kv.key: kv.value for kv in st.values}[
        'rejected_wrong_frame'] == '1'


def test_joint_states_set_the_arm_state_and_bad_ones_are_counted_not_taken(estimator):
    e = estimator(**MANUAL)
    planner, pub = e.node.planner, e.h.publisher(JointState, '/joint_states')
    e.h.matched(pub)
    q = np.linspace(-0.3, 0.3, len(JOINT_NAMES))

    def send(names, position, velocity, then):
        pub.publish(JointState(name=list(names), position=[float(x) for x in position],
                               velocity=[float(x) for x in velocity]))
        e.h.spin_until(then, what='the joint state handled')

    def rejected():
        return planner.counts.rejected['bad_joint_state']
    # an extra joint and another order: each joint is taken by its name
    names = ['gripper'] + list(JOINT_NAMES)[::-1]
    send(names, np.r_[0.04, q[::-1]], np.r_[0.0, 2 * q[::-1]],
         lambda: planner.robot_state is not None)
    assert np.array_equal(planner.robot_state[0], q)
    assert np.array_equal(planner.robot_state[1], 2 * q)
    good = planner.robot_state
    bad = [(JOINT_NAMES, q, 2 * q[:-1]),                  # speeds that do not match the names
           (JOINT_NAMES, q, np.r_[np.nan, q[1:]]),        # a speed not finite
           (JOINT_NAMES, np.r_[q[:-1], np.inf], q),       # a position not finite
           (JOINT_NAMES[:-1], q[:-1], q[:-1])]            # a joint missing
    for n, (names, position, velocity) in enumerate(bad, start=1):
        send(names, position, velocity, lambda: rejected() == n)
        assert planner.robot_state is good
    send(JOINT_NAMES, q, [], lambda: planner.robot_state is not good)    # no speeds: at rest
    assert np.array_equal(planner.robot_state[1], np.zeros(len(q)))
    assert rejected() == 4


def test_replans_follow_simulated_time(estimator, trained):
    """On simulated time the replan rule is deterministic: observations handled at their own
    simulated times replan once per period (on stamps and clock alike), and nothing is
    replanned before the clock runs."""
    _, held = trained
    demo = held[2]
    e = estimator(use_sim_time=True, replan_rate_hz=5.0, diagnostics_period=3600.0)
    e.event('onset', ONSET_NS)
    e.feed(demo, list(range(10)))                 # no /clock yet: the node clock reads zero
    assert e.node.get_clock().now().nanoseconds == 0
    first = len(e.got['posterior'])               # at most the first observation's replan
    n = int(np.searchsorted(demo.t, 0.8 * demo.duration))
    e.feed(demo, list(range(10, n)), clock=True)
    e.h.spin_until(lambda: e.node.planner.counts.received == n, what='observations')
    span = demo.t[n - 1] - demo.t[10]
    replans = len(e.got['posterior']) - first
    assert int(span / 0.2) - 1 <= replans <= int(span / 0.2) + 2
    assert e.got['trajectory'], 'no trajectory from observation-triggered replans'
    times = [stamp_to_ns(t.header.stamp) for t in e.got['trajectory']]
    assert all(b - a >= _ns(0.19) for a, b in zip(times, times[1:]))


def test_run_time_parameters_change_behaviour_and_the_rest_is_read_only(estimator, trained):
    """`ros2 param set` (the SetParameters service): a valid run-time setting takes effect, a
    read-only one and an invalid value are refused with the reason."""
    _, held = trained
    demo = held[1]
    e = estimator(**MANUAL)
    client = AsyncParameterClient(e.h.probe, 'estimator_node')
    e.h.spin_until(lambda: client.services_are_ready(), what='parameter services')

    def set_(**values):
        future = client.set_parameters([Parameter(k, value=v) for k, v in values.items()])
        return e.h.result(future).results

    assert set_(min_observations=100_000, n_points=7)[0].successful
    assert e.node.planner.settings.min_observations == 100_000
    e.event('onset', ONSET_NS)
    e.feed(demo, list(range(len(demo.t) // 2)))
    e.node.replan()
    e.wait_for('posterior', 1)
    assert e.node.state == 'observing'          # too few observations: not committed
    assert set_(min_observations=3, confidence_threshold=0.5)[0].successful
    e.feed(demo, [len(demo.t) // 2])
    e.node.replan()
    traj = e.wait_for('trajectory', 1)
    assert e.node.state == 'committed' and len(traj.points) == 7
    refused = {
        'model_path': set_(model_path='/elsewhere.npz')[0],
        'range': set_(confidence_threshold=1.5)[0],
        'nan': set_(n_points=1)[0],
        'type': set_(replan_rate_hz='fast')[0],
    }
    assert 'read-only' in refused['model_path'].reason
    assert not any(r.successful for r in refused.values())
    assert e.node.params.confidence_threshold == 0.5 and e.node.params.n_points == 7


def test_lifecycle_services_and_parameter_descriptions(estimator, trained):
    e = estimator(start=False, **MANUAL)
    h = e.h
    lifecycle = LifecycleClient(h.probe, 'estimator_node')
    state = h.probe.create_client(GetState, '/estimator_node/get_state')
    h.spin_until(lambda: state.service_is_ready(), what='get_state')
    assert h.result(lifecycle.state_async()).current_state.label == 'unconfigured'
    assert h.result(lifecycle.change_async('configure')).success
    assert h.result(lifecycle.change_async('activate')).success
    assert e.node.lifecycle_state == 'active'
    e.discover()
    client = AsyncParameterClient(h.probe, 'estimator_node')
    h.spin_until(lambda: client.services_are_ready(), what='parameter services')
    described = {d.name: d for d in h.result(client.describe_parameters(
        ['confidence_threshold', 'n_alpha', 'model_path', 'settle_time'])).descriptors}
    ct = described['confidence_threshold']
    assert ct.type == ParameterType.PARAMETER_DOUBLE and not ct.read_only
    assert (ct.floating_point_range[0].from_value, ct.floating_point_range[0].to_value) == (0, 1)
    assert 'p(k* | D)' in ct.description
    assert described['n_alpha'].read_only and described['n_alpha'].integer_range[0].from_value == 1
    assert described['model_path'].read_only and described['model_path'].description
    assert '> 0' in described['settle_time'].description

    # deactivate mid-interaction: the controller is told to stop (an empty trajectory), no
    # plan goes out any more, and the interaction ends
    demo = trained[1][1]
    e.event('onset', ONSET_NS)
    e.feed(demo, list(range(len(demo.t) // 2)))
    e.node.replan()
    e.wait_for('trajectory', 1)
    assert h.result(lifecycle.change_async('deactivate')).success
    stop = e.wait_for('trajectory', 2)
    assert stop.points == [] and stop.joint_names == list(JOINT_NAMES)
    assert e.node.interactions[-1].end_reason == 'deactivated' and e.node.state == 'done'
    # inactive: no longer subscribed, and the trajectory publisher is off
    h.spin_until(lambda: h.probe.count_subscribers('/observer/wrist') == 0,
                 what='the subscription gone')
    assert not e.node.trajectory_pub.is_activated
    assert h.result(lifecycle.change_async('activate')).success
    assert h.result(lifecycle.change_async('deactivate')).success
    assert h.result(lifecycle.change_async('cleanup')).success
    assert e.node.planner is None and e.node.lifecycle_state == 'unconfigured'


def _refusal(harness, match, **params):
    overrides = [Parameter(k, value=v) for k, v in params.items()]
    node = harness.add(EstimatorNode(context=harness.context, parameter_overrides=overrides),
                       start=False)
    assert node.trigger_configure() == TransitionCallbackReturn.FAILURE
    assert node.lifecycle_state == 'unconfigured'
    assert node.refusal is not None
    assert re.search(match, node.refusal), node.refusal


def test_refuses_to_configure_without_a_usable_model(harness, trained, tmp_path):
    model_path, _ = trained
    _refusal(harness, 'model_path is empty')
    _refusal(harness, 'does not exist', model_path=str(tmp_path / 'missing.npz'))
    corrupt = tmp_path / 'corrupt.npz'
    corrupt.write_bytes(b'PK\x03\x04 this is not a model')
    _refusal(harness, f'{corrupt}: not a model file', model_path=str(corrupt))
    _refusal(harness, 'controlled_names .* do not match', model_path=str(model_path),
             joint_names=[f'lbr_joint_{i}' for i in range(1, 8)])
    _refusal(harness, "frame 'iiwa_link_0'.*'world'", model_path=str(model_path),
             observed_frame='world')
    # a model whose observed agent is not a 3-D point
    demos = mixture_demos(seed=3, n_obs=2, n_ctrl=7, n_basis=8)[0]
    two_d = save_model(tmp_path / 'planar.npz', MixtureIProMP(3, n_basis=8).fit(demos),
                       observed_names=['x', 'y'], controlled_names=JOINT_NAMES)
    _refusal(harness, '2 DOFs', model_path=str(two_d))


@pytest.mark.parametrize('params, match', [
    ({'confidence_threshold': 1.5}, 'confidence_threshold'),
    ({'n_points': 1}, 'n_points'),
    ({'min_interval': float('nan')}, 'min_interval'),
    ({'settle_time': 0.0}, 'settle_time'),
    ({'replan_rate_hz': 10}, 'replan_rate_hz'),
])
def test_invalid_parameters_are_refused_at_start_naming_the_parameter(ros_context, params,
                                                                      match):
    overrides = [Parameter(k, value=v) for k, v in params.items()]
    with pytest.raises(ValueError, match=match):
        EstimatorNode(context=ros_context, parameter_overrides=overrides)


def test_main_exits_non_zero_with_a_message_and_no_traceback(tmp_path):
    env = dict(os.environ, ROS_DOMAIN_ID=str(private_domain_id()))
    for args, expected in (
            (['-p', f'model_path:={tmp_path / "missing.npz"}'], 'missing.npz: does not exist'),
            (['-p', 'confidence_threshold:=nan'], 'confidence_threshold'),
            (['-p', 'n_alpha:=many'], 'n_alpha')):
        proc = subprocess.run(
            [sys.executable, '-m', 'mixture_ip_ros.nodes.estimator_node', '--ros-args', *args],
            capture_output=True, text=True, timeout=60, env=env)
        out = proc.stdout + proc.stderr
        assert proc.returncode == 1, out
        assert 'refusing to start' in out and expected in out, out
        assert 'Traceback' not in out, out
