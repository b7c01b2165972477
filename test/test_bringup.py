"""`mixture-ip run` starts the nodes as a user would, prints the interaction one line per event
and stops them all; launch/mixture_ip.launch.py names the same executables, params files and
parameters."""

import ast
import os
from pathlib import Path
import subprocess
import sys

import pytest

from conftest import private_domain_id
from mixture_ip_ros.app.bringup import (BAG_PLAYER_PARAMETERS, LAUNCH_ARGUMENTS, NODES,
                                        PARAMS_FILES, EventLines, node_commands,
                                        node_parameters, run_environment)

LAUNCH_FILE = Path(__file__).resolve().parents[1] / 'launch' / 'mixture_ip.launch.py'


def _launch_nodes():
    """{executable: (params file, parameter names)} of the launch file's Node actions, and the
    names of its declared arguments, read from its syntax tree (launch is not installed)."""
    tree = ast.parse(LAUNCH_FILE.read_text())
    nodes, arguments = {}, []
    for call in ast.walk(tree):
        if not isinstance(call, ast.Call) or not isinstance(call.func, ast.Name):
            continue
        kw = {k.arg: k.value for k in call.keywords}
        if call.func.id == 'DeclareLaunchArgument':
            arguments.append(call.args[0].value)
        if call.func.id != 'Node':
            continue
        files = [a.args[0].value for a in ast.walk(kw['parameters'])
                 if isinstance(a, ast.Call) and getattr(a.func, 'id', '') == '_params_file']
        names = {k.value for d in ast.walk(kw['parameters']) if isinstance(d, ast.Dict)
                 for k in d.keys}
        nodes[kw['executable'].value] = (files, names)
    return nodes, arguments


def test_the_launch_file_starts_the_nodes_mixture_ip_run_starts_with_the_same_parameters():
    nodes, arguments = _launch_nodes()
    assert sorted(arguments) == sorted(LAUNCH_ARGUMENTS)
    assert sorted(nodes) == sorted(NODES)
    replayed = node_parameters('model.npz', 'iiwa14', bag='bag')
    live = node_parameters('model.npz', 'iiwa14')
    for name in NODES:
        files, names = nodes[name]
        assert files == [PARAMS_FILES[name]], name
        expected = set(replayed[name]) | set(live.get(name, {}))
        assert names == expected, (name, names ^ expected)


def test_the_launch_file_is_installed_with_the_package():
    setup = (LAUNCH_FILE.parents[1] / 'setup.py').read_text()
    assert "('share/' + package_name + '/launch', glob('launch/*.launch.py'))" in setup


def test_the_nodes_get_their_params_files_and_the_readmes_parameters():
    commands = dict(node_commands(node_parameters('m.npz', 'ur5', bag='b'), bindir='/bin'))
    assert list(commands) == list(NODES)
    player = commands['bag_player']
    assert player[:4] == ['/bin/bag_player', '--ros-args', '--params-file',
                          player[3]] and player[3].endswith('config/bag_player.yaml')
    for p in ("topics:=['/mocap/wrist']", 'use_sim_time:=true', 'rewrite_stamps:=true', 'start_delay:=2.0', 'bag:=b'):
        assert p in player
    assert 'model_path:=m.npz' in commands['estimator_node']
    assert all('robot:=ur5' in commands[n] for n in ('sim_node', 'observer_node',
                                                      'estimator_node'))
    live = dict(node_commands(node_parameters('m.npz', 'ur5'), bindir='/bin'))
    assert 'bag_player' not in live and 'simulated_time:=false' in live['sim_node']
    assert not any('use_sim_time:=true' in argv for argv in live.values())
    no_sim = node_parameters('m.npz', 'ur5', sim=False)
    assert sorted(no_sim) == ['estimator_node', 'observer_node']
    assert set(BAG_PLAYER_PARAMETERS) <= set(node_parameters('m', 'r', bag='b')['bag_player'])


