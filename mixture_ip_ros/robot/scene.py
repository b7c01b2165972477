"""MuJoCo scene: an arm from its description with torque actuators, table, stands, optional pole.

The world frame is the scene's: the table top is z = 0, the human stands across the table at +x,
and the default robot (the iiwa 14) stands at the origin. Another arm stands where its
description's mount puts its base frame (on a pedestal when raised). Everything here is in
metres, world frame; robot/sim.py speaks the robot's base frame.
"""

from __future__ import annotations

import mujoco
import numpy as np

from mixture_ip_ros.robot.description import RobotDescription, load_description, resolve_uri

TIMESTEP = 0.001
TABLE_TOP_Z = 0.0
TABLE_X = (-0.35, 1.25)
TABLE_Y = (-0.8, 0.8)
TABLE_THICKNESS = 0.04
FLOOR_Z = -0.75

# Box-assembly scenario (thesis 3.4.2): stands beside the robot, clear of the handover region.
STAND_HALF_SIZE = 0.06
STAND_HEIGHT = 0.15
PLATE_STAND_XY = (0.2, 0.55)
SCREW_STAND_XY = (0.2, -0.55)
PLATE_RADIUS = 0.09
PLATE_THICKNESS = 0.01

# Pole-pointing scenario (thesis 3.4.1): a vertical pole in front of the robot.
POLE_XY = (0.5, 0.0)
POLE_RADIUS = 0.03
POLE_HEIGHT = 0.8

HUMAN_WRIST = 'human_wrist'
HUMAN_WRIST_DEFAULT = (1.0, 0.0, 0.3)
FLANGE_SITE = 'flange'
PEDESTAL_RADIUS = 0.09

# Contact filtering: robot geoms touch the environment but not each other (self-collision of the
# simplified geometry would be spurious); environment geoms are static and never touch each other.
ROBOT_CONTYPE, ROBOT_CONAFFINITY = 2, 1
ENV_CONTYPE, ENV_CONAFFINITY = 1, 2

_GREY = (0.55, 0.55, 0.58, 1.0)
_ORANGE = (1.0, 0.42, 0.04, 1.0)
_WOOD = (0.62, 0.48, 0.33, 1.0)


def plate_position(stand_xy=PLATE_STAND_XY) -> np.ndarray:
    """Centre of the plate lying on its stand."""
    return np.array([stand_xy[0], stand_xy[1], TABLE_TOP_Z + STAND_HEIGHT + PLATE_THICKNESS / 2])


def screw_position(stand_xy=SCREW_STAND_XY) -> np.ndarray:
    """Head of the screw standing in its stand."""
    return np.array([stand_xy[0], stand_xy[1], TABLE_TOP_Z + STAND_HEIGHT + 0.05])


def _static_geom(body, name, gtype, size, pos, rgba, collide=True, quat=None):
    geom = body.add_geom(name=name, type=gtype, size=list(size), pos=list(pos), rgba=list(rgba))
    if quat is not None:
        geom.quat = list(quat)
    geom.contype = ENV_CONTYPE if collide else 0
    geom.conaffinity = ENV_CONAFFINITY if collide else 0
    return geom


def actuator_names(robot=None) -> list:
    """The torque actuators' names, one per joint in the description's order."""
    return [f'{name}_torque' for name in load_description(robot).joint_names]


def _mount_robot(spec: mujoco.MjSpec, description: RobotDescription) -> None:
    """Put the model's root (its base frame, robot.kinematics checks) at the description's mount:
    the top-level bodies move with it."""
    R = description.mount_rotation
    t = np.asarray(description.mount_xyz, dtype=float)
    q_mount = np.empty(4)
    mujoco.mju_mat2Quat(q_mount, R.ravel())
    for body in spec.worldbody.bodies:
        body.pos = (R @ np.asarray(body.pos, dtype=float) + t).tolist()
        quat = np.empty(4)
        mujoco.mju_mulQuat(quat, q_mount, np.asarray(body.quat, dtype=float))
        body.quat = quat.tolist()


