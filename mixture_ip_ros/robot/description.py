"""The robot as configuration: one description file per arm, read by everything robot-specific.

A description is a small YAML file (the shipped ones are config/robots/<name>.yaml; the format
and how to add an arm are in docs/robots.md). It names the model file (URDF or MJCF), the
controlled joints in order, the base and end-effector (flange) frames, where the base stands in
the scene, the home posture, the controller gains, the postures the scenario generators start
from, and how the arm looks. Limits (position, velocity, effort) are never written here: they
are read from the model file (robot.kinematics checks the description against it).

This module only parses and checks the file (numpy and PyYAML, no Pinocchio or MuJoCo), so io
and nodes read joint and frame names cheaply. ``robot`` arguments everywhere accept a shipped
name, a path to a description file, or a loaded RobotDescription.
"""

from __future__ import annotations

import functools
import math
import os
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from mixture_ip_ros.core.frames import FrameTransform
from mixture_ip_ros.core.share import config_path, share_dir

DEFAULT_ROBOT = 'iiwa14'
ROBOTS_DIR = 'robots'          # under config/
PACKAGE_NAME = 'mixture_ip_ros'

_REQUIRED = ('model', 'joints', 'base_frame', 'flange_frame', 'home')
_OPTIONAL = ('name', 'mount', 'controller', 'tool_rpy', 'scenarios', 'render')
_SCENARIO_KEYS = ('box_seed', 'pole_home', 'clearance_frames', 'link_radius')


class DescriptionError(ValueError):
    """A robot description that cannot be used; the message names the file and the field."""


def rpy_matrix(rpy) -> np.ndarray:
    """Rotation of URDF roll-pitch-yaw angles (rad): R = Rz(yaw) Ry(pitch) Rx(roll)."""
    r, p, y = (float(a) for a in rpy)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), \
        math.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def rpy_quaternion(rpy) -> tuple:
    """The same rotation as a unit quaternion (x, y, z, w)."""
    r, p, y = (0.5 * float(a) for a in rpy)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), \
        math.sin(y)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy)


def package_share(package: str) -> Path | None:
    """The share folder of a ROS-style package: this package's own, then the prefixes a pip or
    ROS install uses (cmeel.prefix/share inside site-packages, sys.prefix/share,
    AMENT_PREFIX_PATH and CMAKE_PREFIX_PATH entries, ROS_PACKAGE_PATH folders)."""
    if package == PACKAGE_NAME:
        return share_dir()
    candidates = [Path(p) / 'cmeel.prefix' / 'share' / package for p in sys.path if p]
    candidates.append(Path(sys.prefix) / 'share' / package)
    for var in ('AMENT_PREFIX_PATH', 'CMAKE_PREFIX_PATH'):
        candidates += [Path(p) / 'share' / package
                       for p in os.environ.get(var, '').split(os.pathsep) if p]
    candidates += [Path(p) / package
                   for p in os.environ.get('ROS_PACKAGE_PATH', '').split(os.pathsep) if p]
    return next((c for c in candidates if c.is_dir()), None)


def resolve_uri(uri: str, relative_to: Path | None = None) -> Path:
    """A file named the ROS way: ``package://<package>/<path>``, an absolute path, or a path
    relative to ``relative_to`` (the description file's folder). Raises FileNotFoundError."""
    uri = str(uri)
    if uri.startswith('package://'):
        package, _, rest = uri[len('package://'):].partition('/')
        share = package_share(package)
        if share is None:
            raise FileNotFoundError(f'{uri}: package {package!r} not found (looked in '
                                    'site-packages/cmeel.prefix/share, sys.prefix/share, '
                                    'AMENT_PREFIX_PATH, CMAKE_PREFIX_PATH, ROS_PACKAGE_PATH)')
        path = share / rest
    elif uri.startswith('file://'):
        path = Path(uri[len('file://'):])
    else:
        path = Path(uri)
        if not path.is_absolute() and relative_to is not None:
            path = relative_to / path
    if not path.is_file():
        raise FileNotFoundError(f'{uri}: no such file ({path})')
    return path


