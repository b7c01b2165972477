"""estimator_node: recognises the interaction pattern and the person's pace, and sends the robot
the conditioned joint trajectory (thesis eqs. 11-13 and 15-20, recursive: core.online). A managed
node; the logic is estimation.planner's, on the node clock.

Subscribes  observation_topic  geometry_msgs/PointStamped (frame observed_frame), reliable
            event_topic        std_msgs/Header, frame_id 'onset' | 'end' | 'gap', reliable
            joint_state_topic  sensor_msgs/JointState (the arm's state, to time catching up)
Publishes   trajectory_topic   trajectory_msgs/JointTrajectory, reliable, liveliness_lease:
                header.stamp = the stamp of the latest observation the plan rests on (the
                'end' event's for the last plan), joint names of the model; the expected
                trajectory with the speed marginalised (estimation.plans) from the present
                (plus lookahead) for ``horizon`` s, then a stop at rest (estimation.horizon);
                header.stamp + time_from_start = onset + each point's time. Sent once
                p(k* | D) >= confidence_threshold with >= min_observations used (with hedge,
                before that hedged), then at replan_rate_hz while observations arrive, and a
                last time on 'end'; none while the arm's state is stale. Deactivating, or a
                wrist stream gone silent, sends an empty trajectory: stop and hold.
            path_topic         nav_msgs/Path: the whole predicted wrist movement under the
                plan's component at its MAP phase speed alpha*, phases 0..1, pose stamps =
                onset + z / alpha*.
            posterior_topic    std_msgs/Float64MultiArray, one dimension labelled
                'p0,..,p{K-1},alpha,phase,confidence,component' (PosteriorSummary.as_array).
            marker_topic       visualization_msgs/MarkerArray for RViz, in observed_frame: the
                predicted wrist path of every component (opacity = its probability) and the
                robot hand's planned path, at most marker_rate_hz.
            /diagnostics       diagnostic_msgs/DiagnosticArray every diagnostics_period s.
"""

from dataclasses import dataclass
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped
from nav_msgs.msg import Path
import numpy as np
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, Header
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

from mixture_ip_ros.core.online import OnlineEstimator
from mixture_ip_ros.core.stamps import stamp_to_ns
from mixture_ip_ros.estimation.planner import OnlinePlanner, PlannerSettings
from mixture_ip_ros.estimation.plans import (JointLimits, PosteriorSummary, predicted_paths,
                                             predicted_wrist)
from mixture_ip_ros.estimation.records import LatencyStats
from mixture_ip_ros.io.cdr import Float64MultiArrayEncoder, JointTrajectoryEncoder, PathEncoder
from mixture_ip_ros.io.model_file import load_model
from mixture_ip_ros.nodes import qos
from mixture_ip_ros.nodes.diagnostics import PublishesDiagnostics
from mixture_ip_ros.nodes.estimator_diagnostics import (EstimationDiagnostics, finished_report,
                                                       sent_lines)
from mixture_ip_ros.nodes.managed import ManagedNode, run_node
from mixture_ip_ros.nodes.markers import prediction_markers
from mixture_ip_ros.nodes.params import (autostart_param, event_topic_param,
                                         observation_topic_param, param, positive)
from mixture_ip_ros.robot.description import (BASE_FRAME, DEFAULT_ROBOT, JOINT_NAMES,
                                              shipped_robots)
from mixture_ip_ros.robot.kinematics import RobotKinematics

N_OBSERVED = 3   # a PointStamped carries x, y, z


