"""The iiwa 14 in MuJoCo at 1 kHz with the computed-torque controller in the loop, without ROS."""

from __future__ import annotations

import logging
from typing import Sequence

import mujoco
import numpy as np

from mixture_ip_ros.robot.controller import DEFAULT_NATURAL_FREQUENCY, ComputedTorqueController
from mixture_ip_ros.robot.description import JOINT_NAMES
from mixture_ip_ros.robot.kinematics import IiwaKinematics
from mixture_ip_ros.robot.scene import FLANGE_SITE, HUMAN_WRIST, build_scene
from mixture_ip_ros.robot.trajectory import (TrajectoryFollower, TrajectoryPoint,
                                             validate_trajectory)

# Arm bent forward over the table, flange about 0.6 m in front at 0.4 m height, pointing down.
HOME = np.array([0.0, 0.6, 0.0, -1.4, 0.0, 1.1, 0.0])


class IiwaSimulation:
    """MuJoCo model + data, trajectory follower and controller, stepped at the model timestep.

    controller_mass_scale != 1 gives the controller a deliberately wrong Pinocchio model (all link
    masses and inertias scaled) while MuJoCo keeps the true one.
    """

    def __init__(self, q0=None, pole: bool = False, stands: bool = True, model=None,
                 natural_frequency=DEFAULT_NATURAL_FREQUENCY, damping_ratio=1.0, kp=None, kd=None,
                 controller_mass_scale: float = 1.0, allow_partial_joints_goal: bool = False,
                 allow_nonzero_velocity_at_trajectory_end: bool = False,
                 open_loop_control: bool = False, logger=None, **scene_kwargs):
        self.model = model if model is not None else build_scene(pole=pole, stands=stands,
                                                                 **scene_kwargs)
        self.data = mujoco.MjData(self.model)
        self.dt = float(self.model.opt.timestep)
        self.joint_names = list(JOINT_NAMES)
        self.kinematics = IiwaKinematics()
        self.controller_kinematics = (self.kinematics if controller_mass_scale == 1.0
                                      else IiwaKinematics(mass_scale=controller_mass_scale))
        self._log = logger if logger is not None else logging.getLogger(__name__).warning
        self.controller = ComputedTorqueController(
            self.controller_kinematics, kp=kp, kd=kd, natural_frequency=natural_frequency,
            damping_ratio=damping_ratio, logger=self._log)
        self.follower = TrajectoryFollower(7, open_loop=open_loop_control)
        self.allow_partial_joints_goal = allow_partial_joints_goal
        self.allow_nonzero_velocity_at_trajectory_end = allow_nonzero_velocity_at_trajectory_end
        self.rejection_count = 0
        self.last_rejection: str | None = None
        self.accepted_count = 0
        self.reference: tuple | None = None
        self._flange_site = self.model.site(FLANGE_SITE).id
        self._wrist_mocap = int(self.model.body(HUMAN_WRIST).mocapid[0])
        qadr = [self.model.joint(n).qposadr[0] for n in JOINT_NAMES]
        vadr = [self.model.joint(n).dofadr[0] for n in JOINT_NAMES]
        if not (self.model.nq == self.model.nv == self.model.nu == 7
                and qadr == list(range(7)) and vadr == list(range(7))):
            raise ValueError('the scene must have exactly the 7 iiwa joints and their actuators')
        self.set_state(HOME if q0 is None else q0)

    # ------------------------------------------------------------------ state
    @property
    def time(self) -> float:
        return float(self.data.time)

    @property
    def q(self) -> np.ndarray:
        return self.data.qpos[:7].copy()

    @property
    def qd(self) -> np.ndarray:
        return self.data.qvel[:7].copy()

    @property
    def tau(self) -> np.ndarray:
        """Torques applied during the last step."""
        return self.data.ctrl[:7].copy()

    def set_state(self, q, qd=None, time: float | None = None) -> None:
        """Reset the simulation to (q, qd); drops any trajectory and holds at q."""
        q = np.asarray(q, dtype=float)
        if q.shape != (7,) or not np.all(np.isfinite(q)):
            raise ValueError(f'q must be 7 finite numbers, got {q!r}')
        qd = np.zeros(7) if qd is None else np.asarray(qd, dtype=float)
        if qd.shape != (7,) or not np.all(np.isfinite(qd)):
            raise ValueError('qd must be 7 finite numbers')
        mujoco.mj_resetData(self.model, self.data)
        self.data.qpos[:7] = q
        self.data.qvel[:7] = qd
        if time is not None:
            self.data.time = float(time)
        mujoco.mj_forward(self.model, self.data)
        self.follower.clear()
        self.controller.reset_hold(q)
        self.reference = None

    def flange_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Flange position (3,) and quaternion (w, x, y, z) in the base frame, from MuJoCo."""
        pos = self.data.site_xpos[self._flange_site].copy()
        quat = np.empty(4)
        mujoco.mju_mat2Quat(quat, self.data.site_xmat[self._flange_site])
        return pos, quat

    def set_wrist(self, position) -> None:
        """Show the human wrist at `position` (base frame)."""
        p = np.asarray(position, dtype=float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ValueError('wrist position must be 3 finite numbers')
        self.data.mocap_pos[self._wrist_mocap] = p

    # ------------------------------------------------------------------ commands
    def set_trajectory(self, joint_names: Sequence[str], points: Sequence[TrajectoryPoint],
                       start_time: float | None = None) -> str | None:
        """Validate and activate a trajectory; None if accepted, else the logged rejection reason.

        start_time is on the simulation clock (seconds); None starts it at the next step.
        """
        fill = self.reference[0] if self.reference is not None else self.q
        result = validate_trajectory(
            joint_names, points, start_time, self.time, self.joint_names,
            allow_partial_joints_goal=self.allow_partial_joints_goal,
            allow_nonzero_velocity_at_trajectory_end=self.allow_nonzero_velocity_at_trajectory_end,
            fill_positions=fill)
        if isinstance(result, str):
            self.rejection_count += 1
            self.last_rejection = result
            self._log(f'trajectory rejected: {result}')
            return result
        self.accepted_count += 1
        self.follower.set(result)
        return None

    def cancel_trajectory(self) -> None:
        """Drop the trajectory and hold the current position."""
        self.follower.clear()
        self.controller.reset_hold()

    # ------------------------------------------------------------------ stepping
    def step(self, n: int = 1) -> None:
        """Advance n control steps of dt: sample the reference, compute torques, step MuJoCo."""
        model, data = self.model, self.data
        follower, controller = self.follower, self.controller
        # The scene has exactly the 7 arm joints, so qpos/qvel are the arm state (no slicing).
        q = data.qpos
        qd = data.qvel
        ctrl = data.ctrl
        for _ in range(int(n)):
            ref = follower.sample(data.time, q, qd)
            self.reference = ref
            if ref is None:
                tau = controller.compute(q, qd)
            else:
                tau = controller.compute(q, qd, *ref)
            ctrl[:] = tau
            mujoco.mj_step(model, data)