@dataclass(frozen=True)
class RobotDescription:
    """One arm, as its description file gives it (see docs/robots.md for every field).

    Positions are metres and radians. The mount is the pose of ``base_frame`` in the scene's
    world frame (the table-top frame the human's data are recorded in).
    """

    name: str
    source: str         # what load_description takes back: a shipped name or an absolute path
    model_path: Path
    joint_names: tuple
    base_frame: str
    flange_frame: str
    home: tuple
    mount_xyz: tuple = (0.0, 0.0, 0.0)
    mount_rpy: tuple = (0.0, 0.0, 0.0)
    natural_frequency: tuple = (60.0,)   # rad/s, one value or one per joint
    damping_ratio: tuple = (1.0,)
    tool_rpy: tuple = (0.0, 0.0, 0.0)
    box_seed: tuple | None = None
    pole_home: tuple | None = None
    clearance_frames: tuple = ()
    link_radius: float = 0.065
    accent_links: tuple = ()

    @property
    def dof(self) -> int:
        return len(self.joint_names)

    @property
    def mount_rotation(self) -> np.ndarray:
        """R_world_base (3, 3)."""
        return rpy_matrix(self.mount_rpy)

    def base_to_world(self) -> FrameTransform:
        """p_world = R p_base + t."""
        return FrameTransform(self.mount_xyz, rpy_quaternion(self.mount_rpy))

    def world_to_base(self) -> FrameTransform:
        """p_base = R^T (p_world - t): the mocap world in the robot base frame, as the observer's
        mocap_to_base_* parameters and the dataset loader's ``transform`` take it."""
        x, y, z, w = rpy_quaternion(self.mount_rpy)
        R = self.mount_rotation
        return FrameTransform(-R.T @ np.asarray(self.mount_xyz, dtype=float), (-x, -y, -z, w))

    def tool_rotation(self) -> np.ndarray:
        """The flange frame in the scenarios' tool frame (z along the approach direction)."""
        return rpy_matrix(self.tool_rpy)

    def gains(self):
        """Per-joint natural frequency and damping ratio, arrays (dof,)."""
        return (np.broadcast_to(np.asarray(self.natural_frequency, float), (self.dof,)).copy(),
                np.broadcast_to(np.asarray(self.damping_ratio, float), (self.dof,)).copy())

    def home_array(self) -> np.ndarray:
        return np.array(self.home, dtype=float)


# ------------------------------------------------------------------------------------ loading
def shipped_robots() -> list:
    """Names of the description files shipped in config/robots/."""
    folder = config_path(ROBOTS_DIR)
    return sorted(p.stem for p in folder.glob('*.yaml')) if folder.is_dir() else []


def description_file(robot) -> Path:
    """The file of a shipped name, or ``robot`` itself when it is a path to a .yaml file."""
    text = str(robot)
    if text.endswith(('.yaml', '.yml')) or os.sep in text:
        path = Path(text)
        if not path.is_file():
            raise DescriptionError(f'robot description file {path} does not exist')
        return path
    path = config_path(ROBOTS_DIR) / f'{text}.yaml'
    if not path.is_file():
        raise DescriptionError(f'unknown robot {text!r}; shipped: {shipped_robots()} '
                               '(or give the path of a description .yaml file)')
    return path


def load_description(robot=None) -> RobotDescription:
    """The description of ``robot``: None (the default, the iiwa 14), a shipped name, a path to a
    description file, or a RobotDescription (returned as is)."""
    if isinstance(robot, RobotDescription):
        return robot
    robot = DEFAULT_ROBOT if robot is None else robot
    path = description_file(robot).resolve()
    shipped = path.parent == config_path(ROBOTS_DIR).resolve()
    return _load(str(path), path.stat().st_mtime_ns, path.stem if shipped else str(path))


@functools.lru_cache(maxsize=32)
def _load(path: str, _mtime_ns: int, source: str) -> RobotDescription:
    try:
        data = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise DescriptionError(f'{path}: cannot read the robot description: {exc}') from exc
    return parse_description(data, Path(path), source)