@dataclass
class EstimatorParameters:
    autostart: bool = autostart_param()
    model_path: str = param('', 'trained model file (.npz from mixture-ip train); required')
    observation_topic: str = observation_topic_param()
    event_topic: str = event_topic_param()
    joint_state_topic: str = param('/joint_states', "the robot's joints and their speeds, to "
                                                    'time catching up with a plan')
    trajectory_topic: str = param('joint_trajectory', 'trajectory_msgs/JointTrajectory to '
                                                      "the robot's controller (relative: "
                                                      "in the node's namespace)")
    path_topic: str = param('/estimator/predicted_wrist', 'nav_msgs/Path of the whole '
                                                          'predicted wrist movement')
    posterior_topic: str = param('/estimator/posterior', 'std_msgs/Float64MultiArray [p_k.., '
                                                         'alpha, phase, confidence, k]')
    marker_topic: str = param('/estimator/markers', 'visualization_msgs/MarkerArray for RViz')
    robot: str = param(DEFAULT_ROBOT, 'the robot: a shipped name (' + ', '.join(shipped_robots())
                       + ') or a description file. It gives the defaults of joint_names and '
                       'observed_frame, and the joint limits: no plan exceeds them, and a plan '
                       'starts where the arm can reach it within them')
    joint_names: list = param(list(JOINT_NAMES), "the robot's joints; must equal the model's "
                                                 'controlled names', from_robot=True)
    observed_frame: str = param(BASE_FRAME, "frame of the observations (the robot's base "
                                            "frame); must equal the model's (others are "
                                            'rejected)', from_robot=True)
    n_alpha: int = param(50, 'phase-speed hypotheses per component', low=1, high=10_000)
    prune_below: float = param(0.0, 'hypotheses (component, phase speed) whose posterior falls '
                                    'below this are no longer updated (faster; a dropped one '
                                    'never comes back); 0 = exact', low=0.0, high=1.0)
    min_interval: float = param(0.05, 's; observations used at most this often (mocap samples '
                                      'are correlated: more makes the posterior overconfident)',
                                low=0.0, high=10.0)
    confidence_threshold: float = param(0.9, 'p(k* | D) needed before the robot moves',
                                        low=0.0, high=1.0, dynamic=True, check=positive,
                                        rule='> 0')
    min_observations: int = param(3, 'observations used before the robot moves', low=1,
                                  high=100_000, dynamic=True)
    hedge: bool = param(False, 'before p(k* | D) reaches confidence_threshold, once the other '
                               'conditions of the commit hold, send the plan with the component '
                               'marginalised too (every likely interaction weighted by its '
                               'probability): the robot is under way when it commits',
                        dynamic=True)
    replan_rate_hz: float = param(10.0, 'replans per second while observations arrive (a '
                                        'timer covers pauses)', low=0.01, high=1000.0,
                                  dynamic=True)
    replan_on_observation: bool = param(True, 'replan in the callback of the first '
                                              'observation used after each period (low '
                                              'latency); false: the timer only')
    n_points: int = param(25, 'points per trajectory (and per predicted path)', low=2,
                          high=1000, dynamic=True)
    lookahead: float = param(0.1, 's; the first point lies this far ahead of the present',
                             low=0.0, high=10.0)
    settle_time: float = param(0.5, 's; the person at rest: the final posture is reached this '
                                    'long after the latest observation', low=0.0, high=60.0,
                               check=positive, rule='> 0')
    diagnostics_period: float = param(1.0, 's between /diagnostics messages', low=0.001,
                                      high=3600.0)
    hold_window: float = param(2.5, 's of observations held outside an interaction: well over '
                                    "the observer's max_backdate (the onset is dated back and "
                                    'its event comes after the samples)', low=0.001,
                               high=60.0)
    backlog_slice: int = param(8, 'held samples conditioned on per callback after an onset '
                                  '(live observations never wait behind them all)', low=1,
                               high=100_000)
    marker_rate_hz: float = param(10.0, 'RViz markers per second at most; 0 = none', low=0.0,
                                  high=1000.0)
    max_clock_offset: float = param(1.0, "s; plans resting on observations stamped further "
                                         "than this from the node's clock are not sent "
                                         '(another clock); 0 = no check', low=0.0, high=1e9)
    input_queue_depth: int = param(1000, 'reliable input queues: nothing is lost in a stall',
                                   low=1, high=1_000_000)
    output_queue_depth: int = param(10, 'reliable outputs', low=1, high=100_000)
    log_throttle_sec: float = param(2.0, 'at most one rejection warning per this many seconds',
                                    low=0.0, high=3600.0)
    liveliness_lease: float = param(0.1, "s; DDS liveliness lease of the trajectory publisher "
                                    "(at most the sim's command_lease, shorter for a margin; "
                                    '0 = none: a sim requesting one does not match)', low=0.0,
                                    high=60.0)
    max_joint_state_age: float = param(0.5, 's of the node clock: an older arm state sends no '
                                            'plan until one comes (0 = no check)', low=0.0,
                                       high=3600.0)
    horizon: float = param(0.3, 's; trajectories sent follow the plan this long, then stop '
                                'within the joint limits; replans extend them (0 = whole plans)',
                           low=0.0, high=60.0)
    max_wrist_silence: float = param(2.5, 's of the node clock without a wrist observation: '
                                          "the interaction ends, the robot holds (above the "
                                          "observer's max_gap; 0 = no check)", low=0.0,
                                     high=3600.0)


