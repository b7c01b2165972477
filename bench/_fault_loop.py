"""What bench/faults.py and test/test_faults.py share; not a bench itself.

The nodes run as separate processes started as `mixture-ip run` starts them (app.bringup's
node_commands, node_parameters and Children: params files, simulated time, the bag's wrist
replayed on the sim's clock); this process kills and restarts them and watches with a probe
node of its own (:class:`Probe`): /joint_states (positions and speeds, stamped in simulated
time), every JointTrajectory on the arm's command topic, the observer's events, the nodes' log
lines on /rosout and /diagnostics. The measures (:func:`after_kill`, :func:`interaction`) are
read from what the probe recorded, in simulated time. A restarted node gets its executable's
command again; its log goes beside the killed one's (``NAME#2.log``).

The sim owns /clock: while it is dead no simulated time passes anywhere, so what follows its
kill is watched on the wall clock (:meth:`NodeSet.watch_wall`).
"""

from pathlib import Path
import re
import signal
import tempfile
import time
from types import SimpleNamespace

import numpy as np

from mixture_ip_ros.app.bringup import (NODES, OBSERVATION_TOPIC, Children, EventLines,
                                        node_commands, node_parameters, run_environment)
from mixture_ip_ros.app.closed_loop import command_arrays, points_beyond_limits
from mixture_ip_ros.app.demo import demonstrated_target, hand_error_cm
from mixture_ip_ros.io.bags import ONSET_KEY, END_KEY, bag_custom_data
from mixture_ip_ros.robot.kinematics import RobotKinematics

ROOT = Path(__file__).resolve().parents[1]
REST_SPEED = 1e-3          # rad/s: every joint slower is at rest
SETTLE = 1.5               # s of simulated time after the bag's end, as the demo waits
LABEL = re.compile(r'component \d+ \(([^)]*)\)')
DIAGNOSTIC_NODES = ('sim_node', 'estimator_node', 'observer_node')
STRAY_FRAME = 'stray'      # header.frame_id of the stray publisher's commands


class FaultRunError(RuntimeError):
    """A run that could not go on (a node did not come up, an interaction never ended)."""


class Probe:
    """The bench's node, in a DDS participant of its own. Each list grows in arrival order;
    ``seq`` fields index /joint_states received so far (a mark in time that survives a sim
    restart, whose clock starts again at 0)."""

    def __init__(self, domain: int):
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        from diagnostic_msgs.msg import DiagnosticArray
        from rcl_interfaces.msg import Log
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Header
        from trajectory_msgs.msg import JointTrajectory
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = rclpy.create_node('fault_probe', context=self.context, enable_rosout=False)
        reliable = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        rosout = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                            durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.t, self.q, self.qd = [], [], []
        self.plans, self.events, self.lines = [], [], []
        self.diagnostics = {n: [] for n in DIAGNOSTIC_NODES}
        n = self.node
        n.create_subscription(JointState, '/joint_states', self._on_joints, reliable)
        # A subscription requesting no lease matches every publisher (the estimator's, a stray).
        n.create_subscription(JointTrajectory, '/joint_trajectory', self._on_plan, reliable)
        n.create_subscription(Header, '/observer/event', self._on_event, reliable)
        n.create_subscription(Log, '/rosout', self._on_log, rosout)
        n.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, reliable)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(n)

    @property
    def now(self):
        """Simulated time (s): the latest joint state's stamp; None before the first."""
        return self.t[-1] if self.t else None

    @property
    def seq(self) -> int:
        return len(self.t)

    def _on_joints(self, m):
        self.t.append(m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec)
        self.q.append(np.array(m.position))
        self.qd.append(np.array(m.velocity))

    def _on_plan(self, m, info):
        # sent_ns: when the publisher wrote it (system clock, as kill_ns), so a plan written
        # before a kill and delivered after it on a loaded machine is not taken as sent after
        self.plans.append({'seq': self.seq, 't': self.now, 'empty': not m.points,
                           'sent_ns': info['source_timestamp'],
                           'stray': m.header.frame_id == STRAY_FRAME,
                           'command': command_arrays(self.now, m) if m.points else None})

    def _on_event(self, m):
        self.events.append({'seq': self.seq, 'kind': m.frame_id,
                            'stamp': m.stamp.sec + 1e-9 * m.stamp.nanosec})

    def _on_log(self, m):
        if m.name in NODES:
            self.lines.append({'seq': self.seq, 't': self.now, 'node': m.name,
                               'level': int(m.level), 'msg': m.msg})

    def _on_diagnostics(self, m):
        for status in m.status:
            node = status.name.split(':')[0]
            if node in self.diagnostics:
                self.diagnostics[node].append(
                    {'seq': self.seq, 'stamp': m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec,
                     **{v.key: v.value for v in status.values}})

    def spin(self, timeout: float = 0.01) -> None:
        self.executor.spin_once(timeout_sec=timeout)

    def gids(self, topic: str, kind: str = 'subscriptions') -> set:
        """The endpoint gids the graph shows on ``topic`` (``kind``: subscriptions or
        publishers)."""
        info = getattr(self.node, f'get_{kind}_info_by_topic')(topic)
        return {bytes(i.endpoint_gid) for i in info}

    def close(self) -> None:
        import rclpy
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


