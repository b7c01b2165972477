"""`mixture-ip run`: the nodes as separate processes, as a user would start them by hand (README,
"The nodes"), with one line per event on the console and a clean stop.

The children are started in their own session: Ctrl-C reaches this process only, which then
sends SIGINT to each child once, waits, and kills what is still running. Their logs go to files
(one per node), so that the console shows the interaction: the observer's onsets and ends, the
estimator's beliefs (from /estimator/posterior) and its commits, switches and results (its log
lines on /rosout, which carry the label and phase it decided on). rclpy is imported only by
:func:`run`; :data:`NODES`, :data:`PARAMS_FILES` and :data:`LAUNCH_ARGUMENTS` are what
launch/mixture_ip.launch.py must name too (test/test_bringup.py compares them)."""

from dataclasses import dataclass, field
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

from mixture_ip_ros.core.share import config_path

NODES = ('sim_node', 'observer_node', 'estimator_node', 'bag_player')
# The estimator's input from the observer (observation_topic's default), and how long the
# player waits for the estimator to listen to it.
OBSERVATION_TOPIC = '/observer/wrist'
LISTEN_TIMEOUT = 30.0
PARAMS_FILES = {'sim_node': 'sim.yaml', 'observer_node': 'observer.yaml',
                'estimator_node': 'estimator.yaml', 'bag_player': 'bag_player.yaml'}
# The launch file's arguments: the parameters a user chooses per run.
LAUNCH_ARGUMENTS = ('model_path', 'robot', 'bag')
# How a replayed bag is played into the loop: only the wrist, stamped on the simulated clock,
# once the observer subscribes and 2 s more, in which the other nodes discover each other.
BAG_PLAYER_PARAMETERS = {'rewrite_stamps': True, 'topics': ['/mocap/wrist'], 'start_delay': 2.0,
                         'wait_for_subscribers': 1}
# A belief line is printed when k* changes or its probability moved this much since the last.
BELIEF_STEP = 0.1


def node_parameters(model, robot: str, bag=None, sim: bool = True) -> dict:
    """{executable: {parameter: value}} set on top of each node's params file. With the sim,
    a replayed bag runs on its simulated clock (use_sim_time, the bag's stamps rewritten to
    it); live mocap, stamped on the wall clock, runs on the wall clock, the sim's too."""
    sim_time = {'use_sim_time': True} if sim and bag is not None else {}
    nodes = {}
    if sim:
        nodes['sim_node'] = {'robot': robot, **({} if bag is not None
                                                else {'simulated_time': False})}
    nodes['observer_node'] = {**sim_time, 'robot': robot}
    nodes['estimator_node'] = {**sim_time, 'model_path': str(model), 'robot': robot}
    if bag is not None:
        nodes['bag_player'] = {**sim_time, **BAG_PLAYER_PARAMETERS, 'bag': str(bag)}
    return nodes


def ros_value(value) -> str:
    """A value as `-p name:=value` takes it (YAML)."""
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, (list, tuple)):
        return '[' + ', '.join(repr(v) if isinstance(v, str) else ros_value(v)
                               for v in value) + ']'
    return str(value)


def node_commands(parameters: dict, bindir=None) -> list:
    """[(executable, argv)] for :func:`node_parameters`' nodes, in the order to start them."""
    bindir = Path(sys.executable).parent if bindir is None else Path(bindir)
    commands = []
    for name in NODES:
        if name not in parameters:
            continue
        argv = [str(bindir / name), '--ros-args', '--params-file',
                str(config_path(PARAMS_FILES[name]))]
        for key, value in parameters[name].items():
            argv += ['-p', f'{key}:={ros_value(value)}']
        commands.append((name, argv))
    return commands


def run_environment(domain=None, base=None) -> dict:
    """The children's environment: the caller's, with the domain given (else the caller's),
    discovery on this machine unless the caller chose otherwise, one BLAS thread per node."""
    env = dict(os.environ if base is None else base)
    if domain is not None:
        env['ROS_DOMAIN_ID'] = str(domain)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    for name in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS'):
        env.setdefault(name, '1')
    return env


