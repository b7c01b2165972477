"""Real two-person interactions: the NuiSI data set (Prasad et al., "MILD: Multimodal
Interactive Latent Dynamics for Learning Human-Robot Interaction", Humanoids 2022; AGPL-3.0).

Nuitrack skeletons of two people interacting physically. Each person is in their own body
frame (metres); person 2 was resampled to person 1's length upstream. The files carry no time
stamps; times here are frame / rate at the recording rates the provenance gives.

- v1: 6 interactions (clap-fistbump, fistbump, handshake, high-five, rocket fistbump, wave),
  90 train / 24 test recordings at about 9 Hz, 10 joints per person.
- v2: 4 interactions (waving, handshake, rocket fistbump, parachute fistbump), 33 train /
  11 test at about 30 Hz, the 4 joints of the right arm per person: Nuitrack's right collar
  (the body frame's origin), shoulder, elbow and wrist (its last tracked joint of the arm;
  the provenance calls it the hand).

The files are the upstream ones at pinned commits, found in the user cache (io.cache) under
``nuisi/`` and, where they are missing, downloaded from the repository; a file whose sha256 is
not the pinned one is refused. Their recordings are pickled object arrays, read with an
unpickler that admits numpy arrays only (io.safe_npz). The license travels with every copy
(``./dev`` seeds the cache from a local copy with its LICENSE and PROVENANCE.md).
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mixture_ip_ros.core.demonstration import Demonstration, Layout
from mixture_ip_ros.io.cache import cache_dir, check_sha256, download_verified
from mixture_ip_ros.io.safe_npz import load_npz

REPOSITORY = 'https://raw.githubusercontent.com/souljaboy764/nuisi_dataset'


@dataclass(frozen=True)
class Version:
    file: str                 # the name in the cache
    upstream_path: str        # the path in the upstream repository at ``commit``
    commit: str
    sha256: str
    rate: float               # Hz
    interactions: tuple       # label i names interactions[i]
    joints: tuple             # per person, in column order (x, y, z each)
    hand: str                 # the joint the interactions are about


VERSIONS = {
    'v1': Version('nuisiv1_dataset.npz', 'nuisiv1_dataset.npz',
                  '360a14758027b4462db9bff3db215f4e67af2398',
                  '8bd4d7f5b46c04c8ba3e064fc4a4cdac2d5a12bf5b80bae6648acc99af71df98', 9.0,
                  ('clap_fistbump', 'fistbump', 'handshake', 'highfive', 'rocket_fistbump',
                   'wave'),
                  ('head', 'neck', 'torso', 'waist', 'left_shoulder', 'left_elbow',
                   'left_hand', 'right_shoulder', 'right_elbow', 'right_hand'), 'right_hand'),
    'v2': Version('nuisiv2_traj_data.npz', 'traj_data.npz',
                  '26ae5b802c5f3d1799623decc95b0c0dbb5b5078',
                  '012cafd6e57b1fe2ec7a0ad5296d687eb30ca72debc47c6ce18413a7b8c31d2e', 30.0,
                  ('waving', 'handshake', 'rocket_fistbump', 'parachute_fistbump'),
                  ('right_collar', 'right_shoulder', 'right_elbow', 'right_wrist'),
                  'right_wrist'),
}
SOURCE = ('NuiSI {version} (Prasad et al., Humanoids 2022; github.com/souljaboy764/'
          'nuisi_dataset at {commit}, AGPL-3.0)')


@dataclass
class Recording:
    """One interaction: both people's joints (T, J, 3) in their own body frames, at ``rate``."""

    name: str
    label: str
    person1: np.ndarray
    person2: np.ndarray
    rate: float

    @property
    def t(self) -> np.ndarray:
        return np.arange(len(self.person1)) / self.rate


def _version(version: str) -> Version:
    if version not in VERSIONS:
        raise ValueError(f'NuiSI version must be one of {sorted(VERSIONS)}, got {version!r}')
    return VERSIONS[version]


def nuisi_file(version: str, cache=None) -> Path:
    """The checked file of ``version`` in the cache, downloaded the first time."""
    v = _version(version)
    path = Path(cache or cache_dir()) / 'nuisi' / v.file
    if path.is_file():
        return check_sha256(path, v.sha256)
    return download_verified(f'{REPOSITORY}/{v.commit}/{v.upstream_path}', path, v.sha256)


def recordings(version: str, split: str, cache=None) -> list:
    """The ``split`` ('train' or 'test', the upstream split) recordings of ``version``."""
    if split not in ('train', 'test'):
        raise ValueError(f"split must be 'train' or 'test', got {split!r}")
    v = _version(version)
    path = nuisi_file(version, cache)
    arrays = load_npz(path)
    data, labels = arrays.get(f'{split}_data'), arrays.get(f'{split}_labels')
    if data is None or labels is None or len(data) != len(labels):
        raise ValueError(f'{path}: no {split}_data and {split}_labels of equal length')
    J = len(v.joints)
    out = []
    for i, (x, label) in enumerate(zip(data, labels)):
        x = np.asarray(x, dtype=float)
        if x.ndim != 2 or x.shape[1] != 6 * J or len(x) < 2 or not np.isfinite(x).all():
            raise ValueError(f'{path}: {split} recording {i} has shape {x.shape}, not finite '
                             f'(T >= 2, {6 * J}) values')
        if label != int(label) or not 0 <= label < len(v.interactions):
            raise ValueError(f'{path}: {split} recording {i} has label {label!r}')
        people = x.reshape(len(x), 2, J, 3)
        out.append(Recording(f'{version}_{split}_{i:03d}', v.interactions[int(label)],
                             people[:, 0], people[:, 1], v.rate))
    return out


def layout(joint: str) -> Layout:
    """Person 1's ``joint`` observed, person 2's controlled, xyz in metres."""
    return Layout(tuple(f'person1_{joint}_{a}' for a in 'xyz'),
                  tuple(f'person2_{joint}_{a}' for a in 'xyz'), ('m',) * 3, ('m',) * 3)


def demonstrations(version: str, split: str, joint: str = None, cache=None) -> list:
    """The recordings as labelled Demonstrations: person 1's ``joint`` (default: the version's
    hand) observed, person 2's controlled (xyz each), t = frame / rate from the first frame
    (the upstream cut each recording where its interaction starts)."""
    v = _version(version)
    joint = v.hand if joint is None else joint
    if joint not in v.joints:
        raise ValueError(f'NuiSI {version} has joints {v.joints}, not {joint!r}')
    j = v.joints.index(joint)
    return [Demonstration(r.t, r.person1[:, j], r.person2[:, j], label=r.label, name=r.name)
            for r in recordings(version, split, cache)]
