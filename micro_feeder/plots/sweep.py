"""Sweep figures: distance per stroke against one parameter, maps over two, Monte Carlo bands; or any
numeric result column (``quantity``: e.g. the feed rate or the impacts of several parts) over one or two.

Distances are drawn only for runs whose part settled (a part still in flight has not travelled a
distance yet); unsettled runs are marked where they are, by regime. Axes use units that suit the
values (µm, mm, kHz ...).
"""

from __future__ import annotations

import csv
import textwrap
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import ListedColormap, Normalize, SymLogNorm
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from ..explore.designs import Perturbation, RunPlan
from ..explore.evaluate import QUANTITIES
from ..settings import known_parameters
from .dynamics import save

REGIME_STYLE = {'stuck': ('0.55', 'o'), 'slides': ('C0', 'o'), 'flies': ('C3', '^')}
REGIME_LABEL = {'stuck': 'stays stuck', 'slides': 'slides (in contact)', 'flies': 'took off, landed'}
# (factor, unit label) by SI unit, largest unit first: the first that shows the largest value ≥ 1 is used.
SCALES = {'m': [(1e3, 'mm'), (1e6, 'µm'), (1e9, 'nm')], 'Hz': [(1e-6, 'MHz'), (1e-3, 'kHz'), (1.0, 'Hz')],
          'kg': [(1e6, 'mg'), (1e9, 'µg'), (1e12, 'ng')], 'N': [(1e3, 'mN'), (1e6, 'µN'), (1e9, 'nN')],
          's': [(1.0, 's'), (1e3, 'ms'), (1e6, 'µs')], 'm/s': [(1.0, 'm/s'), (1e3, 'mm/s'), (1e6, 'µm/s')]}


def unit_scale(unit: str, values: Sequence[float] | np.ndarray) -> tuple[float, str]:
    """(factor, label) that shows ``values`` (given in ``unit``) with at least 1 before the point."""
    magnitudes = np.abs(np.asarray(values, dtype=float))
    magnitudes = magnitudes[np.isfinite(magnitudes) & (magnitudes > 0)]
    top = magnitudes.max() if magnitudes.size else 0.0
    scales = SCALES.get(unit, [(1.0, unit)])
    return next(((f, label) for f, label in scales if top * f >= 1.0), scales[-1])


def axis_label(name: str, unit_label: str) -> str:
    return f'{name} ({unit_label})' if unit_label else name


def _scaled(name: str, values: np.ndarray) -> tuple[np.ndarray, str]:
    factor, label = unit_scale(known_parameters()[name][0].unit, values)
    return values * factor, axis_label(name, label)


def read_table(path: Path) -> dict[str, np.ndarray]:
    """The sweep CSV as columns (numbers as float, the rest as str)."""
    with Path(path).open() as handle:
        rows = list(csv.DictReader(handle))
    if not rows:
        raise ValueError(f'{path} holds no run')
    columns: dict[str, Any] = {}
    for key in rows[0]:
        raw = [r[key] for r in rows]
        try:
            columns[key] = np.array([float(v) if v != '' else np.nan for v in raw])
        except ValueError:
            columns[key] = np.array(raw)
    columns['settled'] = np.array([r['settled'] == 'True' for r in rows])
    return columns


def plot_sweep_table(table: Path, plan: RunPlan, path: Path | str, summary: Sequence[dict[str, Any]] = (),
                     setting: str = '', quantity: str | None = None) -> Path:
    """The figure that suits the plan: a curve (1 parameter), a map (2), Monte Carlo bands or a map of
    the mean (with --perturb). ``setting``: a line saying what the runs share (strokes, part ...).
    ``quantity``: a column of :data:`~micro_feeder.explore.evaluate.QUANTITIES` to draw instead of the
    distance per stroke (over 1 or 2 parameters, no Monte Carlo). Raises ValueError for 3 or more varied
    parameters, or a quantity with a Monte Carlo."""
    setting = textwrap.fill(setting, 80)
    points = [plan.design.point(i) for i in range(len(plan.design))]
    names = tuple(n for j, n in enumerate(plan.design.names) if len({p[j] for p in points}) > 1)  # a lone value:
    if quantity is not None:                                                                  # not an axis
        if summary:
            raise ValueError(f'{quantity}: a Monte Carlo plot shows the distance per stroke; drop --quantity')
        return plot_quantity(names, read_table(table), quantity, path, setting, gridded=plan.design.kind == 'grid')
    if summary:
        context = '\n'.join(filter(None, (setting, _context(plan))))
        if len(names) == 1:
            return plot_bands(names[0], summary, path, context)
        if len(names) == 2:
            cols = {k: np.array([r[k] for r in summary], dtype=float) for k in summary[0]}
            return plot_map(names, cols, 'mean_per_stroke_m', _regime_of_fractions(cols), path,
                            f'Mean distance per stroke over {plan.replicates} runs per point', context)
        return plot_distribution(read_table(table), path, context)
    data = read_table(table)
    if len(names) == 1:
        return plot_curve(names[0], data, path, setting)
    if len(names) == 2:
        regime_index = np.array([list(REGIME_STYLE).index(r) if r in REGIME_STYLE else -1 for r in data['regime']])
        velocity = data.get('mean_velocity_mps')
        if velocity is not None and np.isfinite(velocity).any():     # a conveying velocity: maps as papers do
            return plot_map(names, data, velocity, regime_index, path, 'Mean conveying velocity (whole periods '
                            "of the burst's second half)", setting, gridded=plan.design.kind == 'grid',
                            quantity=('mean velocity', 'm/s'))
        distance = np.where(data['settled'], data['distance_per_stroke_m'], np.nan)
        return plot_map(names, data, distance, regime_index, path, 'Distance per stroke', setting,
                        gridded=plan.design.kind == 'grid')
    raise ValueError(f'a plot shows 1 or 2 varied parameters, this sweep varies {len(names) or "none"}')


