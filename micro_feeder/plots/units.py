"""Units that suit the values: pick the SI prefix that puts a series' largest magnitude in [1, 1000)."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

PREFIXES = ((1e-9, 1e9, 'n'), (1e-6, 1e6, 'µ'), (1e-3, 1e3, 'm'), (1.0, 1.0, ''))  # (size, factor, prefix)


def scale(values: Iterable[float] | np.ndarray, unit: str) -> tuple[float, str]:
    """(factor, label): ``values * factor`` are in ``label`` (e.g. 1e6, 'µm' for values of ~1e-5 m). The
    prefix is the largest one not above the largest finite magnitude (nano at the smallest, none at the
    largest); all-zero or empty series get no prefix."""
    arrays = [np.asarray(v, dtype=float).ravel() for v in (values if isinstance(values, list) else [values])]
    flat = np.concatenate(arrays) if arrays else np.zeros(0)
    finite = np.abs(flat[np.isfinite(flat)])
    peak = float(finite.max()) if finite.size else 0.0
    if peak == 0.0:
        return 1.0, unit
    factor, prefix = PREFIXES[0][1:]
    for size, candidate, name in PREFIXES:
        if peak >= size * 0.999:
            factor, prefix = candidate, name
    return factor, prefix + unit
