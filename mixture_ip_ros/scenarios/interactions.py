"""Two people's recorded interactions (NuiSI) with an arm in one person's place: the robot takes
the partner's part.

Everything is set in config/interactions.yaml (:func:`load_config`):

- Frames. Each NuiSI person is in their own body frame (origin at the right collar, x toward the
  other person, y left, z up). Where person 1 stood in the partner's (person 2's) frame is not in
  the data; it is derived from it (:func:`derive_person1_to_partner`: in handshakes and fist
  bumps the right hands touch) and stated in the config.
- The arm in the partner's place (:func:`scene`, a robot.partner_place.PartnerPlace, the
  placement any two people's recordings use): the partner's right shoulder where the arm's
  shoulder is, facing person 1, and the whole interaction scaled about that shoulder by the
  reach scale of the training recordings' partner hands, so the two hands still meet. Person
  1's hand goes to the mocap frame ('world') through the same placement.
- The partner's hand becomes the arm's joints (:func:`arm_interaction`): the tracker's glitches
  found with hindsight (estimation.pose_check.plausible_track) are missing samples, never
  targets; the path is low-passed and followed sample by sample within the arm's joint and
  speed limits (robot.partner_place.PartnerPlace.joint_path).
- Person 1's hand is replayed as recorded, glitches included (the observer drops what it drops),
  with the first plausible frame held ``rest_before`` s before it and the last ``rest_after`` s
  after it: the recordings are cut at the interaction's start and stop, and the observer needs
  rest before an onset and after an end. :func:`write_bags` writes these streams with the arm's
  joints as rosbag2 bags: the nodes replay them, and training loads them (io.dataset) segmented
  as the observer segments them, with this scenario's observer settings
  (:func:`segmentation`), so training and the nodes share time zero.
"""

from __future__ import annotations

import inspect
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mixture_ip_ros.core.segmentation import MotionSegmenter
from mixture_ip_ros.core.share import config_path
from mixture_ip_ros.estimation.pose_check import plausible_track
from mixture_ip_ros.robot import partner_place
from mixture_ip_ros.robot.partner_place import AT_LEAST_0, PartnerPlace, PlacementConfig
from mixture_ip_ros.scenarios import nuisi
from mixture_ip_ros.scenarios.folders import write_scenario_bags
from mixture_ip_ros.scenarios.recording import GeneratedDemo

CONFIG_FILE = 'interactions.yaml'
SCENARIO = 'interactions'
# The interactions in which the two right hands touch (waving has no contact).
CONTACT = ('handshake', 'rocket_fistbump', 'parachute_fistbump')
_SEGMENTER_SETTINGS = tuple(p for p in inspect.signature(MotionSegmenter).parameters)


@dataclass(frozen=True)
class InteractionsConfig(PlacementConfig):
    """config/interactions.yaml, checked (see the file for what each value means): the
    placement (robot.partner_place) and this scenario's data, replays and node settings."""

    data: str
    rest_before: float
    rest_after: float
    observer: dict
    estimator: dict


def load_config(path=None) -> InteractionsConfig:
    """The scenario's settings from ``path`` (default config/interactions.yaml); ValueError with
    one line naming the file and the field for anything missing, unknown or out of range."""
    path = Path(path) if path is not None else config_path(CONFIG_FILE)
    settings = partner_place.Settings.read(path, 'interactions settings')
    fail, data = settings.fail, settings.data
    scalars = {'rest_before': AT_LEAST_0, 'rest_after': AT_LEAST_0}
    settings.keys(('data', *partner_place.KEYS, *scalars), ('observer', 'estimator'))
    placement = partner_place.placement_fields(settings)
    values = {k: settings.number(data[k], k, rule) for k, rule in scalars.items()}
    if data['data'] not in nuisi.VERSIONS:
        fail(f'data must be a NuiSI version {sorted(nuisi.VERSIONS)}, got {data["data"]!r}')
    observer = data.get('observer') or {}
    if not isinstance(observer, dict):
        fail(f'observer must be a mapping of segmentation settings, got {observer!r}')
    bad = sorted(set(observer) - set(_SEGMENTER_SETTINGS))
    if bad:
        fail(f'observer: unknown settings {bad}; allowed: {list(_SEGMENTER_SETTINGS)}')
    try:
        MotionSegmenter(**observer)
    except (TypeError, ValueError) as exc:
        fail(f'observer: {exc}')
    estimator = data.get('estimator') or {}
    if not isinstance(estimator, dict) or set(estimator) - {'lookahead', 'hedge'}:
        fail(f'estimator: only lookahead and hedge are set here, got {estimator!r}')
    if 'hedge' in estimator and not isinstance(estimator['hedge'], bool):
        fail(f"estimator.hedge must be true or false, got {estimator['hedge']!r}")
    if 'lookahead' in estimator:
        estimator = {**estimator,
                     'lookahead': settings.number(estimator['lookahead'], 'estimator.lookahead',
                                                  ('in (0, 10]', lambda v: 0 < v <= 10))}
    if values['rest_after'] < observer.get('end_hold', _default_end_hold()):
        fail(f'rest_after ({values["rest_after"]} s) must be at least observer.end_hold: the '
             'observer needs that much rest to see the end')
    return InteractionsConfig(source=str(path), data=data['data'], observer=dict(observer),
                              estimator=estimator, **placement, **values)


