"""The closed loop in one process: bag_player -> observer -> estimator -> sim, on simulated time.

The four real nodes talk over DDS on a private domain; an InteractionRecorder listens. The managed
nodes start unconfigured and are brought up through their lifecycle services (sim, then
observer, then estimator), as an operator would. The sim node owns the clock (/clock, paced at
``real_time_factor``), every other node runs with use_sim_time, and the player publishes each
bag message when the simulated clock reaches its recorded time (stamps rewritten to that time).
The robot is one option, ``robot``: every node gets it as its ``robot`` parameter (joint names,
frames, mocap transform, limits and the simulated arm follow from its
description). Used by ``mixture-ip demo`` and the integration tests.

``command_delay`` (s of simulated time) puts a slow link between the estimator and the sim: the
estimator publishes its commands to a relay (nodes.command_delay) that passes each one on
unchanged once the simulated clock has advanced by that much since it arrived (DDS on both hops).
"""

from dataclasses import asdict
import time
from pathlib import Path

import numpy as np
import rclpy
from rclpy.context import Context
from rclpy.parameter import Parameter
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from mixture_ip_ros.nodes.bag_player import BagPlayer
from mixture_ip_ros.nodes.command_delay import CommandDelay
from mixture_ip_ros.nodes.estimator_node import EstimatorNode
from mixture_ip_ros.nodes.lifecycle_client import LifecycleClient
from mixture_ip_ros.nodes.observer_node import ObserverNode
from mixture_ip_ros.nodes.recorder import InteractionRecorder
from mixture_ip_ros.nodes.sim_node import COMMAND_TOPIC, SimNode
from mixture_ip_ros.nodes.spinning import spin_in_thread
from mixture_ip_ros.core.stamps import stamp_to_ns
from mixture_ip_ros.io.records import InteractionRecord
from mixture_ip_ros.robot.description import load_description
from mixture_ip_ros.robot.kinematics import RobotKinematics


def _params(d: dict):
    return [Parameter(k, value=v) for k, v in d.items()]


