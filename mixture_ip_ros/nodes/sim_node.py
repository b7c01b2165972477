"""sim_node: a MuJoCo arm with computed-torque control, as a managed node.

The arm is the parameter ``robot``: a shipped robot's name (config/robots/) or a robot
description file; its description gives the defaults of initial_positions, the gains and
base_frame.

Subscribes  joint_trajectory (trajectory_msgs/JointTrajectory, reliable, DDS liveliness with
            the lease command_lease) while active, taken from the node ``commander`` only
Publishes   joint_states (sensor_msgs/JointState), flange_pose (geometry_msgs/PoseStamped)
            and, in simulated-time mode, /clock (rosgraph_msgs/Clock), all at publish_rate Hz of
            simulated time; /diagnostics (diagnostic_msgs/DiagnosticArray) every
            diagnostics_period s

The robot's topics are relative names, so they name no particular arm: they resolve in the
node's namespace (``--ros-args -r __ns:=/arm`` gives /arm/joint_trajectory) and are remapped
like any ROS topic, for example to a ros2_control controller's names
(``-r joint_trajectory:=/joint_trajectory_controller/joint_trajectory``).

Lifecycle, as a robot with its joint_trajectory_controller: configure builds the scene and
starts the physics (the arm holds its start posture, state and clock are published); activate
accepts trajectories; deactivate drops the trajectory in progress at once and holds the present
position (the physics and the clock go on: the arm does not fall); cleanup stops the simulation.
An empty trajectory (no points) also stops the motion and holds, as on
joint_trajectory_controller's topic interface.

One commander (robot.commander): commands are taken from the node ``commander`` alone. Another
publisher on the command topic is found in the ROS graph (on each command and at each
diagnostics report) and warned about once; while it is there no command is taken (a message
does not say who sent it), each refusal counted. An empty trajectory, which only stops the arm,
is taken from anyone. With ``command_lease`` the subscription requests DDS liveliness: when a
publisher is gone (its process killed, or stalled longer than the lease) the arm stops following
its plan, braking within its acceleration limits, and holds (RobotSimulation.stop), until the
next command. FastDDS asserts no automatic liveliness between the nodes of one DDS participant
(one rclpy context): a commander there lapses a lease after each message, so such a process runs
the sim with command_lease 0 (app.closed_loop).

Time: with simulated_time true, ROS time is the simulation time, published on /clock; other nodes
run with use_sim_time. Each timer callback advances periods_per_callback publish periods
(publishing after each), as fast as possible (real_time_factor 0) or paced to real_time_factor.
Trajectories are applied between callbacks, on a fixed grid of simulated time, so a run is
deterministic given the callback at which each command arrived. A command that arrives too late
for the arm to reach its first point in time within the joint limits is re-timed, not refused: it
starts later by the shortfall (logged, counted in retimed_count); one whose first point was due
more than max_delay before it arrived is refused as stale. With simulated_time false, the
simulation follows the wall clock and messages carry ROS time. The node's own timers always run
on the steady clock, so it never waits on the clock it publishes.
"""

from dataclasses import dataclass

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
import numpy as np
from rclpy.clock import Clock, ClockType
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.qos import QoSCompatibility, qos_check_compatible
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import JointState
from builtin_interfaces.msg import Time
from trajectory_msgs.msg import JointTrajectory

from mixture_ip_ros.core.stamps import ns_to_parts, seconds_to_ns, stamp_to_ns
from mixture_ip_ros.nodes import qos
from mixture_ip_ros.nodes.diagnostics import OK, WARN, diagnostic_array
from mixture_ip_ros.nodes.managed import ManagedNode, run_node
from mixture_ip_ros.nodes.params import autostart_param, finite_list, param, positive
from mixture_ip_ros.robot.commander import CommandWatch, Publisher
from mixture_ip_ros.robot.description import DEFAULT_ROBOT, load_description, shipped_robots
from mixture_ip_ros.robot.sim import DEFAULT_MAX_DELAY, RobotSimulation
from mixture_ip_ros.robot.trajectory import DEFAULT_MAX_POINTS, TrajectoryPoint, too_many_points

