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
        ax_r.semilogy(t, np.maximum(residual, 1e-18), '.', color='C0', ms=3)
        ax_r.set(xlabel='sim time (ms)', ylabel='|residual| (m)')
        ax_r.grid(alpha=0.3)
    fig.suptitle('Calibration: ' + ', '.join(f'{n} = {v:.6g}' for n, v in values.items()), fontsize=10)
    return save(fig, path)
