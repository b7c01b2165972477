"""The package's folders are layers; a lower layer never imports a higher one, and only nodes and
the applications above them touch ROS client libraries."""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / 'mixture_ip_ros'
# Lowest first.
LAYERS = ('core', 'estimation', 'robot', 'io', 'scenarios', 'nodes', 'viz', 'app')
ROS_CLIENT = ('rclpy', 'builtin_interfaces', 'std_msgs', 'geometry_msgs', 'sensor_msgs',
              'trajectory_msgs', 'nav_msgs', 'visualization_msgs', 'diagnostic_msgs',
              'rosgraph_msgs', 'lifecycle_msgs', 'rcl_interfaces')
FIRST_ROS_LAYER = LAYERS.index('nodes')


def _modules():
    for path in sorted(PACKAGE.rglob('*.py')):
        rel = path.relative_to(PACKAGE)
        yield path, rel.parts[0] if len(rel.parts) > 1 else None


def _imports(path):
    """Absolute names of every import in the file, function-level ones included."""
    tree = ast.parse(path.read_text(), filename=str(path))
    package = '.'.join(('mixture_ip_ros',) + path.relative_to(PACKAGE).parts[:-1])
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split('.')
                base = base[:len(base) - node.level + 1]
                yield '.'.join(base + ([node.module] if node.module else []))
            else:
                yield node.module
                if node.module == 'mixture_ip_ros':
                    for alias in node.names:
                        yield f'mixture_ip_ros.{alias.name}'


def test_every_module_lives_in_a_layer_folder():
    stray = [str(p.relative_to(PACKAGE)) for p, layer in _modules()
             if layer is None and p.name != '__init__.py' or layer is not None
             and layer not in LAYERS]
    assert not stray, f'modules outside the layer folders {LAYERS}: {stray}'


@pytest.mark.parametrize('layer', LAYERS)
def test_a_layer_imports_only_itself_and_lower_layers(layer):
    rank = LAYERS.index(layer)
    wrong = []
    for path, lay in _modules():
        if lay != layer:
            continue
        for name in _imports(path):
            parts = name.split('.')
            if parts[0] == 'mixture_ip_ros' and len(parts) > 1 and parts[1] in LAYERS:
                if LAYERS.index(parts[1]) > rank:
                    wrong.append(f'{path.relative_to(PACKAGE)} imports {name}')
            elif parts[0] in ROS_CLIENT and rank < FIRST_ROS_LAYER:
                wrong.append(f'{path.relative_to(PACKAGE)} imports ROS client {name}')
    assert not wrong, '\n'.join(wrong)



def test_no_module_imports_itself_through_others():
    """No import circle between the package's modules (function-level imports included): each
    concept has one home that the others depend on, not a pair leaning on each other."""
    modules = {}
    for path, _ in _modules():
        rel = path.relative_to(PACKAGE).with_suffix('')
        name = '.'.join(('mixture_ip_ros',) + rel.parts)
        modules[name.removesuffix('.__init__')] = path
    graph = {name: {m for m in _imports(path) if m in modules and m != name}
             for name, path in modules.items()}
    circles, done = [], set()

    def visit(name, stack):
        if name in stack:
            circles.append(stack[stack.index(name):] + [name])
            return
        if name in done:
            return
        for other in sorted(graph[name]):
            visit(other, stack + [name])
        done.add(name)
    for name in sorted(graph):
        visit(name, [])
    assert not circles, '\n'.join(' -> '.join(c) for c in circles)