def _arm_spec(description: RobotDescription, effort_limit) -> mujoco.MjSpec:
    """The description's model as an MjSpec: only its joints movable (others welded at zero),
    meshes found, no damping/friction/armature, a torque motor per joint, a site at the flange."""
    path = description.model_path
    try:
        spec = mujoco.MjSpec.from_file(str(path))
    except Exception as exc:
        raise ValueError(f'MuJoCo cannot load {path}: {exc}') from exc
    for mesh in spec.meshes:
        if mesh.file.startswith('package://'):
            mesh.file = str(resolve_uri(mesh.file))
    keep = set(description.joint_names)
    # Joints that are not the arm's (a gripper's fingers) are welded at zero, as Pinocchio's
    # reduced model locks them; constraints and actuators that use them go with them.
    dropped = {j.name for j in spec.joints if j.name not in keep}
    for equality in list(spec.equalities):
        if equality.name1 in dropped or equality.name2 in dropped:
            spec.delete(equality)
    for joint in list(spec.joints):
        if joint.name in dropped:
            spec.delete(joint)
    for actuator in list(spec.actuators):
        spec.delete(actuator)
    # Keep fixed links (the flange) as bodies so the flange site has a home.
    spec.compiler.fusestatic = False
    # No joint damping or armature anywhere: the controller's Pinocchio model mirrors this exactly.
    for joint in spec.joints:
        joint.damping = [0.0, 0.0, 0.0]
        joint.armature = 0.0
        joint.frictionloss = 0.0
    accent = set(description.accent_links)
    for geom in spec.geoms:
        geom.contype = ROBOT_CONTYPE
        geom.conaffinity = ROBOT_CONAFFINITY
        geom.rgba = list(_ORANGE if geom.parent.name in accent else _GREY)
    flange = spec.body(description.flange_frame)
    if flange is None:
        raise ValueError(f'{path}: flange_frame {description.flange_frame!r} is not a link')
    flange.add_site(name=FLANGE_SITE, size=[0.01, 0, 0], rgba=[0.1, 0.1, 0.9, 1])
    for name, actuator_name, effort in zip(description.joint_names,
                                           actuator_names(description), effort_limit):
        act = spec.add_actuator(name=actuator_name, target=name)
        act.trntype = mujoco.mjtTrn.mjTRN_JOINT
        act.set_to_motor()
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.ctrlrange = [-float(effort), float(effort)]
    _mount_robot(spec, description)
    return spec