class NodeSet:
    """sim_node, observer_node and estimator_node as `mixture-ip run` starts them, bag players
    started one per interaction, the probe; kill and restart by name."""

    def __init__(self, model, domain: int, log_dir=None, robot: str = 'iiwa14'):
        self.model, self.robot = model, robot
        self.log_dir = Path(tempfile.mkdtemp(prefix='faults_') if log_dir is None else log_dir)
        self.children = Children(run_environment(domain), self.log_dir)
        self.probe = Probe(domain)
        self.keys = {}          # node -> its present process's key in children.procs
        self.started = {}       # node -> probe.seq when its present process started
        self.killed = set()     # keys of processes killed on purpose
        self.players = 0

    def _commands(self, bag='') -> dict:
        """{executable: argv} of a replay (simulated time): only the player's depends on the
        bag."""
        return dict(node_commands(node_parameters(self.model, self.robot, str(bag))))

    def _start(self, name: str, argv) -> str:
        n = sum(k.split('#')[0] == name for k in self.children.procs)
        key = name if n == 0 else f'{name}#{n + 1}'
        self.children.start(key, argv)
        self.keys[name] = key
        self.started[name] = self.probe.seq
        return key

    def proc(self, name: str):
        return self.children.procs[self.keys[name]]

    def died(self) -> dict:
        """{key: exit code} of the node processes that exited unasked (bag players end)."""
        return {k: c for k, c in self.children.exited().items()
                if k not in self.killed and not k.startswith('bag_player')}

    def wait(self, condition, timeout: float, what: str, required: bool = True) -> bool:
        """Spin until ``condition()`` (True); FaultRunError when a node dies, and after
        ``timeout`` wall s (far above any run: they only catch a run that cannot go on) unless
        not ``required`` (False then)."""
        deadline = time.monotonic() + timeout
        while not condition():
            died = self.died()
            if not died and time.monotonic() > deadline and not required:
                return False
            if died or time.monotonic() > deadline:
                why = f'died {died}' if died else f'not within {timeout:g} s'
                tails = {k: self.children.log_tail(k, 4) for k in (died or self.keys.values())}
                raise FaultRunError(f'waiting for {what}: {why}; logs: {tails}')
            self.probe.spin(0.01)
        return True

    def watch_wall(self, seconds: float) -> None:
        """Spin for ``seconds`` of the wall clock (while the sim, and so simulated time, is
        stopped)."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.probe.spin(0.01)

    def wait_sim(self, until: float, timeout: float = 60.0) -> None:
        self.wait(lambda: self.probe.now is not None and self.probe.now >= until, timeout,
                  f'simulated time {until:.2f} s')

    # -- the nodes ------------------------------------------------------------------------
    def start(self) -> None:
        """The three nodes; returns once the estimator listens to the observer and the sim
        runs (as `mixture-ip run` waits before it starts the player)."""
        commands = self._commands()
        listeners = self.probe.gids(OBSERVATION_TOPIC)
        for name in ('sim_node', 'observer_node', 'estimator_node'):
            self._start(name, commands[name])
        self.wait_ready('estimator_node', listeners)
        self.wait_ready('sim_node', self.probe.seq)

    def ready_token(self, name: str):
        """What :meth:`wait_ready` compares with, read before ``name`` (re)starts."""
        if name == 'sim_node':
            return self.probe.seq
        return self.probe.gids(OBSERVATION_TOPIC if name == 'estimator_node'
                               else '/mocap/wrist')

    def wait_ready(self, name: str, token, timeout: float = 90.0) -> None:
        """Until ``name``'s new process is in the graph (a subscription the graph did not show
        before: a killed node's stays there until DDS drops its participant) or, for the sim,
        publishes joint states again."""
        if name == 'sim_node':
            self.wait(lambda: self.probe.seq > token + 10, timeout, 'the sim running')
        else:
            topic = OBSERVATION_TOPIC if name == 'estimator_node' else '/mocap/wrist'
            self.wait(lambda: self.probe.gids(topic) - token, timeout, f'{name} listening')

    def kill(self, name: str) -> float:
        """SIGKILL ``name``'s process; the simulated time of the latest joint state then."""
        proc = self.proc(name)
        proc.send_signal(signal.SIGKILL)
        self.killed.add(self.keys[name])
        t = self.probe.now
        proc.wait()
        # once reaped it writes nothing: a plan written after this was written by another
        self.kill_ns = time.time_ns()
        return t

    def restart(self, name: str) -> None:
        """``name`` again, with its command; returns once it is up (:meth:`wait_ready`)."""
        token = self.ready_token(name)
        self._start(name, self._commands()[name])
        self.wait_ready(name, token)

    def play(self, bag) -> str:
        """Start a bag player for ``bag`` (the wrist, stamps on the sim's clock, after the
        observer subscribes and 2 s more); its key."""
        self.players += 1
        return self._start('bag_player', self._commands(bag)['bag_player'])

    def player_done(self) -> bool:
        return self.proc('bag_player').poll() is not None

    def stop_player(self) -> None:
        """SIGINT to the present bag player, as a user's Ctrl-C; waits for it."""
        proc = self.proc('bag_player')
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            proc.wait(timeout=20)

    def errors(self) -> list:
        """Error lines of the nodes (on /rosout) and tracebacks in their logs."""
        out = [f"{line['node']}: {line['msg']}" for line in self.probe.lines
               if line['level'] >= 40]
        for log in sorted(self.log_dir.glob('*.log')):
            text = log.read_text(errors='replace')
            if 'Traceback' in text:
                out.append(f'{log.name}: ' + text[text.index('Traceback'):][:600])
        return out

    def close(self) -> dict:
        """Stop every process (SIGINT, then kill); {key: exit code}."""
        try:
            return self.children.stop()
        finally:
            self.probe.close()


