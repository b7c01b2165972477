"""`mixture-ip evaluate`: the thesis's experiments and real recordings, as PNG plots +
metrics.json, one module per scenario over the pieces they share (common, baselines):

- box_assembly (box), pole (pole): thesis 3.4.2 and 3.4.1 on generated or recorded bags;
- phase, missing_data (letters): thesis 4.3.1 and 4.3.2 on generated letters;
- gestures (gestures): real human motion of one agent, PickupGestureWiimoteZ;
- interactions (interactions): real two-person interactions, NuiSI v1 and v2; and any folder of
  labelled CSV recordings (:func:`evaluate_csv`);
- change_of_mind (change_of_mind): NuiSI v1 and v2 recordings spliced into changes of mind;
- a trained model file scored on labelled CSV recordings without retraining
  (:func:`evaluate_model_csv`, trained_model).

Every scenario measures the model ``training.train`` ships for its training demonstrations.
"""

from __future__ import annotations

from dataclasses import replace
import json
import time
from pathlib import Path
from typing import Optional

from mixture_ip_ros.app.evaluation.common import (EvalConfig, jsonable, load_labelled_bags,
                                                  subsampled)
from mixture_ip_ros.io.files import write_text_atomic

SCENARIOS = ('box_assembly', 'pole', 'phase', 'missing_data', 'gestures', 'interactions',
             'change_of_mind')

__all__ = ['SCENARIOS', 'EvalConfig', 'evaluate', 'evaluate_csv', 'evaluate_model_csv',
           'subsampled']


def evaluate(scenario: str, out_dir: Path, seed: int = 0, quick: bool = False, *,
             bag_dir: Optional[Path] = None, demos: Optional[list] = None,
             config: Optional[EvalConfig] = None, robot=None, progress=None) -> dict:
    """Run one scenario's experiments; write PNGs and ``metrics.json`` into ``out_dir``.

    box_assembly and pole learn from generated demonstrations (``seed``), or from ``bag_dir`` (a
    folder of demonstration bags, labels from the bags' metadata or labels.json), or from
    ``demos`` (labelled Demonstrations). ``config`` replaces the scenario's default settings
    (``quick`` picks smaller ones: fewer K candidates, folds, basis functions and time steps).
    ``robot`` (box_assembly and pole): the arm the demonstrations are for, a shipped name or a
    description file (None: the iiwa 14); it generates them, reads the bags' joints and gives
    the hand positions. ``progress(line)``: told as each fold of a cross-validated scenario
    (interactions) ends.
    """
    if scenario not in SCENARIOS:
        raise ValueError(f'unknown scenario {scenario!r}; known: {list(SCENARIOS)}')
    if bag_dir is not None and demos is not None:
        raise ValueError('give bag_dir or demos, not both')
    robot_scenarios = ('box_assembly', 'pole')
    if scenario not in robot_scenarios and (bag_dir is not None or demos is not None):
        raise ValueError(f'scenario {scenario!r} reads its own data; bag_dir/demos are for '
                         'box_assembly and pole')
    if scenario not in robot_scenarios and robot is not None:
        raise ValueError(f'scenario {scenario!r} has no robot; robot is for box_assembly and pole')
    out_dir = Path(out_dir)
    t0 = time.perf_counter()
    if scenario in robot_scenarios:
        from mixture_ip_ros.robot.kinematics import RobotKinematics
        from mixture_ip_ros.scenarios.folders import generate
        kin = RobotKinematics(robot)
        if bag_dir is not None:
            demos, skipped = load_labelled_bags(bag_dir, kin.description)
            source = {'bags': str(bag_dir), 'skipped': [f'{p.name}: {r}' for p, r in skipped]}
        elif demos is not None:
            demos = list(demos)
            source = 'given demonstrations'
        else:
            demos = [g.to_demonstration()
                     for g in generate(scenario, seed, kinematics=kin)]
            source = f'generated seed {seed}'
        bad = sorted({d.n_controlled_dofs for d in demos} - {kin.dof})
        if bad:
            raise ValueError(f'the demonstrations have {bad[0]} controlled DOFs, the robot '
                             f'{kin.description.name} has {kin.dof} joints')
        out_dir.mkdir(parents=True, exist_ok=True)     # only once there is data to evaluate
        if scenario == 'box_assembly':
            from mixture_ip_ros.app.evaluation.box import box_config, evaluate_box_assembly
            metrics = evaluate_box_assembly(demos, out_dir, config or box_config(quick), kin)
        else:
            from mixture_ip_ros.app.evaluation.pole import evaluate_pole, pole_config
            metrics = evaluate_pole(demos, out_dir, config or pole_config(quick), kin)
        metrics = {'robot': kin.description.name, **metrics}
    elif scenario == 'gestures':
        from mixture_ip_ros.app.evaluation.gestures import evaluate_gestures, gesture_config
        from mixture_ip_ros.scenarios import gestures
        out_dir.mkdir(parents=True, exist_ok=True)
        metrics = evaluate_gestures(
            gestures.gesture_demonstrations('train'), gestures.gesture_demonstrations('test'),
            out_dir, config or gesture_config(quick), seed)
        source = gestures.SOURCE
    elif scenario == 'interactions':
        from mixture_ip_ros.app.evaluation.interactions import (evaluate_nuisi,
                                                                interactions_config)
        out_dir.mkdir(parents=True, exist_ok=True)
        metrics = evaluate_nuisi(out_dir, config or interactions_config(quick), seed,
                                 progress=progress)
        source = 'NuiSI v1 and v2'
    elif scenario == 'change_of_mind':
        from mixture_ip_ros.app.evaluation.change_of_mind import evaluate_change_of_mind
        from mixture_ip_ros.app.evaluation.interactions import interactions_config
        out_dir.mkdir(parents=True, exist_ok=True)
        metrics = evaluate_change_of_mind(config or interactions_config(quick), seed,
                                          progress=progress)
        source = 'NuiSI v1 and v2, spliced'
    else:
        from mixture_ip_ros.app.evaluation.letters import (evaluate_missing_data,
                                                           evaluate_phase, letter_config)
        from mixture_ip_ros.scenarios.letters import missing_data_letters, phase_letters
        cfg = config or letter_config(quick)
        out_dir.mkdir(parents=True, exist_ok=True)
        if scenario == 'phase':
            metrics = evaluate_phase(phase_letters(seed), out_dir, cfg)
        else:
            metrics = evaluate_missing_data(missing_data_letters(seed), out_dir, cfg)
        source = f'generated seed {seed}'
    return _write(out_dir, {'scenario': scenario, 'seed': int(seed), 'quick': bool(quick),
                            'source': source, **metrics,
                            'runtime_s': round(time.perf_counter() - t0, 2)})


