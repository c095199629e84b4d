"""Figures of offline runs: one run's history (strokes, velocity, friction, displacement, height, mode); the
panel helpers are shared with the log plot (plots/log.py)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt
import numpy as np

from ..physics.dynamics import MODES, RunResult
from .units import scale

MS, UM, MM = 1e3, 1e6, 1e3


def save(fig: plt.Figure, path: Path | str) -> Path:
    """Write the figure as a PNG and release it."""
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def actuator_colors(n: int) -> list:
    """One colour per actuator (the same in every figure): tab10, or viridis beyond ten."""
    cmap = plt.get_cmap('tab10' if n <= 10 else 'viridis')
    return [cmap(k if n <= 10 else k / max(n - 1, 1)) for k in range(n)]


def plot_strokes(ax: plt.Axes, t: np.ndarray, strokes: np.ndarray, t_label: str = '') -> None:
    """Actuator strokes (n, k) against ``t`` on ``ax`` in a unit that suits them, one legend entry per
    actuator (``piezo_k``)."""
    factor, unit = scale(strokes, 'm')
    strokes = np.atleast_2d(strokes.T).T
    for k, color in enumerate(actuator_colors(strokes.shape[1])):
        ax.plot(t, strokes[:, k] * factor, color=color, lw=1.2, label=f'piezo_{k}')
    ax.set_ylabel(f'stroke ({unit})' + t_label)
    ax.legend(loc='upper right', fontsize=8, ncol=min(strokes.shape[1], 5))


def plot_friction(ax: plt.Axes, t: np.ndarray, friction: np.ndarray, q_max: np.ndarray,
                  style: str = '-') -> None:
    """Friction T against the static limit ±Q_max(N), on a panel of its own, in a unit that suits T."""
    factor, unit = scale([friction, q_max], 'N')
    ax.plot(t, friction * factor, style, color='C3', lw=1.2, ms=2.5, label='friction T')
    ax.plot(t, q_max * factor, color='0.35', lw=0.9, ls='--', label='±Q_max(N), the static limit')
    ax.plot(t, -q_max * factor, color='0.35', lw=0.9, ls='--')
    ax.axhline(0.0, color='k', lw=0.5)
    ax.set_ylabel(f'friction ({unit})')
    ax.legend(loc='upper right', fontsize=8)


def plot_modes(ax: plt.Axes, t: np.ndarray, mode: np.ndarray, t_end: float | None = None) -> None:
    """The contact mode as a step line (stuck / sliding / flying)."""
    if t_end is not None and len(t):
        t, mode = np.append(t, t_end), np.append(mode, mode[-1])
    ax.step(t, mode, where='post', color='k', lw=1.2)
    ax.set(yticks=range(len(MODES)), yticklabels=MODES, ylim=(-0.5, len(MODES) - 0.5), ylabel='mode')


def time_scale(t: np.ndarray) -> tuple[float, str]:
    """Factor and unit (ms below 1 s of span, s above) for a time axis."""
    span = float(np.ptp(t)) if len(t) else 0.0
    return (MS, 'ms') if 0.0 < span < 1.0 else (1.0, 's')


def plot_history(result: RunResult, path: Path | str, title: str = '') -> Path:
    """Stacked panels against time: the actuator strokes (legend per actuator), the part's velocity along
    the feeder, friction against ±Q_max, its displacement, its height above the surface when it flies, and the mode;
    each in a unit that suits its values."""
    factor_t, unit_t = time_scale(result['t'])
    t = result['t'] * factor_t
    flying = result['mode'] == MODES.index('flying')
    panels = ['strokes', 'velocity', 'friction', 'x'] + (['height'] if flying.any() else []) + ['mode']
    ratios = {'strokes': 2.2, 'velocity': 2.6, 'friction': 2.6, 'x': 2.4, 'height': 2.2, 'mode': 1.2}
    fig, axes = plt.subplots(len(panels), 1, figsize=(9, 1.9 * len(panels) + 1), sharex=True,
                             gridspec_kw={'height_ratios': [ratios[p] for p in panels]})
    ax = dict(zip(panels, axes, strict=True))
    strokes = np.column_stack([result[c] for c in result.columns if c.startswith('stroke_')])
    plot_strokes(ax['strokes'], t, strokes)

    factor_v, unit_v = scale(result['xdot'], 'm/s')
    ax['velocity'].plot(t, result['xdot'] * factor_v, color='C0', lw=1.2, label='ẋ, along the feeder')
    ax['velocity'].axhline(0.0, color='k', lw=0.5)
    ax['velocity'].set_ylabel(f'velocity ({unit_v})')
    ax['velocity'].legend(loc='upper right', fontsize=8)

    q_max = np.where(flying, np.nan, result['q_max'])
    plot_friction(ax['friction'], t, np.where(flying, np.nan, result['friction']), q_max)

    dx = result['x'] - result['x'][0]
    factor_x, unit_x = scale(dx, 'm')
    ax['x'].plot(t, dx * factor_x, color='C2', lw=1.4)
    ax['x'].set_ylabel(f'x − x0 ({unit_x})')

    if flying.any():
        gap = np.where(flying, result['z'] - result['surface_height'], np.nan)
        factor_h, unit_h = scale(gap, 'm')
        ax['height'].plot(t, gap * factor_h, color='C1', lw=1.4, label='height of the part above the surface')
        ax['height'].set_ylabel(f'height ({unit_h})')
        ax['height'].legend(loc='upper right', fontsize=8)

    plot_modes(ax['mode'], t, result['mode'])
    ax['mode'].set_xlabel(f'time ({unit_t})')
    for a in axes:
        a.grid(alpha=0.3)
    fig.suptitle(title or 'Part on the actuated surface: strokes, velocity, friction, displacement, mode')
    return save(fig, path)
