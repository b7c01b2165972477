"""The closed loop with the real nodes: bags -> observer -> estimator -> MuJoCo iiwa (and UR5).

In-process (one executor, private domain), cross-process (the executables, as a user starts
them), bad input into the running system, commands delayed on their way to the arm, and the
loop on a machine loaded with busy processes.

Nothing here depends on the wall clock: the loop runs on simulated time paced at real time, and
a test waits on the simulated clock or a condition (with timeouts far above any run). On a slow
or loaded machine messages arrive later in simulated time; what the assertions demand holds
then too.
"""

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import private_domain_id
from mixture_ip_ros.scenarios.folders import read_labels, write_scenario_bags

pytestmark = pytest.mark.filterwarnings('ignore::DeprecationWarning')
# Where the hand must end (m from the demonstrated target): the model's own error plus 0.5-0.7 cm
# for the online loop. The model, from the whole wrist path with the phase known, puts the
# hand of the iiwa's held-out plate, screwdriver and screw 2.8, 2.8 and 3.3 cm from their targets
# (the screw's place is the teacher's, uncorrelated with the human: 8 mm of noise per axis).
HAND_BOUND = {'plate': 0.035, 'screwdriver': 0.035, 'screw': 0.04}


@pytest.fixture(scope='module')
def setup(box_loop):
    """The session's box-assembly bags and model (conftest.box_loop), the held-out targets."""
    from mixture_ip_ros.app.demo import demonstrated_target
    from mixture_ip_ros.robot.kinematics import RobotKinematics
    kin = RobotKinematics()
    targets = {n: demonstrated_target(box_loop['data'] / n, kin)[0] for n in box_loop['held']}
    return {**box_loop, 'targets': targets}


class _Loops:
    """One in-process loop at a time on the module's domain, started as a test asks for it
    (without or with a command relay). An idle loop costs a third of a core (its simulation
    runs in real time), which the other tests should not pay."""

    def __init__(self, model):
        self.model = model
        self.current = None

    def get(self, command_delay=None):
        from mixture_ip_ros.app.closed_loop import ClosedLoop
        if self.current is not None and (self.current.relay is None) != (command_delay is None):
            self.close()
        if self.current is None:
            self.current = ClosedLoop(self.model, domain_id=private_domain_id(),
                                      command_delay=command_delay)
        elif command_delay is not None:
            self.current.set_command_delay(command_delay)
        return self.current

    def close(self):
        if self.current is not None:
            self.current.close()
            self.current = None


@pytest.fixture(scope='module')
def loops(setup):
    pool = _Loops(setup['model'])
    yield pool
    pool.close()


@pytest.fixture
def loop(loops):
    return loops.get()


def _run(loop, setup, name):
    loop.go_home()
    return loop.run_interaction(setup['data'] / name, true_pattern=setup['labels'][name],
                                target=setup['targets'][name])


def _hand_error(r):
    return float(np.linalg.norm(r.flange[-1] - r.target))


@pytest.fixture(scope='module')
def reference(loops, setup):
    """The three held-out interactions through the loop as it is (no delay, no added load)."""
    loop = loops.get()
    return {name: _run(loop, setup, name) for name in setup['held']}


def _kept_its_promises(r, reference, kinematics):
    """What the loop promises under delay and load: the right pattern, the hand within the
    reference run's error + 0.5 cm, the last plan (conditioned on the final wrist position)
    received and executed (the sim refused nothing), no point beyond the arm's limits in any
    command, nothing non-finite."""
    from mixture_ip_ros.app.closed_loop import points_beyond_limits
    e = r.extra
    assert r.chosen_pattern == r.true_pattern, r.name
    assert _hand_error(r) < _hand_error(reference[r.name]) + 0.005, r.name
    assert e['final_plan_received'], r.name
    assert e['sim_rejections'] == 0, (r.name, e['last_rejection'])
    assert e['commands'] and points_beyond_limits(e['commands'], kinematics) == 0, r.name
    assert e['non_finite_commands'] == 0, r.name


@pytest.mark.decision
def test_three_held_out_interactions_in_process(loop, setup, reference):
    records = [reference[name] for name in setup['held']]
    assert sorted(r.true_pattern for r in records) == ['plate', 'screw', 'screwdriver']
    for r in records:
        assert r.chosen_pattern == r.true_pattern, r.name
        assert r.commit_fraction is not None and 0 < r.commit_fraction < 1
        assert _hand_error(r) < HAND_BOUND[r.true_pattern], r.name
        assert r.extra['non_finite_commands'] == 0
        assert r.extra['sim_rejections'] == 0, r.extra['last_rejection']
        assert r.extra['final_plan_received'], r.name
    # The same interaction again: the same pattern, the hand within its bound. Not the same
    # end to the millimetre: the last plan is conditioned on the latest wrist sample the
    # estimator has when the 'end' event comes (two topics), and which that is, among samples
    # at rest 1 mm of noise apart, depends on how the callbacks interleave on a busy machine.
    again = _run(loop, setup, records[0].name)
    assert again.chosen_pattern == records[0].chosen_pattern
    assert _hand_error(again) < HAND_BOUND[again.true_pattern]
    assert again.extra['sim_rejections'] == 0 and again.extra['final_plan_received']


