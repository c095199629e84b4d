"""``micro-feeder simulate``: one offline run of the particle on the actuated surface."""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ..physics.dynamics import MODES, FeederModel, RunResult, SimulationError
from ..physics.parameters import ParameterError
from ..physics.parts import PartsModel, PartsResult
from ..physics.parts.figures import gate_figures, run_figures, sample_step
from ..settings import SettingsError
from . import CommandError
from ._common import add_model_options, settings_from_args


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        'simulate', help='offline run: stick / slide / flight history of the part',
        description='Simulate the part on the actuated surface for the configured strokes and write the '
                    'time series (CSV) and, with --plot, the velocity / friction / position / mode '
                    'history.',
        epilog='Examples: micro-feeder simulate --plot; micro-feeder simulate --set stroke.frequency=3000 '
               '--duration 0.3 --json; micro-feeder simulate --params config/feeder.yaml --out out')
    add_run_options(parser, 'simulate')
    parser.set_defaults(func=run)


def add_run_options(parser: argparse.ArgumentParser, stem: str) -> None:
    """The model options plus --duration, --out, --json and --plot (outputs DIR/STEM.csv, .png)."""
    add_model_options(parser)
    parser.add_argument('--duration', type=float, metavar='SECONDS',
                        help='simulated time per run (default: end of the last stroke + '
                             'integration.settling_time, then on until the part is stuck again, at most '
                             'integration.settle_max more)')
    parser.add_argument('--out', metavar='DIR', default='out',
                        help=f'directory for {stem}.csv (and {stem}.png); default: out')
    parser.add_argument('--json', action='store_true', help='print one JSON object and nothing else')
    parser.add_argument('--plot', metavar='FILE.png', nargs='?', const='',
                        help=f'write the plot (default file: DIR/{stem}.png)')
    parser.add_argument('--gate', type=float, metavar='X',
                        help='report the feed rate past x = X (m): parts per second crossing it forward '
                             '(with several parts, particle.x0 as a list, also the spacing between neighbours)')


def build_model(flat: dict[str, Any], **overrides: Any) -> FeederModel:
    """The model of the flat settings; a refused value becomes a user-facing SettingsError."""
    try:
        return FeederModel.from_settings(flat, **overrides)
    except ParameterError as err:
        raise SettingsError(str(err)) from err


def write_csv(result: RunResult, path: Path) -> Path:
    """The time series, one row per step and event, mode written as its name; SI units."""
    with path.open('w', newline='') as handle:
        writer = csv.writer(handle)
        writer.writerow(result.columns)
        mode_column = result.columns.index('mode')
        for row in result.data:
            values = [repr(float(v)) for v in row]
            values[mode_column] = MODES[int(row[mode_column])]
            writer.writerow(values)
    return path


def run(args: argparse.Namespace) -> int:
    flat = settings_from_args(args)
    model = build_model(flat)
    if args.duration is not None and not (np.isfinite(args.duration) and args.duration > 0):
        raise CommandError(f'--duration must be a positive number of seconds, got {args.duration}')
    model.run(duration=1e-6)              # load the compiled kernel (numba cache) before timing
    if model.particle.n_parts > 1:
        return run_parts(args, model)
    started = time.perf_counter()
    try:
        # rows every 1/200 stroke for smooth plots, at most ~5000 of them (over the default length)
        result = model.run(duration=args.duration, output_step=sample_step(model, args.duration))
    except SimulationError as err:
        raise CommandError(str(err)) from err
    summary = {**result.summary(), 'wall_time_s': time.perf_counter() - started}
    if args.gate is not None:
        summary.update(gate_figures(result['t'], result['x'], args.gate))

    def plot(path: Path) -> Path:
        from ..plots.dynamics import plot_history
        return plot_history(result, path, title=describe(model))

    return report(args, model, summary, format_summary, lambda path: write_csv(result, path), plot, 'time series')


def run_parts(args: argparse.Namespace, model: FeederModel) -> int:
    """``simulate`` with several parts: per-part figures, impacts, the gate and spacing figures, the
    positions of every part against time (CSV, and the space–time picture with --plot)."""
    parts = PartsModel(model)
    started = time.perf_counter()
    try:
        result = parts.run(duration=args.duration, output_step=sample_step(model, args.duration))
    except SimulationError as err:
        raise CommandError(str(err)) from err
    summary = {**run_figures(result, args.gate), 'wall_time_s': time.perf_counter() - started}

    def plot(path: Path) -> Path:
        from ..plots.parts import plot_space_time
        return plot_space_time(result, path, title=describe(model), gate=args.gate, size=model.particle.size)

    return report(args, model, summary, format_parts_summary, lambda path: write_parts_csv(result, path), plot,
                  'positions')


