"""KUKA iiwa 14 kinematics and rigid-body dynamics with Pinocchio, from models/iiwa14.urdf."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin

from mixture_ip_ros.core.share import model_path

from mixture_ip_ros.robot.description import FLANGE_FRAME, JOINT_NAMES, URDF_NAME


def _as_q(q, name='q') -> np.ndarray:
    q = np.asarray(q, dtype=float)
    if q.shape != (7,):
        raise ValueError(f'{name} must have shape (7,), got {q.shape}')
    return q


class IiwaKinematics:
    """Pinocchio model of the iiwa 14: forward kinematics, IK, mass matrix and inverse dynamics.

    mass_scale multiplies every link's mass and rotational inertia (centres of mass unchanged);
    it exists to build a deliberately wrong controller model for robustness tests.
    """

    def __init__(self, urdf_path: str | Path | None = None, mass_scale: float = 1.0):
        path = Path(urdf_path) if urdf_path is not None else model_path(URDF_NAME)
        if not path.is_file():
            raise ValueError(f'URDF not found: {path}')
        if not (np.isfinite(mass_scale) and mass_scale > 0):
            raise ValueError(f'mass_scale must be a positive number, got {mass_scale}')
        self.model = pin.buildModelFromUrdf(str(path))
        names = [self.model.names[i] for i in range(1, self.model.njoints)]
        if names != list(JOINT_NAMES):
            raise ValueError(f'{path} has joints {names}, expected {JOINT_NAMES}')
        if mass_scale != 1.0:
            for i in range(1, self.model.njoints):
                inertia = self.model.inertias[i]
                self.model.inertias[i] = pin.Inertia(
                    inertia.mass * mass_scale, inertia.lever, inertia.inertia * mass_scale)
        self.data = self.model.createData()
        self.joint_names = list(JOINT_NAMES)
        self.lower = np.array(self.model.lowerPositionLimit, dtype=float)
        self.upper = np.array(self.model.upperPositionLimit, dtype=float)
        self.velocity_limit = np.array(self.model.velocityLimit, dtype=float)
        self.effort_limit = np.array(self.model.effortLimit, dtype=float)
        self.flange_id = self.model.getFrameId(FLANGE_FRAME)
        if self.flange_id >= len(self.model.frames):
            raise ValueError(f'{path} has no frame {FLANGE_FRAME!r}')
        self.mass_scale = float(mass_scale)

    # ------------------------------------------------------------------ kinematics
    def fk(self, q) -> tuple[np.ndarray, np.ndarray]:
        """Flange (tool0) position (3,) and rotation (3, 3) in the base frame iiwa_link_0."""
        q = _as_q(q)
        pin.framesForwardKinematics(self.model, self.data, q)
        placement = self.data.oMf[self.flange_id]
        return placement.translation.copy(), placement.rotation.copy()

    def fk_positions(self, Q) -> np.ndarray:
        """Flange positions (n, 3) for joint configurations Q (n, 7)."""
        Q = np.asarray(Q, dtype=float)
        if Q.ndim != 2 or Q.shape[1] != 7:
            raise ValueError(f'Q must have shape (n, 7), got {Q.shape}')
        out = np.empty((Q.shape[0], 3))
        for i, q in enumerate(Q):
            pin.forwardKinematics(self.model, self.data, q)
            pin.updateFramePlacement(self.model, self.data, self.flange_id)
            out[i] = self.data.oMf[self.flange_id].translation
        return out

    def jacobian(self, q) -> np.ndarray:
        """Flange Jacobian (6, 7), linear rows first, in the base-aligned frame at the flange."""
        q = _as_q(q)
        return pin.computeFrameJacobian(
            self.model, self.data, q, self.flange_id, pin.LOCAL_WORLD_ALIGNED).copy()

    def within_limits(self, q, margin: float = 0.0) -> bool:
        q = _as_q(q)
        return bool(np.all(q >= self.lower + margin) and np.all(q <= self.upper - margin))

    # ------------------------------------------------------------------ inverse kinematics
    def ik(self, position, q0, rotation=None, orientation_weight: float = 0.3,
           max_iters: int = 100, tol: float = 1e-3, rotation_tol: float | None = None,
           limit_margin: float = 0.02, restarts: int = 12) -> np.ndarray:
        """Joint configuration placing the flange at `position` (base frame), warm-started at q0.

        Levenberg-Marquardt damped least squares with a monotone line search and joint-limit
        clamping (joints pinned at a limit leave the step). A target `rotation` (3, 3) is a soft
        task: the solver first minimises |e_pos|^2 + (orientation_weight |e_rot|)^2 (e_rot in
        radians), then polishes the position alone with minimum-norm steps, so an unreachable
        orientation never costs position accuracy. The first attempt starts at q0, so a sequence
        of nearby targets gives a smooth joint path; if it fails, `restarts` deterministic random
        starts are tried. The result stays `limit_margin` rad inside the joint limits.
        Raises ValueError when no attempt gets within `tol` metres (and, if given, `rotation_tol`
        radians).
        """
        target = np.asarray(position, dtype=float)
        if target.shape != (3,) or not np.all(np.isfinite(target)):
            raise ValueError(f'position must be 3 finite numbers, got {position!r}')
        q0 = _as_q(q0, 'q0')
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
        lo = self.lower + limit_margin
        hi = self.upper - limit_margin
        rng = np.random.default_rng(12345)
        starts = [np.clip(q0, lo, hi)] + [rng.uniform(lo, hi) for _ in range(restarts)]
        best = None
        for start in starts:
            q = start
            if R_target is not None and orientation_weight > 0:
                q = self._lm_solve(target, q, R_target, orientation_weight, max_iters, 0.0, lo, hi)
            q = self._lm_solve(target, q, None, 0.0, max_iters, 0.05 * tol, lo, hi)
            pos_err = float(np.linalg.norm(self._residual(q, target, None, 0.0)))
            rot_err = self._rotation_error(q, R_target) if R_target is not None else 0.0
            if pos_err <= tol and (rotation_tol is None or rot_err <= rotation_tol):
                return q
            if best is None or pos_err < best[0]:
                best = (pos_err, rot_err)
        raise ValueError(
            f'IK did not converge to {target.tolist()} within {tol} m '
            f'(best position error {best[0]:.4f} m, rotation error {best[1]:.3f} rad)')

    def _residual(self, q, target, R_target, w_rot) -> np.ndarray:
        pin.forwardKinematics(self.model, self.data, q)
        pin.updateFramePlacement(self.model, self.data, self.flange_id)
        placement = self.data.oMf[self.flange_id]
        e = target - placement.translation
        if R_target is None:
            return e
        return np.concatenate([e, w_rot * pin.log3(R_target @ placement.rotation.T)])

    def _lm_solve(self, target, q, R_target, w_rot, max_iters, stop_err, lo, hi) -> np.ndarray:
        q = np.clip(q, lo, hi)
        rows = 3 if R_target is None else 6
        e = self._residual(q, target, R_target, w_rot)
        cost = float(e @ e)
        for _ in range(max_iters):
            if np.sqrt(cost) <= stop_err:
                break
            J = pin.computeFrameJacobian(self.model, self.data, q, self.flange_id,
                                         pin.LOCAL_WORLD_ALIGNED)[:rows]
            if rows == 6:
                J[3:] *= w_rot
            # Damping grows with the error: Gauss-Newton near the solution, gradient-like far away.
            lam = 1e-6 + 0.5 * cost
            free = np.ones(7, dtype=bool)
            for _attempt in range(3):
                Jf = J * free
                dq = Jf.T @ np.linalg.solve(Jf @ Jf.T + lam * np.eye(rows), e)
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
                e_new = self._residual(q_new, target, R_target, w_rot)
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
        """Joint-space mass matrix M(q) (7, 7), symmetric."""
        q = _as_q(q)
        M = pin.crba(self.model, self.data, q)
        return np.triu(M) + np.triu(M, 1).T

    def rnea(self, q, qd, qdd) -> np.ndarray:
        """Inverse dynamics tau = M(q) qdd + C(q, qd) qd + g(q) (7,)."""
        return pin.rnea(self.model, self.data, _as_q(q), _as_q(qd, 'qd'), _as_q(qdd, 'qdd')).copy()

    def gravity(self, q) -> np.ndarray:
        """Gravity torque g(q) (7,)."""
        return pin.computeGeneralizedGravity(self.model, self.data, _as_q(q)).copy()
