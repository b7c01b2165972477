"""Benchmark of the iiwa simulation with the computed-torque controller in the loop.

Prints one JSON object:
  realtime_factor      simulated s per wall s of RobotSimulation.step at 1 kHz (median of runs)
  step_us_total        wall microseconds per 1 ms control step (from the same runs)
  step_us_mujoco       of which mj_step
  step_us_pinocchio    of which the controller (Pinocchio RNEA + the control law around it)
  step_us_trajectory   of which the trajectory sampling (references evaluated per block)
  step_us_rnea         Pinocchio's RNEA call alone
  node_realtime_factor sim_node in-process (simulated time, as fast as possible), spun by one
                       executor together with a JointState subscriber
  node_joint_state_hz_sim / _wall  JointState messages that subscriber received per simulated /
                       wall second; node_joint_state_max_gap_s the largest stamp gap between them
  executable_*         the same for the sim_node executable in its own process (config/sim.yaml
                       with real_time_factor 0), observed from this process over DDS (a Python
                       subscriber may drop some messages under load: then the rate is a lower
                       bound)
Run: .venv/bin/python bench/sim.py [--runs 5] [--seconds 2.0] [--node-seconds 3.0]
"""

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

import mujoco  # noqa: E402
import numpy as np  # noqa: E402
import pinocchio  # noqa: E402

from mixture_ip_ros.robot.description import JOINT_NAMES  # noqa: E402
from mixture_ip_ros.robot.sim import RobotSimulation  # noqa: E402
from mixture_ip_ros.robot.trajectory import points_from_arrays  # noqa: E402

# Minimum-jerk moves between these in --seconds (2 s): joint 1's peak speed, 1.875 x 1.5 rad /
# 2 s = 1.41 rad/s, is within the iiwa's 1.48 rad/s (a trajectory beyond it is refused).
Q_A = np.array([-0.75, 0.3, 0.5, -1.6, -0.4, 0.8, -0.5])
Q_B = np.array([0.75, 1.0, -0.5, -0.6, 0.5, 1.5, 0.8])


def _min_jerk_points(q_a, q_b, duration, n=21):
    t = np.linspace(0.0, duration, n)
    s = t / duration
    d = q_b - q_a
    p = q_a + np.outer(10 * s**3 - 15 * s**4 + 6 * s**5, d)
    v = np.outer((30 * s**2 - 60 * s**3 + 30 * s**4) / duration, d)
    a = np.outer((60 * s - 180 * s**2 + 120 * s**3) / duration**2, d)
    return points_from_arrays(t, p, v, a)


def _set(sim, points):
    reason = sim.set_trajectory(JOINT_NAMES, points)
    if reason is not None:
        raise SystemExit(f'the benchmark trajectory was refused: {reason}')


def bench_library(runs: int, seconds: float):
    sim = RobotSimulation(q0=Q_A)
    n = int(round(seconds / sim.dt))
    factors = []
    for run in range(runs):
        a, b = (Q_A, Q_B) if run % 2 == 0 else (Q_B, Q_A)
        sim.set_state(a)
        _set(sim, _min_jerk_points(a, b, seconds))
        start = time.perf_counter()
        sim.step(n)
        factors.append(seconds / (time.perf_counter() - start))

    # The same loop as RobotSimulation.step, with a stopwatch around each part: the follower's
    # references, ComputedTorqueController.follow, and inside it each plant step (mj_step); the
    # controller's share is follow's time less the plant's.
    sim.set_state(Q_A)
    _set(sim, _min_jerk_points(Q_A, Q_B, seconds))
    model, data, ctl = sim.model, sim.data, sim.controller
    clock = time.perf_counter
    t_traj = t_follow = 0.0
    t_plant = [0.0]
    q, qd, ctrl = data.qpos, data.qvel, data.ctrl

    def advance():
        t = clock()
        mujoco.mj_step(model, data)
        t_plant[0] += clock() - t
    left = n
    while left > 0:
        t0 = clock()
        refs = sim.follower.references(data.time, sim.dt, left, q, qd)
        t1 = clock()
        ctl.follow(q, qd, refs, ctrl, advance, np.empty((len(refs), 7)))
        t_follow += clock() - t1
        t_traj += t1 - t0
        left -= len(refs)
    t_mj, t_ctrl = t_plant[0], t_follow - t_plant[0]
    # Pinocchio's RNEA call alone (part of step_us_pinocchio).
    pin_model = sim.controller_kinematics.model
    pin_data = pin_model.createData()
    zeros = np.zeros(7)
    start = clock()
    for _ in range(n):
        pinocchio.rnea(pin_model, pin_data, q, qd, zeros)
    t_rnea = clock() - start
    rtf = statistics.median(factors)
    return {
        'realtime_factor': round(rtf, 2),
        'step_us_mujoco': round(t_mj / n * 1e6, 2),
        'step_us_pinocchio': round(t_ctrl / n * 1e6, 2),
        'step_us_trajectory': round(t_traj / n * 1e6, 2),
        'step_us_rnea': round(t_rnea / n * 1e6, 2),
        'step_us_total': round(sim.dt / rtf * 1e6, 2),
        'realtime_factor_runs': [round(f, 2) for f in factors],
    }


