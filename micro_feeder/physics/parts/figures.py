"""Feeder figures of a many-part run: the feed rate past a gate and the spacing between neighbours
(docs/parts.md). Numbers in, numbers out (s, m)."""

from __future__ import annotations

import numpy as np


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
