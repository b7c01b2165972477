"""A dataset is a folder of demonstration bags; each bag becomes one Demonstration.

Loading a bag: read both streams (``bags.read_bag``), move the wrist into the robot base frame,
drop the samples the observer drops as no person's wrist (``estimation.pose_check``: a tracker
that jumps away and back), find the human's movement onset and end
(``core.segmentation.segment_motion``) and resample both streams onto one uniform time base
``t = 0, dt, 2 dt, ...`` from onset to end. Training then sees what the observer passes on.
With ``cut='recorded'`` the onset and end are instead the ones the bag records (its annotator's
cut, io.bags): where a data set was cut by hand, the detector's ends, which only set a training
demonstration's duration, wander by up to a second where a person slows down before the
annotated end, and time-normalised paths of one interaction then disagree.

- Wrist: linear interpolation between the two recorded samples around a resampled time, but only if
  they are at most ``2 * gap_tolerance`` periods apart (period = max(dt, wrist sample period)), so the
  nearest sample is within ``gap_tolerance`` periods; otherwise the row is NaN (missing). With the
  default 1.25 a single dropped mocap packet is bridged, two in a row are not: an occlusion stays
  missing data, never filled in.
- Joints: the robot's encoders are dense, so they are interpolated linearly; a joint stream that does
  not cover the movement, or has a hole longer than ``max_joint_gap`` inside it, is an error.

Frames: ``transform`` is the pose of the mocap world frame in the robot base frame,
``p_base = R(quaternion) @ p_world + translation``, quaternion (x, y, z, w). ``None`` = identity.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import NamedTuple, Optional, Sequence

import numpy as np

from mixture_ip_ros.core.demonstration import Demonstration, Layout
from mixture_ip_ros.core.frames import FrameTransform
from mixture_ip_ros.core.segmentation import segment_motion
from mixture_ip_ros.estimation.pose_check import accepted_online
from mixture_ip_ros.robot.description import JOINT_NAMES
from mixture_ip_ros.io.bags import (END_KEY, JOINT_TOPIC, ONSET_KEY, WRIST_TOPIC, BagError,
                                    RawRecording, read_bag)

logger = logging.getLogger(__name__)

WRIST_NAMES = ('wrist_x', 'wrist_y', 'wrist_z')
# m: the online observation noise of a motion-captured wrist (MixtureIProMP's
# observation_noise), the marker noise plus the hand's departure from a smooth ProMP path.
WRIST_OBSERVATION_NOISE = 0.01


def bag_layout(joint_names: Sequence[str] = JOINT_NAMES) -> Layout:
    """The layout of a demonstration loaded from a bag: the wrist position in the robot base
    frame (metres) observed, the robot's joints (radians) controlled."""
    return Layout(WRIST_NAMES, tuple(joint_names), ('m',), ('rad',))


def resample_wrist(t_src: np.ndarray, xyz_src: np.ndarray, t_query: np.ndarray,
                   tolerance: float) -> np.ndarray:
    """Positions at ``t_query``, linearly interpolated; NaN where the query is not inside an interval
    of at most ``2 * tolerance`` between two recorded samples (or, before the first / after the
    last sample, farther than ``tolerance`` from it).

    Source rows with NaN (a driver that publishes NaN while occluded) count as absent.
    """
    t_src = np.asarray(t_src, dtype=float)
    xyz_src = np.asarray(xyz_src, dtype=float)
    t_query = np.asarray(t_query, dtype=float)
    ok = ~np.isnan(xyz_src).any(axis=1)
    t_src, xyz_src = t_src[ok], xyz_src[ok]
    out = np.full((t_query.size, xyz_src.shape[1]), np.nan)
    if t_src.size == 0:
        return out
    # nxt: first sample at or after the query; prv: last sample at or before it.
    nxt = np.searchsorted(t_src, t_query, side='left')
    prv = np.searchsorted(t_src, t_query, side='right') - 1
    has_prev = prv >= 0
    has_next = nxt < t_src.size
    prv_c = np.clip(prv, 0, t_src.size - 1)
    nxt_c = np.clip(nxt, 0, t_src.size - 1)
    d_prev = t_query - t_src[prv_c]
    d_next = t_src[nxt_c] - t_query
    span = t_src[nxt_c] - t_src[prv_c]
    inside = has_prev & has_next & (span <= 2 * tolerance)
    w = np.where(span > 0, d_prev / np.where(span > 0, span, 1.0), 0.0)
    interp = (1 - w)[:, None] * xyz_src[prv_c] + w[:, None] * xyz_src[nxt_c]
    out[inside] = interp[inside]
    # Before the first / after the last sample: hold it if it is close enough.
    edge_prev = has_prev & ~has_next & (d_prev <= tolerance)
    edge_next = has_next & ~has_prev & (d_next <= tolerance)
    out[edge_prev] = xyz_src[prv_c[edge_prev]]
    out[edge_next] = xyz_src[nxt_c[edge_next]]
    return out


