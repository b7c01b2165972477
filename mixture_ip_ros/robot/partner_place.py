"""An arm in the partner's place: recordings of two people, one observed ('person 1'), the
other (the partner) taken over by an arm whose joints follow the partner's hand.

- Settings (:func:`load_placement`, config/partner_placement.yaml): where person 1 stood in
  the partner's frame, p_partner = Rz(yaw) p_1 + xyz (``person1_to_partner``; zero and 0
  where both hands were recorded in one frame); the partner's shoulder in that frame and the
  yaw that turns it onto the robot's base (``partner``); the reach margin; the low-pass, the
  posture pull and the limit margin of the inverse kinematics; the fraction of the arm's
  speed limits the demonstrated arm keeps to. Every error is one line naming the file and the
  field (:class:`Settings`, which the NuiSI interactions scenario reads its own file with).
- The arm in the partner's place (:class:`PartnerPlace`, :func:`place`): the partner's
  shoulder where the arm's shoulder is, and the whole interaction scaled about it by the reach
  scale of the partner's hand positions (robot.retarget.reach_scale; 1 unless some are out of
  the arm's reach), so the two people's hands still meet. Person 1's hand goes into the base
  frame through the same placement, and on to the mocap frame ('world') through the robot's
  mount: that is where person 1 must stand for the nodes (:meth:`PartnerPlace.person1_pose`).
- The partner's hand becomes the arm's joints (:meth:`PartnerPlace.joint_path`): low-passed
  and followed sample by sample within the arm's joint and speed limits
  (robot.retarget.joint_path). On recordings (:func:`arm_demonstrations`) the samples a hand
  cannot have made (the tracker's glitches, estimation.pose_check.plausible_track) are missing,
  never targets, and person 1's hand keeps what the observer accepts online
  (estimation.pose_check.accepted_online), as training from bags does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from mixture_ip_ros.core.demonstration import Demonstration
from mixture_ip_ros.estimation.pose_check import accepted_online, plausible_track
from mixture_ip_ros.robot import retarget
from mixture_ip_ros.robot.kinematics import RobotKinematics

# (what the rule says, the rule) for a number of the settings
ANY = ('', lambda v: True)
POSITIVE = ('> 0', lambda v: v > 0)
FRACTION = ('in (0, 1]', lambda v: 0 < v <= 1)
AT_LEAST_0 = ('>= 0', lambda v: v >= 0)
SECTIONS = {'person1_to_partner': ('xyz', 'yaw'), 'partner': ('shoulder', 'yaw')}
SCALARS = {'reach_margin': FRACTION, 'lowpass_hz': POSITIVE, 'posture_weight': AT_LEAST_0,
           'limit_margin': AT_LEAST_0, 'speed_fraction': FRACTION}
KEYS = (*SECTIONS, *SCALARS)
# A recording's sample times may stray this far (in periods) from one uniform rate: the
# low-pass and the joints' speed bound between samples need one rate.
_TIME_JITTER = 0.25


class Settings:
    """A mapping of settings (``data``) from ``where`` (a file), checked field by field; every
    error a ValueError of one line naming ``where`` and the field."""

    def __init__(self, data, where):
        self.data, self.where = data, str(where)

    @classmethod
    def read(cls, path, what: str) -> 'Settings':
        """The YAML mapping in ``path`` (``what`` it holds names it in errors)."""
        try:
            data = yaml.safe_load(Path(path).read_text())
        except (OSError, yaml.YAMLError) as exc:
            raise ValueError(f'{path}: cannot read the {what}: '
                             f'{" ".join(str(exc).split())}') from exc
        settings = cls(data, path)
        if not isinstance(data, dict):
            settings.fail(f'the {what} are a YAML mapping (key: value lines)')
        return settings

    def fail(self, message):
        raise ValueError(f'{self.where}: {message}')

    def keys(self, required, optional=()):
        """Refuse keys neither ``required`` nor ``optional``, and missing required ones."""
        known = {*required, *optional}
        unknown = sorted(set(self.data) - known)
        if unknown:
            self.fail(f'unknown keys {unknown}; allowed: {sorted(known)}')
        missing = sorted(set(required) - set(self.data))
        if missing:
            self.fail(f'missing keys {missing}')

    def number(self, value, field, rule=ANY) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
                math.isfinite(value) and rule[1](value)):
            self.fail(f'{field} must be a finite number{" " + rule[0] if rule[0] else ""}, '
                      f'got {value!r}')
        return float(value)

    def point(self, value, field) -> tuple:
        if not isinstance(value, list) or len(value) != 3:
            self.fail(f'{field} must be 3 numbers [x, y, z], got {value!r}')
        return tuple(self.number(v, field) for v in value)


@dataclass(frozen=True)
class PlacementConfig:
    """The placement settings, checked (config/partner_placement.yaml says what each means)."""

    source: str
    person1_xyz: tuple
    person1_yaw: float
    partner_shoulder: tuple
    partner_yaw: float
    reach_margin: float
    lowpass_hz: float
    posture_weight: float
    limit_margin: float
    speed_fraction: float


def placement_fields(settings: Settings) -> dict:
    """The :class:`PlacementConfig` fields (but ``source``) of ``settings``, checked."""
    parsed = {}
    for key, fields in SECTIONS.items():
        section = settings.data[key]
        if not isinstance(section, dict) or set(section) != set(fields):
            settings.fail(f'{key} must be a mapping with exactly {list(fields)}, got '
                          f'{section!r}')
        parsed[key] = (settings.point(section[fields[0]], f'{key}.{fields[0]}'),
                       settings.number(section['yaw'], f'{key}.yaw'))
    return {'person1_xyz': parsed['person1_to_partner'][0],
            'person1_yaw': parsed['person1_to_partner'][1],
            'partner_shoulder': parsed['partner'][0], 'partner_yaw': parsed['partner'][1],
            **{k: settings.number(settings.data[k], k, rule) for k, rule in SCALARS.items()}}


def load_placement(path) -> PlacementConfig:
    """The placement settings in the YAML file ``path``; ValueError of one line naming the file
    and the field for anything missing, unknown or out of range."""
    settings = Settings.read(path, 'placement settings')
    settings.keys(KEYS)
    return PlacementConfig(source=str(path), **placement_fields(settings))


def placement_mapping(config: PlacementConfig) -> dict:
    """The settings of ``config`` as the YAML file spells them."""
    return {'person1_to_partner': {'xyz': list(config.person1_xyz), 'yaw': config.person1_yaw},
            'partner': {'shoulder': list(config.partner_shoulder), 'yaw': config.partner_yaw},
            **{k: getattr(config, k) for k in SCALARS}}


def lowpass(xyz: np.ndarray, rate: float, cutoff: float) -> np.ndarray:
    """A path (n, 3) low-passed at ``cutoff`` Hz (second-order Butterworth, forward and back:
    no lag); NaN rows (missing samples) are bridged linearly between the valid samples first,
    so a missing position is never a target."""
    from scipy.signal import butter, filtfilt
    ok = ~np.isnan(xyz).any(axis=1)
    idx = np.arange(len(xyz))
    filled = np.column_stack([np.interp(idx, idx[ok], xyz[ok, j]) for j in range(3)])
    if cutoff >= rate / 2 or len(xyz) < 10:
        return filled
    b, a = butter(2, cutoff / (rate / 2))
    return filtfilt(b, a, filled, axis=0)


def rz(angle: float) -> np.ndarray:
    """The rotation (3, 3) by ``angle`` rad about z."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class PartnerPlace:
    """One arm in the partner's place: ``placement`` maps the partner's frame into the robot's
    base frame (scale included); person 1 goes there through their place in the partner's
    frame, and on to the mocap frame through the robot's mount."""

    config: PlacementConfig
    kin: RobotKinematics
    placement: retarget.Placement

    @property
    def robot(self):
        return self.kin.description

    def partner_to_base(self, points) -> np.ndarray:
        return self.placement.apply(points)

    def person1_to_base(self, points) -> np.ndarray:
        p = np.asarray(points, dtype=float) @ rz(self.config.person1_yaw).T
        return self.placement.apply(p + np.asarray(self.config.person1_xyz))

    def person1_to_world(self, points) -> np.ndarray:
        return self.robot.base_to_world().apply_array(self.person1_to_base(points))

    def person1_pose(self) -> tuple:
        """Where person 1's frame lies in the mocap frame (where they stand, in a frame of
        their body): its origin (3,) and the yaw of its x axis (rad)."""
        origin = self.person1_to_world(np.zeros((1, 3)))[0]
        forward = self.person1_to_world(np.array([[1.0, 0.0, 0.0]]))[0] - origin
        return origin, math.atan2(forward[1], forward[0])

    def joint_path(self, partner, rate: float) -> retarget.JointPath:
        """The arm following the partner's hand ``partner`` (n, 3) in the base frame, sampled at
        ``rate`` Hz (NaN rows missing), from its home posture: low-passed at ``lowpass_hz``,
        then robot.retarget.joint_path within ``speed_fraction`` of the speed limits."""
        c, kin = self.config, self.kin
        return retarget.joint_path(kin, lowpass(partner, rate, c.lowpass_hz), 1.0 / rate,
                                   kin.description.home_array(),
                                   speed_limit=c.speed_fraction * kin.velocity_limit,
                                   posture_weight=c.posture_weight,
                                   limit_margin=c.limit_margin)

    def metadata(self) -> dict:
        """What a model file records of the placement: the settings, the arm, the arm's
        shoulder, the reach scale, and where person 1's frame lies in the mocap frame
        (:meth:`person1_pose`)."""
        origin, yaw = self.person1_pose()
        return {**placement_mapping(self.config), 'source': self.config.source,
                'robot': self.robot.name,
                'arm_shoulder': [float(v) for v in self.placement.arm_shoulder],
                'reach_scale': self.placement.scale,
                'person1_in_world': {'xyz': origin.tolist(), 'yaw': yaw}}

    @classmethod
    def from_metadata(cls, meta: dict, robot=None, where='model metadata') -> 'PartnerPlace':
        """The placement :meth:`metadata` recorded, on ``robot`` (default: the one recorded);
        other keys (what the recording's reader noted beside it) are left alone."""
        settings = Settings(meta, where)
        if not isinstance(meta, dict):
            settings.fail(f'the placement is a mapping, got {meta!r}')
        settings.keys((*KEYS, 'reach_scale'), set(meta))
        config = PlacementConfig(source=str(meta.get('source', where)),
                                 **placement_fields(settings))
        kin = _kinematics(meta.get('robot') if robot is None else robot)
        scale = settings.number(meta['reach_scale'], 'reach_scale', POSITIVE)
        return cls(config, kin, retarget.Placement(config.partner_shoulder,
                                                   tuple(retarget.shoulder(kin)),
                                                   config.partner_yaw, scale))


