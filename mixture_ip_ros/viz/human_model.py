"""example-robot-data's human model (Gepetto's 36-DOF ISB body), for pictures only.

The person stands across the table from the robot, facing it (-x of the scene's world frame), and
is posed per frame so that the right wrist follows a given wrist path (world frame): damped least
squares over the right arm and a little torso lean, pulled towards a relaxed standing posture.
Nothing here is simulated: the bodies only get kinematics (mj_kinematics), never dynamics.
"""

from __future__ import annotations

import functools
from pathlib import Path

import mujoco
import numpy as np

from mixture_ip_ros.robot.description import package_share
from mixture_ip_ros.robot.scene import FLOOR_Z, TABLE_X

PREFIX = 'human_'
WRIST_BODY = 'right_hand'           # its origin is the wrist joint (right_wrist_Z)
ROOT_BODY = 'middle_pelvis'
# ISB axes: x forward, y up, z to the person's right. Facing the robot (-x), up +z, right is +y.
WORLD_FROM_ISB = np.array([[-1.0, 0.0, 0.0],
                          [0.0, 0.0, 1.0],
                          [0.0, 1.0, 0.0]])
# Standing spot of scenarios/recording.py's person: about 1.35 m from the robot, body against the
# table edge, right hand hanging at y = 0.24 (its rest on the table edge, HUMAN_REST =
# (1.22, 0.24, 0.08)).
DEFAULT_PELVIS_XY = (TABLE_X[1] + 0.10, 0.03)

# Joints the wrist IK moves, with their cost in the IK's joint metric: the arm moves freely,
# the collar bone and the back only when the arm alone cannot reach.
IK_JOINTS = {
    'middle_lumbar_Z': 30.0, 'middle_thoracic_Z': 30.0,          # bending forward
    'middle_lumbar_X': 60.0, 'middle_thoracic_X': 60.0,          # bending sideways
    'middle_thoracic_Y': 20.0,                                   # turning the chest
    'right_clavicle_joint_X': 10.0,
    'right_shoulder_Z': 1.0, 'right_shoulder_X': 1.0, 'right_shoulder_Y': 2.0,
    'right_elbow_Z': 1.0, 'right_elbow_Y': 3.0,
}
# Relaxed standing posture (rad); joints not named stay at 0 (the URDF's upright, arms hanging).
RELAXED = {
    'right_shoulder_Z': 0.35, 'right_shoulder_X': 0.1, 'right_elbow_Z': 0.6, 'right_elbow_Y': 1.2,
    'left_shoulder_Z': 0.1, 'left_shoulder_X': 0.1, 'left_elbow_Z': 0.35, 'left_elbow_Y': 1.2,
    'middle_cervical_Z': 0.2,    # looking a little down, at the table
}

_SHIRT = (0.22, 0.42, 0.68, 1.0)
_SKIN = (0.88, 0.72, 0.60, 1.0)
_TROUSERS = (0.20, 0.21, 0.27, 1.0)
_SHOES = (0.10, 0.10, 0.10, 1.0)


def human_description_dir() -> Path:
    """robots/human_description inside the installed example-robot-data (a cmeel package)."""
    share = package_share('example-robot-data')
    if share is None:
        raise RuntimeError('example-robot-data is not installed')
    path = share / 'robots' / 'human_description'
    if not (path / 'robots' / 'human.urdf').is_file():
        raise RuntimeError(f'human model not found under {path}')
    return path


def _colour(body: str) -> tuple:
    if any(k in body for k in ('head', 'lowerarm', 'hand')):
        return _SKIN
    if any(k in body for k in ('leg', 'pelvis')):
        return _TROUSERS
    if 'foot' in body:
        return _SHOES
    return _SHIRT


def human_spec() -> mujoco.MjSpec:
    """The human URDF as an MjSpec: visual meshes kept, massless link frames given a token mass
    (MuJoCo refuses massless moving bodies), clothes colours instead of the URDF's left/right
    colours."""
    root = human_description_dir()
    text = (root / 'robots' / 'human.urdf').read_text()
    text = text.replace('package://example-robot-data/robots/human_description/meshes/',
                        str(root / 'meshes') + '/')
    head = text.index('>', text.index('<robot')) + 1
    # The URDF has only visuals; MuJoCo would discard them by default.
    text = (text[:head] + '<mujoco><compiler discardvisual="false" fusestatic="false"/></mujoco>'
            + text[head:])
    spec = mujoco.MjSpec.from_string(text)
    for body in spec.bodies:
        if body.name != 'world' and body.mass <= 0:
            body.mass = 1e-3
            body.inertia = [1e-6, 1e-6, 1e-6]
    for geom in spec.geoms:
        geom.rgba = list(_colour(geom.parent.name))
        geom.contype = 0
        geom.conaffinity = 0
        geom.group = 1
    return spec


def _quat(matrix) -> np.ndarray:
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, np.asarray(matrix, dtype=float).ravel())
    return quat


