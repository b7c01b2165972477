"""Computed-torque control in MuJoCo: tracking (every shipped robot), model error, torque limits,
hold under gravity (every shipped robot), bad input."""

import mujoco
import numpy as np
import pytest

from mixture_ip_ros.robot._fast import acceleration_into, clip_into
from mixture_ip_ros.robot.controller import ComputedTorqueController, default_gains
from mixture_ip_ros.robot.description import DEFAULT, JOINT_NAMES, shipped_robots
from mixture_ip_ros.robot.kinematics import RobotKinematics
from mixture_ip_ros.robot.sim import RobotSimulation
from mixture_ip_ros.robot.trajectory import points_from_arrays, validate_trajectory

HOME = DEFAULT.home_array()

J = list(JOINT_NAMES)
# Across the workspace: base swings 1.5 rad, shoulder and elbow open up, the wrist turns; in
# 2 s at most 1.41 rad/s on joint 1 (limit 1.48: the sim refuses faster trajectories).
Q_A = np.array([-0.75, 0.3, 0.5, -1.6, -0.4, 0.8, -0.5])
Q_B = np.array([0.75, 1.0, -0.5, -0.6, 0.5, 1.5, 0.8])
DURATION = 2.0


def across_the_workspace(kin):
    """A move for any arm: from its home posture turned 0.8 rad one way to 0.8 rad the other,
    every other joint moving by 0.5 rad (alternating), within the joint limits (positions, and
    speeds in DURATION: a minimum-jerk move peaks at 1.875 times its mean speed)."""
    home = kin.description.home_array()
    step = 0.5 * (-1.0) ** np.arange(kin.dof)
    step[0] = 0.8
    fastest = 0.95 * kin.velocity_limit * DURATION / 1.875 / 2
    step = np.sign(step) * np.minimum(np.abs(step), fastest)
    lo, hi = kin.lower + 0.05, kin.upper - 0.05
    return np.clip(home - step, lo, hi), np.clip(home + step, lo, hi)


def minimum_jerk(q_a, q_b, duration, t):
    s = np.clip(np.asarray(t) / duration, 0.0, 1.0)
    d = q_b - q_a
    p = 10 * s**3 - 15 * s**4 + 6 * s**5
    v = (30 * s**2 - 60 * s**3 + 30 * s**4) / duration
    a = (60 * s - 180 * s**2 + 120 * s**3) / duration**2
    return q_a + np.outer(p, d), np.outer(v, d), np.outer(a, d)


def run_tracking(mass_scale, robot=None, q_a=Q_A, q_b=Q_B):
    """Track a 2 s minimum-jerk move sent as 21 points with velocities and accelerations.

    Returns the RMS and largest joint error against the exact minimum-jerk path (rad), the
    flange's distance from its goal after settling (m), and the simulation's own tally.
    """
    sim = RobotSimulation(q0=q_a, controller_mass_scale=mass_scale, robot=robot)
    t_points = np.linspace(0.0, DURATION, 21)
    points = points_from_arrays(t_points, *minimum_jerk(q_a, q_b, DURATION, t_points))
    assert sim.set_trajectory(sim.joint_names, points) is None
    n = int(round(DURATION / sim.dt))
    desired = minimum_jerk(q_a, q_b, DURATION, np.arange(n + 1) * sim.dt)[0]
    errors = np.empty((n + 1, sim.dof))
    for k in range(n + 1):
        errors[k] = sim.q - desired[k]
        sim.step(1)
    tally = sim.tracking_error()
    sim.step(500)   # settle while holding the last point
    flange_error = np.linalg.norm(sim.flange_pose()[0] - sim.kinematics.fk(q_b)[0])
    return np.sqrt(np.mean(errors**2)), np.abs(errors).max(), flange_error, tally


def test_tracks_minimum_jerk_with_the_exact_model():
    rms, worst, flange_error, _ = run_tracking(1.0)
    assert rms < 0.5e-3
    assert worst < 0.5e-3
    assert flange_error < 1e-3


