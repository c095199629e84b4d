"""Searching model parameters for an objective with scipy.optimize.differential_evolution.

A :class:`Problem` is a picklable callable (parameter vector -> score to minimise), so the population of
each generation is evaluated by a runner's map (local processes or a Dask cluster) through
differential_evolution's ``workers`` argument. Distance per stroke is piecewise smooth at best (it jumps
where the part starts sliding or takes off), hence a derivative-free global method, with no gradient
polish at the end.

Objectives (all minimised internally; reported in their own terms):

* ``max-distance``: the largest distance per stroke, in a ``direction`` (``negative``: toward the bump
  centre, ``positive``, or ``any``: largest magnitude);
* ``target``: distance per stroke within ``tolerance`` of ``target`` with the smallest stroke amplitude;
* a user's function ``module:function`` or ``path/file.py:function``: called with the run's row (the
  sweep columns plus the searched parameters), returns the number to minimise.

Constraints (a run that breaks one scores worse than any that keeps them all, by how much it breaks
them): ``never-flies`` (no take-off), ``settled`` (the part at rest at the end; implied for distance
objectives, a part in flight has no distance yet), ``within-travel`` (the stroke stays inside
[piezo.stroke_min, piezo.stroke_max] at every instant).
"""

from __future__ import annotations

import importlib
import importlib.util
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from ..physics.dynamics import FeederModel
from .evaluate import Job, evaluate, model_for
from .runners import Runner

OBJECTIVES = ('max-distance', 'target')
DIRECTIONS = ('negative', 'positive', 'any')
CONSTRAINTS = ('never-flies', 'settled', 'within-travel')
INFEASIBLE = 1e12          # added to the score of a run that breaks a constraint (scores are O(1e3) at most)
SAMPLES_PER_STROKE = 256   # stroke samples per period for the travel check


class OptimizeError(ValueError):
    """The problem is ill-posed (unknown objective, empty bounds ...); says why."""


@lru_cache(maxsize=8)
def load_function(spec: str) -> Callable[[Mapping[str, Any]], float]:
    """``module:function`` or ``path/to/file.py:function`` -> the function."""
    where, sep, name = spec.rpartition(':')
    if not sep or not where or not name:
        raise OptimizeError(f'objective {spec!r}: expected module:function or file.py:function')
    try:
        if where.endswith('.py'):
            loader = importlib.util.spec_from_file_location(Path(where).stem, where)
            if loader is None or loader.loader is None:
                raise ImportError(f'cannot load {where}')
            module = importlib.util.module_from_spec(loader)
            loader.loader.exec_module(module)
        else:
            module = importlib.import_module(where)
        return getattr(module, name)
    except (ImportError, OSError, AttributeError) as err:
        raise OptimizeError(f'objective {spec!r}: {err}') from err


def stroke_range(model: FeederModel) -> tuple[float, float]:
    """Lowest and highest stroke (m) over the burst, sampled ``SAMPLES_PER_STROKE`` times per period."""
    table = model.waveform()
    end = table.end_time()
    n = int(min(200_000, max(2, SAMPLES_PER_STROKE * end * model.stroke.frequency)))
    strokes = np.array([table.evaluate(t)[0] for t in np.linspace(0.0, end, n)])
    return float(strokes.min()), float(strokes.max())


