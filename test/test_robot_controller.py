"""Computed-torque control in MuJoCo: tracking, model error, torque limits, hold, bad input."""

import mujoco
import numpy as np
import pytest

from mixture_ip_ros.robot.controller import ComputedTorqueController, default_gains
from mixture_ip_ros.robot.description import JOINT_NAMES
from mixture_ip_ros.robot.kinematics import RobotKinematics
from mixture_ip_ros.robot.description import DEFAULT
from mixture_ip_ros.robot.sim import RobotSimulation
from mixture_ip_ros.robot.trajectory import points_from_arrays

HOME = DEFAULT.home_array()

J = list(JOINT_NAMES)
# Across the workspace: base swings 1.6 rad, shoulder and elbow open up, the wrist turns.
Q_A = np.array([-0.8, 0.3, 0.5, -1.6, -0.4, 0.8, -0.5])
Q_B = np.array([0.8, 1.0, -0.5, -0.6, 0.5, 1.5, 0.8])
DURATION = 2.0


def minimum_jerk(q_a, q_b, duration, t):
    s = np.clip(np.asarray(t) / duration, 0.0, 1.0)
    d = q_b - q_a
    p = 10 * s**3 - 15 * s**4 + 6 * s**5
    v = (30 * s**2 - 60 * s**3 + 30 * s**4) / duration
    a = (60 * s - 180 * s**2 + 120 * s**3) / duration**2
    return q_a + np.outer(p, d), np.outer(v, d), np.outer(a, d)


def run_tracking(mass_scale):
    """Track a 2 s minimum-jerk move sent as 21 points with velocities and accelerations."""
    sim = RobotSimulation(q0=Q_A, controller_mass_scale=mass_scale)
    t_points = np.linspace(0.0, DURATION, 21)
    points = points_from_arrays(t_points, *minimum_jerk(Q_A, Q_B, DURATION, t_points))
    assert sim.set_trajectory(J, points) is None
    n = int(round(DURATION / sim.dt))
    desired = minimum_jerk(Q_A, Q_B, DURATION, np.arange(n + 1) * sim.dt)[0]
    errors = np.empty((n + 1, 7))
    for k in range(n + 1):
        errors[k] = sim.q - desired[k]
        sim.step(1)
    sim.step(500)   # settle while holding the last point
    flange_error = np.linalg.norm(sim.flange_pose()[0] - sim.kinematics.fk(Q_B)[0])
    return np.sqrt(np.mean(errors**2)), np.abs(errors).max(), flange_error


def test_tracks_minimum_jerk_with_the_exact_model():
    rms, worst, flange_error = run_tracking(1.0)
    assert rms < 0.5e-3
    assert worst < 0.5e-3
    assert flange_error < 1e-3


def test_bounded_error_with_masses_ten_percent_too_high():
    # Chosen bound: RMS joint error under 1 mrad, worst under 3 mrad, flange within 1 mm after
    # settling (measured: about 0.36 mrad RMS, 1.0 mrad worst, 0.3 mm), with w = 60 rad/s.
    rms, worst, flange_error = run_tracking(1.1)
    assert rms < 1e-3
    assert worst < 3e-3
    assert flange_error < 1e-3
    # The error really comes from the model mismatch: it is much larger than with the true model.
    assert rms > 5 * run_tracking(1.0)[0]


def test_torques_never_exceed_the_limits():
    sim = RobotSimulation(q0=Q_A)
    # The same move in 0.3 s asks for far more torque than the motors have.
    t_points = np.linspace(0.0, 0.3, 7)
    points = points_from_arrays(t_points, *minimum_jerk(Q_A, Q_B, 0.3, t_points))
    assert sim.set_trajectory(J, points) is None
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


def test_holds_still_under_gravity_without_a_trajectory():
    q0 = np.array([0.4, 1.1, -0.3, -0.9, 0.6, 1.2, -0.7])   # arm stretched out: big gravity load
    sim = RobotSimulation(q0=q0)
    sim.step(2000)
    np.testing.assert_allclose(sim.q, q0, atol=1e-6)
    np.testing.assert_allclose(sim.qd, 0.0, atol=1e-6)
    # The holding torque is MuJoCo's own gravity torque (independent oracle).
    data = mujoco.MjData(sim.model)
    data.qpos[:] = q0
    mujoco.mj_forward(sim.model, data)
    np.testing.assert_allclose(sim.tau, data.qfrc_bias[:7], atol=1e-4)
    assert np.abs(data.qfrc_bias[1]) > 50   # a real load, not a trivial pose


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
