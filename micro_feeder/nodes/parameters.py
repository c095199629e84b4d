"""ROS parameters from :class:`~micro_feeder.physics.parameters.ParamSpec`: one source of truth for every node.

Each node declares a table ``{name: (ParamSpec, default)}``: the model parameters of the physics groups
(``contact.sigma``, ``stroke.frequency`` ... the namespace of ``config/feeder.yaml`` and ``--set``) plus the
node's own settings, described with the same :class:`ParamSpec`. :func:`declare` turns each entry into a
``ParameterDescriptor`` (type, description with unit and rule, range, read-only) and declares it; the
node's on-set callback refuses a value with :func:`check_changes`, which applies the exact rule of the spec
(strict bounds, choices, list lengths) and the cross-parameter checks of the groups, with a reason.
"""

from __future__ import annotations

import difflib
import sys
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType
from rclpy.node import Node
from rclpy.parameter import Parameter

from ..physics.parameters import ParameterError, ParameterGroup, ParamSpec
from ..settings import MODEL_GROUPS, known_parameters, validate_model

SpecTable = Mapping[str, tuple[ParamSpec, Any]]

_ROS_TYPES = {'float': ParameterType.PARAMETER_DOUBLE, 'int': ParameterType.PARAMETER_INTEGER,
              'bool': ParameterType.PARAMETER_BOOL, 'str': ParameterType.PARAMETER_STRING,
              'float_list': ParameterType.PARAMETER_DOUBLE_ARRAY,
              'float_or_list': ParameterType.PARAMETER_DOUBLE}     # dynamically typed: a double or an array
_INT64 = 2 ** 63 - 1


def descriptor(name: str, spec: ParamSpec) -> ParameterDescriptor:
    """The ROS descriptor of one parameter: type, ``description [unit]``, the rule, range and read-only.

    ROS ranges are inclusive; a strict bound (``> 0``) is given as its closed range here and enforced
    exactly by :func:`check_changes`. One-sided bounds use the largest finite value as the open end.
    """
    desc = ParameterDescriptor(name=name, type=_ROS_TYPES[spec.kind], read_only=spec.read_only,
                               dynamic_typing=spec.kind == 'float_or_list',
                               description=spec.description + (f' [{spec.unit}]' if spec.unit else ''),
                               additional_constraints=spec.allowed())
    low = spec.ge if spec.ge is not None else spec.gt
    high = spec.le if spec.le is not None else spec.lt
    if low is None and high is None:
        return desc
    if spec.kind == 'int':
        desc.integer_range = [IntegerRange(from_value=int(low) if low is not None else -_INT64,
                                           to_value=int(high) if high is not None else _INT64, step=0)]
    elif spec.kind == 'float':
        big = sys.float_info.max
        desc.floating_point_range = [FloatingPointRange(from_value=float(low) if low is not None else -big,
                                                        to_value=float(high) if high is not None else big,
                                                        step=0.0)]
    return desc


def _ros_value(spec: ParamSpec, value: Any) -> Any:
    """A value as ROS expects it for the spec's type (ints in a float list or a float parameter -> float),
    so that ``frequency: 1000`` in a YAML file is not a type error."""
    if spec.kind in ('float', 'float_or_list') and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if spec.kind in ('float_list', 'float_or_list') and isinstance(value, (list, tuple)):
        return [float(v) if isinstance(v, int) and not isinstance(v, bool) else v for v in value]
    return value


def declare(node: Node, table: SpecTable, overrides: Mapping[str, Any] | None = None) -> None:
    """Declare every parameter of ``table`` on ``node`` with its descriptor.

    The value comes from, in order: ``overrides`` (e.g. ``micro-feeder run --set``), the node's ROS
    overrides (``--ros-args -p`` / ``--params-file``), the spec default. Integer values given for float
    parameters are converted first. Raises :class:`ParameterError` for a value the spec refuses.
    """
    ros_overrides = node._parameter_overrides   # rclpy keeps --ros-args values here; typed on declare
    refuse_unknown({name: p.value for name, p in ros_overrides.items()}, table)
    for name, (spec, default) in table.items():
        if overrides is not None and name in overrides:
            value = overrides[name]
        elif name in ros_overrides:
            value = ros_overrides[name].value
        else:
            value = default
        value = _ros_value(spec, value)
        checked = spec.check(name, value)
        value = list(checked) if isinstance(checked, tuple) else checked
        node.declare_parameter(name, value, descriptor(name, spec), ignore_override=True)


def refuse_unknown(given: Mapping[str, Any], table: SpecTable) -> None:
    """Raise :class:`ParameterError` for a name in a model or controller namespace (``contact.``,
    ``feed.`` ...) that no micro_feeder node knows, e.g. the typo ``contact.sigmaa``, with the closest
    known names; as ``--set`` does. Other names may belong to other nodes of a shared file and are left."""
    known = {*known_parameters(), *table}
    namespaces = {name.split('.')[0] for name in known if '.' in name}
    for name, value in given.items():
        if name not in known and name.split('.')[0] in namespaces and '.' in name:
            close = difflib.get_close_matches(name, known, n=3)
            raise ParameterError(name, value, 'unknown parameter' + (
                f'; did you mean {", ".join(close)}?' if close else '; see docs/parameters.md'))


def values(node: Node, names: Iterable[str]) -> dict[str, Any]:
    """Current values ``{name: value}`` (arrays as lists)."""
    out = {}
    for name in names:
        value = node.get_parameter(name).value
        out[name] = list(value) if isinstance(value, (list, tuple)) or hasattr(value, 'tolist') else value
    return out


def check_changes(table: SpecTable, current: Mapping[str, Any], changes: Sequence[Parameter],
                  groups: Sequence[type[ParameterGroup]] = MODEL_GROUPS) -> str | None:
    """Why a set of parameter changes must be refused, or ``None`` when it is acceptable.

    Each value is checked against its spec; then the model groups are rebuilt with all the changes at
    once (set related parameters such as ``surface.centers`` and ``surface.widths`` in one atomic call).
    """
    candidate = dict(current)
    for change in changes:
        entry = table.get(change.name)
        if entry is None:
            continue
        try:
            candidate[change.name] = entry[0].check(change.name, _ros_value(entry[0], _plain(change.value)))
        except ParameterError as err:
            return str(err)
    try:
        validate_model(candidate, groups)
    except ParameterError as err:
        return str(err)
    return None


def _plain(value: Any) -> Any:
    return value.tolist() if hasattr(value, 'tolist') else value