def _default_end_hold() -> float:
    return inspect.signature(MotionSegmenter).parameters['end_hold'].default


def segmentation(config: InteractionsConfig) -> dict:
    """The observer's movement segmentation settings of this scenario (observer_node
    parameters, and the keyword arguments io.dataset's loading passes to segment_motion)."""
    return dict(config.observer)


def estimator_settings(config: InteractionsConfig) -> dict:
    """The estimator_node parameters this scenario sets."""
    return dict(config.estimator)


# ------------------------------------------------------------------------------ frames

def _hands(recording, person: int, version: str) -> tuple:
    """(the right hand (n, 3) of person 1 or 2, the mask of samples a hand can have made)."""
    v = nuisi.VERSIONS[version]
    hand = (recording.person1 if person == 1 else recording.person2)[:, v.joints.index(v.hand)]
    return hand, plausible_track(recording.t, hand)


def derive_person1_to_partner(recordings, version: str = 'v2', yaw: float = math.pi,
                              iterations: int = 50):
    """Person 1's body frame in the partner's from where their right hands touch: the xyz of
    p_partner = Rz(yaw) p_1 + xyz that makes, on average over the recordings of interactions
    with contact (CONTACT), the hands' closest approach vanish. Starting from the frames where
    both hands reach farthest forward, each round takes per recording the frame of closest
    approach under the current xyz and sets xyz to the mean of the differences there, until the
    frames repeat. Samples a hand cannot have made (tracker glitches) are left out.
    Returns (xyz (3,), the closest approach per recording (m))."""
    R = partner_place.rz(yaw)
    pairs = []
    for r in recordings:
        if r.label not in CONTACT:
            continue
        (h1, ok1), (h2, ok2) = _hands(r, 1, version), _hands(r, 2, version)
        ok = ok1 & ok2
        pairs.append((h1[ok] @ R.T, h2[ok]))
    if not pairs:
        raise ValueError(f'no recording of an interaction with contact {CONTACT}')
    frames = [int(np.argmax(h2[:, 0] - h1[:, 0])) for h1, h2 in pairs]
    for _ in range(iterations):
        xyz = np.mean([h2[i] - h1[i] for (h1, h2), i in zip(pairs, frames)], axis=0)
        new = [int(np.argmin(np.linalg.norm(h2 - h1 - xyz, axis=1))) for h1, h2 in pairs]
        if new == frames:
            break
        frames = new
    gaps = np.array([np.linalg.norm(h2[i] - h1[i] - xyz) for (h1, h2), i in zip(pairs, frames)])
    return xyz, gaps


def derive_partner_shoulder(recordings, version: str = 'v2') -> np.ndarray:
    """The partner's right shoulder in their body frame: the median over every sample."""
    j = nuisi.VERSIONS[version].joints.index('right_shoulder')
    return np.median(np.concatenate([r.person2[:, j] for r in recordings]), axis=0)


# The arm in the partner's place of this scenario (its config an InteractionsConfig).
Scene = PartnerPlace


def scene(robot=None, config: InteractionsConfig = None, train=None) -> Scene:
    """The arm ``robot`` (a shipped name, a description file or a RobotKinematics) in the
    partner's place, scaled for the partner hands of ``train`` (default: the training split)."""
    config = config or load_config()
    train = nuisi.recordings(config.data, 'train') if train is None else train
    return partner_place.place(robot, config, [h[ok] for h, ok in
                                               (_hands(r, 2, config.data) for r in train)])


# ------------------------------------------------------------------------------ replays

