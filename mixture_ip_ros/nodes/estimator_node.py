"""Estimator: recognises the interaction pattern and the human's pace, and sends the robot the
conditioned joint trajectory (thesis eqs. 11-13 and 15-20, recursive: core.online).

Subscribes  /observer/wrist   geometry_msgs/PointStamped (frame observed_frame), reliable
            /observer/event   std_msgs/Header, frame_id 'onset' | 'end' | 'gap', reliable
Publishes   /iiwa/joint_trajectory     trajectory_msgs/JointTrajectory, reliable depth 10:
                header.stamp = the interaction's onset stamp, joint names of the model,
                points from the current phase (plus lookahead) to z = 1 with positions,
                velocities, accelerations, time_from_start = z / alpha* (planning.build_plan).
                Sent once p(k* | D) >= confidence_threshold with >= min_observations used
                and the samples held before the onset absorbed, then at replan_rate_hz
                while new observations arrive (replanned in the callback of the first
                observation used after each period, so the robot reacts within one
                observation's latency; a timer covers pauses), and a last time on 'end'.
            /estimator/predicted_wrist nav_msgs/Path (frame observed_frame): the whole
                predicted wrist movement, phases 0..1, pose stamps = onset + z / alpha*.
            /estimator/posterior       std_msgs/Float64MultiArray, one dimension labelled
                'p0,..,p{K-1},alpha,phase,confidence,component':
                data = [p(k=0|D) .. p(k=K-1|D), alpha* (1/s), phase z in [0, 1] at the latest
                observation, confidence = p(k*|D), k*]. Published with every replan.
            /diagnostics               diagnostic_msgs/DiagnosticArray about every
                diagnostics_period s: state, update latency (last/mean/max us), observations
                used/skipped/rejected by reason, commit phase, plans sent.
Observations outside an interaction are held for hold_window s; at an onset those from the
(back-dated) onset on are absorbed a backlog_budget slice per callback, live ones at once
(planning.InteractionPlanner). Times are those of the observations' stamps: an observation is
at stamp - onset stamp.
Timers run on the node clock (use_sim_time works). Refuses to start (ValueError, non-zero exit
from main) without a valid model whose joints, observed DOFs and frame match the parameters.
"""

import sys
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PointStamped
from nav_msgs.msg import Path
import numpy as np
import rclpy
from rclpy.exceptions import NameValidationException, ParameterException
from rclpy.logging import get_logger
from rclpy.node import Node
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy,
                       qos_profile_sensor_data)
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, Header, MultiArrayDimension
from trajectory_msgs.msg import JointTrajectory

from mixture_ip_ros.core.online import OnlineEstimator
from mixture_ip_ros.io.model_file import load_model
from mixture_ip_ros.robot.description import DEFAULT_ROBOT, load_description
from mixture_ip_ros.robot.kinematics import RobotKinematics
from mixture_ip_ros.nodes.cdr import JointTrajectoryEncoder, PathEncoder
from mixture_ip_ros.nodes.spinning import spin_until_shutdown
from mixture_ip_ros.estimation.planning import (
    InteractionPlanner, LatencyStats, predicted_wrist, summary_labels)

N_OBSERVED = 3   # a PointStamped carries x, y, z


def _stamp_ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


