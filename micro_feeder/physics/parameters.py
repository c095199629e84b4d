"""Validated, immutable parameter groups addressed by dotted names (``contact.sigma``).

Every model input lives in a frozen dataclass whose fields carry a :class:`ParamSpec` (description,
unit, allowed range or choices). The same spec validates values on construction, documents the
parameter (``docs/parameters.md``) and, in the nodes, becomes a ROS ``ParameterDescriptor``: one
source of truth for the namespace shared by ``config/feeder.yaml``, ``--set`` and ROS parameters.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar, TypeVar

G = TypeVar('G', bound='ParameterGroup')


class ParameterError(ValueError):
    """A parameter value that is not allowed; the message names the parameter, value and rule."""

    def __init__(self, name: str, value: Any, allowed: str):
        self.name = name
        self.value = value
        self.allowed = allowed
        super().__init__(f'{name} = {value!r} is not allowed: {allowed}')


@dataclass(frozen=True)
class ParamSpec:
    """What a parameter means and which values it accepts.

    ``kind`` is ``float``, ``int``, ``bool``, ``str``, ``float_list`` or ``float_or_list`` (a number, kept as a
    float, or a list of numbers, kept as a tuple: one value per part). Bounds apply to every element of a
    list. ``name`` overrides the dotted name (for top-level names such as ``gravity``).
    """

    description: str
    unit: str = ''
    kind: str = 'float'
    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    le: float | None = None
    choices: tuple[str, ...] | None = None
    min_length: int = 0
    name: str | None = None
    read_only: bool = False

    def allowed(self) -> str:
        """Human description of the allowed values, e.g. ``a finite number > 0``."""
        if self.choices is not None:
            return 'one of ' + ', '.join(repr(c) for c in self.choices)
        if self.kind == 'bool':
            return 'true or false'
        if self.kind == 'str':
            return 'a string'
        bounds = [f'{op} {value:g}' for op, value in
                  (('>', self.gt), ('>=', self.ge), ('<', self.lt), ('<=', self.le)) if value is not None]
        noun = 'an integer' if self.kind == 'int' else 'a finite number'
        text = noun + (' ' + ' and '.join(bounds) if bounds else '')
        if self.kind == 'float_list':
            text = f'a list of at least {self.min_length} numbers, each {text}'
        if self.kind == 'float_or_list':
            text = f'{text}, or a non-empty list of such numbers'
        return text

    def check(self, name: str, value: Any) -> Any:
        """Return ``value`` converted to the parameter's type, or raise :class:`ParameterError`."""
        if self.kind == 'float_or_list' and isinstance(value, Sequence) and not isinstance(value, (str, bytes)):
            if not value:
                raise ParameterError(name, value, self.allowed())
            return tuple(self._check_number(name, v, value) for v in value)
        if self.kind == 'float_list':
            if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
                raise ParameterError(name, value, self.allowed())
            if len(value) < self.min_length:
                raise ParameterError(name, value, self.allowed())
            return tuple(self._check_number(name, v, value) for v in value)
        if self.kind == 'bool':
            if not isinstance(value, bool):
                raise ParameterError(name, value, self.allowed())
            return value
        if self.kind == 'str' or self.choices is not None:
            if not isinstance(value, str) or (self.choices is not None and value not in self.choices):
                raise ParameterError(name, value, self.allowed())
            return value
        return self._check_number(name, value, value)

    def _check_number(self, name: str, element: Any, whole: Any) -> float | int:
        if isinstance(element, bool) or not isinstance(element, (int, float)):
            raise ParameterError(name, whole, self.allowed())
        if self.kind == 'int':
            if isinstance(element, float) and not element.is_integer():
                raise ParameterError(name, whole, self.allowed())
            number: float | int = int(element)
        else:
            number = float(element)
            if not math.isfinite(number):
                raise ParameterError(name, whole, self.allowed())
        if ((self.gt is not None and not number > self.gt) or (self.ge is not None and not number >= self.ge)
                or (self.lt is not None and not number < self.lt)
                or (self.le is not None and not number <= self.le)):
            raise ParameterError(name, whole, self.allowed())
        return number


def param(default: Any, description: str, unit: str = '', **rules: Any) -> Any:
    """A dataclass field with its :class:`ParamSpec` (``kind`` is inferred from the default)."""
    if 'kind' not in rules:
        if isinstance(default, bool):
            rules['kind'] = 'bool'
        elif isinstance(default, int):
            rules['kind'] = 'int'
        elif isinstance(default, str):
            rules['kind'] = 'str'
        elif isinstance(default, tuple):
            rules['kind'] = 'float_list'
        else:
            rules['kind'] = 'float'
    spec = ParamSpec(description=description, unit=unit, **rules)
    return field(default=default, metadata={'spec': spec})


@dataclass(frozen=True)
class ParameterGroup:
    """Base of the parameter groups: validates every field on construction.

    Subclasses set ``prefix`` (``contact``) and declare fields with :func:`param`.
    """

    prefix: ClassVar[str] = ''

    def __post_init__(self) -> None:
        for f, name, spec in self.specs():
            object.__setattr__(self, f.name, spec.check(name, getattr(self, f.name)))

    @classmethod
    def specs(cls) -> list[tuple[dataclasses.Field, str, ParamSpec]]:
        """(field, dotted name, spec) for every parameter of the group, in declaration order."""
        out = []
        for f in dataclasses.fields(cls):
            spec = f.metadata.get('spec')
            if spec is not None:
                out.append((f, spec.name or f'{cls.prefix}.{f.name}', spec))
        return out

    @classmethod
    def from_flat(cls: type[G], values: Mapping[str, Any]) -> G:
        """Build from a flat ``{dotted name: value}`` mapping; missing names take their defaults."""
        kwargs = {f.name: values[name] for f, name, _ in cls.specs() if name in values}
        return cls(**kwargs)

    def to_flat(self) -> dict[str, Any]:
        """The group as ``{dotted name: value}`` (lists as Python lists)."""
        return {name: list(v) if isinstance(v := getattr(self, f.name), tuple) else v
                for f, name, _ in self.specs()}

    def replace(self: G, **changes: Any) -> G:
        """A copy with some fields changed (validated like any construction)."""
        return dataclasses.replace(self, **changes)


def all_specs(groups: Sequence[type[ParameterGroup]]) -> dict[str, tuple[ParamSpec, Any]]:
    """``{dotted name: (spec, default)}`` over several groups (for docs, CLI checks, ROS descriptors)."""
    table: dict[str, tuple[ParamSpec, Any]] = {}
    for group in groups:
        for f, name, spec in group.specs():
            table[name] = (spec, f.default)
    return table