def _held(values, first: int, last: int, before: int, after: int) -> np.ndarray:
    """``values`` (n, 3) with row ``first`` repeated ``before`` times ahead and row ``last``
    ``after`` times behind."""
    return np.vstack([np.repeat(values[first:first + 1], before, axis=0), values,
                      np.repeat(values[last:last + 1], after, axis=0)])


def replay_frames(recording, config: InteractionsConfig) -> tuple:
    """(samples held before, samples held after) at the recording's rate."""
    return (int(round(config.rest_before * recording.rate)),
            int(round(config.rest_after * recording.rate)))


def partner_hand(recording, scene: Scene) -> tuple:
    """Where the partner's hand was, in the base frame, on the replay's time base: (t (n,) s
    from the replay's start, xyz (n, 3), NaN where the tracker had lost the hand), its first
    and last position held through the rests."""
    hand, ok = _hands(recording, 2, scene.config.data)
    before, after = replay_frames(recording, scene.config)
    idx = np.flatnonzero(ok)
    xyz = _held(np.where(ok[:, None], hand, np.nan), idx[0], idx[-1], before, after)
    return np.arange(len(xyz)) / recording.rate, scene.partner_to_base(xyz)


def contact(recording, scene: Scene) -> tuple:
    """The recorded contact, the frame where the two people's hands were closest (the grip of
    a handshake, a fist bump; the closest approach of a wave): (its time (s) on the replay's
    time base, person 1's hand, the partner's hand, both in the base frame)."""
    h1, ok1 = _hands(recording, 1, scene.config.data)
    h2, ok2 = _hands(recording, 2, scene.config.data)
    both = np.flatnonzero(ok1 & ok2)
    p1, p2 = scene.person1_to_base(h1[both]), scene.partner_to_base(h2[both])
    i = int(np.argmin(np.linalg.norm(p1 - p2, axis=1)))
    before, _ = replay_frames(recording, scene.config)
    return (before + both[i]) / recording.rate, p1[i], p2[i]


def person1_stream(recording, scene: Scene) -> tuple:
    """Person 1's hand as replayed to the nodes: (t (n,) s, xyz (n, 3) in the mocap frame): the
    recording as it is, glitches included, with the first and last samples a hand can have made
    (estimation.pose_check.plausible_track) held through the rests before and after."""
    hand, ok = _hands(recording, 1, scene.config.data)
    before, after = replay_frames(recording, scene.config)
    idx = np.flatnonzero(ok)
    xyz = _held(hand, idx[0], idx[-1], before, after)
    return np.arange(len(xyz)) / recording.rate, scene.person1_to_world(xyz)


def arm_interaction(recording, scene: Scene) -> GeneratedDemo:
    """One recording with the arm in the partner's place, on the replay's time base: person 1's
    stream (mocap frame) and the arm's joints following the partner's hand (low-passed) within
    ``speed_fraction`` of the arm's speed limits (PartnerPlace.joint_path).
    ``onset``/``end`` are the recording's first and last frames; ``extra`` holds the partner's
    hand in the base frame ('partner', NaN where the tracker lost it) and the flange's distance
    from it ('lag', m: the arm's lag where the hand is faster, and what is out of reach)."""
    kin = scene.kin
    t, person1 = person1_stream(recording, scene)
    _, partner = partner_hand(recording, scene)
    q = scene.joint_path(partner, recording.rate).q
    before, _ = replay_frames(recording, scene.config)
    last = np.flatnonzero(~np.isnan(partner).any(axis=1))[-1]
    return GeneratedDemo(
        name=recording.name, label=recording.label, wrist_t=t, wrist_xyz=person1, joint_t=t,
        joint_q=q, joint_qd=np.gradient(q, t, axis=0), onset=float(t[before]),
        end=float(t[before + len(recording.t) - 1]), wrist_goal=person1[-1],
        flange_goal=partner[last], robot=kin.description,
        extra={'partner': partner, 'lag': np.linalg.norm(kin.fk_positions(q) - partner, axis=1)})


def write_bags(scene: Scene, split: str, out_dir, recordings=None,
               storage: str = 'mcap') -> list:
    """One bag per recording of ``split`` (person 1's stream on /mocap/wrist in 'world', the
    arm's joints on /joint_states) and labels.json into ``out_dir`` (which must not exist or be
    empty); returns the arm interactions written."""
    recordings = (nuisi.recordings(scene.config.data, split) if recordings is None
                  else recordings)
    made = [arm_interaction(r, scene) for r in recordings]
    write_scenario_bags(SCENARIO, out_dir, demos=made, storage=storage)
    return made
