"""One run of the offline model -> one table row: where the part ended, whether it settled, its regime.

Runs in the worker (a local process or a Dask worker): :class:`Job` is the small picklable description
shipped with every chunk of runs (base parameters, duration); the base model and its contact tables are
built once per worker process and reused while the varied parameters leave the contact inputs alone.
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

REGIMES = ('stuck', 'slides', 'flies')
# Parameters whose change needs new contact tables; every other change reuses the base model's.
CONTACT_INPUTS = ('contact.', 'particle.mass', 'particle.area', 'gravity')
COUNTERS = TRANSITION_KINDS
RESULT_COLUMNS = ('distance_m', 'distance_per_stroke_m', 'settled', 'regime', 'final_mode', 'final_offset_m',
                  *COUNTERS, 'max_speed_mps', 'mean_velocity_mps', 'throw_number', 'sim_time_s', 'error')


def regime(transitions: Mapping[str, int]) -> str:
    """``flies`` if the part took off at least once, else ``slides`` if it slipped, else ``stuck``."""
    if transitions['take_off'] > 0:
        return 'flies'
    return 'slides' if transitions['stick_to_slip'] > 0 else 'stuck'


@dataclass(frozen=True)
class Job:
    """What every run of a sweep shares: the base parameters (flat, JSON-able) and the run length
    (s; None: the model's default, end of the last stroke + integration.settling_time)."""

    base: Mapping[str, Any]
    duration: float | None = None

    @property
    def key(self) -> str:
        return json.dumps({'base': dict(self.base), 'duration': self.duration}, sort_keys=True, default=str)


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
    """Run the model with ``changes`` from the initial state; the result columns (:data:`RESULT_COLUMNS`).

    ``distance_m`` / ``distance_per_stroke_m`` are NaN unless the run settled (a part in flight has no
    distance yet); ``final_offset_m`` is x − x0 where the run ended, whatever the mode. A refused
    parameter value or a failed integration gives a row with ``error`` set and NaN figures.
    """
    try:
        model = model_for(job, changes)
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
    except (ParameterError, SimulationError) as err:
        nan = math.nan
        return {'distance_m': nan, 'distance_per_stroke_m': nan, 'settled': False, 'regime': 'error',
                'final_mode': '', 'final_offset_m': nan, **dict.fromkeys(COUNTERS, 0), 'max_speed_mps': nan,
                'mean_velocity_mps': None, 'throw_number': None, 'sim_time_s': nan, 'error': str(err)}
    counts = state.transitions
    distance = state.distance if settled else math.nan
    return {'distance_m': distance, 'distance_per_stroke_m': distance / model.stroke.count,
            'settled': settled, 'regime': regime(counts), 'final_mode': state.mode,
            'final_offset_m': state.distance, **counts, 'max_speed_mps': state.max_speed, **conveying,
            'sim_time_s': state.t, 'error': ''}


def evaluate_chunk(job: Job, runs: Sequence[tuple[int, Mapping[str, float]]]) -> list[dict[str, Any]]:
    """The rows of a chunk of runs ``(run number, changes)``: run number, the changes, the results."""
    return [{'run': run, **changes, **evaluate(job, changes)} for run, changes in runs]
