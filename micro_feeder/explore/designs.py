"""Which runs a sweep makes: full grids, sampled designs and Monte Carlo perturbations.

A :class:`Design` is a numbered list of *points* (one value per varied parameter) that is never
materialised for a grid: the i-th point is computed from i, so a grid of 10^8 points costs no memory
(and is refused by the run-count check, not by the machine running out of it). A Monte Carlo repeats
each point ``replicates`` times with the uncertain parameters drawn from a generator seeded by
(seed, run number): a run's draw does not depend on which worker computes it, or in which order.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..settings import SettingsError, known_parameters

DESIGNS = ('lhs', 'random')
DISTRIBUTIONS = ('normal', 'uniform', 'lognormal')


def _numeric(name: str, option: str) -> str:
    """``name`` if it is a scalar numeric model parameter (or one that takes a number or a list, such as
    ``particle.x0``: it is varied as one number, one part), else a SettingsError saying what is accepted."""
    known = known_parameters()
    if name not in known:
        raise SettingsError(f'{option} {name!r}: not a parameter name (see docs/parameters.md)')
    kind = known[name][0].kind
    if kind not in ('float', 'int', 'float_or_list'):
        raise SettingsError(f'{option} {name}: only scalar numeric parameters can be varied ({kind})')
    return name


def is_integer(name: str) -> bool:
    return known_parameters()[name][0].kind == 'int'


@dataclass(frozen=True)
class Axis:
    """One varied parameter's values: ``count`` evenly spaced from ``start`` to ``stop`` (as
    numpy.linspace computes them), or an explicit list."""

    name: str
    start: float = 0.0
    stop: float = 0.0
    count: int = 0
    listed: tuple[float, ...] | None = None

    def __len__(self) -> int:
        return len(self.listed) if self.listed is not None else self.count

    def value(self, i: int) -> float:
        if self.listed is not None:
            value = self.listed[i]
        elif i == self.count - 1:
            value = self.stop
        else:
            value = self.start + i * ((self.stop - self.start) / max(self.count - 1, 1))
        return float(round(value)) if is_integer(self.name) else value

    def values(self) -> np.ndarray:
        return np.array([self.value(i) for i in range(len(self))])


def parse_axis(text: str) -> Axis:
    """``NAME=START:STOP:N`` (N values) or ``NAME=V1,V2,...``; no value list is built for a range."""
    name, sep, spec = text.partition('=')
    if not sep:
        raise SettingsError(f'--vary expects NAME=START:STOP:N or NAME=V1,V2,..., got {text!r}')
    name = _numeric(name.strip(), '--vary')
    try:
        if ':' in spec:
            start, stop, count = spec.split(':')
            axis = Axis(name, float(start), float(stop), int(count))
        else:
            axis = Axis(name, listed=tuple(float(v) for v in spec.split(',') if v.strip()))
    except ValueError as err:
        raise SettingsError(f'--vary {text!r}: expected NAME=START:STOP:N or NAME=V1,V2,... ({err})') from err
    if len(axis) < 1 or not all(math.isfinite(v) for v in (axis.start, axis.stop, *(axis.listed or ()))):
        raise SettingsError(f'--vary {text!r}: needs at least one finite value')
    return axis


def parse_range(text: str, option: str = '--vary') -> tuple[str, float, float]:
    """``NAME=LOW:HIGH`` (a range to sample, or an optimisation bound) -> (name, low, high)."""
    name, sep, spec = text.partition('=')
    parts = spec.split(':')
    try:
        low, high = (float(p) for p in parts) if sep and len(parts) == 2 else (math.nan, math.nan)
    except ValueError:
        low = high = math.nan
    if not low < high:
        raise SettingsError(f'{option} {text!r}: expected NAME=LOW:HIGH with LOW < HIGH')
    return _numeric(name.strip(), option), low, high


class Design:
    """Numbered points; ``names`` are the varied parameters (columns of the table)."""

    names: tuple[str, ...]

    def __len__(self) -> int:
        raise NotImplementedError

    def point(self, i: int) -> tuple[float, ...]:
        raise NotImplementedError

    @property
    def kind(self) -> str:
        raise NotImplementedError


class Grid(Design):
    """The full product of the axes (the last one varies fastest); one point (no axis) is a plain run."""

    def __init__(self, axes: Sequence[Axis]):
        names = [a.name for a in axes]
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise SettingsError(f'--vary {duplicates[0]} given twice: vary each parameter once')
        self.axes = tuple(axes)
        self.names = tuple(names)
        self.shape = tuple(len(a) for a in axes)

    def __len__(self) -> int:
        return math.prod(self.shape)

    def point(self, i: int) -> tuple[float, ...]:
        index = np.unravel_index(i, self.shape) if self.shape else ()
        return tuple(a.value(int(j)) for a, j in zip(self.axes, index, strict=True))

    @property
    def kind(self) -> str:
        return 'grid'


class Sampled(Design):
    """``n`` points drawn in the box of ``ranges``: a scrambled Latin hypercube (scipy.stats.qmc,
    each parameter's range cut into n strata, one point per stratum) or independent uniform draws;
    the same seed gives the same points."""

    def __init__(self, ranges: Sequence[tuple[str, float, float]], n: int, seed: int, method: str = 'lhs'):
        if method not in DESIGNS:
            raise SettingsError(f'--design {method!r}: one of {", ".join(DESIGNS)}')
        if n < 1:
            raise SettingsError(f'--samples {n}: at least 1')
        self.names = tuple(name for name, _, _ in ranges)
        low = np.array([lo for _, lo, _ in ranges])
        high = np.array([hi for _, _, hi in ranges])
        if method == 'lhs':
            from scipy.stats import qmc
            unit = qmc.LatinHypercube(d=len(ranges), seed=np.random.default_rng(seed)).random(n)
        else:
            unit = np.random.default_rng(seed).random((n, len(ranges)))
        self.points = low + unit * (high - low)
        for j, name in enumerate(self.names):
            if is_integer(name):
                self.points[:, j] = np.round(self.points[:, j])
        self.method = method

    def __len__(self) -> int:
        return len(self.points)

    def point(self, i: int) -> tuple[float, ...]:
        return tuple(self.points[i].tolist())

    @property
    def kind(self) -> str:
        return self.method


@dataclass(frozen=True)
class Perturbation:
    """An uncertain parameter: around the point's value (or the base value when it is not varied),
    ``normal`` adds N(0, spread²), ``uniform`` adds U(−spread, +spread), ``lognormal`` multiplies by
    exp(N(0, spread²)) (median unchanged); ``relative`` spreads are fractions of the value."""

    name: str
    distribution: str
    spread: float
    relative: bool = False

    def draw(self, rng: np.random.Generator, value: float) -> float:
        scale = self.spread * abs(value) if self.relative else self.spread
        if self.distribution == 'normal':
            return value + scale * rng.standard_normal()
        if self.distribution == 'uniform':
            return value + scale * (2.0 * rng.random() - 1.0)
        return value * math.exp(self.spread * rng.standard_normal())


def parse_perturbation(text: str) -> Perturbation:
    """``NAME=normal:SD``, ``NAME=uniform:HALF_WIDTH``, ``NAME=lognormal:SIGMA``; SD and HALF_WIDTH in the
    parameter's unit or, ending in %, relative to its value (``contact.beta=normal:5%``)."""
    name, sep, spec = text.partition('=')
    distribution, _, spread = spec.partition(':')
    relative = spread.strip().endswith('%')
    try:
        value = float(spread.strip().rstrip('%')) / (100.0 if relative else 1.0)
    except ValueError:
        value = math.nan
    if not sep or distribution not in DISTRIBUTIONS or not value >= 0 or not math.isfinite(value):
        raise SettingsError(f'--perturb {text!r}: expected NAME=normal:SD, NAME=uniform:HALF_WIDTH or '
                            f'NAME=lognormal:SIGMA (SD, HALF_WIDTH may end in % of the value), spread ≥ 0')
    return Perturbation(_numeric(name.strip(), '--perturb'), distribution, value,
                        relative and distribution != 'lognormal')


@dataclass(frozen=True)
class RunPlan:
    """Every run of a sweep: ``len(design) × replicates`` runs, run r = point r // replicates.

    ``base`` gives the value a perturbation starts from when its parameter is not varied.
    """

    design: Design
    perturbations: tuple[Perturbation, ...] = ()
    replicates: int = 1
    seed: int = 0

    def __len__(self) -> int:
        return len(self.design) * self.replicates

    @property
    def columns(self) -> tuple[str, ...]:
        """The parameter columns of the table: varied ones, then perturbed ones not varied."""
        extra = tuple(p.name for p in self.perturbations if p.name not in self.design.names)
        return (*self.design.names, *dict.fromkeys(extra))

    def changes(self, run: int, base: Mapping[str, float]) -> dict[str, float]:
        """The parameter values of run ``run`` (varied, then perturbed: drawn from (seed, run))."""
        values = dict(zip(self.design.names, self.design.point(run // self.replicates), strict=True))
        if self.perturbations:
            rng = np.random.default_rng([self.seed, run])
            for p in self.perturbations:
                drawn = p.draw(rng, float(values.get(p.name, base[p.name])))
                values[p.name] = float(round(drawn)) if is_integer(p.name) else drawn
        return values

    def chunks(self, size: int, base: Mapping[str, float]) -> Iterator[list[tuple[int, dict[str, float]]]]:
        """Runs in order, ``size`` at a time, computed as they are asked for."""
        for first in range(0, len(self), size):
            yield [(r, self.changes(r, base)) for r in range(first, min(first + size, len(self)))]