def plot_quantity(names: Sequence[str], data: dict[str, np.ndarray], quantity: str, path: Path | str,
                  setting: str = '', gridded: bool = True) -> Path:
    """The column ``quantity`` of every run (not only the settled ones) against one parameter (a marker per
    regime, joined by a line), or a map over two (a linear colour scale from 0 when no value is negative).
    Raises ValueError for 3 or more varied parameters."""
    what, unit = QUANTITIES[quantity]
    values = np.asarray(data[quantity], dtype=float)
    regime_index = np.array([list(REGIME_STYLE).index(r) if r in REGIME_STYLE else -1 for r in data['regime']])
    if len(names) == 2:
        finite = values[np.isfinite(values)]
        return plot_map(names, data, values, regime_index, path, what[:1].upper() + what[1:], setting,
                        gridded=gridded, quantity=(what, unit), linear=bool(finite.size and finite.min() >= 0),
                        missing='no value (e.g. under two crossings of the gate, or a run that failed)')
    if len(names) != 1:
        raise ValueError(f'a plot shows 1 or 2 varied parameters, this sweep varies {len(names) or "none"}')
    x, xlabel = _scaled(names[0], data[names[0]])
    order = np.argsort(x)
    factor, unit_label = unit_scale(unit, values)
    y = values * factor
    fig, ax = plt.subplots(figsize=(8, 4.8))
    ax.plot(x[order], y[order], '-', color='C0', lw=0.8, alpha=0.6)
    for regime, (color, marker) in REGIME_STYLE.items():
        selected = data['regime'] == regime
        if selected.any():
            ax.plot(x[selected], y[selected], marker, color=color, ms=4, ls='none', label=REGIME_LABEL[regime])
    ax.set(xlabel=xlabel, ylabel=axis_label(what, unit_label),
           title=f'{what[:1].upper() + what[1:]} vs {names[0]}' + (f'\n{setting}' if setting else ''))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return save(fig, path)


def _context(plan: RunPlan) -> str:
    """One line naming the uncertain parameters and their distributions."""
    def spread(p: Perturbation) -> str:
        if p.distribution == 'lognormal':
            return f'σ of log {p.spread:g}'
        what = 'sd' if p.distribution == 'normal' else 'half-width'
        return f'{what} {p.spread:.0%} of value' if p.relative else f'{what} {p.spread:.3g}'
    return 'uncertain: ' + ', '.join(f'{p.name} {p.distribution} ({spread(p)})' for p in plan.perturbations)