def _ros_listener(domain_id):
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState

    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain_id)
    listener = rclpy.create_node('bench_listener', context=ctx)
    received = []
    listener.create_subscription(
        JointState, 'joint_states',
        lambda m: received.append(m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec),
        QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(listener)
    return ctx, listener, executor, received


def _measure(executor, received, seconds, sim_time=None):
    """Spin until the first message, then for `seconds`; (sim s, wall s, messages, max gap)."""
    end = time.perf_counter() + 30
    while not received and time.perf_counter() < end:
        executor.spin_once(timeout_sec=0.01)
    if not received:
        raise RuntimeError('no JointState received')
    first = len(received)
    sim0 = sim_time() if sim_time else received[-1]
    wall0 = time.perf_counter()
    while time.perf_counter() - wall0 < seconds:
        executor.spin_once(timeout_sec=0.01)
    wall = time.perf_counter() - wall0
    sim = (sim_time() if sim_time else received[-1]) - sim0
    stamps = np.array(received[first - 1:])
    return sim, wall, len(received) - first, float(np.max(np.diff(stamps)))


def bench_node(seconds: float):
    """sim_node in this process, one executor with a subscriber (as in the integration tests)."""
    import rclpy
    from rclpy.parameter import Parameter

    from mixture_ip_ros.nodes.sim_node import SimNode

    ctx, listener, executor, received = _ros_listener(150 + os.getpid() % 40)
    try:
        node = SimNode(context=ctx, parameter_overrides=[Parameter('real_time_factor', value=0.0)])
        if not node.start():       # a managed node: configure and activate
            raise RuntimeError(f'sim_node: {node.refusal}')
        executor.add_node(node)
        sim, wall, count, gap = _measure(executor, received, seconds, lambda: node.sim.time)
        executor.shutdown()
        node.destroy_node()
        listener.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
    return {'node_realtime_factor': round(sim / wall, 2),
            'node_joint_state_hz_sim': round(count / sim, 1),
            'node_joint_state_hz_wall': round(count / wall, 1),
            'node_joint_state_max_gap_s': round(gap, 4)}


def bench_executable(seconds: float):
    """The sim_node executable in its own process (config/sim.yaml), observed over DDS."""
    import rclpy

    from mixture_ip_ros.core.share import config_path

    domain = 190 + os.getpid() % 40
    proc = subprocess.Popen(
        [str(Path(sys.executable).parent / 'sim_node'), '--ros-args', '--params-file',
         str(config_path('sim.yaml')), '-p', 'real_time_factor:=0.0'],
        env=dict(os.environ, ROS_DOMAIN_ID=str(domain)),
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    ctx, listener, executor, received = _ros_listener(domain)
    try:
        sim, wall, count, gap = _measure(executor, received, seconds)
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
        executor.shutdown()
        listener.destroy_node()
        rclpy.try_shutdown(context=ctx)
    return {'executable_realtime_factor': round(sim / wall, 2),
            'executable_joint_state_hz_sim': round(count / sim, 1),
            'executable_joint_state_max_gap_s': round(gap, 4)}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--runs', type=int, default=5)
    parser.add_argument('--seconds', type=float, default=2.0)
    parser.add_argument('--node-seconds', type=float, default=3.0)
    args = parser.parse_args()
    result = bench_library(args.runs, args.seconds)
    if args.node_seconds > 0:
        result.update(bench_node(args.node_seconds))
        result.update(bench_executable(args.node_seconds))
    print(json.dumps(result))


if __name__ == '__main__':
    main()