def evaluate_csv(csv_dir, labels: dict, layout, out_dir: Path, time_column: str = 't',
                 seed: int = 0, quick: bool = False, config: Optional[EvalConfig] = None,
                 translation=(), progress=None) -> dict:
    """The interactions' cross-validated metrics and baselines on your own labelled
    recordings: a folder of CSV demonstrations (io.csv_files, any numbers of observed and
    controlled DOFs named by ``layout``) and ``labels`` {file stem or name: label}. Errors are in
    cm when every controlled DOF is in metres, else in the DOFs' own unit. ``translation``:
    the model's translation groups (core.patterns.translation_for), which the nearest-neighbour
    baseline is given too. ``progress(line)``: told as each fold ends."""
    from mixture_ip_ros.app.evaluation.interactions import evaluate_labelled, interactions_config
    demos = _labelled_csv(csv_dir, labels, layout, time_column)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    cm = bool(layout.controlled) and all(u == 'm' for u in layout.controlled_units)
    config = config or interactions_config(quick)
    if translation:
        config = replace(config, model={**config.model, 'translation': tuple(translation)})
    metrics = evaluate_labelled(demos, out_dir, config, 'csv', seed, cm=cm, progress=progress,
                                dof_names=(layout.observed, layout.controlled))
    return _write(out_dir, {'scenario': 'csv', 'seed': int(seed), 'source': str(csv_dir),
                            **metrics, 'runtime_s': round(time.perf_counter() - t0, 2)})


def evaluate_model_csv(model_path, csv_dir, labels: dict, out_dir: Optional[Path] = None, *,
                       observed=None, controlled=None, observed_units=None,
                       controlled_units=None, time_column: str = 't', progress=None) -> dict:
    """A trained model file scored on a folder of labelled CSV recordings without retraining
    (trained_model.evaluate_model): the columns named by ``observed`` / ``controlled`` (one per
    DOF of the model; None: the model's own names), the units the model's. Errors are in cm
    when every controlled DOF is in metres. ``metrics.json`` goes to ``out_dir`` if given."""
    from mixture_ip_ros.app.evaluation.trained_model import evaluate_model, model_columns
    from mixture_ip_ros.io.model_file import load_model
    t0 = time.perf_counter()
    model, meta = load_model(model_path)
    layout = model_columns(meta, observed, controlled, observed_units, controlled_units)
    demos = _labelled_csv(csv_dir, labels, layout, time_column)
    cm = bool(layout.controlled) and all(u == 'm' for u in layout.controlled_units)
    metrics = {'model': str(model_path), 'source': str(csv_dir),
               **evaluate_model(model, demos, cm=cm, progress=progress),
               'runtime_s': round(time.perf_counter() - t0, 2)}
    if out_dir is None:
        return jsonable(metrics)
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    return _write(Path(out_dir), metrics)


def _labelled_csv(csv_dir, labels: dict, layout, time_column: str) -> list:
    """The CSV recordings of ``csv_dir`` (io.csv_files), each with its label from ``labels``
    (file name or stem -> label); ValueError naming the first recording without one."""
    from mixture_ip_ros.io.csv_files import load_csv_dataset
    demos = load_csv_dataset(csv_dir, layout, time=time_column)
    missing = [d.name for d in demos if labels.get(d.name, labels.get(Path(d.name).stem)) is None]
    if missing:
        raise ValueError(f'no label for {len(missing)} recordings (first: {missing[0]!r}); the '
                         'labels file maps every CSV file (name or stem) to its label')
    for d in demos:
        d.label = str(labels.get(d.name, labels.get(Path(d.name).stem)))
    return demos


def _write(out_dir: Path, metrics: dict) -> dict:
    metrics = jsonable(metrics)
    write_text_atomic(out_dir / 'metrics.json', json.dumps(metrics, indent=1) + '\n')
    return metrics
