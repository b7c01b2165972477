"""sim_node: a MuJoCo arm (the iiwa 14 by default) with computed-torque control, as a ROS 2 node.

The arm is the parameter ``robot``: a shipped robot's name (config/robots/) or the path of a
robot description file; its description gives the defaults of initial_positions, the gains and
base_frame.

Subscribes iiwa/joint_trajectory (trajectory_msgs/JointTrajectory, reliable); publishes
joint_states (sensor_msgs/JointState), iiwa/flange_pose (geometry_msgs/PoseStamped) and, in
simulated-time mode, /clock (rosgraph_msgs/Clock), all at publish_rate Hz of simulated time.

Time: with simulated_time true, ROS time is the simulation time, published on /clock; other nodes
run with use_sim_time. Each timer callback advances periods_per_callback publish periods
(publishing after each), as fast as possible (real_time_factor 0) or paced to real_time_factor.
Trajectories are applied between callbacks, on a fixed grid of simulated time, so a run is
deterministic given the callback at which each command arrived.
With simulated_time false, the simulation follows the wall clock and messages carry ROS time.
The node's own timers always run on the steady clock, so it never waits on the clock it publishes.
"""

import math

import numpy as np
import rclpy
from builtin_interfaces.msg import Time as TimeMsg
from geometry_msgs.msg import PoseStamped
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, HistoryPolicy
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from mixture_ip_ros.robot.description import DEFAULT_ROBOT, load_description
from mixture_ip_ros.robot.sim import RobotSimulation
from mixture_ip_ros.robot.trajectory import TrajectoryPoint
from mixture_ip_ros.nodes.spinning import spin_until_shutdown


