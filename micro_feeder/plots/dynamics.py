"""The particle dynamics in the form of the seed's Fig. 11 (one stroke's history) and Fig. 12 (sweep)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt

from ..physics.dynamics import MODES, RunResult

MS, UM, MM = 1e3, 1e6, 1e3


def save(fig: plt.Figure, path: Path | str) -> Path:
    """Write the figure as a PNG and release it."""
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_history(result: RunResult, path: Path | str, title: str = '') -> Path:
    """Four stacked panels vs time: velocity along x, friction force (with ±Q_max), displacement, mode;
    the actuator stroke is drawn faintly behind the velocity."""
    t = result['t'] * MS
    fig, axes = plt.subplots(4, 1, figsize=(9, 9), sharex=True,
                             gridspec_kw={'height_ratios': [3, 3, 3, 1.3]})
    ax_v, ax_f, ax_x, ax_mode = axes
    ax_v.plot(t, result['xdot'] * MM, color='C0', label='particle velocity ẋ (v_x in flight)')
    ax_v.set(ylabel='velocity (mm/s)', title=title or "Particle velocity and friction during the stroke "
                                                      "(seed Fig. 11)")
    ax_v.axhline(0.0, color='k', lw=0.5)
    strokes = [c for c in result.columns if c.startswith('stroke_')]
    ax_s = ax_v.twinx()
    for name in strokes:
        ax_s.plot(t, result[name] * UM, lw=0.8, ls=':', color='0.5')
    ax_s.set_ylabel('stroke (um, dotted)', color='0.4')
    ax_v.legend(loc='upper left', fontsize=8)

    ax_f.plot(t, result['friction'], color='C3', label='friction T')
    ax_f.plot(t, result['q_max'], color='C3', lw=0.7, ls='--', label='±Q_max(N)')
    ax_f.plot(t, -result['q_max'], color='C3', lw=0.7, ls='--')
    ax_f.axhline(0.0, color='k', lw=0.5)
    ax_f.set(ylabel='force (N)')
    ax_f.legend(loc='upper left', fontsize=8)

    ax_x.plot(t, (result['x'] - result['x'][0]) * UM, color='C2')
    ax_x.set(ylabel='x − x0 (um)')

    ax_mode.step(t, result['mode'], where='post', color='k')
    ax_mode.set(yticks=range(len(MODES)), yticklabels=MODES, ylim=(-0.5, len(MODES) - 0.5),
                xlabel='time (ms)')
    for ax in axes:
        ax.grid(alpha=0.3)
    return save(fig, path)