class ClosedLoop:
    """Start the nodes once, then ``run_interaction(bag)`` per replayed demonstration."""

    def __init__(self, model_path, *, robot=None, domain_id=None, real_time_factor=1.0,
                 home=None, sim_params=None, observer_params=None, estimator_params=None,
                 command_delay=None):
        self.robot = load_description(robot)
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        sim_time = [Parameter('use_sim_time', value=True)]
        managed = [Parameter('autostart', value=False)]
        which = {'robot': self.robot.source}
        self.relay = None
        if command_delay is not None:
            self.relay = CommandDelay(context=self.context, parameter_overrides=_params(
                {'delay': float(command_delay)}))
            estimator_params = {**(estimator_params or {}), 'trajectory_topic':
                                self.relay.get_parameter('input_topic').value}
        # One process, one DDS participant: FastDDS asserts no liveliness within it, and the
        # loop sends the arm home itself (go_home): any publisher commands, none is watched.
        self.sim = SimNode(context=self.context, parameter_overrides=managed + _params(
            {**which, 'simulated_time': True, 'real_time_factor': float(real_time_factor),
             'commander': '', 'command_lease': 0.0, **(sim_params or {})}))
        self.observer = ObserverNode(context=self.context, parameter_overrides=(
            managed + sim_time + _params({**which, **(observer_params or {})})))
        self.estimator = EstimatorNode(context=self.context, parameter_overrides=(
            managed + sim_time + _params({**which, 'model_path': str(model_path),
                                          **(estimator_params or {})})))
        self.recorder = InteractionRecorder(context=self.context, parameter_overrides=sim_time)
        self._spinning = {node: spin_in_thread(node) for node in (
            self.sim, self.observer, self.estimator, self.recorder, self.relay)
            if node is not None}
        self._operator = rclpy.create_node('closed_loop_operator', context=self.context)
        self.lifecycle = {node.get_name(): LifecycleClient(self._operator, node.get_name())
                          for node in (self.sim, self.observer, self.estimator)}
        for name in ('sim_node', 'observer_node', 'estimator_node'):
            for transition in ('configure', 'activate'):
                if not self.lifecycle[name].change(transition, timeout=60.0):
                    self.close()
                    refusal = {'sim_node': self.sim, 'observer_node': self.observer,
                               'estimator_node': self.estimator}[name].refusal
                    raise ValueError(f'{name} failed to {transition}: {refusal}')
        self.home = np.asarray(home if home is not None else self.sim.sim.q, dtype=float)
        # Straight to the sim's command topic (past the relay, if there is one).
        self._home_pub = self.recorder.create_publisher(
            JointTrajectory, self.sim.resolve_topic_name(COMMAND_TOPIC), 10)
        self.kinematics = RobotKinematics(self.robot)
        self.wrist_topic = self.observer.params.wrist_topic
        self.labels = (self.estimator.metadata.get('component_labels')
                       or [f'component_{k}' for k in range(self.estimator.model.n_components)])

    def set_command_delay(self, seconds: float) -> None:
        """Change the relay's delay (a loop started with ``command_delay`` only)."""
        if self.relay is None:
            raise ValueError('this loop has no command relay (start it with command_delay)')
        result = self.relay.set_parameters([Parameter('delay', value=float(seconds))])[0]
        if not result.successful:
            raise ValueError(result.reason)

    def set_state(self, node_name: str, transition: str) -> bool:
        """Trigger a lifecycle transition of one of the nodes through its service."""
        return self.lifecycle[node_name].change(transition)

    # ------------------------------------------------------------------ time
    def now(self) -> float:
        return self.sim.sim.time

    def wait_until(self, predicate, timeout: float = 120.0, what: str = 'the condition'):
        """Block until ``predicate()`` holds (the nodes run in their own threads)."""
        deadline = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > deadline:
                raise TimeoutError(f'timed out waiting for {what}')
            time.sleep(0.001)

    def wait_sim(self, seconds: float, timeout: float = 120.0):
        """Block until the simulated clock advanced by ``seconds``."""
        end = self.now() + seconds
        self.wait_until(lambda: self.now() >= end, timeout, 'the simulation to advance')

    def go_home(self, duration: float = 2.0):
        """Send the robot back to its start posture and wait until it is there."""
        msg = JointTrajectory()
        msg.joint_names = list(self.sim.sim.joint_names)
        pt = JointTrajectoryPoint(positions=self.home.tolist(),
                                  velocities=[0.0] * len(msg.joint_names))
        pt.time_from_start.sec = int(duration)
        pt.time_from_start.nanosec = int((duration % 1) * 1e9)
        msg.points = [pt]
        self._home_pub.publish(msg)
        self.wait_sim(duration + 0.3)

    # ------------------------------------------------------------------ one interaction
    def run_interaction(self, bag, *, true_pattern=None, target=None, settle=1.5,
                        extra_params=None, timeout=120.0) -> InteractionRecord:
        """Replay the human's wrist stream of ``bag`` through the loop (the recorded robot joints
        are training data and stay in the bag); returns what happened."""
        self.recorder.clear()
        self.sim.sim.reset_tracking()
        start = self.now()
        counts = self._sim_counts()
        sent = self.estimator.plan_latency.count
        player = BagPlayer(context=self.context, parameter_overrides=[
            Parameter('use_sim_time', value=True)] + _params(
            {'bag': str(bag), 'rewrite_stamps': True, 'topics': [self.wrist_topic],
             **(extra_params or {})}))
        self._spinning[player] = spin_in_thread(player)
        try:
            if not player.wait_until_finished(timeout):
                raise TimeoutError(f'playing {bag} did not finish within {timeout} s')
            self.wait_sim(settle)
            # Every plan the estimator published is in the record: on a loaded machine the
            # recorder's thread can lag the settle on the simulated clock.
            self.wait_until(lambda: self.recorder.plans_received()
                            >= self.estimator.plan_latency.count - sent, timeout,
                            "the recorder to receive the estimator's plans")
        finally:
            self._stop(player)
            player.destroy_node()
        return self._record(Path(bag).name, true_pattern, target, start, counts)

    def _sim_counts(self) -> dict:
        sim = self.sim.sim
        return {'accepted': sim.accepted_count, 'rejections': sim.rejection_count,
                'retimed': sim.retimed_count}

    def _record(self, name, true_pattern, target, start, counts) -> InteractionRecord:
        snap = self.recorder.snapshot()
        joints = [(t, q) for t, q in snap['joints'] if t >= start]
        q = np.array([q for _, q in joints]).reshape(-1, self.kinematics.dof)
        inter = self.estimator.interactions[-1] if self.estimator.interactions else None
        K = len(self.labels)
        post = np.array([d for _, d in snap['posterior']]) if snap['posterior'] else np.zeros(
            (0, K + 4))
        events = dict((kind, t) for t, kind in reversed(snap['events']))
        commands = [command_arrays(t, msg) for t, msg in snap['trajectories'] if t >= start]
        sim = self.sim.sim
        during = {k: v - counts[k] for k, v in self._sim_counts().items()}
        k = None if inter is None else (inter.final_component if inter.final_component is not None
                                        else inter.component)
        return InteractionRecord(
            name=name, true_pattern=true_pattern, component_labels=list(self.labels),
            t=np.array([t for t, _ in joints]), q=q,
            flange=self.kinematics.fk_positions(q) if len(q) else np.zeros((0, 3)),
            wrist_t=np.array([t for t, _ in snap['wrist']]),
            wrist=np.array([p for _, p in snap['wrist']]).reshape(-1, 3),
            posterior_t=np.array([t for t, _ in snap['posterior']]),
            posterior=post[:, :K], alpha=post[:, K], phase=post[:, K + 1],
            onset_time=events.get('onset'), end_time=events.get('end'),
            commit_time=None if inter is None else inter.commit_time,
            chosen_pattern=self.labels[k] if k is not None else None,
            commit_fraction=None if inter is None else inter.commit_phase,
            target=None if target is None else np.asarray(target),
            extra={'interaction': None if inter is None else asdict(inter),
                   'non_finite_commands': self.recorder.non_finite_commands,
                   'commands': commands,
                   # the estimator stamps its last plan with the 'end' event's stamp
                   'final_plan_received': 'end' in events and any(
                       c['stamp'] == events['end'] and len(c['times']) for c in commands),
                   'sim_accepted': during['accepted'], 'sim_rejections': during['rejections'],
                   'last_rejection': sim.last_rejection if during['rejections'] else None,
                   'sim_retimed': during['retimed'],
                   'last_retime_delay': sim.last_delay if during['retimed'] else None,
                   'command_delay': (None if self.relay is None
                                     else self.relay.get_parameter('delay').value),
                   'robot': self.robot.source, 'tracking': sim.tracking_error()})

    def close(self):
        for client in self.lifecycle.values():
            client.destroy()
        self._operator.destroy_node()
        nodes = [n for n in (self.sim, self.observer, self.estimator, self.recorder, self.relay)
                 if n is not None]
        for node in nodes:
            self._stop(node)
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown(context=self.context)

    def _stop(self, node):
        if node not in self._spinning:
            return
        executor, thread = self._spinning.pop(node)
        executor.shutdown()
        thread.join(timeout=5)