def _time_msg(seconds: float) -> TimeMsg:
    nanoseconds = int(round(seconds * 1e9))
    return TimeMsg(sec=nanoseconds // 1_000_000_000, nanosec=nanoseconds % 1_000_000_000)


def _seconds(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


class SimNode(Node):

    def __init__(self, **kwargs):
        super().__init__('sim_node', **kwargs)
        self.declare_parameter('robot', DEFAULT_ROBOT)
        description = load_description(self.get_parameter('robot').value)
        frequency, damping = description.gains()
        self.declare_parameter('simulated_time', True)
        self.declare_parameter('real_time_factor', 1.0)
        self.declare_parameter('publish_rate', 100.0)
        self.declare_parameter('periods_per_callback', 1)
        self.declare_parameter('initial_positions', list(description.home))
        self.declare_parameter('natural_frequency', frequency.tolist())
        self.declare_parameter('damping_ratio', damping.tolist())
        self.declare_parameter('controller_mass_scale', 1.0)
        self.declare_parameter('allow_partial_joints_goal', False)
        self.declare_parameter('allow_nonzero_velocity_at_trajectory_end', False)
        self.declare_parameter('open_loop_control', False)
        self.declare_parameter('pole', False)
        self.declare_parameter('stands', True)
        self.declare_parameter('base_frame', description.base_frame)
        self.declare_parameter('max_catch_up', 0.1)

        param = self.get_parameter
        self.simulated_time = bool(param('simulated_time').value)
        self.real_time_factor = float(param('real_time_factor').value)
        rate = float(param('publish_rate').value)
        if not (math.isfinite(rate) and rate > 0):
            raise ValueError(f'publish_rate must be positive, got {rate}')
        if not (math.isfinite(self.real_time_factor) and self.real_time_factor >= 0):
            raise ValueError(f'real_time_factor must be >= 0, got {self.real_time_factor}')
        self.base_frame = str(param('base_frame').value)
        self.periods_per_callback = int(param('periods_per_callback').value)
        if self.periods_per_callback < 1:
            raise ValueError('periods_per_callback must be >= 1')
        self.max_catch_up = float(param('max_catch_up').value)

        self.sim = RobotSimulation(
            robot=description, q0=np.asarray(param('initial_positions').value, dtype=float),
            pole=bool(param('pole').value), stands=bool(param('stands').value),
            natural_frequency=np.asarray(param('natural_frequency').value, dtype=float),
            damping_ratio=np.asarray(param('damping_ratio').value, dtype=float),
            controller_mass_scale=float(param('controller_mass_scale').value),
            allow_partial_joints_goal=bool(param('allow_partial_joints_goal').value),
            allow_nonzero_velocity_at_trajectory_end=bool(
                param('allow_nonzero_velocity_at_trajectory_end').value),
            open_loop_control=bool(param('open_loop_control').value),
            logger=self.get_logger().warning)
        self.steps_per_publish = max(1, int(round(1.0 / (rate * self.sim.dt))))
        self.publish_period = self.steps_per_publish * self.sim.dt

        reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                              history=HistoryPolicy.KEEP_LAST)
        self.joint_state_pub = self.create_publisher(JointState, 'joint_states', reliable)
        self.flange_pub = self.create_publisher(PoseStamped, 'iiwa/flange_pose', reliable)
        self.clock_pub = None
        if self.simulated_time:
            self.clock_pub = self.create_publisher(
                ClockMsg, '/clock', QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE))
        self.trajectory_sub = self.create_subscription(
            JointTrajectory, 'iiwa/joint_trajectory', self._on_trajectory, reliable)

        self._clock_msg = ClockMsg()
        self._joint_state_msg = JointState(name=list(self.sim.joint_names))
        self._pose_msg = PoseStamped()
        self._pose_msg.header.frame_id = self.base_frame

        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._wall_start = self._steady.now()
        self._sim_start = self.sim.time
        if self.simulated_time:
            chunk = self.periods_per_callback * self.publish_period
            period = 0.0 if self.real_time_factor == 0 else chunk / self.real_time_factor
        else:
            period = self.publish_period
        self.timer = self.create_timer(period, self._on_timer, clock=self._steady)
        self._publish()
        if self.simulated_time:
            pace = f'simulated time, real-time factor {self.real_time_factor or "unlimited"}'
        else:
            pace = 'wall-clock time'
        self.get_logger().info(f'{description.name} sim: dt {self.sim.dt * 1e3:.1f} ms, '
                               f'publishing every {self.publish_period * 1e3:.0f} ms of {pace}')

    @property
    def rejection_count(self) -> int:
        return self.sim.rejection_count

    @property
    def last_rejection(self):
        return self.sim.last_rejection

    # ------------------------------------------------------------------ time
    def _ros_now(self) -> float:
        """Current ROS time in seconds, the clock trajectory stamps refer to."""
        if self.simulated_time:
            return self.sim.time
        return self.get_clock().now().nanoseconds * 1e-9

    def _stamp(self) -> TimeMsg:
        if self.simulated_time:
            return _time_msg(self.sim.time)
        return self.get_clock().now().to_msg()

    # ------------------------------------------------------------------ callbacks
    def _on_trajectory(self, msg: JointTrajectory) -> None:
        try:
            points = [TrajectoryPoint(_seconds(p.time_from_start), p.positions, p.velocities,
                                      p.accelerations) for p in msg.points]
            stamp = _seconds(msg.header.stamp)
            # header.stamp 0 means "start now"; otherwise map ROS time onto the simulation clock.
            start = None if stamp == 0.0 else self.sim.time + (stamp - self._ros_now())
            self.sim.set_trajectory(list(msg.joint_names), points, start)
        except Exception as error:  # a bad message must never kill the node
            self.sim.rejection_count += 1
            self.sim.last_rejection = f'malformed trajectory: {error}'
            self.get_logger().error(self.sim.last_rejection)

    def _on_timer(self) -> None:
        if self.simulated_time:
            for _ in range(self.periods_per_callback):
                self.sim.step(self.steps_per_publish)
                self._publish()
            return
        # Wall-clock mode: catch up with the elapsed time, in publish periods.
        elapsed = (self._steady.now() - self._wall_start).nanoseconds * 1e-9
        target = self._sim_start + elapsed
        behind = target - self.sim.time
        if behind > self.max_catch_up:
            # Too slow to keep up: drop the backlog rather than spiral.
            self._sim_start += behind - self.max_catch_up
            behind = self.max_catch_up
        while behind >= self.publish_period:
            self.sim.step(self.steps_per_publish)
            behind -= self.publish_period
        self._publish()

    def _publish(self) -> None:
        # Messages are reused: publish() serialises them at once.
        stamp = self._stamp()
        if self.clock_pub is not None:
            self._clock_msg.clock = stamp
            self.clock_pub.publish(self._clock_msg)
        data = self.sim.data
        js = self._joint_state_msg
        js.header.stamp = stamp
        js.position = data.qpos.tolist()
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
    rclpy.init(args=args)
    node = None
    try:
        node = SimNode()
        spin_until_shutdown(node)
    except KeyboardInterrupt:
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
