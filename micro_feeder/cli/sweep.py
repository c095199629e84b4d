"""``micro-feeder sweep``: distance per stroke vs one parameter, in parallel (seed Fig. 12)."""

from __future__ import annotations

import argparse
import csv
import json
import multiprocessing
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from ..physics.dynamics import FeederModel, SimulationError
from ..settings import SettingsError, known_parameters
from . import CommandError
from ._common import settings_from_args
from .simulate import add_run_options, build_model

# Parameters whose change needs new contact tables; every other sweep reuses the base model's.
CONTACT_INPUTS = ('contact.', 'particle.mass', 'particle.area', 'gravity')
COLUMNS = ('distance_m', 'distance_per_stroke_m', 'final_mode', 'stick_to_slip', 'slip_to_stick',
           'take_off', 'landing', 'max_speed_mps')


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        'sweep', help='distance per stroke vs one parameter, on all cores (seed Fig. 12)',
        description='Run the offline simulation for each value of one scalar parameter (in parallel, '
                    'one process per core) and write the distance per stroke as CSV and, with --plot, '
                    'as a plot.',
        epilog='Examples: micro-feeder sweep --vary stroke.frequency=100:5000:200 --plot; '
               'micro-feeder sweep --vary stroke.amplitude=20e-6:200e-6:10 --json; '
               'micro-feeder sweep --vary particle.x0=0.1e-3,0.5e-3,1e-3')
    add_run_options(parser, 'sweep')
    parser.add_argument('--vary', required=True, metavar='NAME=START:STOP:N or NAME=V1,V2,...',
                        help='the parameter to vary: N evenly spaced values from START to STOP, or a list')
    parser.add_argument('--processes', type=int, default=os.cpu_count() or 1, metavar='N',
                        help='worker processes (default: all cores)')
    parser.set_defaults(func=run)


def parse_vary(text: str) -> tuple[str, list[float]]:
    """``stroke.frequency=100:5000:200`` -> (name, 200 values); ``x=1,2,3`` -> (name, [1, 2, 3])."""
    name, sep, spec = text.partition('=')
    name = name.strip()
    known = known_parameters()
    if not sep or name not in known:
        raise SettingsError(f'--vary expects NAME=START:STOP:N or NAME=V1,V2,... with a known parameter '
                            f'name, got {text!r}')
    kind = known[name][0].kind
    if kind not in ('float', 'int'):
        raise SettingsError(f'--vary {name}: only scalar numeric parameters can be swept ({kind})')
    try:
        if ':' in spec:
            start, stop, count = spec.split(':')
            values = np.linspace(float(start), float(stop), int(count)).tolist()
        else:
            values = [float(v) for v in spec.split(',') if v.strip()]
    except ValueError as err:
        raise SettingsError(f'--vary {text!r}: {err}') from err
    if not values:
        raise SettingsError(f'--vary {text!r}: no values')
    if kind == 'int':
        values = [round(v) for v in values]
    return name, values


_BASE: dict[str, Any] = {}


def _start_worker(flat: dict[str, Any], name: str, duration: float | None) -> None:
    if not _BASE:
        _BASE.update(model=build_model(flat), flat=flat, name=name, duration=duration)


def _run_one(value: float) -> dict[str, Any]:
    base: FeederModel = _BASE['model']
    name = _BASE['name']
    reuse = not name.startswith(CONTACT_INPUTS)
    model = build_model({**_BASE['flat'], name: value},
                        contact_model=base.contact_model if reuse else None)
    state = model.initial_state()
    model.advance(state, _BASE['duration'] or model.default_duration())
    counts = state.transitions
    return {name: value, 'distance_m': state.distance,
            'distance_per_stroke_m': state.distance / model.stroke.count, 'final_mode': state.mode,
            **counts, 'max_speed_mps': state.max_speed}


def sweep(flat: dict[str, Any], name: str, values: Sequence[float], processes: int = 1,
          duration: float | None = None, progress: bool = True) -> list[dict[str, Any]]:
    """One row per value (in order): distances, final mode, transition counts, max speed.

    The base model (and its contact tables) is built once and inherited by the forked workers; the
    compiled kernel comes from numba's on-disk cache, so a worker starts in well under a second.
    """
    _BASE.clear()
    _start_worker(flat, name, duration)
    _BASE['model'].run(duration=1e-4)                  # load the compiled kernel before forking
    bar = tqdm(total=len(values), file=sys.stderr, disable=not progress, unit='run', desc=name)
    rows = []
    try:
        if processes <= 1:
            for value in values:
                rows.append(_run_one(value))
                bar.update()
        else:
            methods = multiprocessing.get_all_start_methods()
            context = multiprocessing.get_context('fork' if 'fork' in methods else None)
            chunk = max(1, len(values) // (8 * processes))
            with context.Pool(processes, initializer=_start_worker, initargs=(flat, name, duration)) as pool:
                for row in pool.imap(_run_one, values, chunksize=chunk):
                    rows.append(row)
                    bar.update()
    finally:
        bar.close()
    return rows


def run(args: argparse.Namespace) -> int:
    flat = settings_from_args(args)
    name, values = parse_vary(args.vary)
    for value in (values[0], values[-1]):             # refuse bad values before starting the workers
        build_model({**flat, name: value})
    started = time.perf_counter()
    try:
        rows = sweep(flat, name, values, max(1, args.processes), args.duration, progress=True)
    except SimulationError as err:
        raise CommandError(str(err)) from err
    wall = time.perf_counter() - started
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        csv_path = out / 'sweep.csv'
        with csv_path.open('w', newline='') as handle:
            writer = csv.DictWriter(handle, fieldnames=(name, *COLUMNS))
            writer.writeheader()
            writer.writerows(rows)
        plot_path = None
        if args.plot is not None:
            from ..plots.dynamics import plot_sweep
            unit = known_parameters()[name][0].unit
            plot_path = plot_sweep(name, [r[name] for r in rows], [r['distance_per_stroke_m'] for r in rows],
                                   [r['take_off'] > 0 for r in rows],
                                   Path(args.plot) if args.plot else out / 'sweep.png', unit)
    except OSError as err:
        raise CommandError(f'cannot write to {err.filename}: {err.strerror}') from err
    if args.json:
        json.dump({'parameter': name, 'rows': rows, 'wall_time_s': wall}, sys.stdout)
        print()
        return 0
    print(f"{name:>22} {'per stroke (um)':>16} {'final mode':>11} {'slips':>6} {'flights':>8}")
    for row in rows:
        print(f"{row[name]:>22.6g} {row['distance_per_stroke_m'] * 1e6:>16.6g} {row['final_mode']:>11} "
              f"{row['stick_to_slip']:>6} {row['take_off']:>8}")
    print(f'{len(rows)} runs in {wall:.2f} s; table written to {csv_path}'
          + (f', plot to {plot_path}' if plot_path else ''))
    return 0
