"""Every node's parameters come from one schema: the files in config/ and the tables in
docs/parameters.md are checked against it, and the nodes load those files as they are."""

from pathlib import Path
import re

import numpy as np
import pytest
import yaml
from rclpy.parameter import Parameter

from mixture_ip_ros.core.share import config_path
from mixture_ip_ros.nodes.bag_player import BagPlayerParameters
from mixture_ip_ros.nodes.command_delay import CommandDelayParameters
from mixture_ip_ros.nodes.estimator_node import EstimatorNode, EstimatorParameters
from mixture_ip_ros.nodes.observer_node import ObserverNode, ObserverParameters
from mixture_ip_ros.nodes.params import check_params_file, markdown_table, specs
from mixture_ip_ros.nodes.recorder import RecorderParameters
from mixture_ip_ros.nodes.sim_node import COMMAND_TOPIC, SimNode, SimParameters
from mixture_ip_ros.robot.description import DEFAULT_ROBOT, load_description, shipped_robots

TABLES = Path(__file__).resolve().parents[1] / 'docs' / 'parameters.md'
NODES = {'estimator_node': ('estimator.yaml', EstimatorParameters),
         'observer_node': ('observer.yaml', ObserverParameters),
         'sim_node': ('sim.yaml', SimParameters),
         'bag_player': ('bag_player.yaml', BagPlayerParameters)}
# Values the shipped files set on purpose to something other than the schema's default.
DELIBERATE = {'bag_player': {}, 'estimator_node': {}, 'observer_node': {}, 'sim_node': {}}


def _file(node):
    name, _ = NODES[node]
    return yaml.safe_load(config_path(name).read_text())[node]['ros__parameters']


@pytest.mark.parametrize('node', sorted(NODES))
def test_config_file_sets_every_parameter_validly_and_documents_the_defaults(node):
    schema = NODES[node][1]
    values = _file(node)
    missing_ok = {n for n, default, _ in specs(schema) if default == []}   # no YAML type
    problems = [p for p in check_params_file(schema, values)
                if not any(p == f'parameter {n} missing' for n in missing_ok)]
    assert problems == []
    for name, default, _ in specs(schema):
        if name in values:
            assert values[name] == DELIBERATE[node].get(name, default), name


@pytest.mark.parametrize('node_class, node', [(ObserverNode, 'observer_node'),
                                              (SimNode, 'sim_node')])
def test_nodes_load_their_config_file(ros_context, node_class, node):
    path = config_path(NODES[node][0])
    n = node_class(context=ros_context, cli_args=['--ros-args', '--params-file', str(path)])
    try:
        for name, value in _file(node).items():
            assert n.get_parameter(name).value == value, name
    finally:
        n.destroy_node()


@pytest.mark.parametrize('node_class', [EstimatorNode, ObserverNode, SimNode])
def test_the_robot_parameter_gives_the_defaults_of_its_fields(ros_context, node_class):
    """Each shipped robot's description (read independently here) gives the node's from_robot
    fields; the schema's defaults are the default robot's; a value given explicitly wins."""
    schema = {n: (d, s) for n, d, s in specs(node_class.SCHEMA)}
    derived = sorted(n for n, (_, s) in schema.items() if s.from_robot)
    assert derived and list(schema).index('robot') < min(list(schema).index(n) for n in derived)

    def independent(robot):
        d = load_description(robot)
        to_base = d.world_to_base()
        return {'joint_names': list(d.joint_names), 'observed_frame': d.base_frame,
                'base_frame': d.base_frame,
                'initial_positions': list(d.home), 'natural_frequency': list(d.gains()[0]),
                'damping_ratio': list(d.gains()[1]),
                'mocap_to_base_xyz': list(to_base.translation),
                'mocap_to_base_xyzw': list(to_base.quaternion)}

    def same(a, b):
        if isinstance(b, str) or (isinstance(b, list) and isinstance(b[0], str)):
            return list(a) == b if isinstance(b, list) else a == b
        return np.allclose(a, b, rtol=1e-12, atol=1e-12)

    for n in derived:
        assert same(schema[n][0], independent(DEFAULT_ROBOT)[n]), n
    assert len(shipped_robots()) >= 3
    for robot in shipped_robots():
        node = node_class(context=ros_context, parameter_overrides=[
            Parameter('robot', value=robot), Parameter(derived[0], value=schema[derived[0]][0])])
        try:
            got = {n: node.get_parameter(n).value for n in derived}
        finally:
            node.destroy_node()
        expected = {n: independent(robot)[n] for n in derived}
        expected[derived[0]] = schema[derived[0]][0]               # given explicitly
        for n in derived:
            assert same(got[n], expected[n]), (robot, n)


def test_an_unknown_robot_is_refused_naming_the_parameter(ros_context):
    with pytest.raises(ValueError, match='parameter robot: .*no_such_arm'):
        SimNode(context=ros_context, parameter_overrides=[Parameter('robot', value='no_such_arm')])


def test_the_parameter_tables_are_the_schemas():
    text = TABLES.read_text()
    for node, (_, schema) in NODES.items():
        match = re.search(rf'<!-- parameters: {node} -->\n(.*?)\n<!-- end -->', text, re.S)
        assert match, f'docs/parameters.md has no parameter table for {node}'
        assert match.group(1).strip() == markdown_table(schema), (
            f'the table of {node} is stale: mixture-ip params all --update docs/parameters.md')


def test_a_check_names_the_parameter_and_the_rule():
    problems = check_params_file(ObserverParameters, {**_file('observer_node'),
                                                      'onset_sped': 0.1,
                                                      'mocap_to_base_xyzw': [0.0, 0.0, 0.0, 2.0],
                                                      'gap_timeout': 'soon'})
    assert 'unknown parameter onset_sped' in problems
    assert any(p.startswith('parameter mocap_to_base_xyzw: is not unit length') for p in problems)
    assert any(p.startswith('parameter gap_timeout: expected float') for p in problems)


def test_unknown_parameter_names_are_warned_about(ros_context, capfd):
    node = ObserverNode(context=ros_context, parameter_overrides=[
        Parameter('onset_sped', value=0.1)])
    node.destroy_node()
    assert 'unknown parameters ignored: onset_sped' in capfd.readouterr().err


def test_the_command_topic_names_no_robot_and_the_default_system_connects():
    """The estimator (and the closed loop's relay and recorder) command the relative topic the
    sim subscribes: in one namespace they meet, and the names fit any arm."""
    assert not COMMAND_TOPIC.startswith('/')
    assert (EstimatorParameters().trajectory_topic == CommandDelayParameters().output_topic
            == RecorderParameters().trajectory_topic == COMMAND_TOPIC)


def test_the_rviz_config_shows_the_nodes_topics_in_their_frame():
    rviz = yaml.safe_load(config_path('mixture_ip.rviz').read_text())['Visualization Manager']
    topics = {d['Topic']['Value'] for d in rviz['Displays'] if 'Topic' in d}
    est, obs = EstimatorParameters(), ObserverParameters()
    assert {est.marker_topic, est.path_topic, obs.observation_topic,
            '/flange_pose'} <= topics
    assert rviz['Global Options']['Fixed Frame'] == est.observed_frame == obs.base_frame \
        == SimParameters().base_frame