def command_arrays(received: float, msg) -> dict:
    """A JointTrajectory as received (``received``: simulated s): its stamp (s), times from
    start (n,) and positions, velocities, accelerations (n, joints; NaN where not given)."""
    n, dof = len(msg.points), len(msg.joint_names)

    def field(name):
        out = np.full((n, dof), np.nan)
        for i, pt in enumerate(msg.points):
            values = getattr(pt, name)
            if len(values):
                out[i] = values
        return out
    return {'t': received, 'stamp': stamp_to_ns(msg.header.stamp) * 1e-9,
            'joint_names': list(msg.joint_names),
            'times': np.array([stamp_to_ns(pt.time_from_start) * 1e-9 for pt in msg.points]),
            'positions': field('positions'), 'velocities': field('velocities'),
            'accelerations': field('accelerations')}


def points_beyond_limits(commands, kinematics) -> int:
    """How many points of the recorded ``commands`` lie beyond the robot's limits: a position,
    speed or acceleration, or the mean speed from the point before (the limits by joint name)."""
    index = {name: j for j, name in enumerate(kinematics.joint_names)}
    lower, upper = kinematics.lower, kinematics.upper
    speed, accel = kinematics.velocity_limit, kinematics.acceleration_limit
    beyond = 0
    for c in commands:
        j = [index[name] for name in c['joint_names']]
        pos, vel, acc = c['positions'], c['velocities'], c['accelerations']
        bad = (pos < lower[j]) | (pos > upper[j]) | (np.abs(vel) > speed[j]) \
            | (np.abs(acc) > accel[j])
        bad = bad.any(axis=1)
        if len(pos) > 1:
            mean = np.abs(np.diff(pos, axis=0)) / np.diff(c['times'])[:, None]
            bad[1:] |= (mean > speed[j]).any(axis=1)
        beyond += int(bad.sum())
    return beyond