def report(args: argparse.Namespace, model: FeederModel, summary: dict[str, Any],
           format_figures: Callable[[dict[str, Any]], str], write: Callable[[Path], Path],
           plot: Callable[[Path], Path], written: str) -> int:
    """The end of ``simulate``: ``write`` the CSV into ``--out`` (``simulate.csv``), ``plot`` with --plot
    (``simulate.png`` there unless a path is given), then the summary as JSON (``--json``) or as text
    (``format_figures``) with where the ``written`` data went. A file that cannot be written is one clear
    error."""
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        csv_path = write(out / 'simulate.csv')
        plot_path = plot(Path(args.plot) if args.plot else out / 'simulate.png') if args.plot is not None else None
    except OSError as err:
        raise CommandError(f'cannot write to {err.filename}: {err.strerror}') from err
    if args.json:
        json.dump(summary, sys.stdout)
        print()
        return 0
    print(describe(model))
    print(format_figures(summary))
    print(f'{written} written to {csv_path}' + (f', plot to {plot_path}' if plot_path else ''))
    return 0


def write_parts_csv(result: PartsResult, path: Path) -> Path:
    """Every part's position (m) and mode at each sample: columns t, x_0, mode_0, x_1, mode_1 ..."""
    n = result.x.shape[1]
    with path.open('w', newline='') as handle:
        writer = csv.writer(handle)
        writer.writerow(['t', *(name for k in range(n) for name in (f'x_{k}', f'mode_{k}'))])
        for t, xs, modes in zip(result.t, result.x, result.modes, strict=True):
            writer.writerow([repr(float(t)), *(value for x, mode in zip(xs, modes, strict=True)
                                                for value in (repr(float(x)), MODES[int(mode)]))])
    return path


def format_parts_summary(summary: dict[str, Any]) -> str:
    """The human summary of a many-part run: one line per part, impacts, spacing and the gate."""
    lines = ['part  distance (um)  final mode  transitions (stick_to_slip, slip_to_stick, take_off, landing)']
    for k, part in enumerate(summary['parts']):
        counts = ', '.join(str(v) for v in part['transitions'].values())
        lines.append(f"{k:>4}  {part['distance_m'] * 1e6:>13.6g}  {part['final_mode']:<10}  {counts}")
    lines.append(f"impacts      {summary['collisions']}")
    if summary.get('spacing_mean_m') is not None:
        lines.append(f"spacing      mean {summary['spacing_mean_m'] * 1e6:.6g} um, "
                     f"min {summary['spacing_min_m'] * 1e6:.6g} um"
                     ' between neighbouring centres at the end')
    if 'gate_m' in summary:
        rate = summary['feed_rate_hz']
        lines.append(f"gate         x = {summary['gate_m'] * 1e3:g} mm: {summary['crossings']} crossing(s), "
                     f"feed rate {rate if rate is None else f'{rate:.6g}'} parts/s")
    lines.append(f"sim time     {summary['sim_time_s'] * 1e3:.4g} ms in {summary['wall_time_s'] * 1e3:.1f} ms wall"
                 + ('' if summary['settled'] else ' (not every part settled)'))
    return '\n'.join(lines)


def describe(model: FeederModel) -> str:
    """One line naming the stroke and the part's position."""
    s = model.stroke
    if model.surface.kind == 'track':
        surface = (f'track at {math.degrees(model.track.inclination):g} deg, vibrating at '
                   f'{math.degrees(model.track.vibration_angle):g} deg to it')
    else:
        surface = f'{model.n_actuators} actuator(s)'
        if model.surface.thickness > 0.0:
            surface += f', plate {model.surface.thickness * 1e3:g} mm thick'
    contact = f'coulomb mu = {model.contact.mu:g}' if model.contact.model == 'coulomb' else model.contact.preset
    return (f'{s.waveform} stroke {s.amplitude * 1e6:g} um at {s.frequency:g} Hz x {s.count}, {surface}, '
            f'{describe_parts(model)}, contact {contact}, landing {model.landing.law}')


def describe_parts(model: FeederModel) -> str:
    """Where the part starts (``part at x0 = 0.5 mm``), or how many parts start where."""
    positions = model.particle.start_positions
    if len(positions) == 1:
        return f'part at x0 = {positions[0] * 1e3:g} mm'
    return (f'{len(positions)} parts from x0 = {positions[0] * 1e3:g} to {positions[-1] * 1e3:g} mm, '
            f'size {model.particle.size * 1e6:g} um, restitution {model.particle.restitution:g}')


def format_summary(summary: dict[str, Any]) -> str:
    """The human summary of a run."""
    counts = ', '.join(f'{k} {v}' for k, v in summary['transitions'].items())
    return '\n'.join([
        f"distance     {summary['distance_m'] * 1e6:.6g} um",
        f"final mode   {summary['final_mode']}" + ('' if summary['settled'] else
                                                   ' (not settled: the distance is not where the part rests)'),
        f'transitions  {counts}',
        f"max speed    {summary['max_speed_mps'] * 1e3:.4g} mm/s",
        *([f"conveying    {summary['mean_velocity_mps'] * 1e3:.6g} mm/s mean over the burst's second half"]
          if summary.get('mean_velocity_mps') is not None else []),
        *([f"throw number {summary['throw_number']:.4g}"] if summary.get('throw_number') is not None else []),
        *([f"gate         x = {summary['gate_m'] * 1e3:g} mm: {summary['crossings']} crossing(s), feed rate "
           f"{summary['feed_rate_hz']:.6g} parts/s"] if 'gate_m' in summary else []),
        f"sim time     {summary['sim_time_s'] * 1e3:.4g} ms in {summary['wall_time_s'] * 1e3:.1f} ms wall"])
