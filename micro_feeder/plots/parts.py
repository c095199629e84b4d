"""The space–time picture of a many-part run: every part's position against time, coloured by part, with
its mode along the line and the impacts marked (docs/parts.md)."""

from __future__ import annotations

import textwrap
from pathlib import Path

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt
import numpy as np

from ..physics.parts import PartsResult
from .dynamics import save, time_scale

MM = 1e3


def plot_space_time(result: PartsResult, path: Path | str, title: str = '', gate: float | None = None,
                    size: float | None = None) -> Path:
    """Positions (mm) of all parts against time; sliding stretches drawn solid and thick, stuck ones thin,
    flights dotted; impacts as black dots; the gate x = ``gate`` (m) as a dashed line; with ``size`` (m) each
    part drawn as a band that wide, so touching parts read as touching."""
    impacts = [(imp.t, _impact_x(result, imp)) for imp in result.state.impacts]
    return plot_positions(result.t, result.x, result.modes, path, title, gate, size, impacts)


def plot_positions(times: np.ndarray, x: np.ndarray, modes: np.ndarray, path: Path | str, title: str = '',
                   gate: float | None = None, size: float | None = None,
                   impacts: list[tuple[float, float]] | None = None, names: list[str] | None = None) -> Path:
    """:func:`plot_space_time` from arrays: ``times`` (s, n), ``x`` (m, n × parts), ``modes`` (n × parts, codes
    of MODES); ``impacts`` as (t s, x m), none marked when None (a log does not record them)."""
    result_x, result_modes = x, modes
    factor, unit = time_scale(times)
    t = times * factor
    n = result_x.shape[1]
    colors = plt.get_cmap('tab10' if n <= 10 else 'viridis')
    fig, ax = plt.subplots(figsize=(9, 6))
    for k in range(n):
        color = colors(k if n <= 10 else k / max(n - 1, 1))
        x = result_x[:, k] * MM
        if size is not None:
            ax.fill_between(t, x - 0.5 * size * MM, x + 0.5 * size * MM, color=color, alpha=0.18, lw=0)
        label = (names[k] if names else f'part {k}') if n <= 10 else None
        ax.plot(t, x, color=color, lw=0.8, label=label)
        for mode, style in ((1, dict(lw=2.2, ls='-')), (2, dict(lw=1.4, ls=':'))):
            ax.plot(t, np.where(result_modes[:, k] == mode, x, np.nan), color=color, **style)
    if impacts:
        ax.plot([ti * factor for ti, _ in impacts], [xi * MM for _, xi in impacts], 'k.', ms=4,
                label=f'impacts ({len(impacts)})')
    if gate is not None:
        ax.axhline(gate * MM, color='k', ls='--', lw=0.8, label=f'gate x = {gate * MM:g} mm')
    ax.set(xlabel=f'time ({unit})', ylabel='x (mm)',
           title=textwrap.fill(title or f'{n} parts: position against time', 110))
    ax.title.set_fontsize(9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc='upper left', bbox_to_anchor=(1.01, 1.0))
    ax.text(0.01, 0.01, 'thick: sliding   thin: stuck   dotted: flying', transform=ax.transAxes, fontsize=8,
            color='0.3')
    return save(fig, path)


def _impact_x(result: PartsResult, impact) -> float:
    """Where an impact happened (m): the contact point between its first two parts, from the nearest sample."""
    row = int(np.clip(np.searchsorted(result.t, impact.t), 0, len(result.t) - 1))
    rear = impact.parts[0]
    return 0.5 * (result.x[row, rear] + result.x[row, rear + 1])