@pytest.mark.parametrize('robot', shipped_robots())
def test_every_arm_tracks_a_move_across_its_workspace(robot):
    q_a, q_b = across_the_workspace(RobotKinematics(robot))
    assert np.abs(q_b - q_a).max() > 1.0
    rms, worst, flange_error, tally = run_tracking(1.0, robot, q_a, q_b)
    assert rms < 0.5e-3
    assert worst < 0.5e-3
    assert flange_error < 1e-3
    # The simulation's tally (reference against the measured state, every step that followed
    # the trajectory) agrees with the error against the exact path computed here.
    assert tally['steps'] == int(round(DURATION / 0.001)) + 1
    assert tally['rms'] == pytest.approx(rms, rel=0.05, abs=1e-6)
    assert tally['max'] == pytest.approx(worst, rel=0.05, abs=1e-6)


def test_bounded_error_with_masses_ten_percent_too_high():
    # Chosen bound: RMS joint error under 1 mrad, worst under 3 mrad, flange within 1 mm after
    # settling (measured: about 0.36 mrad RMS, 1.0 mrad worst, 0.3 mm), with w = 60 rad/s.
    rms, worst, flange_error, _ = run_tracking(1.1)
    assert rms < 1e-3
    assert worst < 3e-3
    assert flange_error < 1e-3
    # The error really comes from the model mismatch: it is much larger than with the true model.
    assert rms > 5 * run_tracking(1.0)[0]


def test_torques_never_exceed_the_limits():
    sim = RobotSimulation(q0=Q_A)
    # The same move in 0.3 s asks for far more torque than the motors have. The sim refuses
    # it (beyond the speed limits), so it goes to the controller directly.
    t_points = np.linspace(0.0, 0.3, 7)
    points = points_from_arrays(t_points, *minimum_jerk(Q_A, Q_B, 0.3, t_points))
    assert 'beyond its limits' in sim.set_trajectory(J, points)
    sim.follower.set(validate_trajectory(J, points, None, 0.0, J))
    limit = sim.kinematics.effort_limit
    saturated = 0
    for _ in range(1500):
        sim.step(1)
        tau = sim.tau
        assert np.all(np.abs(tau) <= limit + 1e-9)
        # MuJoCo applied exactly what was commanded (no clipping left to the actuator).
        np.testing.assert_allclose(sim.data.actuator_force[:7], tau, atol=1e-9)
        saturated += sim.controller.saturated
    assert saturated > 10
    # Once the reference stops, the arm gets there anyway.
    np.testing.assert_allclose(sim.q, Q_B, atol=1e-3)


@pytest.mark.parametrize('robot', shipped_robots())
def test_holds_still_under_gravity_without_a_trajectory(robot):
    # The arm stretched out forward: the shoulder carries the whole arm.
    kin = RobotKinematics(robot)
    q0 = kin.ik(kin.description.world_to_base().apply_array([0.85, 0.2, 0.35]),
                kin.description.home_array())
    sim = RobotSimulation(q0=q0, robot=robot)
    sim.step(2000)
    np.testing.assert_allclose(sim.q, q0, atol=1e-6)
    np.testing.assert_allclose(sim.qd, 0.0, atol=1e-6)
    # The holding torque is MuJoCo's own gravity torque (independent oracle).
    data = mujoco.MjData(sim.model)
    data.qpos[:] = q0
    mujoco.mj_forward(sim.model, data)
    np.testing.assert_allclose(sim.tau, data.qfrc_bias, atol=1e-4)
    assert np.abs(data.qfrc_bias[1]) > 20   # a real load, not a trivial pose


@pytest.fixture
def controller():
    logged = []
    ctrl = ComputedTorqueController(RobotKinematics(), logger=logged.append)
    ctrl.logged = logged
    return ctrl


def _gravity(q):
    model = RobotSimulation(q0=q).model
    data = mujoco.MjData(model)
    data.qpos[:] = q
    mujoco.mj_forward(model, data)
    return data.qfrc_bias[:7].copy()


