"""One run of the offline model -> one table row: where the part ended, whether it settled, its regime;
with several parts (``particle.x0`` a list) also the impacts, the spacing, each part's figures and, with a
gate, the feed rate (docs/parts.md).

Runs in the worker (a local process or a Dask worker): :class:`Job` is the small picklable description
shipped with every chunk of runs (base parameters, duration, gate); the base model and its contact tables
are built once per worker process and reused while the varied parameters leave the contact inputs alone.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

from ..interface.names import TRANSITION_KINDS
from ..physics.dynamics import FeederModel, SimulationError
from ..physics.dynamics.conveying import ConveyingWindow
from ..physics.parameters import ParameterError
from ..physics.parts import PartsModel
from ..physics.parts.figures import gate_figures, run_figures, sample_step

REGIMES = ('stuck', 'slides', 'flies')
# Parameters whose change needs new contact tables; every other change reuses the base model's.
CONTACT_INPUTS = ('contact.', 'particle.mass', 'particle.area', 'gravity')
COUNTERS = TRANSITION_KINDS
RESULT_COLUMNS = ('distance_m', 'distance_per_stroke_m', 'settled', 'regime', 'final_mode', 'final_offset_m',
                  *COUNTERS, 'max_speed_mps', 'mean_velocity_mps', 'throw_number', 'sim_time_s', 'error')
# With several parts: impacts, spacing between neighbouring centres at the end, and each part's figures
# (a list of {distance_m, final_mode, transitions, max_speed_mps}, as simulate --json's ``parts``).
PARTS_COLUMNS = ('collisions', 'spacing_mean_m', 'spacing_min_m', 'parts')
# With a gate (Job.gate, --gate X): forward crossings of x = X, per second of the run, mean time between them.
GATE_COLUMNS = ('gate_m', 'crossings', 'feed_rate_hz', 'headway_s')
# The numeric result columns a sweep's plot can draw: what each is, and its SI unit.
QUANTITIES = {
    'distance_m': ('distance', 'm'), 'distance_per_stroke_m': ('distance per stroke', 'm'),
    'final_offset_m': ('offset where the run ended', 'm'),
    **{name: (f'{name.replace("_", " ")} transitions', '') for name in COUNTERS},
    'max_speed_mps': ('largest speed', 'm/s'), 'mean_velocity_mps': ('mean conveying velocity', 'm/s'),
    'throw_number': ('throw number', ''), 'sim_time_s': ('simulated time', 's'),
    'collisions': ('impacts between parts', ''), 'spacing_mean_m': ('mean spacing at the end', 'm'),
    'spacing_min_m': ('smallest spacing at the end', 'm'), 'crossings': ('crossings of the gate', ''),
    'feed_rate_hz': ('feed rate past the gate', 'parts/s'), 'headway_s': ('mean time between crossings', 's'),
}


def regime(transitions: Mapping[str, int]) -> str:
    """``flies`` if the part took off at least once, else ``slides`` if it slipped, else ``stuck``."""
    if transitions['take_off'] > 0:
        return 'flies'
    return 'slides' if transitions['stick_to_slip'] > 0 else 'stuck'


@dataclass(frozen=True)
class Job:
    """What every run of a sweep shares: the base parameters (flat, JSON-able), the run length
    (s; None: the model's default, end of the last stroke + integration.settling_time) and the gate
    (m; None: no feed-rate figures)."""

    base: Mapping[str, Any]
    duration: float | None = None
    gate: float | None = None

    @property
    def key(self) -> str:
        return json.dumps({'base': dict(self.base), 'duration': self.duration}, sort_keys=True, default=str)

    @property
    def several_parts(self) -> bool:
        """Whether the base settings put several parts on the feeder (``particle.x0`` a list of two or more).

        Raises ParameterError for refused base settings."""
        return _base_model(self.key).particle.n_parts > 1

    @property
    def columns(self) -> tuple[str, ...]:
        """The result columns of this job's rows: :data:`RESULT_COLUMNS`, then :data:`PARTS_COLUMNS` with
        several parts, then :data:`GATE_COLUMNS` with a gate."""
        return (*RESULT_COLUMNS, *(PARTS_COLUMNS if self.several_parts else ()),
                *(GATE_COLUMNS if self.gate is not None else ()))


@lru_cache(maxsize=4)
def _base_model(key: str) -> FeederModel:
    return FeederModel.from_settings(json.loads(key)['base'])


def model_for(job: Job, changes: Mapping[str, float]) -> FeederModel:
    """The job's model with ``changes``; contact tables reused unless a contact input changes.

    Raises ParameterError for a refused value.
    """
    base = _base_model(job.key)
    if not changes:
        return base
    reuse = not any(name.startswith(CONTACT_INPUTS) for name in changes)
    return FeederModel.from_settings({**job.base, **changes}, contact_model=base.contact_model if reuse else None)


def evaluate(job: Job, changes: Mapping[str, float]) -> dict[str, Any]:
    """Run the model with ``changes`` from the initial state; the result columns (:attr:`Job.columns`).

    ``distance_m`` / ``distance_per_stroke_m`` are NaN unless the run settled (a part in flight has no
    distance yet); ``final_offset_m`` is x − x0 where the run ended, whatever the mode. A refused
    parameter value or a failed integration gives a row with ``error`` set and NaN figures. Several parts:
    :func:`evaluate_parts`. With a gate, one part: the gate figures of ``simulate --gate`` (a second run,
    sampled as ``simulate`` samples it).
    """
    try:
        model = model_for(job, changes)
        if job.several_parts:
            return evaluate_parts(job, model)
        state = model.initial_state()
        end = job.duration or model.default_duration()
        window = ConveyingWindow.of(model.stroke)
        at_marks = []
        if window is not None and window.t_end <= end:    # the mean velocity's periods: x exactly there
            for mark in window.marks:
                model.advance(state, mark)
                at_marks.append(state.x)
        model.advance(state, end)
        if not job.duration:       # the default length, then on until the part is stuck again (settle_max)
            model.settle(state)
        settled = state.mode == 'stuck'
        conveying = {name: None if math.isnan(value) else value     # not applicable: empty, as simulate's JSON
                     for name, value in model.conveying_figures(window.velocity(*at_marks) if at_marks
                                                                else math.nan).items()}
        gate = {}
        if job.gate is not None:
            result = model.run(duration=job.duration, output_step=sample_step(model, job.duration))
            gate = gate_figures(result['t'], result['x'], job.gate)
    except (ParameterError, SimulationError) as err:
        return error_row(job, err)
    counts = state.transitions
    distance = state.distance if settled else math.nan
    return {'distance_m': distance, 'distance_per_stroke_m': distance / model.stroke.count,
            'settled': settled, 'regime': regime(counts), 'final_mode': state.mode,
            'final_offset_m': state.distance, **counts, 'max_speed_mps': state.max_speed, **conveying,
            'sim_time_s': state.t, 'error': '', **gate}


def evaluate_parts(job: Job, model: FeederModel) -> dict[str, Any]:
    """The row of a run with several parts, the figures ``simulate --json`` gives for it (the same run, sampled
    the same way: :func:`~micro_feeder.physics.parts.figures.run_figures`): ``collisions``, ``spacing_mean_m``,
    ``spacing_min_m``, ``parts`` (one dict per part) and, with a gate, the feed rate. The columns a one-part
    row has describe the parts together: ``distance_m`` and ``final_offset_m`` are the mean over the parts
    (the distance NaN unless every part is stuck at the end), ``final_mode`` the parts' common mode or
    ``mixed``, the transition counts summed, ``regime`` from these sums (``flies`` if any part took off),
    ``max_speed_mps`` the largest of any part; ``mean_velocity_mps`` is not computed for several parts
    (None). Raises SimulationError as the run does."""
    result = PartsModel(model).run(duration=job.duration, output_step=sample_step(model, job.duration))
    figures = run_figures(result, job.gate)
    parts = figures['parts']
    counts = {name: sum(part['transitions'][name] for part in parts) for name in COUNTERS}
    offset = sum(part['distance_m'] for part in parts) / len(parts)
    distance = offset if figures['settled'] else math.nan
    modes = {part['final_mode'] for part in parts}
    return {'distance_m': distance, 'distance_per_stroke_m': distance / model.stroke.count,
            'settled': figures['settled'], 'regime': regime(counts),
            'final_mode': modes.pop() if len(modes) == 1 else 'mixed', 'final_offset_m': offset, **counts,
            'max_speed_mps': max(part['max_speed_mps'] for part in parts), 'mean_velocity_mps': None,
            'throw_number': _none_for_nan(model.throw_number()), 'sim_time_s': figures['sim_time_s'], 'error': '',
            **{name: figures[name] for name in (*PARTS_COLUMNS, *(GATE_COLUMNS if job.gate is not None else ()))}}


def error_row(job: Job, err: Exception) -> dict[str, Any]:
    """The row of a run that failed: ``error`` says why, the regime is ``error``, the figures NaN or empty."""
    nan = math.nan
    row = {'distance_m': nan, 'distance_per_stroke_m': nan, 'settled': False, 'regime': 'error',
           'final_mode': '', 'final_offset_m': nan, **dict.fromkeys(COUNTERS, 0), 'max_speed_mps': nan,
           'mean_velocity_mps': None, 'throw_number': None, 'sim_time_s': nan, 'error': str(err)}
    try:
        columns = job.columns
    except ParameterError:             # the base settings themselves refused: the one-part columns
        columns = RESULT_COLUMNS
    return {**row, **{name: None for name in columns if name not in row}}


def _none_for_nan(value: float) -> float | None:
    return None if math.isnan(value) else value


def evaluate_chunk(job: Job, runs: Sequence[tuple[int, Mapping[str, float]]]) -> list[dict[str, Any]]:
    """The rows of a chunk of runs ``(run number, changes)``: run number, the changes, the results."""
    return [{'run': run, **changes, **evaluate(job, changes)} for run, changes in runs]