# -- measures ---------------------------------------------------------------------------------
def speeds(qd) -> np.ndarray:
    return np.abs(np.asarray(qd)).max(axis=1)


def after_kill(t, q, qd, t_kill: float, kinematics) -> dict:
    """What the arm did from the joint state at ``t_kill`` to the last one: its speed then,
    when it came to rest for good (speed < REST_SPEED on every later sample; None: still
    moving at the end), the flange's distance from where it was (cm) at rest (or at the end)
    and the length of its path."""
    t, q = np.asarray(t), np.asarray(q)
    i = int(np.searchsorted(t, t_kill - 1e-9))
    speed = speeds(qd)
    moving = np.flatnonzero(speed[i:] >= REST_SPEED)
    rest = i if not moving.size else i + moving[-1] + 1
    end = min(rest, len(t) - 1)
    flange = kinematics.fk_positions(q[i:end + 1])
    return {'speed_at_kill': float(speed[i]),
            'max_speed_after_kill': float(speed[i:].max()),
            'rest_after_kill_s': float(t[rest] - t_kill) if rest < len(t) else None,
            'flange_travel_cm': float(100 * np.linalg.norm(flange[-1] - flange[0])),
            'flange_path_cm': float(100 * np.linalg.norm(np.diff(flange, axis=0),
                                                          axis=1).sum()),
            'watched_s': float(t[-1] - t_kill)}


def stopping_time(qd, kinematics) -> float:
    """The time the arm needs to brake from speeds ``qd`` at its acceleration limits (the
    slowest joint's, as robot.trajectory.stopping_trajectory)."""
    return float(np.max(np.abs(qd) / kinematics.acceleration_limit))


