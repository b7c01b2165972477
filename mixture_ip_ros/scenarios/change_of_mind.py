"""Change-of-mind bags (issue 50): a person who reaches toward one part and turns to another
mid-reach, made of two demonstration bags as core.splice joins two demonstrations.

:func:`splice_recordings` keeps recording A up to the share ``at`` of A's movement (its rest
before the onset included), then B from the same share of B's own movement on, offset to start
at A's wrist and faded into B's path over core.splice.BLEND s (core.splice.splice, applied to
both streams at once), then B's rest after its end. The robot's recorded joints are joined the
same way: after the fade they are B's, so the bag ends where B's demonstration ended. The
movement is cut where each bag records it (io.bags: the generator's true onset and end), so
the shares are shares of the true movements.

Both streams are put on the wrist's clock first (the joints interpolated to the wrist's sample
times: encoders are dense), one splice then joins both and the change is at one time for both.
The wrist stays in the mocap frame: the join is a translation, the same in any frame.

:func:`write_change_of_mind_bags` writes the spliced bags into a folder as
scenarios.folders.write_scenario_bags writes a scenario's: labels.json maps each bag to the
pattern turned to (B's), and records where each came from (``splices``, also read back by
:func:`read_splices`); each bag's metadata has the first pattern, the share and the change's
stamp.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from mixture_ip_ros.core.demonstration import Demonstration
from mixture_ip_ros.core.splice import BLEND, splice
from mixture_ip_ros.io.bags import RawRecording, read_bag, write_demonstration_bag
from mixture_ip_ros.io.dataset import resample_wrist, segment_recording
from mixture_ip_ros.robot.description import JOINT_NAMES
from mixture_ip_ros.scenarios.folders import LABEL_FILE, read_label_entry

SCENARIO = 'change_of_mind'
FIRST_KEY = 'mixture_ip_ros.first'
SHARE_KEY = 'mixture_ip_ros.share'
CHANGE_KEY = 'mixture_ip_ros.change_ns'
# A single dropped wrist sample is bridged, an occlusion stays missing (io.dataset's default).
GAP_TOLERANCE = 1.25


@dataclass
class SplicedRecording:
    """A change-of-mind recording: times (s, the first recording's time base), the wrist
    (mocap frame; NaN rows: no sample), the joints at the same times, the movement's onset and
    end, when the person turned (``t_change``: the first sample of B's part), the two patterns
    and the share of the first movement."""

    t: np.ndarray
    wrist_xyz: np.ndarray
    joint_q: np.ndarray
    onset: float
    end: float
    t_change: float
    first: str
    second: str
    share: float


def _on_wrist_clock(rec: RawRecording, source: str):
    """(times, wrist, joints, onset, end): the wrist's own uniform clock over the whole
    recording, NaN where no accepted wrist sample is, the joints interpolated to it, and the
    movement as the bag records it."""
    xyz, onset, end = segment_recording(rec, cut='recorded', source=source)
    present = ~np.isnan(xyz).any(axis=1)
    period = float(np.median(np.diff(rec.wrist_t[present])))
    n = int(round((rec.wrist_t[-1] - rec.wrist_t[0]) / period)) + 1
    t = rec.wrist_t[0] + period * np.arange(n)
    wrist = resample_wrist(rec.wrist_t, xyz, t, GAP_TOLERANCE * period)
    joints = np.column_stack([np.interp(t, rec.joint_t, rec.joint_q[:, j])
                              for j in range(rec.joint_q.shape[1])])
    return t, wrist, joints, onset, end


def _movement(t, wrist, joints, onset, end, label, source):
    """(rows, Demonstration) of the samples inside [onset, end], t = 0 at the first."""
    rows = np.flatnonzero((t >= onset - 1e-9) & (t <= end + 1e-9))
    if rows.size < 2:
        raise ValueError(f'{source}: fewer than 2 samples inside its recorded movement')
    return rows, Demonstration(t[rows] - t[rows[0]], wrist[rows], joints[rows], label=label,
                               name=source)


def splice_recordings(a: RawRecording, b: RawRecording, at: float, blend: float = BLEND,
                      sources=('A', 'B')) -> SplicedRecording:
    """A's recording up to the share ``at`` of its movement, then B's from the same share of
    its own movement to its end (module docstring). ``sources`` name the two in errors.
    Raises ValueError where core.splice.splice does, for a recording without a recorded
    movement, and where B's part after the change is shorter than the fade (its end would
    not be B's)."""
    ta, wa, qa, onset_a, end_a = _on_wrist_clock(a, sources[0])
    tb, wb, qb, onset_b, end_b = _on_wrist_clock(b, sources[1])
    if wa.shape[1] != wb.shape[1] or qa.shape[1] != qb.shape[1]:
        raise ValueError(f'{sources[0]} and {sources[1]} have different layouts')
    ra, da = _movement(ta, wa, qa, onset_a, end_a, a.label, sources[0])
    rb, db = _movement(tb, wb, qb, onset_b, end_b, b.label, sources[1])
    s = splice(da, db, at, blend)
    if s.demo.t[-1] - s.t_change < blend:
        raise ValueError(f'{sources[1]} after a share of {at:g} is shorter than the '
                         f'{blend:g} s fade into it')
    t0 = ta[ra[0]]
    t_last = t0 + s.demo.t[-1]
    after = slice(rb[-1] + 1, None)
    return SplicedRecording(
        t=np.r_[ta[:ra[0]], t0 + s.demo.t, t_last + tb[after] - tb[rb[-1]]],
        wrist_xyz=np.vstack([wa[:ra[0]], s.demo.observed, wb[after]]),
        joint_q=np.vstack([qa[:ra[0]], s.demo.controlled, qb[after]]),
        onset=float(onset_a), end=float(t_last + end_b - tb[rb[-1]]),
        t_change=float(t0 + s.t_change), first=a.label, second=b.label, share=float(at))


def splice_name(first_bag, second_bag, at: float) -> str:
    return f'{Path(first_bag).name}_to_{Path(second_bag).name}_at_{at:g}'


def write_change_of_mind_bags(splices: Sequence[tuple], out_dir, *,
                              joint_names: Sequence[str] = JOINT_NAMES, blend: float = BLEND,
                              storage: str = 'mcap') -> list:
    """One bag per (bag A, bag B, share) of ``splices`` (:func:`splice_recordings`) into
    ``out_dir`` (new or empty), named :func:`splice_name`, and labels.json; returns the bag
    paths. ``joint_names``: the robot's joints, as its bags name them."""
    out = Path(out_dir)
    if out.exists() and any(out.iterdir()):
        raise ValueError(f'{out} is not empty; refusing to mix demonstration sets')
    plans = []
    robots = set()
    for first_bag, second_bag, at in splices:
        recs = [read_bag(p, joint_names=joint_names) for p in (first_bag, second_bag)]
        robots |= {(r.custom_data or {}).get('mixture_ip_ros.robot') for r in recs}
        spliced = splice_recordings(*recs, float(at), blend,
                                    sources=(str(first_bag), str(second_bag)))
        plans.append((splice_name(first_bag, second_bag, at), first_bag, second_bag,
                      recs[0].start_time_ns, spliced))
    if len(robots) != 1:
        raise ValueError(f'demonstrations of several robots {sorted(map(str, robots))}; one '
                         'folder, one robot')
    robot = robots.pop()
    out.mkdir(parents=True, exist_ok=True)
    paths, recipe = [], {}
    for name, first_bag, second_bag, start_ns, s in plans:
        present = ~np.isnan(s.wrist_xyz).any(axis=1)
        change_ns = start_ns + int(round(s.t_change * 1e9))
        paths.append(write_demonstration_bag(
            out / name, s.t[present], s.wrist_xyz[present], s.t, s.joint_q, storage=storage,
            label=s.second, joint_names=joint_names, start_time_ns=start_ns,
            segment=(s.onset, s.end),
            custom_data={'mixture_ip_ros.scenario': SCENARIO, 'mixture_ip_ros.robot': str(robot),
                         FIRST_KEY: str(s.first), SHARE_KEY: f'{s.share:g}',
                         CHANGE_KEY: str(change_ns)}))
        recipe[name] = {'first_bag': Path(first_bag).name, 'second_bag': Path(second_bag).name,
                        'first': s.first, 'second': s.second, 'share': s.share,
                        'change_after_onset_s': s.t_change - s.onset,
                        'duration_s': s.end - s.onset}
    labels = {'scenario': SCENARIO, 'robot': robot, 'blend': blend,
              'labels': {name: r['second'] for name, r in recipe.items()}, 'splices': recipe}
    (out / LABEL_FILE).write_text(json.dumps(labels, indent=2, sort_keys=True) + '\n')
    return paths


def read_splices(folder) -> dict:
    """{bag name: {'first_bag', 'second_bag', 'first', 'second', 'share',
    'change_after_onset_s', 'duration_s'}} of a folder :func:`write_change_of_mind_bags`
    wrote (evaluation only)."""
    return read_label_entry(folder, 'splices', 'their recipes')