def _kinematics(robot) -> RobotKinematics:
    return robot if isinstance(robot, RobotKinematics) else RobotKinematics(robot)


def place(robot, config: PlacementConfig, partner_hands) -> PartnerPlace:
    """The arm ``robot`` (a shipped name, a description file or a RobotKinematics) in the
    partner's place, scaled for ``partner_hands`` (arrays (n, 3) in the partner's frame, the
    positions the arm must reach; NaN rows are left out)."""
    kin = _kinematics(robot)
    unscaled = retarget.Placement(config.partner_shoulder, tuple(retarget.shoulder(kin)),
                                  config.partner_yaw)
    hands = np.concatenate([np.asarray(h, dtype=float).reshape(-1, 3) for h in partner_hands])
    hands = hands[~np.isnan(hands).any(axis=1)]
    scale = retarget.reach_scale(kin, unscaled.offsets(hands), config.reach_margin)
    return PartnerPlace(config, kin, retarget.Placement(unscaled.body_shoulder,
                                                        unscaled.arm_shoulder, unscaled.yaw,
                                                        scale))


# ------------------------------------------------------------------------------ recordings

def _partner_hand(demo: Demonstration) -> np.ndarray:
    """The partner's hand (n, 3) of a recording, NaN where it is missing or no hand can have
    made it (plausible_track)."""
    hand = np.asarray(demo.controlled, dtype=float)
    return np.where(plausible_track(demo.t, hand)[:, None], hand, np.nan)


