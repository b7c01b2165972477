"""Kinematics and rigid-body dynamics of a serial arm with Pinocchio, from its description.

The Pinocchio model is the description's model file with every joint that is not one of the
description's joints locked at zero (e.g. a gripper's fingers), so its configuration is exactly
the controlled joints, in the description's order. Everything is in the robot's base frame;
gravity points along the scene's -z seen from the base (the mount may tilt the base).
"""

from __future__ import annotations

import functools

import numpy as np
import pinocchio as pin

from mixture_ip_ros.robot.description import DescriptionError, RobotDescription, load_description

GRAVITY = 9.81


def load_arm_model(description: RobotDescription) -> pin.Model:
    """The description's model reduced to its joints, checked against the description.

    Raises DescriptionError when the model does not fit: a joint missing or not a 1-DOF
    revolute/prismatic joint, the joints not being the chain from the base frame to the flange
    frame in order, a limit missing, the home posture outside the limits.
    """
    where = f'robot {description.name!r} ({description.model_path})'
    path = str(description.model_path)
    try:
        if description.model_path.suffix.lower() == '.urdf':
            full = pin.buildModelFromUrdf(path)
        else:
            full = pin.buildModelFromMJCF(path)
    except (RuntimeError, ValueError) as exc:
        raise DescriptionError(f'{where}: Pinocchio cannot load the model: {exc}') from exc
    names = [full.names[i] for i in range(1, full.njoints)]
    for name in description.joint_names:
        if name not in names:
            raise DescriptionError(f'{where}: no joint {name!r}; the model has {names}')
        joint = full.joints[full.getJointId(name)]
        if joint.nq != 1 or joint.nv != 1:
            raise DescriptionError(f'{where}: joint {name!r} is not a 1-DOF revolute or '
                                   f'prismatic joint ({joint.shortname()})')
    lock = [full.getJointId(n) for n in names if n not in description.joint_names]
    model = pin.buildReducedModel(full, lock, pin.neutral(full)) if lock else full
    kept = [model.names[i] for i in range(1, model.njoints)]
    if kept != list(description.joint_names):
        raise DescriptionError(f'{where}: joints must be listed in chain order {kept}, got '
                               f'{list(description.joint_names)}')
    for field, frame in (('base_frame', description.base_frame),
                         ('flange_frame', description.flange_frame)):
        if not model.existFrame(frame):
            raise DescriptionError(f'{where}: {field} {frame!r} is not a frame of the model')
    base = model.frames[model.getFrameId(description.base_frame)]
    if base.parentJoint != 0 or not base.placement.isIdentity(1e-9):
        raise DescriptionError(
            f'{where}: base_frame {description.base_frame!r} must be the model\'s root frame '
            '(fixed, at the origin of the model); place the arm with mount instead')
    flange = model.frames[model.getFrameId(description.flange_frame)]
    chain = [model.names[j] for j in model.supports[flange.parentJoint][1:]]
    if chain != list(description.joint_names):
        raise DescriptionError(f'{where}: the flange frame {description.flange_frame!r} hangs '
                               f'on the joints {chain}, not on {list(description.joint_names)}: '
                               'the joints must be the serial chain from base to flange')
    lower, upper = model.lowerPositionLimit, model.upperPositionLimit
    for label, values in (('velocity', model.velocityLimit), ('effort', model.effortLimit)):
        bad = [n for n, v in zip(description.joint_names, values) if not (0 < v < np.inf)]
        if bad:
            raise DescriptionError(f'{where}: joints {bad} have no positive finite {label} '
                                   'limit in the model file')
    if not (np.all(np.isfinite(lower)) and np.all(np.isfinite(upper))
            and np.all(lower < upper)):
        raise DescriptionError(f'{where}: every joint needs finite position limits')
    for label, q in (('home', description.home), ('scenarios.box_seed', description.box_seed),
                     ('scenarios.pole_home', description.pole_home)):
        if q is not None and not (np.all(np.asarray(q) >= lower)
                                  and np.all(np.asarray(q) <= upper)):
            raise DescriptionError(f'{where}: {label} {list(q)} is outside the joint limits '
                                   f'{lower.tolist()} .. {upper.tolist()}')
    for frame in description.clearance_frames:
        if not model.existFrame(frame):
            raise DescriptionError(f'{where}: scenarios.clearance_frames: no frame {frame!r}')
    model.gravity.linear = description.mount_rotation.T @ np.array([0.0, 0.0, -GRAVITY])
    return model