class EstimatorNode(Node):

    def __init__(self, **kwargs):
        super().__init__('estimator_node', **kwargs)
        try:
            self._setup()
        except BaseException:
            self.destroy_node()
            raise

    def _setup(self):
        self.declare_parameter('model_path', '')
        self.declare_parameter('observation_topic', '/observer/wrist')
        self.declare_parameter('event_topic', '/observer/event')
        self.declare_parameter('trajectory_topic', '/iiwa/joint_trajectory')
        self.declare_parameter('path_topic', '/estimator/predicted_wrist')
        self.declare_parameter('posterior_topic', '/estimator/posterior')
        # The robot (a shipped name or a description file) gives the defaults of joint_names,
        # observed_frame (its base frame) and catch_up_velocity.
        self.declare_parameter('robot', DEFAULT_ROBOT)
        robot = load_description(self.get_parameter('robot').value)
        self.declare_parameter('joint_names', list(robot.joint_names))
        self.declare_parameter('observed_frame', robot.base_frame)
        self.declare_parameter('n_alpha', 50)
        self.declare_parameter('min_interval', 0.05)
        self.declare_parameter('confidence_threshold', 0.9)
        self.declare_parameter('min_observations', 3)
        self.declare_parameter('replan_rate_hz', 10.0)
        self.declare_parameter('replan_on_observation', True)
        self.declare_parameter('n_points', 25)
        self.declare_parameter('lookahead', 0.1)
        self.declare_parameter('settle_time', 0.5)
        self.declare_parameter('joint_state_topic', '/joint_states')
        # Joint speeds the robot may use to catch up with a new plan: half its velocity limits.
        self.declare_parameter('catch_up_velocity',
                               (0.5 * RobotKinematics(robot).velocity_limit).tolist())
        self.declare_parameter('diagnostics_period', 1.0)
        # Observations held outside an interaction, s of their stamps: well over the observer's
        # max_backdate, so that a back-dated onset (its event comes later) finds its samples.
        self.declare_parameter('hold_window', 2.5)
        # Time per callback spent absorbing the held samples after an onset, so that live
        # observations do not wait behind all of them.
        self.declare_parameter('backlog_budget', 0.002)
        self.declare_parameter('input_queue_depth', 1000)
        self.declare_parameter('output_queue_depth', 10)
        self.declare_parameter('log_throttle_sec', 2.0)

        param = self._param
        model_path = param('model_path')
        if not model_path:
            raise ValueError('parameter model_path is empty: give a trained model file '
                             '(--ros-args -p model_path:=/path/to/model.npz)')
        self.joint_names = list(param('joint_names'))
        self.observed_frame = param('observed_frame')
        model, meta = load_model(model_path, controlled_names=self.joint_names)
        if model.n_observed_ != N_OBSERVED:
            raise ValueError(f'model file {model_path}: the observed agent has '
                             f'{model.n_observed_} DOFs, {param("observation_topic")} carries '
                             f'{N_OBSERVED} (x, y, z)')
        if meta.get('observed_frame') != self.observed_frame:
            raise ValueError(f"model file {model_path}: trained in frame "
                             f"{meta.get('observed_frame')!r}, observations are expected in "
                             f'{self.observed_frame!r} (parameter observed_frame)')
        for name in ('replan_rate_hz', 'diagnostics_period', 'log_throttle_sec', 'hold_window',
                     'backlog_budget'):
            if not float(param(name)) > 0:
                raise ValueError(f'parameter {name} must be > 0, got {param(name)}')
        for name in ('input_queue_depth', 'output_queue_depth'):
            if int(param(name)) < 1:
                raise ValueError(f'parameter {name} must be >= 1, got {param(name)}')
        if int(param('n_alpha')) < 1 or not float(param('min_interval')) >= 0:
            raise ValueError('parameters n_alpha must be >= 1 and min_interval >= 0')
        self.model_path = model_path
        self.model = model
        self.metadata = meta
        self.estimator = OnlineEstimator(model, n_alpha=int(param('n_alpha')),
                                         min_interval=float(param('min_interval')))
        self._warm_up()
        self.planner = InteractionPlanner(
            self.estimator, confidence_threshold=float(param('confidence_threshold')),
            min_observations=int(param('min_observations')), n_points=int(param('n_points')),
            lookahead=float(param('lookahead')), settle_time=float(param('settle_time')),
            labels=meta.get('component_labels'), hold_window=float(param('hold_window')),
            catch_up_velocity=self._catch_up_velocity(param('catch_up_velocity')))
        self._throttle = float(param('log_throttle_sec'))
        self._replan_period = 1.0 / float(param('replan_rate_hz'))
        self._replan_on_observation = bool(param('replan_on_observation'))
        self._backlog_budget = float(param('backlog_budget'))
        self._next_replan = None   # stamp-clock time (s since onset) of the next replan
        self._last_replan_wall = -float('inf')   # of the latest replan by an observation
        self.latency = LatencyStats()         # OnlineEstimator update, per used observation
        self.plan_latency = LatencyStats()    # one replan: posterior, plan, messages, publish
        self.events = {'onset': 0, 'end': 0, 'gap': 0, 'unknown': 0}
        self._diag_seen = (0, 0)   # rejections and plan failures at the last diagnostics
        self._labels = ','.join(summary_labels(model.n_components))
        self._trajectory_encoder = JointTrajectoryEncoder(self.joint_names)
        self._path_encoder = PathEncoder(self.observed_frame)

        def reliable(depth):
            return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=int(depth),
                              reliability=ReliabilityPolicy.RELIABLE,
                              durability=DurabilityPolicy.VOLATILE)
        out_qos = reliable(param('output_queue_depth'))
        in_qos = reliable(param('input_queue_depth'))
        self._traj_pub = self.create_publisher(JointTrajectory, param('trajectory_topic'),
                                               out_qos)
        self._path_pub = self.create_publisher(Path, param('path_topic'), out_qos)
        self._post_pub = self.create_publisher(Float64MultiArray, param('posterior_topic'),
                                               out_qos)
        self._diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', reliable(10))
        # Every callback stays in the node's default (mutually exclusive) callback group: the
        # planner is not thread safe, also under a MultiThreadedExecutor.
        # Events first: when both are ready in one wait, the onset is handled before the
        # observations it precedes (the planner also holds early observations for it).
        self.create_subscription(Header, param('event_topic'), self.on_event, in_qos)
        self.create_subscription(PointStamped, param('observation_topic'), self.on_observation,
                                 in_qos)
        self.create_subscription(JointState, param('joint_state_topic'), self.on_joint_state,
                                 qos_profile_sensor_data)
        self.create_timer(1.0 / float(param('replan_rate_hz')), self.on_replan_timer)
        self.create_timer(float(param('diagnostics_period')), self.publish_diagnostics)
        labels = meta.get('component_labels')
        self.get_logger().info(
            f'model {model_path}: {model.n_components} components'
            f"{' (' + ', '.join(labels) + ')' if labels else ''}, {model.n_basis} basis "
            f"functions; observing {param('observation_topic')} in {self.observed_frame}, "
            f"commanding {param('trajectory_topic')}")

    def _param(self, name):
        return self.get_parameter(name).value

    def _catch_up_velocity(self, value):
        v = np.asarray(value, dtype=float)
        if v.shape != (len(self.joint_names),) or not np.all(np.isfinite(v) & (v > 0)):
            raise ValueError(f'parameter catch_up_velocity must be {len(self.joint_names)} '
                             f'positive speeds, got {list(value)}')
        return v

    def on_joint_state(self, msg: JointState) -> None:
        try:
            index = {name: i for i, name in enumerate(msg.name)}
            q = np.array([msg.position[index[n]] for n in self.joint_names])
            if np.all(np.isfinite(q)):
                self.planner.robot_q = q
        except (KeyError, IndexError):
            self.planner.reject('bad_joint_state')

    def _warm_up(self):
        # First update compiles the numba kernel (cached on disk); do it now, not mid-reach.
        self.estimator.update(0.0, np.zeros(self.estimator.n_observed))
        self.estimator.predict(np.linspace(0.0, 1.0, 3))
        self.estimator.mean_trajectories([0.5], [0.5])
        self.estimator.reset()

    @property
    def interactions(self):
        """One dict per interaction (planning.InteractionPlanner.interactions)."""
        return self.planner.interactions

    @property
    def state(self) -> str:
        return self.planner.state

    # -- callbacks: never raise --------------------------------------------------------
    def on_observation(self, msg: PointStamped) -> None:
        try:
            if msg.header.frame_id != self.observed_frame:
                self._warn_rejected(self.planner.refuse('wrong_frame'),
                                    f'frame {msg.header.frame_id!r}')
                return
            p = msg.point
            t0 = time.perf_counter()
            result = self.planner.observe(_stamp_ns(msg.header.stamp), (p.x, p.y, p.z))
            if result == 'used':
                self.latency.add(time.perf_counter() - t0)
            elif result not in ('skipped', 'held'):
                self._warn_rejected(result, f'stamp {msg.header.stamp.sec}.'
                                            f'{msg.header.stamp.nanosec:09d}')
                return
            absorbed_all = self._absorb_slice()
            # Replan right away (at most at replan_rate_hz on the stamps' clock): the robot
            # reacts within the observation's latency, not a timer period. Also limited on the
            # wall clock, for streams replayed faster than real time (the timer follows up).
            t = self.planner.t_now
            if result == 'used' and self._replan_on_observation and (
                    self._next_replan is None or t >= self._next_replan - 1e-9) and (
                    time.perf_counter() - self._last_replan_wall >= self._replan_period):
                self._next_replan = t + self._replan_period
                self._last_replan_wall = time.perf_counter()
                self.replan()
            elif absorbed_all:
                self.replan()     # on all the evidence: the robot may be committed now
        except Exception as exc:  # a bad message must not kill the node
            self.planner.reject('exception')
            self.get_logger().error(f'observation dropped, callback failed: {exc!r}',
                                    throttle_duration_sec=self._throttle)

    def on_event(self, msg: Header) -> None:
        try:
            kind = msg.frame_id
            stamp_ns = _stamp_ns(msg.stamp)
            if kind == 'onset':
                self.events['onset'] += 1
                self._next_replan = None
                if self.planner.active:
                    self._log_unfinished()
                self.planner.onset(stamp_ns)
                self.get_logger().info(f'onset at {msg.stamp.sec}.{msg.stamp.nanosec:09d}: '
                                       f'new interaction, {self.planner.n_backlog} held '
                                       'observations to absorb')
                if self._absorb_slice():
                    self.replan()
            elif kind == 'end':
                self.events['end'] += 1
                if self.planner.active:
                    t0 = time.perf_counter()
                    self._publish_step(self.planner.end(stamp_ns, self._clock_since_onset()), t0)
                    self._log_finished(self.planner.current)
            elif kind == 'gap':
                self.events['gap'] += 1
                self.planner.gap()
            else:
                self.events['unknown'] += 1
                self.get_logger().warning(f'unknown event {kind!r} ignored',
                                          throttle_duration_sec=self._throttle)
        except Exception as exc:
            self.get_logger().error(f'event {msg.frame_id!r} failed: {exc!r}',
                                    throttle_duration_sec=self._throttle)

    def _clock_since_onset(self):
        """The node clock (sim time with use_sim_time) in s since the onset, or None."""
        onset = self.planner.onset_ns
        return None if onset is None else (self.get_clock().now().nanoseconds - onset) * 1e-9

    def on_replan_timer(self) -> None:
        """Covers pauses: replans unless an observation replanned within the last period."""
        if self._absorb_slice() or (
                time.perf_counter() - self._last_replan_wall >= self._replan_period):
            self.replan()

    def _absorb_slice(self) -> bool:
        """backlog_budget s of the samples held before the onset; True if that was the last."""
        if not self.planner.n_backlog:
            return False
        self.planner.absorb_backlog(self._backlog_budget)
        return self.planner.n_backlog == 0

    def replan(self) -> None:
        """Update the posterior summary, the predicted path and (once committed) the robot's
        trajectory from what was observed so far."""
        try:
            t0 = time.perf_counter()
            self._publish_step(self.planner.step(clock_now=self._clock_since_onset()), t0)
        except Exception as exc:
            self.get_logger().error(f'replanning failed: {exc!r}',
                                    throttle_duration_sec=self._throttle)

    # -- output ------------------------------------------------------------------------
    def _publish_step(self, step, t0) -> None:
        """Publish what a replan produced; ``t0``: when the replan started (its latency)."""
        if step is None:
            return
        onset_ns = self.planner.onset_ns
        plan = step.plan if step.problem is None else None
        # The robot's trajectory first, serialized directly (nodes.cdr): it is what the
        # latency is about; the posterior and the predicted path follow.
        if plan is not None and step.send:
            self._traj_pub.publish(self._trajectory_encoder.encode(
                onset_ns, np.round(plan.times * 1e9).astype(np.int64), plan.positions,
                plan.velocities, plan.accelerations))
        self._post_pub.publish(self._posterior_msg(step.summary))
        if plan is None:
            self.get_logger().error(f'plan not published: {step.problem}',
                                    throttle_duration_sec=self._throttle)
            return
        self._publish_path(plan, onset_ns)
        if step.send:
            rec = self.planner.current
            if step.committed_now:
                self.get_logger().info(
                    f"committed to component {plan.component}{self._label(plan.component)} "
                    f"(p = {rec['confidence']:.3f}) at phase {rec['commit_phase']:.3f} after "
                    f"{rec['commit_observations']} observations, alpha* = {plan.alpha:.3f}/s")
            if step.switched_from is not None:
                self.get_logger().info(
                    f'switching from component {step.switched_from}'
                    f'{self._label(step.switched_from)} to {plan.component}'
                    f"{self._label(plan.component)} at phase {rec['phase']:.3f}")
        self.plan_latency.add(time.perf_counter() - t0)

    def _publish_path(self, plan, onset_ns) -> None:
        """The whole predicted wrist movement under the plan's hypothesis (for RViz)."""
        times, positions = predicted_wrist(self.estimator, plan, self.planner.n_points)
        if not np.isfinite(positions).all():
            self.get_logger().error('predicted wrist path not published: non-finite',
                                    throttle_duration_sec=self._throttle)
            return
        self._path_pub.publish(self._path_encoder.encode(
            onset_ns + round(self.planner.t_now * 1e9),
            onset_ns + np.round(times * 1e9).astype(np.int64), positions))

    def _posterior_msg(self, summary) -> Float64MultiArray:
        msg = Float64MultiArray()
        msg.layout.dim = [MultiArrayDimension(label=self._labels, size=len(summary),
                                              stride=len(summary))]
        msg.data = summary.tolist()
        return msg

    def publish_diagnostics(self) -> None:
        try:
            self._diag_pub.publish(self.diagnostics_msg())
        except Exception as exc:
            self.get_logger().error(f'diagnostics failed: {exc!r}',
                                    throttle_duration_sec=self._throttle)

    def diagnostics_msg(self) -> DiagnosticArray:
        pl = self.planner
        rec = pl.current or {}
        values = {
            'state': pl.state,
            'interactions': len(pl.interactions),
            'component': rec.get('component'),
            'label': rec.get('label'),
            'confidence': rec.get('confidence'),
            'alpha': rec.get('alpha'),
            'phase': rec.get('phase'),
            'commit_phase': rec.get('commit_phase'),
            'switches': len(rec.get('switches', [])),
            'observations_received': pl.received,
            'observations_used': pl.used,
            'observations_skipped': pl.skipped,
            'observations_held': pl.n_held,
            'observations_backlog': pl.n_backlog,
            'interaction_observations_used': rec.get('n_observations'),
            **{f'rejected_{k}': v for k, v in pl.rejected.items()},
            'update_latency_last_us': round(self.latency.last_us, 1),
            'update_latency_mean_us': round(self.latency.mean_us, 1),
            'update_latency_max_us': round(self.latency.max_us, 1),
            'plan_latency_last_us': round(self.plan_latency.last_us, 1),
            'plan_latency_max_us': round(self.plan_latency.max_us, 1),
            'plans_sent': pl.plans_sent,
            'plan_failures': pl.plan_failures,
            'events_unknown': self.events['unknown'],
        }
        # WARN while problems are new (since the previous message); totals stay in the values.
        n_rejected = sum(pl.rejected.values())
        new_rejected = n_rejected - self._diag_seen[0]
        new_failures = pl.plan_failures - self._diag_seen[1]
        self._diag_seen = (n_rejected, pl.plan_failures)
        status = DiagnosticStatus(name='estimator_node: estimation', hardware_id='mixture_ip_ros')
        if new_failures:
            status.level = DiagnosticStatus.WARN
            status.message = f'{pl.state}; {new_failures} plans not published (non-finite)'
        elif new_rejected:
            status.level = DiagnosticStatus.WARN
            status.message = f'{pl.state}; {new_rejected} observations rejected'
        else:
            status.level = DiagnosticStatus.OK
            status.message = pl.state
        status.values = [KeyValue(key=k, value='' if v is None else str(v))
                         for k, v in values.items()]
        msg = DiagnosticArray()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.status = [status]
        return msg

    # -- logging ----------------------------------------------------------------------
    def _label(self, k) -> str:
        lbl = self.planner.label(k)
        return f' ({lbl})' if lbl is not None else ''

    def _warn_rejected(self, reason, detail) -> None:
        counts = {k: v for k, v in self.planner.rejected.items() if v}
        self.get_logger().warning(f'observation rejected ({reason}, {detail}); rejected so far: '
                                  f'{counts}', throttle_duration_sec=self._throttle)

    def _log_finished(self, rec) -> None:
        if rec['commit_phase'] is None:
            self.get_logger().warning(
                f"interaction ended without a confident component (p(k*) = "
                f"{rec['confidence'] if rec['confidence'] is not None else float('nan'):.3f} "
                f"< {self.planner.confidence_threshold} or fewer than "
                f'{self.planner.min_observations} observations): robot not moved')
            return
        self.get_logger().info(
            f"interaction done: component {rec['component']}{self._label(rec['component'])}, "
            f"alpha* = {rec['alpha']:.3f}/s, committed at phase {rec['commit_phase']:.3f}, "
            f"{rec['n_observations']} observations used, {rec['plans']} plans, "
            f"{len(rec['switches'])} switches")

    def _log_unfinished(self) -> None:
        self.get_logger().warning('onset before the previous interaction ended: starting over')


def main(args=None):
    rclpy.init(args=args)
    try:
        node = EstimatorNode()
    except KeyboardInterrupt:
        rclpy.try_shutdown()
        return 0
    except (ValueError, ParameterException, NameValidationException) as exc:
        # Expected refusals (no/corrupt/mismatched model, bad parameters): a message, no trace.
        get_logger('estimator_node').fatal(f'refusing to start: {exc}')
        rclpy.try_shutdown()
        return 1
    try:
        spin_until_shutdown(node)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
