"""An arm in MuJoCo at 1 kHz with the computed-torque controller in the loop, without ROS."""

from __future__ import annotations

import logging
from functools import partial
from typing import Sequence

import mujoco
import numpy as np

from mixture_ip_ros.robot.controller import ComputedTorqueController
from mixture_ip_ros.robot.kinematics import RobotKinematics
from mixture_ip_ros.robot.scene import FLANGE_SITE, build_scene
from mixture_ip_ros.estimation.plans import JointLimits
from mixture_ip_ros.robot.trajectory import (DEFAULT_MAX_POINTS, TrajectoryFollower,
                                             TrajectoryPoint, stopping_trajectory,
                                             validate_trajectory)

# s a command may arrive after its first point was due and still be executed (re-timed); the
# estimator's max_clock_offset, for plans resting on observations, is the same.
DEFAULT_MAX_DELAY = 1.0
# s of simulated time between log lines about re-timed trajectories (one per plan would be ten
# a second on a slow link).
RETIME_LOG_PERIOD = 1.0


class RobotSimulation:
    """MuJoCo model + data, trajectory follower and controller, stepped at the model timestep.

    ``robot``: a description, a shipped robot's name or a description file (None: the iiwa 14).
    q0 defaults to the description's home posture; gains default to its controller section.
    controller_mass_scale != 1 gives the controller a deliberately wrong Pinocchio model (all link
    masses and inertias scaled) while MuJoCo keeps the true one. Positions and poses in and out
    are in the robot's base frame (the scene's world frame differs by the description's mount).

    A trajectory whose first point comes too late for the arm to reach it within its limits is
    re-timed (validate_trajectory: it starts later by the shortfall), counted in
    ``retimed_count`` with its ``last_delay``, and logged at most once per RETIME_LOG_PERIOD of
    simulated time; one due more than ``max_delay`` s before it arrived is refused as stale.
    """

    def __init__(self, q0=None, pole: bool = False, stands: bool = True, model=None,
                 natural_frequency=None, damping_ratio=None, kp=None, kd=None,
                 controller_mass_scale: float = 1.0, allow_partial_joints_goal: bool = False,
                 allow_nonzero_velocity_at_trajectory_end: bool = False,
                 open_loop_control: bool = False, logger=None, robot=None,
                 max_trajectory_points: int | None = DEFAULT_MAX_POINTS,
                 max_delay: float | None = DEFAULT_MAX_DELAY, **scene_kwargs):
        self.kinematics = RobotKinematics(robot)
        self.description = description = self.kinematics.description
        self.model = model if model is not None else build_scene(
            pole=pole, stands=stands, robot=description, **scene_kwargs)
        self.data = mujoco.MjData(self.model)
        self.dt = float(self.model.opt.timestep)
        self.joint_names = list(description.joint_names)
        n = self.dof = len(self.joint_names)
        self.controller_kinematics = (
            self.kinematics if controller_mass_scale == 1.0
            else RobotKinematics(description, mass_scale=controller_mass_scale))
        self._log = logger if logger is not None else logging.getLogger(__name__).warning
        self.controller = ComputedTorqueController(
            self.controller_kinematics, kp=kp, kd=kd, natural_frequency=natural_frequency,
            damping_ratio=damping_ratio, logger=self._log)
        self.follower = TrajectoryFollower(n, open_loop=open_loop_control)
        self.allow_partial_joints_goal = allow_partial_joints_goal
        self.allow_nonzero_velocity_at_trajectory_end = allow_nonzero_velocity_at_trajectory_end
        k = self.kinematics
        # Enforced on every trajectory, as by a controller with joint limits on.
        self.limits = JointLimits(k.lower, k.upper, k.velocity_limit, k.acceleration_limit)
        self.max_trajectory_points = max_trajectory_points
        self.max_delay = max_delay
        self.retimed_count = 0
        self.last_delay: float | None = None
        self._retimed_unlogged = 0
        self._retime_logged_at = -np.inf
        self.rejection_count = 0
        self.last_rejection: str | None = None
        self.accepted_count = 0
        self.reference: tuple | None = None
        self._flange_site = self.model.site(FLANGE_SITE).id
        qadr = [self.model.joint(name).qposadr[0] for name in self.joint_names]
        vadr = [self.model.joint(name).dofadr[0] for name in self.joint_names]
        if not (self.model.nq == self.model.nv == self.model.nu == n
                and qadr == list(range(n)) and vadr == list(range(n))):
            raise ValueError(f'the scene must have exactly the {n} joints of '
                             f'{description.name} and their actuators')
        self._to_base = description.world_to_base()
        self.reset_tracking()
        self.set_state(description.home_array() if q0 is None else q0)

    # ------------------------------------------------------------------ state
    @property
    def time(self) -> float:
        return float(self.data.time)

    @property
    def q(self) -> np.ndarray:
        return self.data.qpos.copy()

    @property
    def qd(self) -> np.ndarray:
        return self.data.qvel.copy()

    @property
    def tau(self) -> np.ndarray:
        """Torques applied during the last step."""
        return self.data.ctrl.copy()

    def set_state(self, q, qd=None, time: float | None = None) -> None:
        """Reset the simulation to (q, qd); drops any trajectory and holds at q."""
        n = self.dof
        q = np.asarray(q, dtype=float)
        if q.shape != (n,) or not np.all(np.isfinite(q)):
            raise ValueError(f'q must be {n} finite numbers, got {q!r}')
        qd = np.zeros(n) if qd is None else np.asarray(qd, dtype=float)
        if qd.shape != (n,) or not np.all(np.isfinite(qd)):
            raise ValueError(f'qd must be {n} finite numbers')
        mujoco.mj_resetData(self.model, self.data)
        self.data.qpos[:] = q
        self.data.qvel[:] = qd
        if time is not None:
            self.data.time = float(time)
        mujoco.mj_forward(self.model, self.data)
        self.follower.clear()
        self.controller.reset_hold(q)
        self.reference = None
        self._retime_logged_at = -np.inf      # the clock may have been set back

    # ------------------------------------------------------------------ tracking
    def reset_tracking(self) -> None:
        """Start a new tracking tally (see tracking_error)."""
        self._track_sq = 0.0
        self._track_max = 0.0
        self._track_steps = 0

    def tracking_error(self) -> dict:
        """Joint tracking error since reset_tracking, over the steps that followed a trajectory:
        {'rms': sqrt of the mean over steps and joints of (q_ref - q)^2 (rad), 'max': largest
        |q_ref - q| (rad), 'steps': how many steps}. q_ref is the reference the controller was
        sampled at the step's start time, q the measured position at that time."""
        steps = self._track_steps
        rms = float(np.sqrt(self._track_sq / (steps * self.dof))) if steps else None
        return {'rms': rms, 'max': self._track_max if steps else None, 'steps': steps}

    def flange_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Flange position (3,) and quaternion (w, x, y, z) in the base frame, from MuJoCo."""
        pos = self._to_base.apply_array(self.data.site_xpos[self._flange_site])
        R = self._to_base.rotation @ self.data.site_xmat[self._flange_site].reshape(3, 3)
        quat = np.empty(4)
        mujoco.mju_mat2Quat(quat, R.ravel())
        return pos, quat

    # ------------------------------------------------------------------ commands
    def set_trajectory(self, joint_names: Sequence[str], points: Sequence[TrajectoryPoint],
                       start_time: float | None = None) -> str | None:
        """Validate and activate a trajectory; None if accepted, else the logged rejection reason.

        start_time is on the simulation clock (seconds); None starts it at the next step.
        """
        fill = self.reference[0] if self.reference is not None else self.q
        # The next step anchors the trajectory at the present time, from this state.
        q, qd = self.follower.blend_state(self.time, self.q, self.qd)
        result = validate_trajectory(
            joint_names, points, start_time, self.time, self.joint_names,
            allow_partial_joints_goal=self.allow_partial_joints_goal,
            allow_nonzero_velocity_at_trajectory_end=self.allow_nonzero_velocity_at_trajectory_end,
            fill_positions=fill, limits=self.limits, positions_now=q, velocities_now=qd,
            control_period=self.dt, max_delay=self.max_delay,
            max_points=self.max_trajectory_points)
        if isinstance(result, str):
            return self.refuse(result)
        self.accepted_count += 1
        if result.delay > 0:
            self._retimed(result.delay)
        self.follower.set(result)
        return None

    def _retimed(self, delay: float) -> None:
        self.retimed_count += 1
        self.last_delay = delay
        self._retimed_unlogged += 1
        if self.time - self._retime_logged_at >= RETIME_LOG_PERIOD:
            n, self._retimed_unlogged = self._retimed_unlogged, 0
            self._retime_logged_at = self.time
            self._log(f'trajectory late: re-timed to start {delay:.3g} s later (its first '
                      'point could not be reached in time within the joint limits)' if n == 1
                      else f'{n} trajectories late since the last report, the latest re-timed '
                      f'to start {delay:.3g} s later')

    def refuse(self, reason: str) -> str:
        """Count and log a refused trajectory (one warning each); what the arm is doing goes on
        (holding, or the trajectory accepted before), as a controller rejecting a goal."""
        self.rejection_count += 1
        self.last_rejection = reason
        self._log(f'trajectory rejected: {reason}')
        return reason

    def cancel_trajectory(self) -> None:
        """Drop the trajectory and hold the current position."""
        self.follower.clear()
        self.controller.reset_hold()

    @property
    def following(self) -> bool:
        """Whether the arm is on a trajectory not yet at its end."""
        return self.follower.following(self.time)

    def stop(self) -> bool:
        """Stop following the trajectory in progress: brake to rest within the joint
        acceleration limits (robot.trajectory.stopping_trajectory, from the state the next step
        starts from) and hold there. False, and nothing changes, if there is none."""
        if not self.following:
            return False
        q, qd = self.follower.blend_state(self.time, self.q, self.qd)
        self.follower.set(stopping_trajectory(q, qd, self.limits.acceleration, self.dt))
        return True

    # ------------------------------------------------------------------ stepping
    def step(self, n: int = 1) -> None:
        """Advance n control steps of dt: sample the reference, compute torques, step MuJoCo."""
        model, data = self.model, self.data
        follower, controller = self.follower, self.controller
        advance = partial(mujoco.mj_step, model, data)
        # The scene has exactly the arm's joints, so qpos/qvel are the arm state (no slicing).
        q = data.qpos
        qd = data.qvel
        ctrl = data.ctrl
        n = int(n)
        track_sq, track_max, track_steps = 0.0, self._track_max, 0
        while n > 0:
            # The references of the next steps at once (MuJoCo's clock advances by t += dt).
            refs = follower.references(data.time, self.dt, n, q, qd)
            if refs is None:
                controller.hold(q, qd, n, ctrl, advance)
                self.reference = None
                break
            m = len(refs)
            errors = np.empty((m, self.dof))
            controller.follow(q, qd, refs, ctrl, advance, errors)
            self.reference = tuple(refs[-1])
            # Tally: each step's e.e as numpy's dot computes it, summed in step order; the
            # maximum |e_j| over the steps whose e.e is a number.
            sq = (errors[:, None, :] @ errors[:, :, None]).ravel()
            for v in sq.tolist():
                track_sq += v
            counted = errors[~np.isnan(sq)]
            if counted.size:
                track_max = max(track_max, float(np.abs(counted).max()))
            track_steps += m
            n -= m
        self._track_sq += track_sq
        self._track_max = track_max
        self._track_steps += track_steps