class NoRecordedInterval(BagError):
    """A bag cut where it records its movement interval (``cut='recorded'``) records none."""


def _recorded_cut(rec: RawRecording, source: str) -> tuple:
    """The (onset, end) the bag records, seconds on the recording's time base."""
    custom = rec.custom_data or {}
    if ONSET_KEY not in custom or END_KEY not in custom:
        raise NoRecordedInterval(source, f'no recorded movement interval ({ONSET_KEY}, '
                                         f"{END_KEY} in its metadata custom_data); load it "
                                         "with cut='detected'")
    try:
        onset_ns, end_ns = int(custom[ONSET_KEY]), int(custom[END_KEY])
    except (TypeError, ValueError):
        raise BagError(source, f'the recorded movement interval is not two integer stamps: '
                               f'{custom[ONSET_KEY]!r}, {custom[END_KEY]!r}') from None
    return (onset_ns - rec.start_time_ns) * 1e-9, (end_ns - rec.start_time_ns) * 1e-9


def segment_recording(rec: RawRecording, *, transform=None, segmentation: Optional[dict] = None,
                      source: str = 'recording', cut: str = 'detected'):
    """The wrist stream in the robot base frame (N, 3), NaN where no sample is or the observer
    would drop it, and the movement's onset and end times (s, the recording's time base), found
    as the observer finds them (``cut='detected'``) or as the bag records them
    (``'recorded'``). Raises BagError."""
    tf = FrameTransform.from_any(transform)
    xyz = tf.apply_array(rec.wrist_xyz)
    valid = ~np.isnan(xyz).any(axis=1)
    valid[valid] = accepted_online(rec.wrist_t[valid], xyz[valid])
    xyz[~valid] = np.nan
    if valid.sum() < 2:
        raise BagError(source, 'fewer than 2 valid wrist samples')
    if cut == 'recorded':
        t_onset, t_end = _recorded_cut(rec, source)
    elif cut == 'detected':
        try:
            t_onset, t_end = segment_motion(rec.wrist_t, xyz, **(segmentation or {}))
        except ValueError as exc:
            raise BagError(source, f'no movement onset/end found in the wrist stream: '
                                   f'{exc}') from exc
    else:
        raise ValueError(f"cut must be 'detected' or 'recorded', got {cut!r}")
    t_onset, t_end = float(t_onset), float(t_end)
    if not (np.isfinite(t_onset) and np.isfinite(t_end) and t_end > t_onset):
        raise BagError(source, f'segmentation gave onset {t_onset} s and end {t_end} s')
    return xyz, t_onset, t_end


def recording_to_demonstration(rec: RawRecording, *, transform=None, dt: float = 0.01,
                               gap_tolerance: float = 1.25, max_joint_gap: float = 0.1,
                               segmentation: Optional[dict] = None, wrist_frame: Optional[str] = None,
                               name: Optional[str] = None, source: str = 'recording',
                               cut: str = 'detected') -> Demonstration:
    """Resample a :class:`RawRecording` onto the onset..end time base (see module docstring).

    ``source`` names the recording in errors (the bag path when called from load_demonstration).
    """
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f'dt must be a positive number of seconds, got {dt!r}')
    if not (np.isfinite(gap_tolerance) and gap_tolerance >= 0.5):
        raise ValueError(f'gap_tolerance must be >= 0.5 (in sample periods), got {gap_tolerance!r}')
    if wrist_frame is not None and rec.wrist_frame != wrist_frame:
        raise BagError(source, f'wrist poses are in frame {rec.wrist_frame!r}, expected {wrist_frame!r}')
    xyz, t_onset, t_end = segment_recording(rec, transform=transform,
                                            segmentation=segmentation, source=source, cut=cut)
    valid = ~np.isnan(xyz).any(axis=1)
    n = int(np.floor((t_end - t_onset) / dt + 1e-9)) + 1
    if n < 2:
        raise BagError(source, f'movement of {t_end - t_onset:.3f} s is shorter than dt = {dt} s')
    rel = dt * np.arange(n)
    grid = t_onset + rel

    wrist_period = float(np.median(np.diff(rec.wrist_t[valid]))) if valid.sum() > 1 else dt
    tol = gap_tolerance * max(dt, wrist_period)
    observed = resample_wrist(rec.wrist_t, xyz, grid, tol)
    if np.isnan(observed).all():
        raise BagError(source, 'no wrist sample inside the movement interval')

    jt = rec.joint_t
    joint_period = float(np.median(np.diff(jt))) if jt.size > 1 else dt
    cover_tol = gap_tolerance * max(dt, joint_period)
    if jt[0] > grid[0] + cover_tol or jt[-1] < grid[-1] - cover_tol:
        raise BagError(source, f'joint states cover {jt[0]:.3f}..{jt[-1]:.3f} s but the movement spans '
                               f'{grid[0]:.3f}..{grid[-1]:.3f} s')
    inside = (jt >= grid[0] - cover_tol) & (jt <= grid[-1] + cover_tol)
    gaps = np.diff(jt[inside])
    if gaps.size and gaps.max() > max_joint_gap:
        k = int(np.argmax(gaps))
        raise BagError(source, f'joint states have a {gaps[k]:.3f} s hole at {jt[inside][k]:.3f} s '
                               f'(max_joint_gap = {max_joint_gap} s)')
    controlled = np.column_stack([np.interp(grid, jt, rec.joint_q[:, j])
                                  for j in range(rec.joint_q.shape[1])])
    try:
        return Demonstration(t=rel, observed=observed, controlled=controlled, label=rec.label,
                             name=name)
    except ValueError as exc:
        raise BagError(source, str(exc)) from exc