def test_non_finite_reference_holds_and_logs(controller):
    q = HOME.copy()
    for bad in (np.nan, np.inf):
        q_ref = HOME.copy()
        q_ref[2] = bad
        tau = controller.compute(q, np.zeros(7), q_ref, np.zeros(7), np.zeros(7))
        assert np.all(np.isfinite(tau))
        np.testing.assert_allclose(tau, _gravity(q), atol=1e-6)
    assert controller.holding
    assert controller.fault_count == 2
    assert any('non-finite' in m for m in controller.logged)


def test_non_finite_state_never_gives_non_finite_torque(controller):
    tau_good = controller.compute(HOME, np.zeros(7))
    qd = np.zeros(7)
    qd[4] = np.nan
    tau = controller.compute(HOME, qd, HOME + 0.1, np.zeros(7), np.zeros(7))
    assert np.all(np.isfinite(tau))
    q = HOME.copy()
    q[0] = np.inf
    tau = controller.compute(q, np.zeros(7))
    assert np.all(np.isfinite(tau))
    np.testing.assert_allclose(tau, tau_good)   # the last safe torque
    assert controller.fault_count == 2


def test_hold_position_is_kept_when_the_arm_is_pushed_away(controller):
    # Hold starts where the arm is; displaced later, the controller pulls it back (spring).
    controller.compute(HOME, np.zeros(7))
    displaced = HOME + 0.01
    tau = controller.compute(displaced, np.zeros(7))
    kin = controller.kinematics
    expected = kin.rnea(displaced, np.zeros(7), controller.kp * (HOME - displaced))
    np.testing.assert_allclose(tau, expected, atol=1e-9)


def test_default_gains_are_critically_damped():
    kp, kd = default_gains(60.0, 1.0, 7)
    np.testing.assert_allclose(kd, 2 * np.sqrt(kp))
    # Per joint, with another damping ratio.
    kp, kd = default_gains(np.arange(1.0, 8.0), 0.7, 7)
    np.testing.assert_allclose(kp, np.arange(1.0, 8.0) ** 2)
    np.testing.assert_allclose(kd, 1.4 * np.arange(1.0, 8.0))
    with pytest.raises(ValueError):
        default_gains(-1.0, 1.0, 7)


def _straightforward(sim, n, tally):
    """The control loop one call per part (the oracle of RobotSimulation.step): sample the
    reference, compute the torque, step MuJoCo; the tracking tally as its docstring defines it
    (the squares summed per call, then added)."""
    data = sim.data
    sq = 0.0
    for _ in range(n):
        ref = sim.follower.sample(data.time, data.qpos, data.qvel)
        if ref is None:
            data.ctrl[:] = sim.controller.compute(data.qpos, data.qvel)
        else:
            data.ctrl[:] = sim.controller.compute(data.qpos, data.qvel, *ref)
            err = ref[0] - data.qpos
            sq += err.dot(err)
            tally['max'] = max(tally['max'], float(np.abs(err).max()))
            tally['steps'] += 1
        mujoco.mj_step(sim.model, data)
    tally['sq'] += sq


