"""One parameter schema per node: a dataclass whose fields are the parameters.

Each field has its default, a description, an optional inclusive range (shown by
``ros2 param describe``, enforced by rclpy), an optional rule for what a range cannot say
(positive, finite, list length...), and whether it may change at run time; the others are
read-only. A field marked ``from_robot`` takes its default from the node's ``robot`` parameter
(declared before it): the schema's own default is the default robot's. :func:`declare` declares
them all with ``ParameterDescriptor``s, validates every value (from a params file, ``-p``, or ``ros2 param set``) in an on-set-parameters callback, and
returns the typed struct the node reads. The same schema renders the README's parameter tables
and checks the files in ``config/``.
"""

from dataclasses import MISSING, dataclass, field, fields
import math
from typing import Any, Callable, Optional

BUILTIN = ('use_sim_time', 'start_type_description_service')
_INT_MAX = 2**31 - 1


@dataclass(frozen=True)
class Spec:
    description: str
    low: Optional[float] = None        # inclusive bounds (numbers)
    high: Optional[float] = None
    dynamic: bool = False              # may change at run time
    check: Optional[Callable[[Any], Optional[str]]] = None   # why a value is wrong, or None
    rule: str = ''                     # what ``check`` requires, for the docs
    from_robot: bool = False           # the default comes from the robot's description


def param(default, description: str, *, low=None, high=None, dynamic: bool = False,
          check=None, rule: str = '', from_robot: bool = False):
    """A schema field. Lists get a fresh copy per instance."""
    spec = Spec(description, low, high, dynamic, check, rule, from_robot)
    if isinstance(default, list):
        return field(default_factory=lambda: list(default), metadata={'spec': spec})
    return field(default=default, metadata={'spec': spec})


def autostart_param():
    """The ``autostart`` field every managed node's schema has (see nodes.managed)."""
    return param(True, 'configure and activate at start-up; false: wait for lifecycle '
                       'transitions (mixture-ip lifecycle NODE configure ...)')


def observation_topic_param():
    """The observer's cleaned wrist stream, which the estimator reads (one default for both)."""
    return param('/observer/wrist', 'geometry_msgs/PointStamped, reliable')


def event_topic_param():
    """The observer's movement events, which the estimator reads (one default for both)."""
    return param('/observer/event', 'std_msgs/Header, frame_id onset | end | gap')


# -- rules a range cannot express ---------------------------------------------------------
def positive(value) -> Optional[str]:
    return None if value > 0 else 'must be > 0'


def finite_list(length: Optional[int] = None, positive_values: bool = False):
    def check(values) -> Optional[str]:
        if length is not None and len(values) != length:
            return f'must have {length} values, got {len(values)}'
        if not all(math.isfinite(v) for v in values):
            return 'must be finite numbers'
        if positive_values and not all(v > 0 for v in values):
            return 'must be positive numbers'
        return None
    return check


def _default(f):
    return f.default_factory() if f.default is MISSING else f.default


def specs(schema):
    """(name, default, Spec) of every field of a schema dataclass."""
    return [(f.name, _default(f), f.metadata['spec']) for f in fields(schema)]


def _type_ok(default, value) -> bool:
    if isinstance(default, bool):
        return isinstance(value, bool)
    if isinstance(default, float):
        return isinstance(value, float)
    if isinstance(default, int):
        return isinstance(value, int) and not isinstance(value, bool)
    if isinstance(default, str):
        return isinstance(value, str)
    if isinstance(default, list):
        if not isinstance(value, (list, tuple)):
            return False
        if default:
            return all(_type_ok(default[0], v) for v in value)
        return all(isinstance(v, str) for v in value)
    return False


def problem(name: str, default, spec: Spec, value) -> Optional[str]:
    """Why ``value`` is not acceptable for the parameter, or None."""
    if not _type_ok(default, value):
        kind = type(default).__name__ + (f' of {type(default[0]).__name__}'
                                         if isinstance(default, list) and default else '')
        return f'parameter {name}: expected {kind}, got {value!r}'
    if isinstance(value, float) and not math.isfinite(value):
        return f'parameter {name}: must be a finite number, got {value}'
    if spec.low is not None and not value >= spec.low:
        return f'parameter {name}: must be >= {spec.low}, got {value}'
    if spec.high is not None and not value <= spec.high:
        return f'parameter {name}: must be <= {spec.high}, got {value}'
    if spec.check is not None:
        why = spec.check(value)
        if why:
            return f'parameter {name}: {why}, got {value!r}'
    return None