class RobotKinematics:
    """Pinocchio model of an arm: forward kinematics, IK, mass matrix and inverse dynamics.

    ``robot``: a description, a shipped name or a description file (None: the default iiwa 14).
    mass_scale multiplies every link's mass and rotational inertia (centres of mass unchanged);
    it exists to build a deliberately wrong controller model for robustness tests.
    """

    def __init__(self, robot=None, mass_scale: float = 1.0):
        self.description = load_description(robot)
        if not (np.isfinite(mass_scale) and mass_scale > 0):
            raise ValueError(f'mass_scale must be a positive number, got {mass_scale}')
        self.model = load_arm_model(self.description)
        if mass_scale != 1.0:
            for i in range(1, self.model.njoints):
                inertia = self.model.inertias[i]
                self.model.inertias[i] = pin.Inertia(
                    inertia.mass * mass_scale, inertia.lever, inertia.inertia * mass_scale)
        self.data = self.model.createData()
        self.joint_names = list(self.description.joint_names)
        self.dof = self.model.nv
        self.lower = np.array(self.model.lowerPositionLimit, dtype=float)
        self.upper = np.array(self.model.upperPositionLimit, dtype=float)
        self.velocity_limit = np.array(self.model.velocityLimit, dtype=float)
        self.effort_limit = np.array(self.model.effortLimit, dtype=float)
        self.flange_id = self.model.getFrameId(self.description.flange_frame)
        self.mass_scale = float(mass_scale)

    @functools.cached_property
    def acceleration_limit(self) -> np.ndarray:
        """rad/s^2 per joint that the arm reaches everywhere: the acceleration joint j alone gets
        from its full effort, less what holds the arm against gravity, at the posture where
        that is least, (tau_max_j - |g_j(q)|) / M_jj(q) (URDFs carry no acceleration limits; a
        datasheet's, where there is one, are lower). Over the home posture and 200 postures
        drawn uniformly inside the limits (seeded: the same every time)."""
        rng = np.random.default_rng(0)
        postures = [np.asarray(self.description.home, dtype=float)]
        postures += list(rng.uniform(self.lower, self.upper, (200, self.dof)))
        out = np.full(self.dof, np.inf)
        for q in postures:
            M = self.mass_matrix(q)
            free = self.effort_limit - np.abs(self.gravity(q))
            out = np.minimum(out, np.maximum(free, 0.05 * self.effort_limit) / np.diag(M))
        return out

    def _as_q(self, q, name='q') -> np.ndarray:
        q = np.asarray(q, dtype=float)
        if q.shape != (self.dof,):
            raise ValueError(f'{name} must have shape ({self.dof},), got {q.shape}')
        return q

    def frame_positions(self, q, frames) -> np.ndarray:
        """Origins (len(frames), 3) of the named frames at q, base frame."""
        pin.framesForwardKinematics(self.model, self.data, self._as_q(q))
        return np.array([self.data.oMf[self.model.getFrameId(f)].translation for f in frames])

    # ------------------------------------------------------------------ kinematics
    def fk(self, q) -> tuple[np.ndarray, np.ndarray]:
        """Flange position (3,) and rotation (3, 3) in the base frame."""
        q = self._as_q(q)
        pin.framesForwardKinematics(self.model, self.data, q)
        placement = self.data.oMf[self.flange_id]
        return placement.translation.copy(), placement.rotation.copy()

    def fk_positions(self, Q) -> np.ndarray:
        """Flange positions (n, 3) for joint configurations Q (n, dof)."""
        Q = np.asarray(Q, dtype=float)
        if Q.ndim != 2 or Q.shape[1] != self.dof:
            raise ValueError(f'Q must have shape (n, {self.dof}), got {Q.shape}')
        out = np.empty((Q.shape[0], 3))
        for i, q in enumerate(Q):
            pin.forwardKinematics(self.model, self.data, q)
            pin.updateFramePlacement(self.model, self.data, self.flange_id)
            out[i] = self.data.oMf[self.flange_id].translation
        return out

    def jacobian(self, q) -> np.ndarray:
        """Flange Jacobian (6, dof), linear rows first, in the base-aligned frame at the flange."""
        q = self._as_q(q)
        return pin.computeFrameJacobian(
            self.model, self.data, q, self.flange_id, pin.LOCAL_WORLD_ALIGNED).copy()

    def within_limits(self, q, margin: float = 0.0) -> bool:
        q = self._as_q(q)
        return bool(np.all(q >= self.lower + margin) and np.all(q <= self.upper - margin))

    # ------------------------------------------------------------------ inverse kinematics
    def ik(self, position, q0, rotation=None, orientation_weight: float = 0.3,
           max_iters: int = 100, tol: float = 1e-3, rotation_tol: float | None = None,
           limit_margin: float = 0.02, restarts: int = 12, posture=None,
           posture_weight: float = 0.0) -> np.ndarray:
        """Joint configuration placing the flange at `position` (base frame), warm-started at q0.

        Levenberg-Marquardt damped least squares with a monotone line search and joint-limit
        clamping (joints pinned at a limit leave the step). A target `rotation` (3, 3) and a
        preferred `posture` (dof,) are soft tasks: the solver first minimises
        |e_pos|^2 + (orientation_weight |e_rot|)^2 + (posture_weight |q - posture|)^2 (e_rot in
        radians, the posture's in rad, weights in m/rad), then polishes the position alone with
        minimum-norm steps, so neither soft task ever costs position accuracy. The first attempt
        starts at q0, so a sequence of nearby targets gives a smooth joint path; if it fails,
        `restarts` deterministic random starts are tried. The result stays `limit_margin` rad
        inside the joint limits.
        Raises ValueError when no attempt gets within `tol` metres (and, if given, `rotation_tol`
        radians).
        """
        target, q0, R_target, posture = self._ik_inputs(position, q0, rotation,
                                                        orientation_weight, posture,
                                                        posture_weight)
        lo = self.lower + limit_margin
        hi = self.upper - limit_margin
        rng = np.random.default_rng(12345)
        starts = [np.clip(q0, lo, hi)] + [rng.uniform(lo, hi) for _ in range(restarts)]
        best = None
        for start in starts:
            q, pos_err = self._attempt(target, start, R_target, orientation_weight, posture,
                                       posture_weight, max_iters, tol, lo, hi)
            rot_err = self._rotation_error(q, R_target) if R_target is not None else 0.0
            if pos_err <= tol and (rotation_tol is None or rot_err <= rotation_tol):
                return q
            if best is None or pos_err < best[0]:
                best = (pos_err, rot_err)
        raise ValueError(
            f'IK did not converge to {target.tolist()} within {tol} m '
            f'(best position error {best[0]:.4f} m, rotation error {best[1]:.3f} rad)')

    def closest(self, position, q0, *, posture=None, posture_weight: float = 0.0,
                max_change=None, max_iters: int = 100, tol: float = 1e-3,
                limit_margin: float = 0.02) -> tuple[np.ndarray, float]:
        """One attempt of :meth:`ik` from q0, never raising for a target out of reach: the
        configuration (dof,) whose flange is as close to `position` as the solver gets from q0
        within the limits (less `limit_margin`) and, if given, within `max_change` rad per
        joint (a number or one per joint) of q0, and that distance in metres. For paths: the
        solution moves continuously with the target, where ik's restarts could jump to another
        arm configuration."""
        target, q0, _, posture = self._ik_inputs(position, q0, None, 0.0, posture,
                                                 posture_weight)
        lo = self.lower + limit_margin
        hi = self.upper - limit_margin
        if max_change is not None:
            change = np.broadcast_to(np.asarray(max_change, dtype=float), (self.dof,))
            if not np.all(change > 0):
                raise ValueError(f'max_change must be positive, got {max_change!r}')
            q0 = np.clip(q0, lo, hi)
            lo, hi = np.maximum(lo, q0 - change), np.minimum(hi, q0 + change)
        return self._attempt(target, np.clip(q0, lo, hi), None, 0.0, posture, posture_weight,
                             max_iters, tol, lo, hi)

    def _ik_inputs(self, position, q0, rotation, orientation_weight, posture, posture_weight):
        target = np.asarray(position, dtype=float)
        if target.shape != (3,) or not np.all(np.isfinite(target)):
            raise ValueError(f'position must be 3 finite numbers, got {position!r}')
        q0 = self._as_q(q0, 'q0')
        if not np.all(np.isfinite(q0)):
            raise ValueError('q0 must be finite')
        R_target = None
        if rotation is not None:
            R_target = np.asarray(rotation, dtype=float)
            if R_target.shape != (3, 3) or not np.all(np.isfinite(R_target)):
                raise ValueError('rotation must be a finite (3, 3) matrix')
            if not np.allclose(R_target @ R_target.T, np.eye(3), atol=1e-6):
                raise ValueError('rotation must be orthonormal')
        if not (np.isfinite(orientation_weight) and orientation_weight >= 0):
            raise ValueError('orientation_weight must be >= 0')
        if not (np.isfinite(posture_weight) and posture_weight >= 0):
            raise ValueError('posture_weight must be >= 0')
        if posture is not None:
            posture = self._as_q(posture, 'posture')
            if not np.all(np.isfinite(posture)):
                raise ValueError('posture must be finite')
        return target, q0, R_target, posture

    def _attempt(self, target, q, R_target, w_rot, posture, w_post, max_iters, tol, lo,
                 hi) -> tuple[np.ndarray, float]:
        """The soft tasks (if any), then the position alone; (q, position error)."""
        soft_rotation = R_target is not None and w_rot > 0
        soft_posture = posture is not None and w_post > 0
        if soft_rotation or soft_posture:
            q = self._lm_solve(target, q, R_target if soft_rotation else None, w_rot,
                               max_iters, 0.0, lo, hi,
                               (posture, w_post) if soft_posture else None)
        q = self._lm_solve(target, q, None, 0.0, max_iters, 0.05 * tol, lo, hi)
        return q, float(np.linalg.norm(self._residual(q, target, None, 0.0)))

    def _residual(self, q, target, R_target, w_rot) -> np.ndarray:
        pin.forwardKinematics(self.model, self.data, q)
        pin.updateFramePlacement(self.model, self.data, self.flange_id)
        placement = self.data.oMf[self.flange_id]
        e = target - placement.translation
        if R_target is None:
            return e
        return np.concatenate([e, w_rot * pin.log3(R_target @ placement.rotation.T)])

    def _lm_solve(self, target, q, R_target, w_rot, max_iters, stop_err, lo, hi,
                  posture=None) -> np.ndarray:
        """``posture``: None or (q_preferred, weight), rows weight (q_preferred - q) appended to
        the residual; the damping follows the task rows' error only (the posture's never
        vanishes)."""
        q = np.clip(q, lo, hi)
        rows = 3 if R_target is None else 6

        def residual(q):
            e = self._residual(q, target, R_target, w_rot)
            return e if posture is None else np.concatenate([e, posture[1] * (posture[0] - q)])

        e = residual(q)
        cost = float(e @ e)
        n = rows if posture is None else rows + self.dof
        for _ in range(max_iters):
            if np.sqrt(cost) <= stop_err:
                break
            J = pin.computeFrameJacobian(self.model, self.data, q, self.flange_id,
                                         pin.LOCAL_WORLD_ALIGNED)[:rows]
            if rows == 6:
                J[3:] *= w_rot
            task_cost = cost
            if posture is not None:
                J = np.vstack([J, posture[1] * np.eye(self.dof)])
                task_cost = float(e[:rows] @ e[:rows])
            # Damping grows with the error: Gauss-Newton near the solution, gradient-like far away.
            lam = 1e-6 + 0.5 * task_cost
            free = np.ones(self.dof, dtype=bool)
            for _attempt in range(3):
                Jf = J * free
                dq = Jf.T @ np.linalg.solve(Jf @ Jf.T + lam * np.eye(n), e)
                blocked = free & (((q <= lo + 1e-9) & (dq < 0)) | ((q >= hi - 1e-9) & (dq > 0)))
                if not np.any(blocked):
                    break
                free &= ~blocked
            step = float(np.max(np.abs(dq)))
            if step > 0.5:
                dq *= 0.5 / step
            accepted = False
            alpha = 1.0
            for _ls in range(6):
                q_new = np.clip(q + alpha * dq, lo, hi)
                e_new = residual(q_new)
                cost_new = float(e_new @ e_new)
                if cost_new < cost:
                    accepted = True
                    break
                alpha *= 0.5
            if not accepted:
                break
            converged = cost - cost_new < 1e-14
            q, e, cost = q_new, e_new, cost_new
            if converged:
                break
        return q

    def _rotation_error(self, q, R_target) -> float:
        _, R = self.fk(q)
        return float(np.linalg.norm(pin.log3(R_target @ R.T)))

    # ------------------------------------------------------------------ dynamics
    def mass_matrix(self, q) -> np.ndarray:
        """Joint-space mass matrix M(q) (dof, dof), symmetric."""
        q = self._as_q(q)
        M = pin.crba(self.model, self.data, q)
        return np.triu(M) + np.triu(M, 1).T

    def rnea(self, q, qd, qdd) -> np.ndarray:
        """Inverse dynamics tau = M(q) qdd + C(q, qd) qd + g(q) (dof,)."""
        return pin.rnea(self.model, self.data, self._as_q(q), self._as_q(qd, 'qd'),
                        self._as_q(qdd, 'qdd')).copy()

    def gravity(self, q) -> np.ndarray:
        """Gravity torque g(q) (dof,)."""
        return pin.computeGeneralizedGravity(self.model, self.data, self._as_q(q)).copy()
