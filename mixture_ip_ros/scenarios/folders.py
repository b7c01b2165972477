"""Scenario folders: one rosbag2 bag per demonstration and labels.json (evaluation only), and
the generated scenarios by name."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

from mixture_ip_ros.robot.description import DEFAULT_ROBOT
from mixture_ip_ros.scenarios.box_assembly import box_assembly
from mixture_ip_ros.scenarios.pole import pole

LABEL_FILE = 'labels.json'

SCENARIOS = {'box_assembly': box_assembly, 'pole': pole}


def generate(scenario: str, seed: int = 0, robot=None, **kwargs) -> list:
    """Demonstrations of a named scenario ('box_assembly' or 'pole') for ``robot`` (a shipped
    name, a description file or a RobotDescription; None: the iiwa 14)."""
    if scenario not in SCENARIOS:
        raise ValueError(f'unknown scenario {scenario!r}; known: {sorted(SCENARIOS)}')
    if kwargs.get('kinematics') is None:
        from mixture_ip_ros.robot.kinematics import RobotKinematics
        kwargs['kinematics'] = RobotKinematics(robot)
    return SCENARIOS[scenario](seed, **kwargs)


def write_scenario_bags(scenario: str, out_dir, seed: int = 0, occlusion: float = 0.0,
                        storage: str = 'mcap', demos: Optional[list] = None,
                        robot=None) -> list:
    """Write one rosbag2 bag per demonstration into ``out_dir`` plus labels.json (evaluation only).

    ``out_dir`` must not exist or be empty. Returns the bag paths. labels.json maps bag name to
    label and records the scenario, seed and robot; the label, scenario, seed and robot are also
    in each bag's metadata custom_data, with the movement's true onset and end. Wrist poses are
    in the frame 'world', joint states carry the robot's joint names. ``robot`` is used when ``demos`` is None (else the demos' own).
    """
    from mixture_ip_ros.io.bags import write_demonstration_bag
    out = Path(out_dir)
    if out.exists() and any(out.iterdir()):
        raise ValueError(f'{out} is not empty; refusing to mix demonstration sets')
    if demos is None:
        demos = generate(scenario, seed, robot=robot, occlusion=occlusion)
    robots = {d.robot.name for d in demos}
    if len(robots) != 1:
        raise ValueError(f'demonstrations of several robots {sorted(robots)}; one folder, '
                         'one robot')
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for d in demos:
        paths.append(write_demonstration_bag(
            out / d.name, d.wrist_t, d.wrist_xyz, d.joint_t, d.joint_q, joint_qd=d.joint_qd,
            storage=storage, label=d.label, joint_names=d.robot.joint_names,
            custom_data={'mixture_ip_ros.scenario': scenario, 'mixture_ip_ros.seed': str(seed),
                         'mixture_ip_ros.robot': d.robot.name}, segment=(d.onset, d.end)))
    labels = {'scenario': scenario, 'seed': seed, 'occlusion': occlusion,
              'robot': robots.pop(), 'labels': {d.name: d.label for d in demos}}
    (out / LABEL_FILE).write_text(json.dumps(labels, indent=2, sort_keys=True) + '\n')
    return paths


def read_scenario_robot(folder) -> str:
    """The name of the robot a scenario folder was generated for (labels.json; a folder that does
    not say is the default robot's)."""
    path = Path(folder) / LABEL_FILE
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise ValueError(f'cannot read {path}: {exc}') from exc
    return str(data.get('robot', DEFAULT_ROBOT)) if isinstance(data, dict) else DEFAULT_ROBOT


def read_label_entry(folder, key: str, what: str) -> dict:
    """The object under ``key`` of a scenario folder's labels.json, keyed by bag name;
    ValueError naming ``what`` it should hold when it cannot be read or is no object."""
    path = Path(folder) / LABEL_FILE
    try:
        entry = json.loads(path.read_text())[key]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ValueError(f'cannot read {key} from {path}: {exc}') from exc
    if not isinstance(entry, dict):
        raise ValueError(f'{path}: "{key}" must map bag names to {what}')
    return entry


def read_labels(folder) -> dict:
    """{bag name: label} from a scenario folder's labels.json (evaluation only)."""
    return {str(k): str(v) for k, v in read_label_entry(folder, 'labels', 'labels').items()}
