"""The simulator's parameters as a log records them: ``simulator/parameters`` (``rcl_interfaces/ParameterEvent``,
latched; the parameters in force at start, after each reset and after a change that applies at once).

Read by ``resim`` (to rebuild the simulation) and ``info`` (to say how the run was driven). No rclpy.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from .reader import LogReader

TOPIC = 'simulator/parameters'

# rcl_interfaces/ParameterValue: type code -> field holding the value.
_VALUE_FIELDS = {1: 'bool_value', 2: 'integer_value', 3: 'double_value', 4: 'string_value',
                 5: 'byte_array_value', 6: 'bool_array_value', 7: 'integer_array_value',
                 8: 'double_array_value', 9: 'string_array_value'}


def parameter_value(value: Any) -> Any:
    """A decoded ``rcl_interfaces/ParameterValue`` as a Python value (arrays as lists). Raises ValueError
    for an unknown type code."""
    name = _VALUE_FIELDS.get(value.type)
    if name is None:
        raise ValueError(f'parameter value of unknown type {value.type}')
    v = getattr(value, name)
    return list(v) if isinstance(v, (list, tuple, bytes)) or hasattr(v, 'tolist') else v


def recorded_parameters(log: LogReader) -> list[dict[str, Any]]:
    """Every ``simulator/parameters`` snapshot of the log, in log order, as ``{name: value}``."""
    return [{p.name: parameter_value(p.value) for p in m.message.new_parameters}
            for m in log.messages([TOPIC], decoded=True)]


def run_mode(params: Mapping[str, Any] | None) -> str:
    """How the simulator was driven: 'lockstep' (one step per simulator/step call and per command),
    'stepped' (start_paused, simulator/step), 'as fast as possible' (real_time_factor 0), 'real time'
    (any other factor), or 'unknown' without parameters."""
    if params is None:
        return 'unknown'
    if params.get('lockstep'):
        return 'lockstep'
    if params.get('start_paused'):
        return 'stepped'
    return 'as fast as possible' if params.get('real_time_factor') == 0 else 'real time'