def test_bad_input_does_not_break_the_running_system(loop, setup):
    """NaN poses, wrong frame, stamps going back, a 10x burst, a 0.5 s gap, and a flood of
    invalid trajectories: no crash, no non-finite command, and the next interaction works."""
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import PoseStamped
    from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
    node = loop.recorder
    raw_pub = node.create_publisher(PoseStamped, '/mocap/wrist', qos_profile_sensor_data)
    observer = loop.observer

    class pose_pub:  # best effort, depth 5: one at a time, as a mocap driver's pace allows
        @staticmethod
        def publish(msg):
            handled = observer.accepted + sum(observer.drop_counts.values())
            raw_pub.publish(msg)
            loop.wait_until(lambda: observer.accepted + sum(observer.drop_counts.values())
                            > handled, timeout=10, what='the observer to take the pose')
    traj_pub = node.create_publisher(JointTrajectory, '/joint_trajectory',
                                     QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
    rejected_before = loop.sim.rejection_count
    accepted_before = loop.sim.sim.accepted_count
    drops_before = dict(loop.observer.drop_counts)

    def pose(t, xyz, frame='world', q=(0.0, 0.0, 0.0, 1.0)):
        msg = PoseStamped()
        ns = int(round(t * 1e9))
        msg.header.stamp = Time(sec=ns // 10**9, nanosec=ns % 10**9)
        msg.header.frame_id = frame
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = xyz
        (msg.pose.orientation.x, msg.pose.orientation.y, msg.pose.orientation.z,
         msg.pose.orientation.w) = q
        return msg
    t = loop.now() + 0.05
    rest = (1.2, 0.25, 0.08)
    for i in range(20):                                   # a valid stream at rest, 100 Hz
        pose_pub.publish(pose(t + 0.01 * i, rest))
    t += 0.2
    pose_pub.publish(pose(t, (math.nan, 0.2, 0.1)))
    pose_pub.publish(pose(t + 0.01, rest, frame='camera'))
    pose_pub.publish(pose(t + 0.02, rest, q=(0.0, 0.0, 0.5, 0.5)))
    pose_pub.publish(pose(t - 1.0, rest))                 # stamp going backwards
    for i in range(200):                                  # 10x burst (1 kHz) at rest
        pose_pub.publish(pose(t + 0.03 + 0.001 * i, rest))
    loop.wait_sim(0.6)                                    # a 0.5 s gap in the stream
    bad = []
    for kind in range(6):
        msg = JointTrajectory()
        msg.joint_names = [f'iiwa_joint_{i}' for i in range(1, 8)]
        p = JointTrajectoryPoint(positions=[0.0] * 7)
        p.time_from_start.sec = 1
        if kind == 0:
            p.positions = [math.nan] + [0.0] * 6
        elif kind == 1:
            p.positions = [math.inf] * 7
        elif kind == 2:
            msg.joint_names = ['elbow'] * 7
        elif kind == 3:
            p.positions = [0.0] * 3
        elif kind == 4:
            msg.points = [p, JointTrajectoryPoint(positions=[0.0] * 7)]   # times not increasing
        elif kind == 5:
            p.velocities = [math.nan] * 7
        if kind != 4:
            msg.points = [p]
        bad.append(msg)
    for _ in range(20):
        for msg in bad:
            traj_pub.publish(msg)
    loop.wait_sim(0.5)
    # KEEP_LAST 10 on the command topic: a flood of 120 loses most on the way; every invalid
    # one that arrives is rejected, none is accepted
    assert loop.sim.rejection_count - rejected_before >= 10
    assert loop.sim.sim.accepted_count == accepted_before
    assert np.all(np.isfinite(loop.sim.sim.tau)) and np.all(np.isfinite(loop.sim.sim.q))
    drops = {k: loop.observer.drop_counts[k] - drops_before.get(k, 0)
             for k in loop.observer.drop_counts}
    assert drops['non_finite'] >= 1 and drops['wrong_frame'] >= 1
    assert drops['bad_quaternion'] >= 1 and drops['stamp_backwards'] >= 1
    node.destroy_publisher(raw_pub)
    node.destroy_publisher(traj_pub)
    # The next valid interaction still works.
    name = setup['held'][1]
    r = _run(loop, setup, name)
    assert r.chosen_pattern == r.true_pattern
    assert np.linalg.norm(r.flange[-1] - r.target) < HAND_BOUND[r.true_pattern]
    assert r.extra['non_finite_commands'] == 0


def test_deactivating_the_estimator_mid_interaction_stops_the_robot(loop, setup):
    """Through its lifecycle service, while the robot follows a plan: no plan reaches the
    robot afterwards, the arm stops and holds, and the reactivated estimator works again."""
    import threading
    name = setup['held'][0]
    loop.go_home()
    done = []
    replay = threading.Thread(target=lambda: done.append(loop.run_interaction(
        setup['data'] / name)), daemon=True)
    replay.start()
    loop.wait_until(lambda: loop.estimator.state == 'committed', timeout=60,
                    what='the robot committed')
    loop.wait_sim(0.2)                                    # moving along its plan
    assert loop.set_state('estimator_node', 'deactivate')
    sim = loop.sim.sim
    loop.wait_until(lambda: not sim.follower.active, timeout=10, what='the stop')
    accepted, q_stop = sim.accepted_count, sim.q
    replay.join(timeout=120)
    assert done, 'the replay did not finish'
    assert sim.accepted_count == accepted                # nothing accepted after the stop
    assert np.abs(sim.q - q_stop).max() < 0.02 and np.abs(sim.qd).max() < 1e-3
    assert loop.estimator.interactions[-1].end_reason == 'deactivated'
    assert loop.set_state('estimator_node', 'activate')
    r = _run(loop, setup, setup['held'][1])
    assert r.chosen_pattern == r.true_pattern
    assert np.linalg.norm(r.flange[-1] - r.target) < 0.03


# Every command held this long (s of simulated time) on its way to the arm, each on one held-out
# interaction of another pattern: 20 s of suite time, where all nine pairs would take a minute
# (`mixture-ip demo --command-delay` runs them all, docs/results.md).
DELAYED = {0.02: 'plate', 0.05: 'screw', 0.1: 'screwdriver'}


def _busy_processes(n):
    """``n`` processes that compete for the CPUs for as long as they run."""
    return [subprocess.Popen([sys.executable, '-c', 'while True: pass']) for _ in range(n)]


def test_the_loop_keeps_its_promises_with_two_busy_processes_beside_it(loop, setup,
                                                                        reference):
    """Two processes spinning on the 2 CPUs while the three held-out interactions replay: late
    plans are re-timed by the sim, none is refused, every interaction ends as unloaded."""
    from mixture_ip_ros.robot.kinematics import RobotKinematics
    busy = _busy_processes(2)
    try:
        records = [_run(loop, setup, name) for name in setup['held']]
    finally:
        for p in busy:
            p.kill()
            p.wait()
    kinematics = RobotKinematics()
    for r in records:
        _kept_its_promises(r, reference, kinematics)


@pytest.mark.parametrize('delay', sorted(DELAYED))
def test_the_loop_keeps_its_promises_when_every_command_is_late(loops, setup, reference,
                                                                delay):
    """Every command held ``delay`` s by a relay between the estimator and the sim (DDS on both
    hops): the plans come after their first point was due and are re-timed, not refused."""
    from mixture_ip_ros.robot.kinematics import RobotKinematics
    loop = loops.get(command_delay=delay)
    name = next(n for n in setup['held'] if setup['labels'][n] == DELAYED[delay])
    r = _run(loop, setup, name)
    assert r.extra['command_delay'] == delay
    _kept_its_promises(r, reference, RobotKinematics())


def test_cross_process_one_interaction(loops, setup, tmp_path):
    """The executables as separate processes (as `ros2 run` would start them)."""
    loops.close()
    import rclpy
    from rclpy.context import Context
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray
    from ros_harness import RosHarness
    domain = private_domain_id(offset=1)     # apart from the in-process loop's domain
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), OPENBLAS_NUM_THREADS='1',
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    bindir = Path(sys.executable).parent
    name = setup['held'][2]
    cfg = Path(__file__).resolve().parents[1] / 'config'
    configs = {'sim_node': 'sim.yaml', 'observer_node': 'observer.yaml',
               'estimator_node': 'estimator.yaml', 'bag_player': 'bag_player.yaml'}
    procs = []

    def start(exe, *params):
        args = [str(bindir / exe), '--ros-args', '--params-file', str(cfg / configs[exe])]
        for p in params:
            args += ['-p', p]
        procs.append(subprocess.Popen(args, env=env, stdout=subprocess.DEVNULL,
                                      stderr=open(tmp_path / f'{exe}.log', 'w')))
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain)
    h = RosHarness(ctx)
    joints = h.subscribe(JointState, '/joint_states')
    posterior = h.subscribe(Float64MultiArray, '/estimator/posterior')
    try:
        start('sim_node', 'real_time_factor:=1.0')
        start('observer_node', 'use_sim_time:=true')
        start('estimator_node', 'use_sim_time:=true', f'model_path:={setup["model"]}')
        h.spin_until(lambda: len(joints) > 10, what='joint states from sim_node')
        # the estimator is up: its subscription to the observer is matched
        h.spin_until(lambda: h.probe.count_subscribers('/observer/wrist') >= 1
                     and h.probe.count_publishers('/joint_trajectory') >= 1,
                     what='the estimator')
        start('bag_player', 'use_sim_time:=true', 'rewrite_stamps:=true',
              "topics:=['/mocap/wrist']", 'start_delay:=2.0',   # cross-process discovery
              f'bag:={setup["data"] / name}')
        h.spin_until(lambda: procs[-1].poll() is not None, timeout=60,
                     what='bag_player to finish')
        n = len(joints)
        h.spin_until(lambda: len(joints) > n + 150, what='1.5 s of simulated settling')
        # where the hand comes to rest (a loaded machine's late replans stop the arm on the way,
        # plans ending a horizon ahead, and it catches up later)
        h.spin_until(lambda: max(map(abs, joints[-1].velocity)) < 1e-3, timeout=60,
                     what='the arm at rest')
        q = dict(zip(joints[-1].name, joints[-1].position))
        q = np.array([q[f'iiwa_joint_{i}'] for i in range(1, 8)])
        from mixture_ip_ros.robot.kinematics import RobotKinematics
        hand = RobotKinematics().fk(q)[0]
        assert posterior, 'no posterior from estimator_node'
        assert np.linalg.norm(hand - setup['targets'][name]) < HAND_BOUND[setup['labels'][name]]
        for p in procs[:3]:
            assert p.poll() is None, 'a node died'
    finally:
        for p in procs:
            if p.poll() is None:
                p.send_signal(2)
        for p in procs:
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
        h.close()
        rclpy.try_shutdown(context=ctx)