def _sample_grid(demo: Demonstration) -> tuple:
    """(period (s), each sample's index on the uniform grid of that period): ValueError if the
    times stray from one rate by more than a quarter period (dropped samples are gaps of the
    grid)."""
    t = demo.t
    dt = float(np.median(np.diff(t)))
    index = np.rint(t / dt).astype(int)
    stray = np.abs(t - index * dt)
    if stray.max() > _TIME_JITTER * dt or np.any(np.diff(index) <= 0):
        k = int(np.argmax(stray))
        raise ValueError(f'recording {demo.name!r}: sample {k} at {t[k]:g} s is off the rate of '
                         f'its other samples ({1 / dt:.4g} Hz): the arm in the partner\'s place '
                         'needs one sample rate (resample the recording)')
    return dt, index


def _check_positions(demo: Demonstration):
    if demo.n_observed_dofs != 3 or demo.n_controlled_dofs != 3:
        raise ValueError(f'recording {demo.name!r}: the arm in the partner\'s place needs 3 '
                         f'observed and 3 controlled positions (x, y, z), got '
                         f'{demo.n_observed_dofs} and {demo.n_controlled_dofs}')


def arm_demonstration(arm: PartnerPlace, demo: Demonstration) -> tuple:
    """One recording (observed: person 1's hand, controlled: the partner's, x y z in metres)
    with ``arm`` in the partner's place: (the Demonstration of person 1's hand in the base
    frame, NaN where missing or where the observer would drop it, and the arm's joints; the
    flange's distance from the partner's placed hand at each sample, m, NaN where the hand is
    missing: the arm's lag where the hand is faster, and what is out of its reach)."""
    _check_positions(demo)
    dt, index = _sample_grid(demo)
    hand = _partner_hand(demo)
    if np.isnan(hand).all():
        raise ValueError(f'recording {demo.name!r}: no sample of the partner\'s hand')
    grid = np.full((index[-1] + 1, 3), np.nan)
    grid[index] = arm.partner_to_base(hand)
    q = arm.joint_path(grid, 1.0 / dt).q[index]
    observed = arm.person1_to_base(demo.observed)
    valid = ~np.isnan(observed).any(axis=1)
    valid[valid] = accepted_online(demo.t[valid], observed[valid])
    observed[~valid] = np.nan
    lag = np.linalg.norm(arm.kin.fk_positions(q) - grid[index], axis=1)
    return Demonstration(demo.t, observed, q, label=demo.label, name=demo.name), lag


def arm_demonstrations(robot, config: PlacementConfig, demos) -> tuple:
    """Recordings of two people (see :func:`arm_demonstration`) with the arm ``robot`` in the
    partner's place, scaled for every recording's partner hand: (the PartnerPlace, the arm's
    demonstrations, the flange's distance from the partner's hand per recording)."""
    demos = list(demos)
    if not demos:
        raise ValueError('no recordings to put the arm into')
    for d in demos:
        _check_positions(d)
    arm = place(robot, config, [_partner_hand(d) for d in demos])
    made = [arm_demonstration(arm, d) for d in demos]
    return arm, [m[0] for m in made], [m[1] for m in made]