def test_the_environment_keeps_the_callers_choices_and_sets_the_defaults():
    env = run_environment(7, base={'ROS_DOMAIN_ID': '3', 'ROS_AUTOMATIC_DISCOVERY_RANGE':
                                   'SUBNET'})
    assert env['ROS_DOMAIN_ID'] == '7' and env['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'SUBNET'
    assert env['OPENBLAS_NUM_THREADS'] == '1'
    env = run_environment(None, base={'ROS_DOMAIN_ID': '3'})
    assert env['ROS_DOMAIN_ID'] == '3' and env['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'


def test_beliefs_are_printed_when_the_likeliest_pattern_or_its_probability_changes():
    lines = EventLines(labels=['plate', 'screw'])
    assert lines.event('onset') == 'onset: interaction 1 begins'
    first = lines.posterior([0.6, 0.4, 0.5, 0.1, 0.6, 0])
    assert first == 'belief: plate 0.60, screw 0.40; most likely plate at phase 0.10'
    assert lines.posterior([0.65, 0.35, 0.5, 0.15, 0.65, 0]) is None    # moved < 0.1
    assert lines.posterior([0.75, 0.25, 0.5, 0.2, 0.75, 0]) is not None
    assert 'most likely screw' in lines.posterior([0.45, 0.55, 0.5, 0.3, 0.55, 1])
    assert lines.estimator_log('committed to component 1 (screw) (p = 0.9)') == \
        'commit: component 1 (screw) (p = 0.9)'
    assert lines.estimator_log('onset at 1.0: new interaction') is None
    assert not lines.settled
    lines.event('end')
    lines.estimator_log('interaction done: component 1 (screw), ...')
    assert lines.settled


@pytest.fixture(scope='module')
def model_and_bag(tmp_path_factory):
    """Box-assembly bags, a 3-pattern model on 4 of each pattern's, one bag not trained on."""
    from mixture_ip_ros.app.training import train_to_file
    from mixture_ip_ros.io.dataset import load_demonstration
    from mixture_ip_ros.scenarios.folders import read_labels, write_scenario_bags
    root = tmp_path_factory.mktemp('bringup')
    data = root / 'bags'
    write_scenario_bags('box_assembly', data, seed=3)
    by_pattern = {}
    for name, label in sorted(read_labels(data).items()):
        by_pattern.setdefault(label, []).append(name)
    model = root / 'model.npz'
    train_to_file([load_demonstration(data / n) for names in by_pattern.values()
                   for n in names[1:5]], model, n_components=3)
    return model, data / next(iter(by_pattern.values()))[0]


def test_mixture_ip_run_replays_a_bag_prints_onset_and_commit_and_stops_every_node(
        model_and_bag, tmp_path):
    model, bag = model_and_bag
    env = dict(os.environ, ROS_DOMAIN_ID=str(private_domain_id()))
    proc = subprocess.run([str(Path(sys.executable).parent / 'mixture-ip'), 'run', '--model',
                           str(model), '--bag', str(bag), '--log-dir', str(tmp_path)],
                          env=env, capture_output=True, text=True, timeout=120)
    out = proc.stdout
    assert proc.returncode == 0, out + proc.stderr
    events = [line.split('] ', 1)[1] for line in out.splitlines() if '] ' in line]
    kinds = [e.split(':')[0] for e in events]
    assert 'onset' in kinds and 'commit' in kinds and 'end' in kinds, out
    assert kinds.index('onset') < kinds.index('commit') < kinds.index('result'), out
    assert any(k == 'belief' for k in kinds), out
    # every child stopped on SIGINT (exit code 0), none killed
    assert events[-1] == ('stopped: sim_node 0, observer_node 0, estimator_node 0, '
                          'bag_player 0'), out
    assert {p.name for p in tmp_path.glob('*.log')} == {f'{n}.log' for n in NODES}