# ------------------------------------------------------------------ another arm: the UR5
@pytest.fixture(scope='module')
def ur5_setup(tmp_path_factory):
    """The same task for the UR5 (6 joints, its base 10 cm from the iiwa's): its own bags (the
    same human movements), a model of its joints, the loop started with robot='ur5' only."""
    from mixture_ip_ros.io.dataset import load_demonstration
    from mixture_ip_ros.app.demo import demonstrated_target, split_held_out
    from mixture_ip_ros.robot.description import load_description
    from mixture_ip_ros.robot.kinematics import RobotKinematics
    from mixture_ip_ros.app.training import train_to_file
    robot = load_description('ur5')
    root = tmp_path_factory.mktemp('closed_loop_ur5')
    data = root / 'bags'
    write_scenario_bags('box_assembly', data, seed=3, robot='ur5')
    labels = read_labels(data)
    train, held = split_held_out(labels, 1, seed=3)
    model = root / 'model.npz'
    train_to_file([load_demonstration(data / n, joint_names=robot.joint_names,
                                      transform=robot.world_to_base()) for n in train],
                  model, robot=robot, n_components=3)
    kin = RobotKinematics(robot)
    targets = {n: demonstrated_target(data / n, kin)[0] for n in held}
    return {'data': data, 'labels': labels, 'held': held, 'model': model, 'targets': targets}


@pytest.mark.decision
def test_the_closed_loop_with_the_ur5(loops, ur5_setup):
    from mixture_ip_ros.app.closed_loop import ClosedLoop
    loops.close()
    loop = ClosedLoop(ur5_setup['model'], robot='ur5', domain_id=private_domain_id(offset=1))
    try:
        assert loop.sim.sim.joint_names == list(loop.robot.joint_names)
        assert loop.observer.get_parameter('base_frame').value == 'base_link'
        records = [_run(loop, ur5_setup, name) for name in ur5_setup['held']]
    finally:
        loop.close()
    assert sorted(r.true_pattern for r in records) == ['plate', 'screw', 'screwdriver']
    for r in records:
        assert r.q.shape[1] == 6
        assert r.chosen_pattern == r.true_pattern, r.name
        # The iiwa's bounds + 20 %, the aim for another arm (measured: 1.2-3.2 cm).
        assert np.linalg.norm(r.flange[-1] - r.target) < 1.2 * HAND_BOUND[r.true_pattern], r.name
        assert r.extra['tracking']['rms'] < 0.5e-3, r.name
        assert r.extra['non_finite_commands'] == 0
        assert r.extra['sim_rejections'] == 0, r.extra['last_rejection']