def parse_description(data, path: Path, source: str | None = None) -> RobotDescription:
    """Check a parsed description (a dict) and build the RobotDescription; ``path`` is where it
    came from (model paths are relative to its folder)."""
    where = str(path)

    def fail(message):
        raise DescriptionError(f'{where}: {message}')

    if not isinstance(data, dict):
        fail('a robot description is a YAML mapping (key: value lines)')
    unknown = sorted(set(data) - set(_REQUIRED) - set(_OPTIONAL))
    if unknown:
        fail(f'unknown keys {unknown}; allowed: {sorted(_REQUIRED + _OPTIONAL)}')
    missing = [k for k in _REQUIRED if k not in data]
    if missing:
        fail(f'missing keys {missing}')

    def text(value, field):
        if not isinstance(value, str) or not value.strip():
            fail(f'{field} must be a non-empty string, got {value!r}')
        return value.strip()

    def numbers(value, field, n=None, positive=False):
        try:
            arr = np.atleast_1d(np.asarray(value, dtype=float))
        except (TypeError, ValueError):
            fail(f'{field} must be numbers, got {value!r}')
        if arr.ndim != 1 or (n is not None and arr.size != n) or arr.size == 0:
            fail(f'{field} must be {n if n is not None else "one or more"} numbers, '
                 f'got {value!r}')
        if not np.all(np.isfinite(arr)) or (positive and np.any(arr <= 0)):
            fail(f'{field} must be finite{" and positive" if positive else ""}, got {value!r}')
        return tuple(float(v) for v in arr)

    def section(key, allowed):
        value = data.get(key) or {}
        if not isinstance(value, dict):
            fail(f'{key} must be a mapping')
        extra = sorted(set(value) - set(allowed))
        if extra:
            fail(f'{key}: unknown keys {extra}; allowed: {list(allowed)}')
        return value

    name = text(data.get('name', path.stem), 'name')
    try:
        model_path = resolve_uri(text(data['model'], 'model'), path.parent)
    except FileNotFoundError as exc:
        fail(f'model: {exc}')
    if model_path.suffix.lower() not in ('.urdf', '.xml', '.mjcf'):
        fail(f'model must be a URDF (.urdf) or MJCF (.xml) file, got {model_path.name}')
    joints = data['joints']
    if (not isinstance(joints, list) or not joints
            or not all(isinstance(j, str) and j for j in joints)):
        fail(f'joints must be a list of joint names, got {joints!r}')
    if len(set(joints)) != len(joints):
        fail(f'joints has duplicates: {joints}')
    n = len(joints)
    mount = section('mount', ('xyz', 'rpy'))
    controller = section('controller', ('natural_frequency', 'damping_ratio'))
    scenarios = section('scenarios', _SCENARIO_KEYS)
    render = section('render', ('accent_links',))

    def per_joint(value, field):
        v = numbers(value, field, positive=True)
        if len(v) not in (1, n):
            fail(f'{field} must be one number or {n} (one per joint), got {len(v)}')
        return v

    def posture(key):
        return None if scenarios.get(key) is None else numbers(
            scenarios[key], f'scenarios.{key}', n)

    clearance = scenarios.get('clearance_frames', [])
    if not isinstance(clearance, list) or not all(isinstance(f, str) for f in clearance):
        fail(f'scenarios.clearance_frames must be a list of frame names, got {clearance!r}')
    accents = render.get('accent_links', [])
    if not isinstance(accents, list) or not all(isinstance(f, str) for f in accents):
        fail(f'render.accent_links must be a list of link names, got {accents!r}')
    link_radius = numbers(scenarios.get('link_radius', 0.065), 'scenarios.link_radius', 1,
                          positive=True)[0]
    return RobotDescription(
        name=name, source=source if source is not None else where, model_path=model_path,
        joint_names=tuple(joints), base_frame=text(data['base_frame'], 'base_frame'),
        flange_frame=text(data['flange_frame'], 'flange_frame'),
        home=numbers(data['home'], 'home', n),
        mount_xyz=numbers(mount.get('xyz', [0, 0, 0]), 'mount.xyz', 3),
        mount_rpy=numbers(mount.get('rpy', [0, 0, 0]), 'mount.rpy', 3),
        natural_frequency=per_joint(controller.get('natural_frequency', 60.0),
                                    'controller.natural_frequency'),
        damping_ratio=per_joint(controller.get('damping_ratio', 1.0),
                                'controller.damping_ratio'),
        tool_rpy=numbers(data.get('tool_rpy', [0, 0, 0]), 'tool_rpy', 3),
        box_seed=posture('box_seed'), pole_home=posture('pole_home'),
        clearance_frames=tuple(clearance), link_radius=link_radius,
        accent_links=tuple(accents))


# The default robot's names, for code that only ever talks to it (and for defaults).
DEFAULT = load_description()
JOINT_NAMES = DEFAULT.joint_names
BASE_FRAME = DEFAULT.base_frame
FLANGE_FRAME = DEFAULT.flange_frame