_DEFAULT = load_description(DEFAULT_ROBOT)
PER_JOINT = ('initial_positions', 'natural_frequency', 'damping_ratio')
# Relative: resolved in the node's namespace, remappable (--ros-args -r NAME:=...).
COMMAND_TOPIC = 'joint_trajectory'
JOINT_STATE_TOPIC = 'joint_states'
POSE_TOPIC = 'flange_pose'
DIAGNOSTIC_NAME = 'sim_node: arm'
UNKNOWN_NODE = '_NODE_NAME_UNKNOWN_'      # the graph's name of a node not yet discovered


@dataclass
class SimParameters:
    autostart: bool = autostart_param()
    robot: str = param(DEFAULT_ROBOT, 'the arm: a shipped name (' + ', '.join(shipped_robots())
                       + ') or a description file. It gives the defaults of '
                       'initial_positions, natural_frequency, damping_ratio and base_frame')
    simulated_time: bool = param(True, 'true: ROS time is the simulation time, published on '
                                       '/clock (other nodes: use_sim_time); false: the '
                                       'simulation follows the wall clock')
    real_time_factor: float = param(1.0, 'simulated-time mode: simulated s per wall s; 0 = as '
                                         'fast as the machine allows', low=0.0, high=1000.0)
    publish_rate: float = param(100.0, 'Hz of simulated time for joint_states, flange_pose '
                                       'and /clock (a whole number of 1 ms control steps)',
                                low=0.01, high=1000.0)
    periods_per_callback: int = param(1, 'simulated-time mode: publish periods per timer '
                                         'callback (more: less overhead, but in-process '
                                         'subscribers may miss JointStates)', low=1,
                                      high=10_000)
    initial_positions: list = param(_DEFAULT.home_array().tolist(),
                                    'start configuration (rad), one per joint',
                                    check=finite_list(), rule='one finite number per joint',
                                    from_robot=True)
    natural_frequency: list = param(_DEFAULT.gains()[0].tolist(),
                                    'computed-torque gains per joint: Kp = w^2 (rad/s)',
                                    check=finite_list(positive_values=True),
                                    rule='one positive number per joint', from_robot=True)
    damping_ratio: list = param(_DEFAULT.gains()[1].tolist(),
                                'Kd = 2 zeta w per joint (1 = critically damped)',
                                check=finite_list(positive_values=True),
                                rule='one positive number per joint', from_robot=True)
    controller_mass_scale: float = param(1.0, "scales every link mass and inertia of the "
                                              "controller's model (1 = the true model)",
                                         low=0.0, high=100.0, check=positive, rule='> 0')
    allow_partial_joints_goal: bool = param(False, 'as joint_trajectory_controller')
    allow_nonzero_velocity_at_trajectory_end: bool = param(False,
                                                           'as joint_trajectory_controller')
    open_loop_control: bool = param(False, 'true: a new trajectory is blended from the last '
                                           'reference; false: from the measured state')
    pole: bool = param(False, 'the pole of the pole-pointing scenario in the scene')
    stands: bool = param(True, 'the plate and screw stands of box assembly in the scene')
    table: bool = param(True, 'the table the arm stands on; false: the arm on its own in the '
                              'open (the interactions scenario: a person\'s hand hangs below '
                              'the table top)')
    base_frame: str = param(_DEFAULT.base_frame, 'frame of flange_pose', from_robot=True)
    max_trajectory_points: int = param(DEFAULT_MAX_POINTS, 'longer trajectories are refused '
                                       'before they are read', low=2, high=10_000_000)
    max_catch_up: float = param(0.1, 'wall-clock mode: the largest backlog (s) caught up on '
                                     'in one go', low=0.0, high=10.0)
    max_delay: float = param(DEFAULT_MAX_DELAY, 's; a trajectory whose first point was due '
                             'more than this before it arrived is refused as stale (another '
                             'clock, or held up); one that comes too late for the arm to follow '
                             'starts later, when the arm can reach its first point within the '
                             'joint limits', low=0.0, high=1e9)
    commander: str = param('estimator_node', 'the one node whose commands are taken: a node '
                           "name, in any namespace, or a full name ('/arm/estimator_node'). "
                           'While another publisher is on the command topic no command is '
                           'taken (warned about once, each refusal counted); an empty '
                           "trajectory (stop) is taken from anyone. '' = any publisher")
    command_lease: float = param(0.3, 's; DDS liveliness lease requested of the command '
                                      'publishers: a publisher gone (or stalled) this long '
                                      'stops the plan in progress, the arm braking within its '
                                      'limits, and it holds. Publishers must offer a lease no '
                                      "longer (the estimator's liveliness_lease); 0 = none: any "
                                      'publisher matches, none is watched', low=0.0, high=60.0)
    diagnostics_period: float = param(1.0, 's between /diagnostics messages', low=0.001,
                                      high=3600.0)