def plot_curve(name: str, data: dict[str, np.ndarray], path: Path | str, setting: str = '') -> Path:
    """Distance per stroke vs one parameter, a marker style per regime; flight points are not joined to
    contact points; unsettled runs drawn as open markers at the x axis (no distance)."""
    x, xlabel = _scaled(name, data[name])
    order = np.argsort(x)
    per_stroke = data['distance_per_stroke_m']
    factor, unit = unit_scale('m', per_stroke)
    y = per_stroke * factor
    fig, ax = plt.subplots(figsize=(8, 4.8))
    contact = data['settled'] & (data['regime'] != 'flies')
    xs, ys = x[order], np.where(contact[order], y[order], np.nan)
    ax.plot(xs, ys, '-', color='C0', lw=0.8, alpha=0.6)          # joins contact runs only
    for regime, (color, marker) in REGIME_STYLE.items():
        sel = (data['regime'] == regime) & data['settled']
        if sel.any():
            ax.plot(x[sel], y[sel], marker, color=color, ms=4, ls='none',
                    label=REGIME_LABEL[regime])
        open_ = (data['regime'] == regime) & ~data['settled']
        if open_.any():
            ax.plot(x[open_], np.zeros(open_.sum()), marker, mfc='none', color=color, ms=6, ls='none',
                    label=f'{regime}: not at rest when the run ended (no distance)')
    ax.axhline(0.0, color='k', lw=0.5)
    ax.set(xlabel=xlabel, ylabel=f'distance per stroke ({unit})',
           title=f'Distance per stroke vs {name}' + (f'\n{setting}' if setting else ''))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return save(fig, path)


def _regime_of_fractions(cols: dict[str, np.ndarray]) -> np.ndarray:
    """The most frequent regime per Monte Carlo point (0 stuck, 1 slides, 2 flies)."""
    return np.argmax(np.vstack([cols[f'fraction_{r}'] for r in REGIME_STYLE]), axis=0)


def plot_map(names: Sequence[str], data: dict[str, np.ndarray], value: str | np.ndarray,
             regime_index: np.ndarray, path: Path | str, title: str, context: str = '',
             gridded: bool = True, quantity: tuple[str, str] = ('distance per stroke', 'm'), linear: bool = False,
             missing: str | None = None) -> Path:
    """Heat map of ``quantity`` (what, SI unit; distance per stroke by default) over two parameters
    (symmetric log colour scale: micrometres of creep and millimetres of flight on one map; with ``linear``
    a linear one from 0, for counts and rates), regime boundaries drawn as lines, cells with no value (the
    part not at rest) hatched; ``missing`` says what a cell with no value means."""
    values = data[value] if isinstance(value, str) else value
    x, xlabel = _scaled(names[0], data[names[0]])
    y, ylabel = _scaled(names[1], data[names[1]])
    factor, unit = unit_scale(quantity[1], values)
    z = values * factor
    finite = np.abs(z[np.isfinite(z)])
    top = max(finite.max(), 1e-3) if finite.size else 1.0
    norm = (Normalize(vmin=0.0, vmax=top) if linear else
            SymLogNorm(linthresh=max(top * 1e-3, 1e-3), vmin=-top, vmax=top, base=10))
    cmap = 'viridis' if linear else 'coolwarm'
    fig, ax = plt.subplots(figsize=(8.5, 6))
    if gridded:
        xs, ys = np.unique(x), np.unique(y)
        shape = (xs.size, ys.size)
        grid = lambda v: v.reshape(shape).T  # noqa: E731 - rows of the table: names[0] slowest
        mesh = ax.pcolormesh(xs, ys, grid(z), cmap=cmap, norm=norm, shading='nearest')
        missing = np.ma.masked_where(np.isfinite(grid(z)), np.ones(shape[::-1]))
        ax.pcolor(xs, ys, missing, hatch='///', cmap=ListedColormap(['none']), shading='nearest',
                  edgecolor='0.6', lw=0)
        if xs.size > 1 and ys.size > 1:
            lines = ax.contour(xs, ys, grid(regime_index.astype(float)), levels=[0.5, 1.5],
                               colors=['k', 'k'], linewidths=[1.2, 2.0], linestyles=['--', '-'])
            ax.clabel(lines, fmt={0.5: 'stuck | slides', 1.5: 'contact | flight'}, fontsize=7)
    else:
        mesh = ax.scatter(x, y, c=z, cmap=cmap, norm=norm, s=25)
        ax.scatter(x[~np.isfinite(z)], y[~np.isfinite(z)], marker='x', color='0.4', s=20)
        for i, (regime, (color, marker)) in enumerate(REGIME_STYLE.items()):
            sel = regime_index == i
            ax.scatter(x[sel], y[sel], marker=marker, facecolors='none', edgecolors=color, s=60, lw=0.6,
                       label=regime)
        ax.add_artist(ax.legend(fontsize=8, title='regime', loc='upper left'))
    bar = fig.colorbar(mesh, ax=ax, label=axis_label(quantity[0], unit))
    if not linear:
        bar.set_ticks(symlog_ticks(norm.linthresh, top))
    if not np.isfinite(z).all():
        label = missing or ('part not at rest when the run ended: no distance' if quantity[1] == 'm' else
                            'no value (a run shorter than the burst, or one stroke)')
        handle = (Patch(facecolor='none', edgecolor='0.5', hatch='///', label=label) if gridded else
                  Line2D([], [], marker='x', color='0.4', ls='none', label=label))
        ax.legend(handles=[handle], fontsize=8, loc='lower right')
    ax.set(xlabel=xlabel, ylabel=ylabel,
           title=title + (f'\n{context}' if context else '')
           + ('\nlines: regime boundaries (stuck | slides | flies)' if gridded else '\nmarker outline: regime'))
    return save(fig, path)


