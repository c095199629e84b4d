"""Reading model parameters from YAML files and ``--set NAME=VALUE`` overrides.

The result is one flat ``{dotted name: value}`` mapping in the shared namespace (``contact.sigma``,
``stroke.frequency`` ...). A file may be a ROS 2 parameters file (``/**: ros__parameters: {...}``, as
``config/feeder.yaml`` is, so the nodes read the same file) or a plain nested or flat mapping.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml

from .control.feed_planner import FeedGoal
from .physics.contact.params import ContactParams
from .physics.dynamics.params import dynamics_parameter_groups
from .physics.parameters import ParameterError, ParameterGroup, ParamSpec, all_specs
from .physics.particle import ParticleParams
from .physics.surface import SurfaceParams
from .physics.waveforms import StrokeParams, waveform_table

# The model's parameter groups: the simulator declares these as ROS parameters.
PARAMETER_GROUPS: list[type[ParameterGroup]] = [ContactParams, ParticleParams, *dynamics_parameter_groups()]
# Parameters of the example feed controller (``feed.*``): known to --set and parameters files, but not model
# parameters, so the simulator does not declare them.
CONTROLLER_GROUPS: list[type[ParameterGroup]] = [FeedGoal]


# Sections of a ROS 2 parameters file that hold model parameters, merged in this order.
ROS_SECTIONS = ('/**', 'simulator', '/simulator')


class _Yaml12FloatLoader(yaml.SafeLoader):
    """SafeLoader that also reads ``30e-9`` and ``1e9`` as floats (YAML 1.2; PyYAML's YAML 1.1 resolver
    wants a dot and would hand these over as strings)."""


_Yaml12FloatLoader.add_implicit_resolver(
    'tag:yaml.org,2002:float',
    re.compile(r'^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$'),
    list('-+0123456789'))


def _load_yaml(text: str) -> Any:
    return yaml.load(text, Loader=_Yaml12FloatLoader)


class SettingsError(ValueError):
    """A parameters file or override that cannot be read; the message says what to fix."""


def known_parameters() -> dict[str, tuple[ParamSpec, Any]]:
    """``{dotted name: (spec, default)}`` for every model parameter."""
    return all_specs([*PARAMETER_GROUPS, *CONTROLLER_GROUPS])


def flatten(tree: Mapping[str, Any], prefix: str = '') -> dict[str, Any]:
    """``{'a': {'b': 1}}`` -> ``{'a.b': 1}``; dotted keys are kept as they are."""
    flat: dict[str, Any] = {}
    for key, value in tree.items():
        name = f'{prefix}{key}'
        if isinstance(value, Mapping):
            flat.update(flatten(value, name + '.'))
        else:
            flat[name] = value
    return flat


def read_parameters_file(path: Path | str) -> dict[str, Any]:
    """The model parameters in a YAML file, flattened.

    In a ROS 2 parameters file, the ``ros__parameters`` of the ``/**`` section and of the
    ``simulator`` node are merged (in that order); node-only settings such as ``publish_rate`` that are
    not model parameters are left to the nodes.
    """
    path = Path(path)
    try:
        tree = _load_yaml(path.read_text())
    except OSError as err:
        raise SettingsError(f'cannot read parameters file {path}: {err.strerror}') from err
    except UnicodeDecodeError:
        raise SettingsError(f'parameters file {path} is not text (binary data): give a YAML parameters file '
                            'such as config/feeder.yaml') from None
    except yaml.YAMLError as err:
        raise SettingsError(f'parameters file {path} is not valid YAML: {err}') from err
    if tree is None:
        return {}
    if not isinstance(tree, Mapping):
        raise SettingsError(f'parameters file {path} must hold a mapping of names to values')
    sections = [v['ros__parameters'] for k, v in tree.items()
                if isinstance(v, Mapping) and 'ros__parameters' in v and k in ROS_SECTIONS]
    if not sections and any(isinstance(v, Mapping) and 'ros__parameters' in v for v in tree.values()):
        return {}
    flat: dict[str, Any] = {}
    for section in sections or [tree]:
        flat.update(flatten(section))
    known = known_parameters()
    return {k: v for k, v in flat.items() if k in known} if sections else flat


def parse_override(text: str) -> tuple[str, Any]:
    """``'stroke.frequency=1e3'`` -> ``('stroke.frequency', 1000.0)``; the value is read as YAML."""
    name, sep, raw = text.partition('=')
    if not sep or not name.strip():
        raise SettingsError(f'--set expects NAME=VALUE, got {text!r} (e.g. --set contact.beta=0.05)')
    try:
        value = _load_yaml(raw)
    except yaml.YAMLError as err:
        raise SettingsError(f'--set {text!r}: the value is not valid YAML: {err}') from err
    if isinstance(value, str) and value.strip().lower() in ('nan', '.nan', 'inf', '-inf'):
        value = float(value)
    return name.strip(), value


def load_settings(params_files: Iterable[Path | str] = (), overrides: Iterable[str] = ()) -> dict[str, Any]:
    """Merge parameters files (in order) and ``--set`` overrides into one checked flat mapping.

    Unknown names are refused with the closest known names; values are validated later, when the
    parameter groups are built (see :func:`build_group`).
    """
    flat: dict[str, Any] = {}
    for path in params_files:
        flat.update(read_parameters_file(path))
    for text in overrides:
        name, value = parse_override(text)
        flat[name] = value
    known = known_parameters()
    for name in flat:
        if name not in known:
            close = difflib.get_close_matches(name, known, n=3)
            hint = f'; did you mean {", ".join(close)}?' if close else '; see docs/parameters.md'
            raise SettingsError(f'unknown parameter {name!r}{hint}')
    return flat


def build_group(group: type[ParameterGroup], flat: Mapping[str, Any]) -> Any:
    """Construct one parameter group, turning a validation failure into a :class:`SettingsError`."""
    try:
        return group.from_flat(flat)
    except ParameterError as err:
        raise SettingsError(str(err)) from err


# Every model parameter group (the namespace of config/feeder.yaml and --set), as the nodes declare them.
MODEL_GROUPS: tuple[type[ParameterGroup], ...] = tuple(PARAMETER_GROUPS)


def model_specs(groups: Iterable[type[ParameterGroup]] = MODEL_GROUPS) -> dict[str, tuple[ParamSpec, Any]]:
    """``{dotted name: (spec, default)}`` of the model parameters (defaults as ROS values: lists, not tuples)."""
    return {name: (spec, list(default) if isinstance(default, tuple) else default)
            for name, (spec, default) in all_specs(list(groups)).items()}


def validate_model(flat: Mapping[str, Any], groups: Sequence[type[ParameterGroup]] = MODEL_GROUPS) -> None:
    """Check a whole flat model mapping without building the contact tables: every group, and one
    stroke phase per actuator when both groups are present. Raises :class:`ParameterError`."""
    built = {group: group.from_flat(flat) for group in groups}
    if SurfaceParams in built and StrokeParams in built:
        waveform_table(built[StrokeParams], built[SurfaceParams].n_actuators)