def human_end(bag, onset_stamp: float) -> float:
    """The simulated time the bag's annotated movement ends, from the observer's onset stamp."""
    custom = bag_custom_data(bag)
    return onset_stamp + (int(custom[END_KEY]) - int(custom[ONSET_KEY])) * 1e-9


def estimator_outcome(lines) -> dict:
    """The committed and the final label of one interaction from the estimator's log lines,
    and the line that ended it (its report, or why it held)."""
    events = EventLines()
    out = {'committed_to': None, 'label': None, 'result': None}
    for line in lines:
        if line['node'] != 'estimator_node':
            continue
        said = events.estimator_log(line['msg'])
        if said is None and line['msg'].endswith('the robot holds'):
            said = 'result: ' + line['msg']      # held, unexplained: no end report follows
        if said is None:
            continue
        found = LABEL.search(said)
        if said.startswith('commit: ') and out['committed_to'] is None:
            out['committed_to'] = found and found.group(1)
        elif said.startswith('result: ') and out['result'] is None:
            out['result'] = said[len('result: '):]
            if said.startswith('result: interaction done'):
                out['label'] = found and found.group(1)
    return out


def latest(diagnostics, node: str, since_seq: int = 0):
    """The latest /diagnostics values of ``node`` received at or after ``since_seq``."""
    found = [d for d in diagnostics[node] if d['seq'] >= since_seq]
    return found[-1] if found else None


def count(values, key: str) -> int:
    return int(values[key]) if values and values.get(key) not in (None, '') else 0


def interaction(ns: NodeSet, bag, truth: str, target_bag=None, timeout: float = 90.0) -> dict:
    """Replay ``bag`` through the running nodes: the right pattern (committed and final label
    the bag's), the hand error (cm, the demo's: flange to where the demonstration's hand ended)
    SETTLE s after the bag ended with the arm at rest, the plans sent, their points beyond the
    limits, and what the sim refused (limits, sender) meanwhile, from its /diagnostics.
    ``target_bag``: the bag whose demonstration gives the target (default ``bag``)."""
    p = ns.probe
    kin = RobotKinematics(ns.robot)
    # the present sim's counts (a restarted sim counts from 0)
    sim_before = latest(p.diagnostics, 'sim_node', ns.started['sim_node'])
    lines0, plans0 = len(p.lines), len(p.plans)
    ns.play(bag)
    ns.wait(ns.player_done, timeout, f'the bag {Path(bag).name} played')
    ns.wait(lambda: estimator_outcome(p.lines[lines0:])['result'] is not None, 15.0,
            'the estimator reporting the interaction', required=False)
    ns.wait_sim(p.now + SETTLE)
    rest_deadline = p.now + 5.0
    ns.wait(lambda: speeds(p.qd[-1:])[0] < REST_SPEED or p.now > rest_deadline, 30.0,
            'the arm at rest')
    seq_end = p.seq
    ns.wait(lambda: latest(p.diagnostics, 'sim_node', seq_end + 1) is not None, 10.0,
            'a sim report')
    sim_after = latest(p.diagnostics, 'sim_node', seq_end + 1)
    target = demonstrated_target(target_bag or bag, kin)[0]
    flange = kin.fk(p.q[-1])[0]
    plans = [c for c in p.plans[plans0:] if not c['empty'] and not c['stray']]
    outcome = estimator_outcome(p.lines[lines0:])
    delta = {k: count(sim_after, k) - count(sim_before, k)
             for k in ('commands_accepted', 'commands_rejected', 'commands_refused_sender')}
    return {'bag': Path(bag).name, 'truth': truth, **outcome,
            'right': outcome['committed_to'] == outcome['label'] == truth,
            'hand_error_cm': hand_error_cm(SimpleNamespace(flange=np.array([flange]),
                                                            target=target)),
            'at_rest': bool(speeds(p.qd[-1:])[0] < REST_SPEED),
            'plans': len(plans), 'holds': sum(c['empty'] for c in p.plans[plans0:]),
            'points_beyond_limits': points_beyond_limits([c['command'] for c in plans], kin),
            'sim_accepted': delta['commands_accepted'],
            'sim_rejected': delta['commands_rejected'],
            'sim_refused_sender': delta['commands_refused_sender']}