class SimNode(ManagedNode):

    NODE_NAME = 'sim_node'
    SCHEMA = SimParameters

    def __init__(self, **kwargs):
        super().__init__(self.NODE_NAME, **kwargs)
        self.sim = None
        self.trajectory_sub = None
        self._timer = None
        self.watch = CommandWatch(self.params.commander)
        self._reported = (0, 0, 0)   # rejections, refusals, lapses in the previous report

    @staticmethod
    def robot_defaults(robot: str) -> dict:
        description = load_description(robot)
        frequency, damping = description.gains()
        return {'initial_positions': description.home_array().tolist(),
                'natural_frequency': frequency.tolist(), 'damping_ratio': damping.tolist(),
                'base_frame': description.base_frame}

    @property
    def rejection_count(self) -> int:
        return self.sim.rejection_count

    @property
    def last_rejection(self):
        return self.sim.last_rejection

    # -- lifecycle ----------------------------------------------------------------------
    def configure(self) -> None:
        p = self.params
        description = load_description(p.robot)
        for name in PER_JOINT:
            if len(getattr(p, name)) != description.dof:
                raise ValueError(f'parameter {name}: {description.name} has {description.dof} '
                                 f'joints, got {len(getattr(p, name))} values')
        self.sim = RobotSimulation(
            robot=description, q0=np.asarray(p.initial_positions), pole=p.pole, stands=p.stands,
            table=p.table,
            natural_frequency=np.asarray(p.natural_frequency),
            damping_ratio=np.asarray(p.damping_ratio),
            controller_mass_scale=p.controller_mass_scale,
            allow_partial_joints_goal=p.allow_partial_joints_goal,
            allow_nonzero_velocity_at_trajectory_end=p.allow_nonzero_velocity_at_trajectory_end,
            open_loop_control=p.open_loop_control, logger=self.get_logger().warning,
            max_trajectory_points=p.max_trajectory_points, max_delay=p.max_delay)
        self.steps_per_publish = max(1, int(round(1.0 / (p.publish_rate * self.sim.dt))))
        self.publish_period = self.steps_per_publish * self.sim.dt
        state = qos.reliable(10)
        self.joint_state_pub = self.create_publisher(JointState, JOINT_STATE_TOPIC, state)
        self.flange_pub = self.create_publisher(PoseStamped, POSE_TOPIC, state)
        # Reliable: a recorder's reliable subscription matches too (rclpy's TimeSource
        # subscribes best effort, which a reliable publisher also serves).
        self.clock_pub = (self.create_publisher(ClockMsg, '/clock', qos.reliable(1))
                          if p.simulated_time else None)
        self._clock_msg = ClockMsg()
        self._joint_state_msg = JointState(name=list(self.sim.joint_names))
        self._pose_msg = PoseStamped()
        self._pose_msg.header.frame_id = p.base_frame
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._wall_start = self._steady.now()
        self._sim_start = self.sim.time
        if p.simulated_time:
            chunk = p.periods_per_callback * self.publish_period
            period = 0.0 if p.real_time_factor == 0 else chunk / p.real_time_factor
        else:
            period = self.publish_period
        self._timer = self.create_timer(period, self._on_timer, clock=self._steady)
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics',
                                                     qos.reliable(10))
        self._diagnostics_timer = self.create_timer(p.diagnostics_period, self._on_diagnostics,
                                                    clock=self._steady)
        self._publish()
        pace = (f'simulated time, real-time factor {p.real_time_factor or "unlimited"}'
                if p.simulated_time else 'wall-clock time')
        self.get_logger().info(f'{description.name} sim: dt {self.sim.dt * 1e3:.1f} ms, '
                               f'publishing every {self.publish_period * 1e3:.0f} ms of {pace}')

    def activate(self) -> None:
        self._command_qos = qos.command(10, self.params.command_lease)
        events = SubscriptionEventCallbacks(
            incompatible_qos=self._on_incompatible,
            liveliness=self._on_liveliness if self.params.command_lease > 0 else None)
        self.trajectory_sub = self.create_subscription(
            JointTrajectory, COMMAND_TOPIC, self._on_trajectory, self._command_qos,
            event_callbacks=events)

    def deactivate(self) -> None:
        if self.trajectory_sub is not None:
            self.destroy_subscription(self.trajectory_sub)
            self.trajectory_sub = None
        if self.sim is not None:
            self.sim.cancel_trajectory()

    def cleanup(self) -> None:
        for timer in (self._timer, getattr(self, '_diagnostics_timer', None)):
            if timer is not None:
                self.destroy_timer(timer)
        for pub in (getattr(self, 'joint_state_pub', None), getattr(self, 'flange_pub', None),
                    getattr(self, 'clock_pub', None), getattr(self, 'diagnostics_pub', None)):
            if pub is not None:
                self.destroy_publisher(pub)
        self._timer = self._diagnostics_timer = None
        self.joint_state_pub = self.flange_pub = self.clock_pub = self.diagnostics_pub = None
        self.sim = None

    # -- time ---------------------------------------------------------------------------
    def _ros_now_ns(self) -> int:
        """Current ROS time, the clock trajectory stamps refer to."""
        if self.params.simulated_time:
            return seconds_to_ns(self.sim.time)
        return self.get_clock().now().nanoseconds

    # -- callbacks ----------------------------------------------------------------------
    def _on_trajectory(self, msg: JointTrajectory) -> None:
        try:
            self._check_graph()
            taken, why = self.watch.accept(stop=not msg.points)
            if why:
                self.get_logger().warning(why)
            if not taken:
                return
            if not msg.points:
                self.sim.cancel_trajectory()
                self.get_logger().info('empty trajectory: stopping and holding the position')
                return
            why = too_many_points(len(msg.points), self.sim.max_trajectory_points)
            if why:
                self.sim.refuse(why)
                return
            points = [TrajectoryPoint(stamp_to_ns(p.time_from_start) * 1e-9, p.positions,
                                      p.velocities, p.accelerations) for p in msg.points]
            stamp_ns = stamp_to_ns(msg.header.stamp)
            # A zero stamp means "start now"; otherwise map ROS time onto the simulation clock.
            start = (None if stamp_ns == 0
                     else self.sim.time + (stamp_ns - self._ros_now_ns()) * 1e-9)
            self.sim.set_trajectory(list(msg.joint_names), points, start)
        except Exception as error:  # a bad message (or a failed graph query) never kills the node
            self.sim.refuse(f'trajectory refused: {error!r}')

    # -- the command topic's publishers -----------------------------------------------
    def _check_graph(self) -> None:
        """Tell the watch who publishes on the command topic (robot.commander)."""
        sub = self.trajectory_sub
        if sub is None:
            return
        publishers = []
        for info in self.get_publishers_info_by_topic(sub.topic_name):
            node = ('' if info.node_name == UNKNOWN_NODE else
                    info.node_namespace.rstrip('/') + '/' + info.node_name)
            fits = qos_check_compatible(info.qos_profile, self._command_qos)[0]
            publishers.append(Publisher(node, bytes(info.endpoint_gid),
                                        fits != QoSCompatibility.ERROR))
        for line in self.watch.graph(publishers, sub.get_publisher_count()):
            self.get_logger().warning(line)

    def _on_incompatible(self, _status) -> None:
        self.get_logger().warning(self.watch.incompatible_publisher())

    def _on_liveliness(self, status) -> None:
        try:
            following = self.sim is not None and self.sim.following
            if self.watch.liveliness(status.alive_count, status.alive_count_change,
                                     self.sim.time if self.sim else 0.0, following):
                self.sim.stop()
                self.get_logger().warning(
                    'a publisher on the command topic is gone (it left, or asserted no '
                    f'liveliness for {self.params.command_lease} s): the arm stops within its '
                    'limits and holds')
            elif status.alive_count_change < 0:
                self.get_logger().info('a publisher on the command topic is gone; the arm '
                                       'was not moving')
        except Exception as exc:  # a callback must never kill the node
            self.get_logger().error(f'liveliness change not handled: {exc!r}')

    # -- diagnostics ---------------------------------------------------------------------
    def diagnostics_msg(self) -> DiagnosticArray:
        sim, watch = self.sim, self.watch
        values = {
            'state': 'following' if sim.following else 'holding',
            'commands_accepted': sim.accepted_count,
            'commands_rejected': sim.rejection_count,
            'last_rejection': sim.last_rejection,
            'commands_retimed': sim.retimed_count,
            'commander': self.params.commander,
            'commands_refused_sender': watch.refused,
            'refusing': watch.blocked,
            'other_publishers': watch.others,
            'incompatible_publishers': watch.incompatible,
            'publishers_alive': watch.alive,
            'liveliness_lapses': watch.lapses,
            'holds_source_lost': watch.holds,
            'controller_faults': sim.controller.fault_count,
        }
        totals = (sim.rejection_count, watch.refused, watch.lapses)
        new = [now - before for now, before in zip(totals, self._reported)]
        self._reported = totals
        problems = [f'{n} {what}' for n, what in zip(new, ('commands rejected',
                                                           'commands refused (sender)',
                                                           'publishers gone')) if n]
        sec, nanosec = ns_to_parts(self._ros_now_ns())
        stamp = Time(sec=sec, nanosec=nanosec)
        return diagnostic_array(stamp, DIAGNOSTIC_NAME, WARN if problems else OK,
                                '; '.join([values['state']] + problems), values)

    def _on_diagnostics(self) -> None:
        # A report that cannot be built or sent is logged, never raised: the arm goes on.
        try:
            self._check_graph()
            self.diagnostics_pub.publish(self.diagnostics_msg())
        except Exception as exc:
            self.get_logger().error(f'diagnostics failed: {exc!r}')

    def _on_timer(self) -> None:
        p = self.params
        if p.simulated_time:
            for _ in range(p.periods_per_callback):
                self.sim.step(self.steps_per_publish)
                self._publish()
            return
        # Wall-clock mode: catch up with the elapsed time, in publish periods.
        elapsed = (self._steady.now() - self._wall_start).nanoseconds * 1e-9
        behind = self._sim_start + elapsed - self.sim.time
        if behind > p.max_catch_up:
            # Too slow to keep up: drop the backlog rather than spiral.
            self._sim_start += behind - p.max_catch_up
            behind = p.max_catch_up
        while behind >= self.publish_period:
            self.sim.step(self.steps_per_publish)
            behind -= self.publish_period
        self._publish()

    def _publish(self) -> None:
        # Messages are reused: publish() serialises them at once.
        if self.params.simulated_time:
            sec, nanosec = ns_to_parts(seconds_to_ns(self.sim.time))
            stamp = Time(sec=sec, nanosec=nanosec)
            self._clock_msg.clock = stamp
            self.clock_pub.publish(self._clock_msg)
        else:
            stamp = self.get_clock().now().to_msg()
        data = self.sim.data
        js = self._joint_state_msg
        js.header.stamp = stamp
        js.position = data.qpos.tolist()      # the scene has the arm's joints only, in order
        js.velocity = data.qvel.tolist()
        js.effort = data.ctrl.tolist()
        self.joint_state_pub.publish(js)
        pos, quat = self.sim.flange_pose()
        pose = self._pose_msg
        pose.header.stamp = stamp
        p, o = pose.pose.position, pose.pose.orientation
        p.x, p.y, p.z = pos.tolist()
        o.w, o.x, o.y, o.z = quat.tolist()
        self.flange_pub.publish(pose)


def main(args=None):
    return run_node(SimNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