@functools.lru_cache(maxsize=1)
def pelvis_height() -> float:
    """Height of the pelvis origin above the lowest point of the feet, in the upright posture."""
    model = human_spec().compile()
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    lowest = np.inf
    for g in range(model.ngeom):
        if model.geom_type[g] != mujoco.mjtGeom.mjGEOM_MESH:
            continue
        mesh = model.geom_dataid[g]
        start, count = model.mesh_vertadr[mesh], model.mesh_vertnum[mesh]
        verts = model.mesh_vert[start:start + count]
        world = data.geom_xpos[g] + verts @ data.geom_xmat[g].reshape(3, 3).T
        lowest = min(lowest, float(world[:, 1].min()))    # ISB y is up
    return float(data.xpos[model.body(ROOT_BODY).id][1] - lowest)


@functools.lru_cache(maxsize=1)
def collar_height() -> float:
    """Height of the collar (the clavicles' joint, between the shoulders) above the lowest point
    of the feet, in the upright posture: where a skeleton tracker's body frame has its origin."""
    model = human_spec().compile()
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    pelvis = data.xpos[model.body(ROOT_BODY).id]
    collar = data.xpos[model.body('right_clavicle').id]
    return float(pelvis_height() + collar[1] - pelvis[1])      # ISB y is up


def add_human(spec: mujoco.MjSpec, pelvis_xy=DEFAULT_PELVIS_XY, floor_z: float = FLOOR_Z,
              height: float | None = None) -> None:
    """Attach the human to `spec` standing on the floor at `pelvis_xy`, facing the robot (-x).

    Its bodies and joints are prefixed with PREFIX. The joints come after the robot's in qpos.
    Sets spec.compiler.discardvisual = False: the human's geoms touch nothing, and a spec imported
    from URDF would otherwise drop every such visual-only geom when compiled.
    """
    spec.compiler.discardvisual = False
    if height is None:
        height = pelvis_height()
    pos = [float(pelvis_xy[0]), float(pelvis_xy[1]), float(floor_z + height)]
    frame = spec.worldbody.add_frame(pos=pos, quat=list(_quat(WORLD_FROM_ISB)))
    frame.attach_body(human_spec().body(ROOT_BODY), PREFIX, '')


class HumanPoser:
    """Poses the attached human so its right wrist is at a target point (world frame)."""

    def __init__(self, model: mujoco.MjModel, prefix: str = PREFIX):
        self.model = model
        self._wrist = model.body(prefix + WRIST_BODY).id
        names = [model.joint(j).name for j in range(model.njnt)]
        human = [n for n in names if n.startswith(prefix)]
        if not human:
            raise ValueError(f'model has no joints prefixed {prefix!r}; was add_human called?')
        self._all_qadr = np.array([model.joint(n).qposadr[0] for n in human])
        self.relaxed = np.zeros(model.nq)
        for name, value in RELAXED.items():
            self.relaxed[model.joint(prefix + name).qposadr[0]] = value
        ik = [prefix + n for n in IK_JOINTS]
        self._qadr = np.array([model.joint(n).qposadr[0] for n in ik])
        self._dadr = np.array([model.joint(n).dofadr[0] for n in ik])
        self._lo = np.array([model.jnt_range[model.joint(n).id][0] for n in ik])
        self._hi = np.array([model.jnt_range[model.joint(n).id][1] for n in ik])
        self._weight = np.array(list(IK_JOINTS.values()))
        self._jacp = np.zeros((3, model.nv))
        self.posture_gain = 0.1

    def relax(self, data: mujoco.MjData) -> None:
        """Put every human joint in the relaxed standing posture."""
        data.qpos[self._all_qadr] = self.relaxed[self._all_qadr]
        mujoco.mj_kinematics(self.model, data)

    def wrist(self, data: mujoco.MjData) -> np.ndarray:
        return data.xpos[self._wrist].copy()

    def reach(self, data: mujoco.MjData, target, iterations: int = 30,
              damping: float = 1e-4, tolerance: float = 1e-3) -> float:
        """Move the IK joints (from their current values) so the wrist approaches `target`;
        returns the remaining distance in metres. Other joints are left as they are."""
        target = np.asarray(target, dtype=float)
        if target.shape != (3,) or not np.all(np.isfinite(target)):
            raise ValueError(f'wrist target must be 3 finite numbers, got {target!r}')
        model, qa = self.model, self._qadr
        rest = self.relaxed[qa]
        w_inv = 1.0 / self._weight
        err = np.inf
        for _ in range(iterations):
            mujoco.mj_kinematics(model, data)
            mujoco.mj_comPos(model, data)
            e = target - data.xpos[self._wrist]
            err = float(np.linalg.norm(e))
            if err < tolerance:
                break
            mujoco.mj_jacBody(model, data, self._jacp, None, self._wrist)
            J = self._jacp[:, self._dadr]
            q = data.qpos[qa]
            # Weighted damped pseudo-inverse for the wrist; the relaxed posture in its null space.
            JW = J * w_inv
            G = JW.T @ np.linalg.inv(JW @ J.T + damping * np.eye(3))
            dq = G @ e - (np.eye(len(qa)) - G @ J) @ (self.posture_gain * (q - rest))
            data.qpos[qa] = np.clip(q + dq, self._lo, self._hi)
        else:
            mujoco.mj_kinematics(model, data)
            err = float(np.linalg.norm(target - data.xpos[self._wrist]))
        return err