class Children:
    """The node processes: started in their own session, logs in ``log_dir``; :meth:`stop`
    sends SIGINT to each, waits up to ``grace`` s for all, then kills the rest."""

    def __init__(self, env: dict, log_dir: Path):
        self.env, self.log_dir = env, Path(log_dir)
        self.procs = {}

    def start(self, name: str, argv: list) -> None:
        self.log_dir.mkdir(parents=True, exist_ok=True)
        with open(self.log_dir / f'{name}.log', 'w') as log:
            self.procs[name] = subprocess.Popen(argv, env=self.env, stdout=log,
                                                stderr=subprocess.STDOUT,
                                                stdin=subprocess.DEVNULL,
                                                start_new_session=True)

    def exited(self) -> dict:
        """{name: exit code} of the children that have exited."""
        return {n: p.returncode for n, p in self.procs.items() if p.poll() is not None}

    def stop(self, grace: float = 10.0) -> dict:
        """Stop every child; {name: exit code} (negative: killed by that signal)."""
        for p in self.procs.values():
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
        deadline = time.monotonic() + grace
        for p in self.procs.values():
            try:
                p.wait(timeout=max(deadline - time.monotonic(), 0.0))
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        return {n: p.returncode for n, p in self.procs.items()}

    def log_tail(self, name: str, lines: int = 5) -> str:
        try:
            text = (self.log_dir / f'{name}.log').read_text(errors='replace')
        except OSError:
            return ''
        return '\n'.join(text.strip().splitlines()[-lines:])


@dataclass
class EventLines:
    """The console lines of the run, from the messages the monitor receives (no ROS here):
    each method returns the line to print, or None."""

    labels: list = None
    onsets: int = 0
    ends: int = 0
    results: int = 0
    _belief: tuple = field(default=None, repr=False)

    def name(self, k: int) -> str:
        if self.labels and 0 <= k < len(self.labels):
            return self.labels[k]
        return f'component {k}'

    def event(self, kind: str) -> str:
        """An observer event (onset, end, gap)."""
        if kind == 'onset':
            self.onsets += 1
            self._belief = None
            return f'onset: interaction {self.onsets} begins'
        if kind == 'end':
            self.ends += 1
            return f'end: interaction {self.onsets} ends'
        if kind == 'gap':
            return 'gap: the wrist was not seen for a moment'
        return None

    def posterior(self, values) -> str:
        """A /estimator/posterior message [p_0 .. p_K-1, alpha, phase, confidence, k]."""
        values = list(values)
        if len(values) < 5:
            return None
        probabilities, (alpha, phase, confidence, k) = values[:-4], values[-4:]
        k = int(round(k))
        if (self._belief is not None and self._belief[0] == k
                and abs(confidence - self._belief[1]) < BELIEF_STEP):
            return None
        self._belief = (k, confidence)
        beliefs = ', '.join(f'{self.name(i)} {p:.2f}' for i, p in enumerate(probabilities))
        return f'belief: {beliefs}; most likely {self.name(k)} at phase {phase:.2f}'

    def estimator_log(self, text: str) -> str:
        """A line the estimator logged: its commits, switches and results are events."""
        if text.startswith('committed to '):
            return 'commit: ' + text[len('committed to '):]
        if text.startswith('switching from '):
            return 'switch: ' + text[len('switching from '):]
        # An interaction also ends without an 'end' event: its wrist gone silent, or the
        # clock reset (estimation.planner: '...: the interaction ends').
        if (text.startswith('interaction done') or text.startswith('interaction ended')
                or ': the interaction ends' in text):
            self.results += 1
            return 'result: ' + text
        return None

    @property
    def settled(self) -> bool:
        """Every interaction begun has ended and the estimator reported on it."""
        return self.onsets > 0 and self.ends >= self.onsets and self.results >= self.onsets


def _labels(model) -> list:
    from mixture_ip_ros.io.model_file import load_model
    meta = load_model(model)[1]
    return list(meta.get('component_labels') or [])


