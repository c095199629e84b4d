"""A run plan through a runner: rows streamed in run order, Monte Carlo summaries kept per point.

Nothing here holds the whole table: :func:`run_plan` yields rows as they arrive (the caller writes
them), and :class:`PointSummary` keeps running sums per point (mean, spread, regime fractions).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator, Mapping
from typing import Any

import numpy as np

from ..physics.parameters import ParameterError
from ..settings import known_parameters
from .designs import RunPlan
from .evaluate import REGIMES, Job, evaluate, evaluate_chunk
from .runners import Runner

MAX_RUNS = 1_000_000          # more runs than this need --force
MAX_ESTIMATE_S = 3600.0       # so does a run estimated to take longer than this


def base_values(flat: Mapping[str, Any], names: tuple[str, ...]) -> dict[str, float]:
    """The value of each named parameter in the base settings (its default when not set).

    Raises ParameterError for a parameter that is a list there (``particle.x0`` of several parts): a sweep
    varies one number."""
    known = known_parameters()
    values = {name: flat.get(name, known[name][1]) for name in names}
    for name, value in values.items():
        if isinstance(value, list | tuple):
            raise ParameterError(name, list(value), 'a list in the base settings cannot be swept: a sweep '
                                 'varies one number (vary another parameter, or set one value)')
    return {name: float(value) for name, value in values.items()}


def chunk_size(runs: int, workers: int) -> int:
    """Runs per task: about 16 tasks per worker, 1 to 200 runs each (a 5-stroke run costs ~1 ms,
    a task ~1 ms of overhead on Dask)."""
    return int(min(200, max(1, runs // (16 * workers))))


def estimate_seconds(job: Job, plan: RunPlan, workers: int) -> float:
    """Wall time estimate: the first run of the plan, timed here, × runs / workers."""
    first = plan.changes(0, base_values(job.base, plan.columns))
    evaluate(job, first)                                    # builds tables, loads the kernel
    started = time.perf_counter()
    evaluate(job, first)
    return (time.perf_counter() - started) * len(plan) / max(workers, 1)


def too_big(runs: int, estimate_s: float) -> str | None:
    """Why a run of this size needs --force, or None."""
    if runs > MAX_RUNS or estimate_s > MAX_ESTIMATE_S:
        return (f'{runs:,} runs, estimated {format_duration(estimate_s)} '
                f'(limits without --force: {MAX_RUNS:,} runs, {format_duration(MAX_ESTIMATE_S)})')
    return None


def format_duration(seconds: float) -> str:
    if seconds < 120:
        return f'{seconds:.0f} s'
    if seconds < 7200:
        return f'{seconds / 60:.0f} min'
    return f'{seconds / 3600:.1f} h' if seconds < 172800 else f'{seconds / 86400:.0f} days'


def run_plan(job: Job, plan: RunPlan, runner: Runner,
             progress: Callable[[int], None] | None = None) -> Iterator[dict[str, Any]]:
    """Every row of the plan in run order (with ``point`` when the plan has replicates)."""
    base = base_values(job.base, plan.columns)
    size = chunk_size(len(plan), runner.workers)
    for rows in runner.imap(evaluate_chunk, plan.chunks(size, base), job):
        for row in rows:
            if plan.replicates > 1:
                row['point'] = row['run'] // plan.replicates
            yield row
        if progress is not None:
            progress(len(rows))


class PointSummary:
    """Monte Carlo statistics per design point, accumulated row by row: over the settled runs the
    mean, standard deviation, 5th and 95th percentiles of the distance per stroke; over all runs the
    fraction settled and the fraction in each regime."""

    def __init__(self, plan: RunPlan):
        self.plan = plan
        self.values: dict[int, list[float]] = {}
        self.counts: dict[int, dict[str, int]] = {}

    def add(self, row: Mapping[str, Any]) -> None:
        point = row['run'] // self.plan.replicates
        counts = self.counts.setdefault(point, dict.fromkeys((*REGIMES, 'error', 'settled', 'runs'), 0))
        counts[row['regime']] += 1
        counts['runs'] += 1
        if row['settled']:
            counts['settled'] += 1
            self.values.setdefault(point, []).append(row['distance_per_stroke_m'])

    def rows(self) -> Iterator[dict[str, Any]]:
        for point in sorted(self.counts):
            counts = self.counts[point]
            d = np.asarray(self.values.get(point, []), dtype=float)
            stats = ((d.mean(), d.std(ddof=1) if d.size > 1 else 0.0, *np.percentile(d, [5, 95]))
                     if d.size else (math.nan,) * 4)
            n = counts['runs']
            yield {'point': point, **dict(zip(self.plan.design.names, self.plan.design.point(point), strict=True)),
                   'runs': n, 'mean_per_stroke_m': stats[0], 'std_per_stroke_m': stats[1],
                   'p5_per_stroke_m': stats[2], 'p95_per_stroke_m': stats[3],
                   'fraction_settled': counts['settled'] / n,
                   **{f'fraction_{r}': counts[r] / n for r in (*REGIMES, 'error')}}


def sweep(flat: Mapping[str, Any], name: str, values: list[float], processes: int = 1,
          duration: float | None = None) -> list[dict[str, Any]]:
    """One row per value of one parameter, in order (a library shortcut for a 1-parameter grid)."""
    from .designs import Axis, Grid
    from .runners import make_runner
    plan = RunPlan(Grid([Axis(name, listed=tuple(values))]))
    with make_runner(processes) as runner:
        return list(run_plan(Job(dict(flat), duration), plan, runner))