class EstimatorNode(PublishesDiagnostics, ManagedNode):

    NODE_NAME = 'estimator_node'
    SCHEMA = EstimatorParameters

    def __init__(self, **kwargs):
        super().__init__(self.NODE_NAME, **kwargs)
        self.latency = LatencyStats()        # planner.observe of a used observation
        self.plan_latency = LatencyStats()   # callback start to the trajectory sent
        self.events = dict.fromkeys(('onset', 'end', 'gap', 'unknown'), 0)
        self.planner = None
        self._subscriptions_made = []
        self._timers = []
        self._sent_any = False
        self._next_markers_ns = 0

    @staticmethod
    def robot_defaults(robot: str) -> dict:
        kinematics = RobotKinematics(robot)
        return {'joint_names': list(kinematics.joint_names),
                'observed_frame': kinematics.description.base_frame}

    # -- lifecycle ----------------------------------------------------------------------
    def configure(self) -> None:
        p = self.params
        if not p.model_path:
            raise ValueError('parameter model_path is empty: give a trained model file '
                             '(--ros-args -p model_path:=/path/to/model.npz)')
        model, meta = load_model(p.model_path, controlled_names=p.joint_names)
        if model.n_observed_ != N_OBSERVED:
            raise ValueError(f'model file {p.model_path}: the observed agent has '
                             f'{model.n_observed_} DOFs, {p.observation_topic} carries '
                             f'{N_OBSERVED} (x, y, z)')
        if meta.get('observed_frame') != p.observed_frame:
            raise ValueError(f"model file {p.model_path}: trained in frame "
                             f"{meta.get('observed_frame')!r}, observations are expected in "
                             f'{p.observed_frame!r} (parameter observed_frame)')
        self.model, self.metadata = model, meta
        self.estimator = OnlineEstimator(model, n_alpha=p.n_alpha, min_interval=p.min_interval,
                                         prune_below=p.prune_below)
        self._warm_up()
        novelty = getattr(model, 'novelty_', None)
        if novelty is None:
            self.get_logger().warning(
                f'model file {p.model_path} has no novelty thresholds (trained before they '
                'existed): the robot commits on confidence alone, also to movements the model '
                'never learned. Train it again with mixture-ip train.')
        elif abs(novelty.min_interval - p.min_interval) > 1e-9:
            self.get_logger().warning(
                f'the novelty thresholds were calibrated with min_interval '
                f'{novelty.min_interval} s, this node uses {p.min_interval} s: they may refuse '
                'movements the model knows, or accept others')
        robot = RobotKinematics(p.robot)
        if list(p.joint_names) == robot.joint_names:
            limits = JointLimits(robot.lower, robot.upper, robot.velocity_limit,
                                 robot.acceleration_limit)
            self._hand = robot
        else:
            limits = self._hand = None
            self.get_logger().warning(
                f'joint_names are not the joints of robot {p.robot!r} '
                f'({", ".join(robot.joint_names)}): plans are not checked against joint limits, '
                'and an arm behind a plan is not caught up')
        self.planner = OnlinePlanner(self.estimator, self._planner_settings(p),
                                     labels=meta.get('component_labels'),
                                     novelty=novelty, limits=limits)
        self._posterior_encoder = Float64MultiArrayEncoder(
            ','.join(PosteriorSummary.labels(model.n_components)))
        self._trajectory_encoder = JointTrajectoryEncoder(p.joint_names)
        self._path_encoder = PathEncoder(p.observed_frame)
        out = qos.reliable(p.output_queue_depth)
        publisher = self.create_lifecycle_publisher
        self.trajectory_pub = publisher(JointTrajectory, p.trajectory_topic,
                                        qos.command(p.output_queue_depth, p.liveliness_lease))
        self.path_pub = publisher(Path, p.path_topic, out)
        self.posterior_pub = publisher(Float64MultiArray, p.posterior_topic, out)
        self.marker_pub = publisher(MarkerArray, p.marker_topic, out)
        self.diagnostics_pub = publisher(DiagnosticArray, '/diagnostics', out)
        self._diagnostics = EstimationDiagnostics()
        labels = meta.get('component_labels')
        self.get_logger().info(
            f'model {p.model_path}: {model.n_components} components'
            f"{' (' + ', '.join(labels) + ')' if labels else ''}, {model.n_basis} basis "
            f'functions; observing {p.observation_topic} in {p.observed_frame}, commanding '
            f'{self.trajectory_pub.topic_name}')

    def activate(self) -> None:
        p = self.params
        inputs = qos.reliable(p.input_queue_depth)
        # Events and observations on one reliable queue each; an onset may come after the
        # observations it precedes (the planner holds early observations for it).
        self._subscriptions_made = [
            self.create_subscription(Header, p.event_topic, self.on_event, inputs),
            self.create_subscription(PointStamped, p.observation_topic, self.on_observation,
                                     inputs),
            self.create_subscription(JointState, p.joint_state_topic, self.on_joint_state,
                                     qos.sensor_data()),
        ]
        self._replan_timer = self.create_timer(1.0 / p.replan_rate_hz, self.on_replan_timer)
        self._timers = [self._replan_timer,
                        self.create_timer(p.diagnostics_period, self.publish_diagnostics)]

    def deactivate(self) -> None:
        """Stop commanding at once: the controller gets an empty trajectory (stop and hold),
        the interaction in progress ends, no input is taken any more."""
        for sub in self._subscriptions_made:
            self.destroy_subscription(sub)
        for timer in self._timers:
            self.destroy_timer(timer)
        self._subscriptions_made, self._timers = [], []
        if self.planner is None:
            return
        if self._sent_any:
            self.trajectory_pub.publish(JointTrajectory(joint_names=list(self.params.joint_names)))
            self._sent_any = False
        if self.planner.active:
            self.planner.deactivate()
            self.get_logger().warning('deactivated during an interaction: the robot holds')

    def cleanup(self) -> None:
        for name in ('trajectory_pub', 'path_pub', 'posterior_pub', 'marker_pub',
                     'diagnostics_pub'):
            pub = getattr(self, name, None)
            if pub is not None:
                self.destroy_lifecycle_publisher(pub)
                setattr(self, name, None)
        self.planner = self.estimator = self.model = None

    def apply_parameters(self, changes: dict) -> None:
        if self.planner is not None:
            self.planner.update_settings(**self._planner_settings(changes, partial=True))
        if 'replan_rate_hz' in changes and self._timers:
            self.destroy_timer(self._replan_timer)
            self._replan_timer = self.create_timer(1.0 / changes['replan_rate_hz'],
                                                   self.on_replan_timer)
            self._timers[0] = self._replan_timer
        super().apply_parameters(changes)

    @staticmethod
    def _planner_settings(p, partial=False):
        get = (lambda n: p.get(n)) if partial else (lambda n: getattr(p, n))
        names = ('confidence_threshold', 'min_observations', 'n_points', 'lookahead',
                 'settle_time', 'hold_window', 'backlog_slice', 'replan_on_observation',
                 'max_clock_offset', 'hedge', 'max_joint_state_age', 'max_wrist_silence',
                 'horizon')
        values = {n: get(n) for n in names if get(n) is not None}
        if get('replan_rate_hz') is not None:
            values['replan_period'] = 1.0 / get('replan_rate_hz')
        return values if partial else PlannerSettings(**values)

    def _warm_up(self):
        # The first update compiles core._fast's kernels (cached on disk): now, not mid-reach.
        self.estimator.update(0.0, np.zeros(self.estimator.n_observed))
        self.estimator.predict(np.linspace(0.0, 1.0, 3))
        self.estimator.mean_trajectories([0.5], [0.5])
        self.estimator.reset()

    # -- queries ------------------------------------------------------------------------
    @property
    def interactions(self):
        """One record per interaction (estimation.records.Interaction), the last is current."""
        return self.planner.interactions if self.planner is not None else []

    @property
    def state(self) -> str:
        """The interaction state (idle, observing, committed, done)."""
        return self.planner.state if self.planner is not None else 'idle'

    def _now_ns(self) -> int:
        return self.get_clock().now().nanoseconds

    # -- callbacks: never raise --------------------------------------------------------
    def on_observation(self, msg: PointStamped) -> None:
        try:
            t0 = time.perf_counter()
            if msg.header.frame_id != self.params.observed_frame:
                self._warn_rejected(self.planner.refuse('wrong_frame'),
                                    f'frame {msg.header.frame_id!r}')
                return
            p = msg.point
            result, due = self.planner.observe(stamp_to_ns(msg.header.stamp), (p.x, p.y, p.z),
                                               self._now_ns())
            if result == 'used':
                self.latency.add(time.perf_counter() - t0)
            elif result not in ('skipped', 'held'):
                self._warn_rejected(result, f'stamp {msg.header.stamp.sec}.'
                                            f'{msg.header.stamp.nanosec:09d}')
            if due:
                self.replan(t0)
        except Exception as exc:  # a bad message must not kill the node
            self.planner.reject('exception')
            self.get_logger().error(f'observation dropped, callback failed: {exc!r}',
                                    throttle_duration_sec=self.params.log_throttle_sec)

    def on_event(self, msg: Header) -> None:
        try:
            t0 = time.perf_counter()
            kind = msg.frame_id
            if kind not in ('onset', 'end', 'gap'):
                self.events['unknown'] += 1
                self.get_logger().warning(f'unknown event {kind!r} ignored',
                                          throttle_duration_sec=self.params.log_throttle_sec)
                return
            self.events[kind] += 1
            if kind == 'onset':
                if self.planner.active:
                    self.get_logger().warning('onset before the previous interaction ended: '
                                              'starting over')
                due = self.planner.onset(stamp_to_ns(msg.stamp))
                self.get_logger().info(
                    f'onset at {msg.stamp.sec}.{msg.stamp.nanosec:09d}: new interaction, '
                    f'{self.planner.current.n_observations} held observations taken, '
                    f'{self.planner.n_backlog} still to absorb')
                if due:
                    self.replan(t0)
            elif kind == 'end':
                if self.planner.active:
                    self._publish(self.planner.end(stamp_to_ns(msg.stamp), self._now_ns()), t0)
                    rec = self.planner.current
                    warn, text = finished_report(rec, self.planner.settings,
                                                 self._label(rec.component))
                    log = self.get_logger()     # a call site per severity (rclpy's rule)
                    log.warning(text) if warn else log.info(text)
            else:
                self.planner.gap()
        except Exception as exc:
            self.get_logger().error(f'event {msg.frame_id!r} failed: {exc!r}',
                                    throttle_duration_sec=self.params.log_throttle_sec)

    def on_joint_state(self, msg: JointState) -> None:
        try:
            index = {name: i for i, name in enumerate(msg.name)}
            rows = [index[n] for n in self.params.joint_names]
            q = np.array([msg.position[i] for i in rows])
            # A state without speeds (some drivers publish none) is taken as at rest.
            qd = (np.array([msg.velocity[i] for i in rows]) if len(msg.velocity)
                  else np.zeros(len(rows)))
            if len(msg.velocity) not in (0, len(msg.name)) or not (
                    np.all(np.isfinite(q)) and np.all(np.isfinite(qd))):
                self.planner.reject('bad_joint_state')
                return
            self.planner.joint_state(q, qd, self._now_ns())
        except (KeyError, IndexError):
            self.planner.reject('bad_joint_state')

    def on_replan_timer(self) -> None:
        try:
            if self.planner.tick(self._now_ns()):
                self.replan(time.perf_counter())
        except Exception as exc:
            self.get_logger().error(f'replanning failed: {exc!r}',
                                    throttle_duration_sec=self.params.log_throttle_sec)

    def replan(self, t0: float = None) -> None:
        """Replan on what was observed so far and publish; ``t0``: when the callback started."""
        self._publish(self.planner.replan(self._now_ns()),
                      time.perf_counter() if t0 is None else t0)

    # -- output ------------------------------------------------------------------------
    def _publish(self, step, t0: float) -> None:
        """Publish what a replan produced: the trajectory first (it is what the latency is
        about), then the posterior, the predicted path and the markers."""
        if step is None:
            return
        if step.hold:
            self.trajectory_pub.publish(JointTrajectory(joint_names=list(self.params.joint_names)))
            self.get_logger().warning(step.notice or f'the movement is none the model knows any '
                                      f'more ({step.unexplained}): the robot holds')
        elif step.notice is not None:
            self.get_logger().warning(step.notice)
        elif step.unexplained is not None:
            self.get_logger().info(f'not committing: {step.unexplained}',
                                   throttle_duration_sec=self.params.log_throttle_sec)
        onset_ns = self.planner.onset_ns
        plan = step.plan if step.problem is None else None
        if plan is not None and step.send:
            trigger, command = step.trigger_ns, step.command or plan
            self.trajectory_pub.publish(self._trajectory_encoder.encode(
                trigger, onset_ns + np.round(command.times * 1e9).astype(np.int64) - trigger,
                command.positions, command.velocities, command.accelerations))
            self._sent_any = True
            self.plan_latency.add(time.perf_counter() - t0)
        self.posterior_pub.publish(self._posterior_encoder.encode(step.summary.as_array()))
        if plan is None:
            if step.problem is not None:
                self.get_logger().error(f'plan not published: {step.problem}',
                                        throttle_duration_sec=self.params.log_throttle_sec)
            return
        self._publish_path(plan, onset_ns, step.trigger_ns)
        self._publish_markers(step, onset_ns)
        if step.send:
            for line in sent_lines(step, self.planner.current, self._label):
                self.get_logger().info(line)

    def _publish_path(self, plan, onset_ns, stamp_ns) -> None:
        times, positions = predicted_wrist(self.estimator, plan, self.params.n_points)
        if not np.isfinite(positions).all():
            self.get_logger().error('predicted wrist path not published: non-finite',
                                    throttle_duration_sec=self.params.log_throttle_sec)
            return
        self.path_pub.publish(self._path_encoder.encode(
            stamp_ns, onset_ns + np.round(times * 1e9).astype(np.int64), positions))

    def _publish_markers(self, step, onset_ns) -> None:
        rate = self.params.marker_rate_hz
        now = self._now_ns()
        if (rate <= 0 or now < self._next_markers_ns
                or self.marker_pub.get_subscription_count() == 0):
            return
        self._next_markers_ns = now + round(1e9 / rate)
        paths = [(k, step.summary.probabilities[k], positions)
                 for k, _, _, positions in predicted_paths(self.estimator, self.params.n_points)]
        hand = None
        if self._hand is not None and step.send:
            hand = self._hand.fk_positions(step.plan.positions)
        self.marker_pub.publish(prediction_markers(
            self.params.observed_frame, self.get_clock().now().to_msg(), paths, hand,
            [self._label(k).strip(' ()') or f'component {k}' for k, _, _ in paths]))

    def diagnostics_msg(self) -> DiagnosticArray:
        return self._diagnostics.message(self.get_clock().now().to_msg(), self.planner,
                                         self.latency, self.plan_latency, self.events)

    # -- logging ------------------------------------------------------------------------
    def _label(self, k) -> str:
        lbl = self.planner.label(k)
        return f' ({lbl})' if lbl is not None else ''

    def _warn_rejected(self, reason, detail) -> None:
        counts = {k: v for k, v in self.planner.counts.rejected.items() if v}
        self.get_logger().warning(f'observation rejected ({reason}, {detail}); rejected so far: '
                                  f'{counts}', throttle_duration_sec=self.params.log_throttle_sec)


def main(args=None):
    return run_node(EstimatorNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
