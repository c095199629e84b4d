"""Plot of a log: position, velocity, contact mode, friction and normal load vs time (PNG, Agg)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt

from .reader import LogReader
from .series import MODES, part_series


def plot_log(log: LogReader, output: Path | str, title: str | None = None) -> Path:
    """Write the four-panel figure of the part's motion to ``output``; returns the path."""
    s = part_series(log)
    fig, axes = plt.subplots(4, 1, sharex=True, figsize=(9, 9), constrained_layout=True)
    ax = axes[0]
    ax.plot(s.pose.t, s.pose.values['x'] * 1e3, label='x')
    ax.plot(s.pose.t, s.pose.values['z'] * 1e3, label='z')
    ax.set_ylabel('position [mm]')
    ax = axes[1]
    ax.plot(s.twist.t, s.twist.values['vx'] * 1e3, label='vx')
    ax.plot(s.twist.t, s.twist.values['vz'] * 1e3, label='vz')
    ax.set_ylabel('velocity [mm/s]')
    ax = axes[2]
    if len(s.mode):
        end = max([s.mode.t[-1], *(x.t[-1] for x in (s.pose, s.twist, s.wrench) if len(x))])
        ax.step([*s.mode.t, end], [*s.mode.values['mode'], s.mode.values['mode'][-1]], where='post')
    ax.set_yticks(range(len(MODES)), MODES)
    ax.set_ylim(-0.5, len(MODES) - 0.5)
    ax.set_ylabel('mode')
    ax = axes[3]
    ax.plot(s.wrench.t, s.wrench.values['friction'] * 1e6, label='friction T')
    ax.plot(s.wrench.t, s.wrench.values['normal'] * 1e6, label='normal load N')
    ax.set_ylabel('force [µN]')
    ax.set_xlabel(f'{s.time_axis} [s]')
    for ax in axes:
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc='upper right')
    fig.suptitle(title or str(log.path))
    output = Path(output)
    output.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(output, dpi=110)
    plt.close(fig)
    return output