def load_demonstration(bag, *, transform=None, dt: float = 0.01, gap_tolerance: float = 1.25,
                       max_joint_gap: float = 0.1, segmentation: Optional[dict] = None,
                       cut: str = 'detected',
                       wrist_topic: str = WRIST_TOPIC, joint_topic: str = JOINT_TOPIC,
                       joint_names: Sequence[str] = JOINT_NAMES,
                       wrist_frame: Optional[str] = None) -> Demonstration:
    """One bag -> one Demonstration (robot base frame, t = 0 at onset). Raises BagError.

    ``segmentation`` holds keyword parameters for ``segment_motion``; ``wrist_frame``, if given,
    must equal the frame_id of the recorded poses (the frame ``transform`` maps from).
    """
    bag = Path(bag)
    rec = read_bag(bag, wrist_topic=wrist_topic, joint_topic=joint_topic, joint_names=joint_names)
    return recording_to_demonstration(rec, transform=transform, dt=dt, gap_tolerance=gap_tolerance,
                                      max_joint_gap=max_joint_gap, segmentation=segmentation,
                                      cut=cut,
                                      wrist_frame=wrist_frame, name=bag.name, source=str(bag))


class SkippedBag(NamedTuple):
    path: Path
    reason: str


class LoadedDataset(NamedTuple):
    """``demos, skipped = load_dataset(folder)``."""

    demonstrations: list
    skipped: list


def find_bags(folder) -> list:
    """Bag directories directly inside ``folder`` (sorted by name).

    A subdirectory counts as a bag if it has a metadata.yaml or a .mcap/.db3 file, so a recording
    that lost its metadata.yaml is reported as a bad bag instead of silently ignored.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise ValueError(f'dataset folder {folder} does not exist or is not a directory')
    if (folder / 'metadata.yaml').is_file():
        raise ValueError(f'{folder} is a single bag, not a folder of bags')
    return sorted(p for p in folder.iterdir()
                  if p.is_dir() and ((p / 'metadata.yaml').is_file() or any(p.glob('*.mcap'))
                                     or any(p.glob('*.db3'))))


def load_dataset(folder, *, on_error: str = 'skip', **kwargs) -> LoadedDataset:
    """Load every bag in ``folder`` (keyword arguments go to :func:`load_demonstration`).

    ``on_error='skip'``: a bad bag is logged as a warning and listed in ``skipped`` with its reason;
    ``'raise'``: the first bad bag raises its BagError. Raises ValueError if no bag loads.
    """
    if on_error not in ('skip', 'raise'):
        raise ValueError(f"on_error must be 'skip' or 'raise', got {on_error!r}")
    bags = find_bags(folder)
    if not bags:
        raise ValueError(f'no rosbag2 bags in {folder}')
    demos, skipped = [], []
    for bag in bags:
        try:
            demos.append(load_demonstration(bag, **kwargs))
        except BagError as exc:
            if on_error == 'raise':
                raise
            logger.warning('skipping %s', exc)
            skipped.append(SkippedBag(bag, exc.problem))
    if not demos:
        reasons = '; '.join(f'{s.path.name}: {s.reason}' for s in skipped)
        raise ValueError(f'none of the {len(bags)} bags in {folder} could be loaded ({reasons})')
    return LoadedDataset(demos, skipped)