def run(model, robot: str, bag=None, live: bool = False, sim: bool = True, domain=None,
        log_dir=None, end_timeout: float = 15.0, out=print) -> int:
    """Start the nodes, print the events until Ctrl-C (or, with a bag, until the bag is played
    and its last interaction reported, at most ``end_timeout`` s after the bag ends), stop them.
    Returns 0, or 1 when a node exited on its own."""
    import tempfile
    if (bag is None) == (not live):
        raise ValueError('give either a bag (--bag) or --live')
    if bag is not None and not Path(bag).is_dir():
        raise ValueError(f'bag {bag} is not a folder (a rosbag2 directory)')
    env = run_environment(domain)
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    lines = EventLines(labels=_labels(model))
    log_dir = Path(tempfile.mkdtemp(prefix='mixture_ip_run_') if log_dir is None else log_dir)
    commands = node_commands(node_parameters(model, robot, bag, sim=sim))
    children = Children(env, log_dir)
    start = time.monotonic()

    def say(text):
        if text is not None:
            out(f'[{time.monotonic() - start:7.2f} s] {text}', flush=True)

    # Ctrl-C and SIGTERM stop the children, also when started in the background (where a
    # shell makes this process ignore SIGINT).
    previous = {sig: signal.signal(sig, signal.default_int_handler)
                for sig in (signal.SIGINT, signal.SIGTERM)}
    code = 0
    monitor = None
    try:
        # The player starts once the estimator listens to the observer: a replay whose first
        # samples reach the observer alone would make the first interaction start later than
        # the same bag's next replay (bag_player's wait_for_subscribers covers the observer).
        for name, argv in commands:
            if name != 'bag_player':
                children.start(name, argv)
        monitor = _Monitor(lines, say, int(env.get('ROS_DOMAIN_ID', '0')))
        for name, argv in commands:
            if name == 'bag_player':
                if not monitor.wait_for_listener(OBSERVATION_TOPIC, children, LISTEN_TIMEOUT):
                    say(f'the estimator is not listening on {OBSERVATION_TOPIC} after '
                        f'{LISTEN_TIMEOUT:g} s: playing the bag anyway')
                children.start(name, argv)
        say(f"started {', '.join(n for n, _ in commands)} on ROS domain "
            f"{env.get('ROS_DOMAIN_ID', '0')}; their logs are in {log_dir}")
        bag_done_at = None
        while True:
            monitor.spin_once(0.1)
            exited = children.exited()
            died = [n for n in exited if n != 'bag_player']
            if died:
                for n in died:
                    say(f'{n} exited (code {exited[n]}): {children.log_tail(n, 3)}')
                code = 1
                break
            if 'bag_player' in exited and bag_done_at is None:
                bag_done_at = time.monotonic()
                say('the bag is played' + ('' if exited['bag_player'] == 0 else
                                           f" (bag_player exit code {exited['bag_player']}: "
                                           f"{children.log_tail('bag_player', 3)})"))
            if bag_done_at is not None and (lines.settled
                                           or time.monotonic() - bag_done_at > end_timeout):
                if not lines.settled:
                    say('stopping: no interaction reported '
                        f'{end_timeout:g} s after the bag ended')
                break
    except KeyboardInterrupt:
        say('interrupted')
    finally:
        # A second Ctrl-C or a SIGTERM while the children stop must not leave them running.
        for sig in previous:
            signal.signal(sig, signal.SIG_IGN)
        try:
            if monitor is not None:
                monitor.close()
            codes = children.stop()
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)
        say('stopped: ' + ', '.join(f'{n} {c}' for n, c in codes.items()))
    return code


class _Monitor:
    """The run process's own ROS node: the observer's events, the posterior, the estimator's
    log lines."""

    def __init__(self, lines: EventLines, say, domain: int):
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        from rcl_interfaces.msg import Log
        from std_msgs.msg import Float64MultiArray, Header
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = rclpy.create_node('mixture_ip_run', context=self.context,
                                      enable_rosout=False)
        reliable = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        rosout = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                            durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.node.create_subscription(Header, '/observer/event',
                                      lambda m: say(lines.event(m.frame_id)), reliable)
        self.node.create_subscription(Float64MultiArray, '/estimator/posterior',
                                      lambda m: say(lines.posterior(m.data)), reliable)

        def on_log(m):
            if m.name == 'estimator_node':
                say(lines.estimator_log(m.msg))
            elif m.level >= Log.ERROR and m.name in NODES:
                say(f'{m.name}: {m.msg}')
        self.node.create_subscription(Log, '/rosout', on_log, rosout)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def spin_once(self, timeout: float) -> None:
        self.executor.spin_once(timeout_sec=timeout)

    def wait_for_listener(self, topic: str, children, timeout: float) -> bool:
        """Spin until a node subscribes to ``topic`` (True), a child exits or ``timeout`` s
        pass (False)."""
        deadline = time.monotonic() + timeout
        while self.node.count_subscribers(topic) < 1:
            if children.exited() or time.monotonic() > deadline:
                return False
            self.spin_once(0.05)
        return True

    def close(self) -> None:
        import rclpy
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