@pytest.mark.parametrize('open_loop', [False, True])
@pytest.mark.parametrize('robot', shipped_robots())
def test_step_equals_the_straightforward_loop_bit_for_bit(robot, open_loop):
    """Holding, a trajectory with every kind of segment, a replacement mid-way (cubic), one
    started in the past (linear), its end, a cancel; stepped in chunks that cross the
    reference blocks: the same states, torques and tally bit for bit as the plain loop."""
    sims = [RobotSimulation(robot=robot, open_loop_control=open_loop) for _ in range(2)]
    home = sims[0].description.home_array()
    # across_the_workspace's move made 2.5 times faster: 0.35 of its distance stays within the
    # speed limits the simulation enforces.
    q_a, q_b = (home + 0.35 * (q - home) for q in across_the_workspace(sims[0].kinematics))
    t = np.linspace(0.0, 1.0, 11)
    quintic = points_from_arrays(t + 0.05, *minimum_jerk(home, q_b, 1.0, t))
    p, v, _ = minimum_jerk(q_b, q_a, 0.8, t)
    tally = {'sq': 0.0, 'max': 0.0, 'steps': 0}
    plan = [('hold', 3), ('hold', 40), ('set', (quintic, None)), (None, 1), (None, 7),
            (None, 300), (None, 1), ('set', (points_from_arrays(t + 0.3, p, v), None)),
            (None, 255), (None, 1100), ('set', (points_from_arrays(t, p[::-1]), -0.2)),
            (None, 1000), ('cancel', 0), (None, 2), (None, 300)]
    for what, arg in plan:
        for i, sim in enumerate(sims):
            if what == 'set':
                points, start = arg
                assert sim.set_trajectory(sim.joint_names, points,
                                          None if start is None else sim.time + start) is None
            elif what == 'cancel':
                sim.cancel_trajectory()
            elif i == 0:
                sim.step(arg)
            else:
                _straightforward(sim, arg, tally)
        fast, plain = sims
        for name in ('qpos', 'qvel', 'ctrl'):
            assert np.array_equal(getattr(fast.data, name), getattr(plain.data, name)), name
        assert fast.data.time == plain.data.time
        assert fast.controller.holding == plain.controller.holding
        assert np.array_equal(fast.controller._last_safe, plain.controller._last_safe)
    assert fast.tracking_error() == {'rms': float(np.sqrt(tally['sq'] / (tally['steps'] *
                                                                          fast.dof))),
                                     'max': tally['max'], 'steps': tally['steps']}


def test_follow_holds_through_a_non_finite_reference_as_compute_does():
    """A reference row that is not finite goes through compute's careful path: the same torques
    and the same fault record as compute called per step."""
    logs = [[], []]
    ctrls = [ComputedTorqueController(RobotKinematics(), logger=logs[i].append)
             for i in range(2)]
    refs = np.zeros((6, 3, 7))
    refs[:, 0] = HOME + 0.05
    refs[3, 0, 2] = np.nan
    q, qd = HOME.copy(), np.full(7, 0.1)
    out, expected = np.empty(7), []
    torques = []
    ctrls[0].follow(q, qd, refs, out, lambda: torques.append(out.copy()), np.empty((6, 7)))
    for k in range(6):
        expected.append(ctrls[1].compute(q, qd, *refs[k]))
    assert np.array_equal(np.array(torques), np.array(expected))
    assert ctrls[0].fault_count == ctrls[1].fault_count == 1
    assert logs[0] == logs[1] and 'non-finite' in logs[0][0]
    assert ctrls[0].holding == ctrls[1].holding is False
    assert np.array_equal(ctrls[0]._last_safe, ctrls[1]._last_safe)


def test_compiled_steps_equal_their_numpy_bit_for_bit():
    """robot._fast against the numpy of ComputedTorqueController._fast on random inputs: the
    acceleration and error of the control law, and the finiteness check and the clip."""
    rng = np.random.default_rng(4)
    for trial in range(300):
        n = int(rng.integers(1, 10))
        refs = rng.normal(0, 10.0 ** rng.integers(-3, 4), (4, 3, n))
        q, qd = rng.normal(0, 2, (2, n))
        kp, kd = rng.uniform(0, 500, (2, n))
        k = int(rng.integers(4))
        a, errors = np.empty(n), np.zeros((4, n))
        acceleration_into(refs, k, q, qd, kp, kd, a, errors)
        q_ref, qd_ref, qdd_ref = refs[k]
        assert np.array_equal(a, qdd_ref + kp * (q_ref - q) + kd * (qd_ref - qd))
        assert np.array_equal(errors[k], q_ref - q)
        tau = rng.normal(0, 10.0 ** rng.integers(-2, 5), n)
        if trial % 5 == 0:
            tau[rng.integers(n)] = rng.choice([np.nan, np.inf, -np.inf])
        high = rng.uniform(1, 300, n)
        out = np.full(n, 7.0)
        ok = clip_into(tau, -high, high, out)
        assert ok == np.isfinite(tau.dot(tau))
        assert np.array_equal(out, tau.clip(-high, high) if ok else np.full(n, 7.0))
