"""Feeder figures of a many-part run: the feed rate past a gate and the spacing between neighbours
(docs/parts.md). Numbers in, numbers out (s, m).

:func:`sample_step` and :func:`run_figures` are the one way ``simulate`` and ``sweep`` sample a run and
reduce it to its figures, so the two give the same numbers for the same point."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..dynamics import FeederModel
from .model import PartsResult

SAMPLE_PERIODS = 0.005        # positions sampled every this fraction of a stroke period ...
MAX_SAMPLES = 5000            # ... but at most about this many over the run length


def gate_crossings(t: np.ndarray, x: np.ndarray, gate: float) -> np.ndarray:
    """Times (s) at which a part passes x = ``gate`` (m) forward (from below to at or above it), linearly
    interpolated between samples; ``t`` (n,), ``x`` (n, parts). A part that comes back and passes again
    counts again (its backward crossings are not subtracted)."""
    x = np.asarray(x, dtype=float).reshape(len(t), -1)
    times = []
    for k in range(x.shape[1]):
        before, after = x[:-1, k], x[1:, k]
        for i in np.flatnonzero((before < gate) & (after >= gate)):
            share = (gate - before[i]) / (after[i] - before[i])
            times.append(t[i] + share * (t[i + 1] - t[i]))
    return np.sort(np.asarray(times, dtype=float))


def gate_figures(t: np.ndarray, x: np.ndarray, gate: float) -> dict[str, float | int | None]:
    """``gate_m``, ``crossings`` (forward passages of x = gate), ``feed_rate_hz`` (crossings per second of the
    run) and ``headway_s`` (mean time between successive crossings; None below two)."""
    crossings = gate_crossings(t, x, gate)
    duration = float(t[-1] - t[0])
    return {'gate_m': gate, 'crossings': int(crossings.size),
            'feed_rate_hz': crossings.size / duration if duration > 0 else None,
            'headway_s': float(np.diff(crossings).mean()) if crossings.size > 1 else None}


def spacing_figures(positions: np.ndarray) -> dict[str, float | None]:
    """``spacing_mean_m`` and ``spacing_min_m``: the distance between neighbouring centres (m) where the parts
    are (None for one part)."""
    spacing = np.diff(np.sort(np.asarray(positions, dtype=float)))
    if spacing.size == 0:
        return {'spacing_mean_m': None, 'spacing_min_m': None}
    return {'spacing_mean_m': float(spacing.mean()), 'spacing_min_m': float(spacing.min())}


def sample_step(model: FeederModel, duration: float | None) -> float:
    """The step (s) at which a run's positions are sampled: 1/200 of a stroke period, or longer so that
    the run (``duration`` s, or the model's default length) has at most ~5000 samples. The gate's
    crossings are interpolated between these samples."""
    length = model.default_duration() if duration is None else duration
    return max(SAMPLE_PERIODS / model.stroke.frequency, length / MAX_SAMPLES)


def run_figures(result: PartsResult, gate: float | None = None) -> dict[str, Any]:
    """The figures of a many-part run (JSON-able): :meth:`PartsResult.summary` (``parts``, ``collisions``,
    ``settled``, ``sim_time_s``), the spacing where the parts end and, with a ``gate`` (m), the feed rate
    past it (:func:`gate_figures`)."""
    return {**result.summary(), **spacing_figures(result.state.positions),
            **(gate_figures(result.t, result.x, gate) if gate is not None else {})}