def build_spec(pole: bool = False, stands: bool = True, table: bool = True,
               pole_xy=POLE_XY, pole_radius: float = POLE_RADIUS, pole_height: float = POLE_HEIGHT,
               plate_stand_xy=PLATE_STAND_XY, screw_stand_xy=SCREW_STAND_XY,
               timestep: float = TIMESTEP, robot=None,
               floor_z: float = FLOOR_Z) -> mujoco.MjSpec:
    """The scene as an MjSpec, for callers that want to add things before compiling.

    ``robot``: a description, a shipped robot's name or a description file (None: the iiwa 14).
    ``floor_z``: the floor's height (nothing touches it; a picture puts it under a person's
    feet).
    """
    from mixture_ip_ros.robot.kinematics import load_arm_model
    description = load_description(robot)
    if not (timestep > 0 and np.isfinite(timestep)):
        raise ValueError(f'timestep must be positive, got {timestep}')
    if pole and not (pole_radius > 0 and pole_height > 0):
        raise ValueError('pole_radius and pole_height must be positive')
    # Effort limits as Pinocchio reads them from the model (one reading of the limits).
    spec = _arm_spec(description, load_arm_model(description).effortLimit)
    spec.compiler.discardvisual = False   # keep the visual-only geoms (floor, legs, objects)
    spec.modelname = f'{description.name}_scene'
    spec.option.timestep = timestep

    world = spec.worldbody
    world.add_light(name='sun', pos=[0.5, -0.5, 2.5], dir=[0, 0.3, -1], castshadow=False)
    world.add_camera(name='overview', pos=[2.1, -1.5, 1.3], xyaxes=[0.6, 0.8, 0, -0.35, 0.26, 0.9])
    world.add_camera(name='side', pos=[0.5, -2.2, 0.5], xyaxes=[1, 0, 0, 0, 0.2, 1])
    _static_geom(world, 'floor', mujoco.mjtGeom.mjGEOM_PLANE, (3, 3, 0.1), (0, 0, floor_z),
                 (0.85, 0.85, 0.85, 1), collide=False)
    if table:
        half = ((TABLE_X[1] - TABLE_X[0]) / 2, (TABLE_Y[1] - TABLE_Y[0]) / 2, TABLE_THICKNESS / 2)
        centre = ((TABLE_X[0] + TABLE_X[1]) / 2, (TABLE_Y[0] + TABLE_Y[1]) / 2,
                  TABLE_TOP_Z - TABLE_THICKNESS / 2)
        _static_geom(world, 'table_top', mujoco.mjtGeom.mjGEOM_BOX, half, centre, _WOOD)
        leg_half = (TABLE_TOP_Z - TABLE_THICKNESS - floor_z) / 2
        for i, (x, y) in enumerate([(TABLE_X[0] + 0.05, TABLE_Y[0] + 0.05),
                                    (TABLE_X[0] + 0.05, TABLE_Y[1] - 0.05),
                                    (TABLE_X[1] - 0.05, TABLE_Y[0] + 0.05),
                                    (TABLE_X[1] - 0.05, TABLE_Y[1] - 0.05)]):
            _static_geom(world, f'table_leg_{i}', mujoco.mjtGeom.mjGEOM_BOX,
                         (0.03, 0.03, leg_half), (x, y, floor_z + leg_half), _WOOD, collide=False)
    if stands:
        for name, xy in (('plate', plate_stand_xy), ('screw', screw_stand_xy)):
            half = (STAND_HALF_SIZE, STAND_HALF_SIZE, STAND_HEIGHT / 2)
            _static_geom(world, f'{name}_stand', mujoco.mjtGeom.mjGEOM_BOX, half,
                         (xy[0], xy[1], TABLE_TOP_Z + STAND_HEIGHT / 2), (0.3, 0.3, 0.35, 1))
        # The objects are shown, not simulated: the scenarios move them by script, not by grasp.
        _static_geom(world, 'plate', mujoco.mjtGeom.mjGEOM_CYLINDER,
                     (PLATE_RADIUS, PLATE_THICKNESS / 2), plate_position(plate_stand_xy),
                     (0.9, 0.9, 0.95, 1), collide=False)
        screw = screw_position(screw_stand_xy)
        _static_geom(world, 'screw', mujoco.mjtGeom.mjGEOM_CYLINDER, (0.006, 0.025),
                     screw - np.array([0, 0, 0.025]), (0.75, 0.75, 0.2, 1), collide=False)
    if pole:
        _static_geom(world, 'pole', mujoco.mjtGeom.mjGEOM_CYLINDER, (pole_radius, pole_height / 2),
                     (pole_xy[0], pole_xy[1], TABLE_TOP_Z + pole_height / 2), (0.2, 0.5, 0.9, 1))

    # The arm stands on the table, or without one on a column from the floor.
    ground = TABLE_TOP_Z if table else floor_z
    height = description.mount_xyz[2] - ground
    if height > 1e-3:
        x, y = description.mount_xyz[:2]
        _static_geom(world, 'robot_pedestal', mujoco.mjtGeom.mjGEOM_CYLINDER,
                     (PEDESTAL_RADIUS, height / 2), (x, y, ground + height / 2),
                     (0.3, 0.3, 0.35, 1), collide=False)

    wrist = world.add_body(name=HUMAN_WRIST, mocap=True, pos=list(HUMAN_WRIST_DEFAULT))
    wrist.add_site(name=HUMAN_WRIST, size=[0.03, 0, 0], rgba=[0.9, 0.2, 0.2, 0.8])
    return spec


def build_scene(pole: bool = False, stands: bool = True, **kwargs) -> mujoco.MjModel:
    """Compiled MuJoCo model of the scene; see build_spec for the options."""
    return build_spec(pole=pole, stands=stands, **kwargs).compile()