def symlog_ticks(linthresh: float, top: float) -> list[float]:
    """0 and ±10^k for the decades between the linear threshold and the top of a symmetric log scale."""
    decades = 10.0 ** np.arange(np.ceil(np.log10(linthresh)), np.floor(np.log10(top)) + 1)
    return [*(-decades[::-1]), 0.0, *decades]


def plot_bands(name: str, summary: Sequence[dict[str, Any]], path: Path | str, context: str) -> Path:
    """Monte Carlo over one parameter: mean ± standard deviation and the 5–95 % band of the distance per
    stroke (settled runs), and below it the fraction of runs in each regime."""
    cols = {k: np.array([r[k] for r in summary], dtype=float) for k in summary[0]}
    x, xlabel = _scaled(name, cols[name])
    factor, unit = unit_scale('m', np.concatenate([cols['p5_per_stroke_m'], cols['p95_per_stroke_m']]))
    fig, (ax, ax_r) = plt.subplots(2, 1, figsize=(8, 6.5), sharex=True, gridspec_kw={'height_ratios': [3, 1.4]})
    ax.fill_between(x, cols['p5_per_stroke_m'] * factor, cols['p95_per_stroke_m'] * factor, color='C0', alpha=0.2,
                    label='5–95 % of runs')
    mean, std = cols['mean_per_stroke_m'] * factor, cols['std_per_stroke_m'] * factor
    ax.fill_between(x, mean - std, mean + std, color='C0', alpha=0.35, label='mean ± 1 sd')
    ax.plot(x, mean, '.-', color='C0', lw=1, label='mean')
    ax.axhline(0.0, color='k', lw=0.5)
    ax.set(ylabel=f'distance per stroke ({unit})',
           title=f'Distance per stroke vs {name}, {int(cols["runs"][0])} runs per point\n{context}')
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    bottom = np.zeros_like(x)
    for regime, (color, _) in REGIME_STYLE.items():
        share = cols[f'fraction_{regime}']
        ax_r.fill_between(x, bottom, bottom + share, color=color, alpha=0.6, step='mid', label=regime)
        bottom = bottom + share
    ax_r.plot(x, cols['fraction_settled'], 'k--', lw=1, label='settled')
    ax_r.set(xlabel=xlabel, ylabel='fraction of runs', ylim=(0, 1))
    ax_r.legend(fontsize=7, ncol=4, loc='lower left')
    return save(fig, path)


def plot_distribution(data: dict[str, np.ndarray], path: Path | str, context: str) -> Path:
    """Monte Carlo of one point: histogram of the distance per stroke of the settled runs."""
    per_stroke = data['distance_per_stroke_m'][data['settled']]
    factor, unit = unit_scale('m', per_stroke)
    fig, ax = plt.subplots(figsize=(8, 4.8))
    ax.hist(per_stroke * factor, bins=30, color='C0')
    shares = ', '.join(f'{r} {np.mean(data["regime"] == r):.0%}' for r in REGIME_STYLE)
    ax.set(xlabel=f'distance per stroke ({unit})', ylabel='runs',
           title=f'Distance per stroke over {len(data["run"])} runs ({shares}; '
                 f'{np.mean(~data["settled"]):.0%} not at rest)\n{context}')
    ax.grid(alpha=0.3)
    return save(fig, path)


def plot_convergence(history: Sequence[tuple[int, float]], objective: str, score: str, path: Path | str) -> Path:
    """Best score found against evaluations used (one point per generation); scores of runs that break
    a constraint (≥ 1e12) are left out."""
    evaluations = np.array([h[0] for h in history], dtype=float)
    best = np.array([h[1] for h in history], dtype=float)
    feasible = best < 1e12
    fig, ax = plt.subplots(figsize=(8, 4.5))
    ax.plot(evaluations[feasible], best[feasible], '.-', color='C0')
    if (~feasible).any():
        ax.text(0.02, 0.95, f'{(~feasible).sum()} generations with no feasible run yet', transform=ax.transAxes,
                fontsize=8, va='top')
    ax.set(xlabel='evaluations (model runs)', ylabel=f'best {score}',
           title=f'Convergence of the search: {objective}')
    ax.grid(alpha=0.3)
    return save(fig, path)
