"""Calibration figure: recorded and re-simulated part trajectories, before and after the fit."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt
import numpy as np

from .dynamics import save

UM, MS = 1e6, 1e3
FLOOR = 1e-18        # m: where a residual of exactly 0 is drawn on the log axis


def motion_window(t: np.ndarray, series: Sequence[np.ndarray]) -> tuple[float, float]:
    """The time span in which any series changes, with a margin of a fifth of it on each side (the
    whole record when nothing moves): a 1 s log whose part moves for 5 ms shows those 5 ms."""
    moving = np.zeros(t.size - 1, dtype=bool)
    for x in series:
        moving |= np.abs(np.diff(x)) > 1e-12
    if not moving.any():
        return float(t[0]), float(t[-1])
    first, last = t[np.argmax(moving)], t[len(moving) - np.argmax(moving[::-1])]
    margin = max((last - first) / 5, (t[-1] - t[0]) * 1e-3)
    return max(t[0], first - margin), min(t[-1], last + margin)


def plot_calibration(logs: Sequence[str], times: Sequence[np.ndarray], recorded: Sequence[np.ndarray],
                     start: Sequence[np.ndarray], fitted: Sequence[np.ndarray], values: Mapping[str, float],
                     path: Path | str) -> Path:
    """Per log: displacement x − x(0) recorded (dots), re-simulated with the starting values (dashed) and
    with the fitted ones (line); below, the fitted residual |Δ(x, z)| per pose."""
    fig, axes = plt.subplots(2, len(logs), figsize=(8 * len(logs) ** 0.5 + 1, 6.5), squeeze=False, sharex='col',
                             gridspec_kw={'height_ratios': [3, 1.5]})
    for k, name in enumerate(logs):
        ax, ax_r = axes[0, k], axes[1, k]
        t = times[k] * MS
        x0 = recorded[k][0, 0]
        ax.plot(t, (recorded[k][:, 0] - x0) * UM, '.', color='k', ms=3, label='recorded')
        ax.plot(t, (start[k][:, 0] - x0) * UM, '--', color='C1', label='re-simulated, start values')
        ax.plot(t, (fitted[k][:, 0] - x0) * UM, '-', color='C0', lw=1, label='re-simulated, fitted')
        ax.set(ylabel='x − x(0) (µm)', title=Path(name).name)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        residual = np.hypot(*(fitted[k] - recorded[k]).T)
        ax_r.semilogy(t, np.maximum(residual, FLOOR), '.', color='C0', ms=3)
        ax_r.set(xlabel='sim time (ms)', ylabel=f'|residual| (m; 0 at {FLOOR:g})')
        ax_r.grid(alpha=0.3)
        ax.set_xlim(*motion_window(t, [recorded[k][:, 0], start[k][:, 0], fitted[k][:, 0]]))
    fig.suptitle('Calibration: ' + ', '.join(f'{n} = {v:.6g}' for n, v in values.items()), fontsize=10)
    return save(fig, path)