def descriptor(name: str, default, spec: Spec):
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
    text = spec.description + (f' ({spec.rule})' if spec.rule else '')
    d = ParameterDescriptor(name=name, description=text, read_only=not spec.dynamic)
    if spec.low is not None or spec.high is not None:
        if isinstance(default, float):
            d.floating_point_range = [FloatingPointRange(
                from_value=float(-math.inf if spec.low is None else spec.low),
                to_value=float(math.inf if spec.high is None else spec.high), step=0.0)]
        elif isinstance(default, int) and not isinstance(default, bool):
            d.integer_range = [IntegerRange(
                from_value=int(-_INT_MAX if spec.low is None else spec.low),
                to_value=int(_INT_MAX if spec.high is None else spec.high), step=1)]
    return d


def declare(node, schema, on_change: Callable[[dict], None] = None,
            robot_defaults: Callable[[str], dict] = None):
    """Declare every parameter of ``schema`` on ``node`` and return the values as a ``schema``
    instance. Every value is validated (ValueError naming the parameter at start-up, a refused
    ``set`` later). ``on_change(changes)`` applies accepted run-time changes ({name: value} of
    dynamic parameters) and may raise ValueError to refuse them. ``robot_defaults(robot)``
    gives the defaults of the ``from_robot`` fields once ``robot`` is declared. Parameters
    given to the node but not in the schema are warned about (a typo would otherwise be
    ignored)."""
    from rcl_interfaces.msg import SetParametersResult
    from rclpy.exceptions import InvalidParameterValueException
    from rclpy.parameter import Parameter

    table = {name: (default, spec) for name, default, spec in specs(schema)}
    starting = [True]
    refused = [None]     # the reason of the last refusal, for a one-line error at start-up

    def validate(parameters):
        changes = {}
        for p in parameters:
            if p.name not in table:
                continue
            default, spec = table[p.name]
            if default == [] and p.value is None:     # an empty list: declared without value
                continue
            why = problem(p.name, default, spec, p.value)
            if why:
                refused[0] = why
                return SetParametersResult(successful=False, reason=why)
            changes[p.name] = list(p.value) if isinstance(default, list) else p.value
        if not starting[0] and on_change is not None and changes:
            try:
                on_change(changes)
            except ValueError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(validate)
    values = {}
    derived = {}
    for name, (default, spec) in table.items():
        if spec.from_robot:
            default = derived.get(name, default)
        # An empty list carries no element type: such parameters are lists of strings.
        initial = Parameter.Type.STRING_ARRAY if default == [] else default
        try:
            values[name] = node.declare_parameter(name, initial,
                                                  descriptor(name, default, spec)).value
        except InvalidParameterValueException as exc:
            reason = refused[0] if refused[0] and refused[0].startswith(f'parameter {name}:') \
                else f'parameter {name}: {exc}'
            raise ValueError(reason) from None
        except Exception as exc:   # a wrongly typed override: rclpy raises its own types
            raise ValueError(f'parameter {name}: {exc}') from None
        if isinstance(default, list):
            values[name] = list(values[name] or [])
        if name == 'robot' and robot_defaults is not None:
            try:
                derived = robot_defaults(values[name])
            except (ValueError, OSError) as exc:
                raise ValueError(f'parameter robot: {exc}') from None
    starting[0] = False
    unknown = sorted(set(node._parameter_overrides) - set(table) - set(BUILTIN))
    unknown = [n for n in unknown if not n.startswith('qos_overrides.')]
    if unknown:
        node.get_logger().warning(f'unknown parameters ignored: {", ".join(unknown)} '
                                  f'(known: {", ".join(table)})')
    return schema(**values)


def check_params_file(schema, values: dict) -> list:
    """Problems of a params file's ``ros__parameters`` against the schema (unknown names,
    missing ones, wrong values)."""
    table = {name: (default, spec) for name, default, spec in specs(schema)}
    out = [f'unknown parameter {n}' for n in sorted(set(values) - set(table) - set(BUILTIN))]
    out += [f'parameter {n} missing' for n, (_, spec) in table.items()
            if n not in values and not spec.from_robot]
    for name, value in values.items():
        if name in table:
            why = problem(name, *table[name], value)
            if why:
                out.append(why)
    return out


def markdown_table(schema) -> str:
    """The README table of a schema: name, default, range/rule, run time, description."""
    rows = ['| parameter | default | allowed | run time | description |',
            '|---|---|---|---|---|']
    for name, default, spec in specs(schema):
        allowed = []
        if spec.low is not None or spec.high is not None:
            lo = '' if spec.low is None else f'{spec.low} <= '
            hi = '' if spec.high is None else f' <= {spec.high}'
            allowed.append(f'{lo}x{hi}')
        if spec.rule:
            allowed.append(spec.rule)
        shown = repr(default) if isinstance(default, str) else str(default).replace(
            'True', 'true').replace('False', 'false')
        shown = "the robot's" if spec.from_robot else f'`{shown}`'
        cells = [f'`{name}`', shown, '; '.join(allowed), 'yes' if spec.dynamic else '',
                 spec.description]
        rows.append('| ' + ' | '.join(c.replace('|', '\\|') for c in cells) + ' |')
    return '\n'.join(rows)
