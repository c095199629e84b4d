"""Plot of a log (PNG, Agg): what the part did under the recorded strokes, zoomed to where it happens.

Panels, sharing a sim-time axis: the commanded strokes (rebuilt from the recorded commands,
:mod:`.strokes`, so a 1 kHz stroke is drawn whole rather than aliased by 1 kHz samples; a legend entry
per actuator), the part's displacement x − x0, its velocity along the feeder, friction T against the
static limit ±Q_max(N) (evaluated with the contact model of the recorded parameters at the recorded
normal load) on a panel of its own, the normal load, the part's height above the surface while it flies
(when it does), and the contact mode. Recorded samples are drawn as dots joined by lines: between two
samples the log knows nothing. Each panel picks the unit that suits its values (µm, mm/s, nN/µN ...).

By default the time axis spans where something happens (commands moving the strokes, the part moving or
not stuck) with a margin; ``start``/``end`` (s, sim time) choose the window instead.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt
import numpy as np

from ..logs.friction_limit import static_limit
from ..logs.reader import LogReader
from ..logs.series import MODES, PartSeries, part_series
from ..logs.sim_parameters import recorded_parameters
from ..logs.strokes import CommandedStrokes, commanded_strokes
from .dynamics import plot_friction, plot_modes, plot_strokes, time_scale
from .units import scale

STROKE_POINTS = 4000     # points of the commanded strokes over the window
MARGIN = 0.25            # of the active span, each side of the default window
MIN_MARGIN = 1e-3        # s
FLYING = MODES.index('flying')


def plot_log(log: LogReader, output: Path | str, title: str | None = None, start: float | None = None,
             end: float | None = None) -> Path:
    """Write the figure of the part's motion to ``output`` (see the module docstring); returns the path.
    ``start``/``end``: the window in sim time (s); default: where something happens. Raises ValueError for
    an empty window."""
    s = part_series(log)
    params = (recorded_parameters(log) or [{}])[0]
    n_act = len(params.get('surface.centers', [])) or 1
    commands = commanded_strokes(log, n_act, s.pose.log_t, s.pose.t) if len(s.pose) else None
    t_first, t_last = _extent(s)
    lo, hi = active_window(s, commands, t_first, t_last)
    lo, hi = (lo if start is None else start), (hi if end is None else end)
    if not hi > lo:
        raise ValueError(f'empty time window: start {lo:g} s, end {hi:g} s (the log spans {t_first:g}–{t_last:g} s)')
    pose, twist, wrench = (_clip(x, lo, hi) for x in (s.pose, s.twist, s.wrench))
    mode_t, mode_v = _mode_in(s, lo, hi)
    flying_pose = _flying_at(s, pose['t'])
    panels = ['strokes', 'x', 'velocity', 'friction', 'normal'] + (['height'] if flying_pose.any() else []) + ['mode']
    ratios = {'strokes': 2.2, 'x': 2.2, 'velocity': 2.2, 'friction': 2.4, 'normal': 1.8, 'height': 2.0, 'mode': 1.1}
    fig, axes = plt.subplots(len(panels), 1, sharex=True, figsize=(9, 1.75 * len(panels) + 1.2),
                             gridspec_kw={'height_ratios': [ratios[p] for p in panels]}, constrained_layout=True)
    ax = dict(zip(panels, axes, strict=True))
    k, t_unit = time_scale(np.array([lo, hi]))

    grid = np.linspace(lo, hi, STROKE_POINTS)
    if commands is not None:
        plot_strokes(ax['strokes'], grid * k, commands.at(grid), ', commanded')
    else:
        joints = _joint_samples(log, lo, hi)
        if joints is not None:
            plot_strokes(ax['strokes'], joints[0] * k, joints[1], ', sampled: no command recorded')

    x0 = s.pose.values['x'][0] if len(s.pose) else 0.0
    f, unit = scale(pose['x'] - x0, 'm')
    ax['x'].plot(pose['t'] * k, (pose['x'] - x0) * f, '.-', color='C2', lw=1.0, ms=2.5)
    ax['x'].set_ylabel(f'x − x0 ({unit})')

    f, unit = scale(twist['vx'], 'm/s')
    ax['velocity'].plot(twist['t'] * k, twist['vx'] * f, '.-', color='C0', lw=1.0, ms=2.5)
    ax['velocity'].axhline(0.0, color='k', lw=0.5)
    ax['velocity'].set_ylabel(f'ẋ ({unit})')

    flying_wrench = _flying_at(s, wrench['t'])
    friction = np.where(flying_wrench, np.nan, wrench['friction'])
    plot_friction(ax['friction'], wrench['t'] * k, friction, _q_max(params, wrench['normal'], flying_wrench), '.-')

    f, unit = scale(wrench['normal'], 'N')
    ax['normal'].plot(wrench['t'] * k, wrench['normal'] * f, '.-', color='C4', lw=1.0, ms=2.5)
    ax['normal'].axhline(0.0, color='k', lw=0.5)
    ax['normal'].set_ylabel(f'normal load ({unit})')

    if 'height' in ax:
        height = _height(params, commands, pose, flying_pose)
        f, unit = scale(height, 'm')
        ax['height'].plot(pose['t'] * k, height * f, '.-', color='C1', lw=1.0, ms=3)
        ax['height'].set_ylabel(f'height in flight ({unit})')

    plot_modes(ax['mode'], mode_t * k, mode_v, hi * k)
    ax['mode'].set_xlabel(f'{s.time_axis} ({t_unit})')
    ax['mode'].set_xlim(lo * k, hi * k)
    for a in axes:
        a.grid(alpha=0.3)
    zoom = '' if (lo, hi) == (t_first, t_last) else f' of {t_first:.3f}–{t_last:.3f} s'
    fig.suptitle(title or f'{log.path.name}: the part under the recorded strokes, '
                          f'{s.time_axis} {lo:.4g}–{hi:.4g} s{zoom}')
    output = Path(output)
    output.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(output, dpi=110)
    plt.close(fig)
    return output


def _extent(s: PartSeries) -> tuple[float, float]:
    times = [x.t for x in (s.pose, s.twist, s.wrench, s.mode) if len(x)]
    if not times:
        return 0.0, 1.0
    return float(min(t.min() for t in times)), float(max(t.max() for t in times))


def active_window(s: PartSeries, commands: CommandedStrokes | None, t_first: float,
                  t_last: float) -> tuple[float, float]:
    """Where something happens: commands moving the strokes, the part moving or not stuck; with a margin."""
    moments: list[float] = []
    if commands is not None:
        moments += [t for span in commands.active for t in span]
    if len(s.pose) > 1:
        moving = np.flatnonzero(np.diff(s.pose.values['x']) != 0.0)
        if moving.size:
            moments += [float(s.pose.t[moving[0]]), float(s.pose.t[moving[-1] + 1])]
    not_stuck = np.flatnonzero(s.mode.values['mode'] != MODES.index('stuck')) if len(s.mode) else []
    for i in not_stuck:
        moments.append(float(s.mode.t[i]))
        if i + 1 < len(s.mode):
            moments.append(float(s.mode.t[i + 1]))
    moments = [t for t in moments if t_first <= t <= t_last]
    if not moments:
        return t_first, t_last
    lo, hi = min(moments), max(moments)
    pad = max(MARGIN * (hi - lo), MIN_MARGIN)
    return max(t_first, lo - pad), min(t_last, hi + pad)


def _clip(series: Any, lo: float, hi: float) -> dict[str, np.ndarray]:
    keep = (series.t >= lo) & (series.t <= hi)
    return {'t': series.t[keep], **{name: v[keep] for name, v in series.values.items()}}


def _mode_in(s: PartSeries, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray]:
    """The mode steps within [lo, hi], starting with the mode in force at ``lo``."""
    if not len(s.mode):
        return np.zeros(0), np.zeros(0)
    t, v = s.mode.t, s.mode.values['mode']
    before = np.flatnonzero(t <= lo)
    inside = (t > lo) & (t <= hi)
    first = v[before[-1]] if before.size else v[0]
    return np.concatenate([[lo], t[inside]]), np.concatenate([[first], v[inside]])


def _flying_at(s: PartSeries, t: np.ndarray) -> np.ndarray:
    """True where the mode in force at each of ``t`` is flying."""
    if not len(s.mode) or not len(t):
        return np.zeros(len(t), dtype=bool)
    i = np.searchsorted(s.mode.t, t, side='right') - 1
    return (i >= 0) & (s.mode.values['mode'][np.clip(i, 0, None)] == FLYING)


def _q_max(params: dict[str, Any], normal: np.ndarray, flying: np.ndarray) -> np.ndarray:
    """Q_max at each recorded normal load (NaN in flight, or without the recorded contact parameters)."""
    if not params or not normal.size:
        return np.full(normal.shape, np.nan)
    return np.where(flying, np.nan, static_limit(params)(normal))


def _height(params: dict[str, Any], commands: CommandedStrokes | None, pose: dict[str, np.ndarray],
            flying: np.ndarray) -> np.ndarray:
    """Height of the part above the surface under it, z − h(x, t), at the flying poses (NaN elsewhere; z
    itself when the strokes or the surface are unknown)."""
    height = np.where(flying, pose['z'], np.nan)
    centers, widths = params.get('surface.centers'), params.get('surface.widths')
    if commands is None or not centers or not widths or not flying.any():
        return height
    from ..physics.surface import surface_profile
    strokes = commands.at(pose['t'][flying])
    h = [float(surface_profile(np.array([x]), st, centers, widths)[0])
         for x, st in zip(pose['x'][flying], strokes, strict=True)]
    height[flying] = pose['z'][flying] - np.asarray(h)
    return height


def _joint_samples(log: LogReader, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray] | None:
    """The recorded joint states within [lo, hi] (t, strokes), for a log without commands."""
    if log.resolve('actuator/joint_states') is None:
        return None
    rows = [(m.publish_time_ns * 1e-9, list(m.message.position)) for m in log.messages(['actuator/joint_states'])]
    rows = [r for r in rows if lo <= r[0] <= hi and r[1]]
    if not rows:
        return None
    return np.array([r[0] for r in rows]), np.array([r[1] for r in rows])