@dataclass(frozen=True)
class Problem:
    """Parameters ``names`` of ``job``'s model searched within ``bounds`` for ``objective``."""

    job: Job
    names: tuple[str, ...]
    bounds: tuple[tuple[float, float], ...]
    objective: str = 'max-distance'
    direction: str = 'negative'
    target: float = 0.0
    tolerance: float = 0.0
    constraints: tuple[str, ...] = ()
    integers: tuple[bool, ...] = field(default=())

    def __post_init__(self) -> None:
        if self.objective not in OBJECTIVES and ':' not in self.objective:
            raise OptimizeError(f'objective {self.objective!r}: one of {", ".join(OBJECTIVES)} or module:function')
        if self.direction not in DIRECTIONS:
            raise OptimizeError(f'direction {self.direction!r}: one of {", ".join(DIRECTIONS)}')
        unknown = sorted(set(self.constraints) - set(CONSTRAINTS))
        if unknown:
            raise OptimizeError(f'constraint {unknown[0]!r}: one of {", ".join(CONSTRAINTS)}')
        if self.objective == 'target' and not self.tolerance > 0:
            raise OptimizeError('a target distance needs a tolerance > 0 (m per stroke)')
        if ':' in self.objective:
            load_function(self.objective)          # refuse a wrong name before any run

    def changes(self, x: Sequence[float]) -> dict[str, float]:
        integers = self.integers or (False,) * len(self.names)
        return {name: float(round(v)) if whole else float(v)
                for name, v, whole in zip(self.names, x, integers, strict=True)}

    def evaluate(self, x: Sequence[float]) -> tuple[float, dict[str, Any]]:
        """(score, row): the row of the run at ``x`` with its ``score`` and ``violation`` columns."""
        changes = self.changes(x)
        row = {**changes, **evaluate(self.job, changes)}
        violation = self._violation(row, changes)
        if violation > 0:
            score = INFEASIBLE * (1.0 + violation)
        else:
            score = self._score(row, changes)
            if not math.isfinite(score):
                violation, score = 1.0, INFEASIBLE * 2.0
        row.update(score=score, violation=violation)
        return score, row

    def __call__(self, x: Sequence[float]) -> float:
        return self.evaluate(x)[0]

    def _violation(self, row: Mapping[str, Any], changes: Mapping[str, float]) -> float:
        """0 when every constraint holds; else a positive measure of how badly they break."""
        if row['error']:
            return 1e4
        v = 0.0
        if 'never-flies' in self.constraints:
            v += row['take_off']
        if ('settled' in self.constraints or self.objective in OBJECTIVES) and not row['settled']:
            v += 1e3                           # no distance at all: worse than any distance off target
        if self.objective == 'target' and row['settled']:
            v += max(0.0, abs(row['distance_per_stroke_m'] - self.target) / self.tolerance - 1.0)
        if 'within-travel' in self.constraints:
            model = model_for(self.job, changes)
            low, high = stroke_range(model)
            over = max(0.0, high - model.piezo.stroke_max) + max(0.0, model.piezo.stroke_min - low)
            v += over / max(model.piezo.stroke_max - model.piezo.stroke_min, 1e-12)
        return v

    def _score(self, row: Mapping[str, Any], changes: Mapping[str, float]) -> float:
        """The number minimised: −distance (µm per stroke) in the chosen direction, the amplitude (µm)
        for a target, or the user's function."""
        if self.objective == 'max-distance':
            d = row['distance_per_stroke_m'] * 1e6
            return {'negative': d, 'positive': -d, 'any': -abs(d)}[self.direction]
        if self.objective == 'target':
            return model_for(self.job, changes).stroke.amplitude * 1e6
        return float(load_function(self.objective)(dict(row)))


@dataclass
class OptimizeResult:
    """The optimum found, its run, the evaluations used, the history of the best score and the
    optimizer's own message (``converged`` False when it stopped on its iteration limit)."""

    optimum: dict[str, float]
    row: dict[str, Any]
    score: float
    feasible: bool
    evaluations: int
    generations: int
    converged: bool
    message: str
    history: list[tuple[int, float]]       # (evaluations so far, best score) per generation

    def as_dict(self) -> dict[str, Any]:
        clean = {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in self.row.items()}
        return {'optimum': self.optimum, 'score': self.score, 'feasible': self.feasible, 'run': clean,
                'evaluations': self.evaluations, 'generations': self.generations, 'converged': self.converged,
                'message': self.message, 'history': self.history}


def optimize(problem: Problem, runner: Runner, seed: int = 0, max_generations: int = 30, popsize: int = 10,
             tol: float = 1e-3, progress: Callable[[int, float], None] | None = None) -> OptimizeResult:
    """Differential evolution over the problem's bounds, each generation evaluated by ``runner``."""
    from scipy.optimize import differential_evolution

    history: list[tuple[int, float]] = []

    def callback(intermediate_result: Any) -> None:
        history.append((int(intermediate_result.nfev), float(intermediate_result.fun)))
        if progress is not None:
            progress(*history[-1])

    result = differential_evolution(             # 'deferred': one batch per generation, the same on any runner
        problem, list(problem.bounds), seed=seed, maxiter=max_generations, popsize=popsize, tol=tol, polish=False,
        init='latinhypercube', updating='deferred', workers=runner.as_map(), callback=callback,
        integrality=list(problem.integers) if problem.integers else None)
    score, row = problem.evaluate(result.x)
    return OptimizeResult(problem.changes(result.x), row, score, row['violation'] == 0, int(result.nfev),
                          int(result.nit), bool(result.success), str(result.message), history)
