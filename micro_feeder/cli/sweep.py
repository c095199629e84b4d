"""``micro-feeder sweep``: distance per stroke over grids, sampled designs and Monte Carlo runs."""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

from tqdm import tqdm

from ..explore.designs import DESIGNS, Grid, RunPlan, Sampled, parse_axis, parse_perturbation, parse_range
from ..explore.evaluate import QUANTITIES, Job, model_for
from ..explore.runners import Runner, RunnerError
from ..explore.sweep import PointSummary, base_values, estimate_seconds, run_plan, too_big
from ..physics.parameters import ParameterError
from ..settings import SettingsError
from . import CommandError
from ._common import settings_from_args
from ._explore import add_runner_options, runner_from_args
from .simulate import add_run_options, describe_parts

SHOWN_ROWS = 40   # the terminal table shows at most this many rows (the CSV has them all)


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        'sweep', help='distance per stroke over a grid, a sampled design or a Monte Carlo',
        description='Run the offline simulation for every point of a design and write one row per run '
                    '(CSV, or JSON with --json): the varied parameters, the distance per stroke (only for '
                    'runs whose part settled: a part still in flight has travelled no distance yet), the '
                    'settled flag, the regime (stuck / slides / flies) and the transition counts; with '
                    'several parts (particle.x0 a list) also the impacts, the spacing and each part\'s '
                    'figures, and with --gate X the feed rate past x = X. Runs on local processes, or on a '
                    'Dask cluster with --scheduler.',
        epilog='Examples: micro-feeder sweep --vary stroke.frequency=100:5000:200 --plot; '
               'micro-feeder sweep --vary stroke.frequency=500:3000:40 --vary stroke.amplitude=20e-6:200e-6:40 '
               '--plot (a map); micro-feeder sweep --vary stroke.frequency=500:3000 --vary '
               'stroke.amplitude=20e-6:200e-6 --samples 200 --seed 1; micro-feeder sweep --vary '
               'stroke.frequency=500:2000:30 --perturb contact.friction_scale=normal:10% --replicates 50 '
               '--plot (bands); micro-feeder sweep --params config/travelling_wave.yaml --set '
               '"particle.x0=[0.4e-3,0.7e-3,1.0e-3]" --gate 0.9e-3 --vary stroke.amplitude=100e-6:200e-6:11 '
               '--plot --quantity feed_rate_hz (several parts). docs/explore.md and docs/parts.md have more.')
    add_run_options(parser, 'sweep')
    parser.add_argument('--vary', action='append', default=[], metavar='NAME=START:STOP:N | NAME=V1,V2,...',
                        help='a parameter to vary; repeat for a full grid (the product of the values). '
                             'With --samples: NAME=LOW:HIGH, the range to sample')
    parser.add_argument('--samples', type=int, metavar='N',
                        help='draw N points in the --vary ranges instead of a grid (see --design, --seed)')
    parser.add_argument('--design', choices=DESIGNS, default='lhs',
                        help='with --samples: lhs (Latin hypercube, default) or random')
    parser.add_argument('--perturb', action='append', default=[], metavar='NAME=DIST:SPREAD',
                        help='an uncertain parameter, drawn for every run: normal:SD, uniform:HALF_WIDTH '
                             '(in its unit, or ending in %% of its value) or lognormal:SIGMA; repeatable')
    parser.add_argument('--replicates', type=int, default=100, metavar='N',
                        help='with --perturb: Monte Carlo runs per point (default 100)')
    parser.add_argument('--seed', type=int, default=0, help='seed of --samples and --perturb draws (default 0)')
    parser.add_argument('--quantity', choices=tuple(QUANTITIES), metavar='COLUMN',
                        help='with --plot over 1 or 2 parameters (no --perturb): the result column to draw, e.g. '
                             'feed_rate_hz or collisions (several parts), max_speed_mps; default: the distance '
                             'per stroke (the mean conveying velocity on a map of a track)')
    add_runner_options(parser)
    parser.set_defaults(func=run)


def build_plan(args: argparse.Namespace) -> RunPlan:
    """The runs the options describe."""
    if not args.vary and not args.perturb:
        raise SettingsError('give at least one --vary NAME=START:STOP:N (or --perturb for a Monte Carlo)')
    if args.samples is not None:
        if not args.vary:
            raise SettingsError('--samples needs at least one --vary NAME=LOW:HIGH (the range to sample)')
        design = Sampled([parse_range(text) for text in args.vary], args.samples, args.seed, args.design)
    else:
        design = Grid([parse_axis(text) for text in args.vary])
    perturbations = tuple(parse_perturbation(text) for text in args.perturb)
    if perturbations and args.replicates < 1:
        raise SettingsError(f'--replicates {args.replicates}: at least 1')
    return RunPlan(design, perturbations, args.replicates if perturbations else 1, args.seed)


def run(args: argparse.Namespace) -> int:
    flat = settings_from_args(args)
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise CommandError(f'--duration must be a positive number of seconds, got {args.duration}')
    plan = build_plan(args)
    job = Job(flat, args.duration, args.gate)
    for run_number in (0, len(plan) - 1):           # refuse bad values before starting any worker
        try:
            model_for(job, plan.changes(run_number, base_values(job.base, plan.columns)))
        except ParameterError as err:
            raise SettingsError(str(err)) from err
    if args.quantity is not None and (args.plot is None or plan.replicates > 1):
        raise SettingsError(f'--quantity {args.quantity}: draws a column with --plot, over 1 or 2 parameters; a '
                            'Monte Carlo plot shows the distance per stroke' if args.plot is not None else
                            f'--quantity {args.quantity} needs --plot')
    if args.quantity is not None and args.quantity not in job.columns:
        raise SettingsError(f'--quantity {args.quantity}: not a column of these runs '
                            f'({"several parts" if job.several_parts else "one part"}'
                            f'{", a gate" if args.gate is not None else ", no --gate"})')
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise CommandError(f'cannot write to {err.filename}: {err.strerror}') from err
    runner = runner_from_args(args)
    with runner:
        estimate = estimate_seconds(job, plan, runner.workers)
        reason = too_big(len(plan), estimate)
        if reason and not args.force:
            raise CommandError(f'{reason} on {runner.where}: reduce the sweep, or add --force')
        started = time.perf_counter()
        try:
            counts, summary = _write_rows(job, plan, runner, out, args.json)
        except RunnerError as err:
            raise CommandError(str(err)) from err
    wall = time.perf_counter() - started
    return _report(args, plan, out, counts, summary, wall, runner.where, describe_runs(job, plan))


def describe_runs(job: Job, plan: RunPlan) -> str:
    """What the runs share, for plot titles: stroke shape and count, the part's start, the run length."""
    model = model_for(job, {})
    s = model.stroke
    parts = [f'{s.count} {s.waveform} stroke{"s" * (s.count > 1)} per run' if 'stroke.count' not in plan.columns
             else f'{s.waveform} strokes']
    for name, text in (('stroke.amplitude', f'{s.amplitude * 1e6:g} µm'), ('stroke.frequency', f'{s.frequency:g} Hz'),
                       ('particle.x0', describe_parts(model))):
        if name not in plan.columns:
            parts.append(text)
    parts += [f'{a.name} = {a.value(0):g}' for a in getattr(plan.design, 'axes', ()) if len(a) == 1]
    end = (f'runs of {job.duration:g} s' if job.duration else
           f'runs end when the part rests (at most {model.integration.settle_max:g} s after the last stroke)')
    return ', '.join(parts) + f'; {end}'


def _write_rows(job: Job, plan: RunPlan, runner: Runner, out: Path, as_json: bool
                ) -> tuple[dict[str, int], PointSummary | None]:
    """Stream the rows to DIR/sweep.csv (and, with --json, to stdout as they come); count the regimes."""
    columns = ('run', *(('point',) if plan.replicates > 1 else ()), *plan.columns, *job.columns)
    summary = PointSummary(plan) if plan.replicates > 1 else None
    counts: dict[str, int] = {}
    bar = tqdm(total=len(plan), file=sys.stderr, unit='run', desc='sweep', smoothing=0.1)
    try:
        with (out / 'sweep.csv').open('w', newline='') as handle:
            writer = csv.DictWriter(handle, fieldnames=columns)
            writer.writeheader()
            if as_json:
                sys.stdout.write(json.dumps({'parameters': list(plan.columns), 'design': plan.design.kind,
                                             'runs': len(plan)})[:-1] + ', "rows": [')
            for i, row in enumerate(run_plan(job, plan, runner, progress=bar.update)):
                writer.writerow(_csv_row(row))
                counts[row['regime']] = counts.get(row['regime'], 0) + 1
                counts['unsettled'] = counts.get('unsettled', 0) + (not row['settled'])
                if summary is not None:
                    summary.add(row)
                if as_json:
                    sys.stdout.write((', ' if i else '') + json.dumps(_json_row(row)))
    except OSError as err:
        raise CommandError(f'cannot write to {err.filename}: {err.strerror}') from err
    finally:
        bar.close()
    return counts, summary


def _csv_row(row: dict[str, Any]) -> dict[str, Any]:
    """A row as the CSV holds it: a list or a dict (each part's figures) as JSON text, None as empty."""
    return {k: json.dumps(v) if isinstance(v, list | dict) else v for k, v in row.items()}


def _json_row(row: dict[str, Any]) -> dict[str, Any]:
    """NaN (no distance: the run did not settle) as null, which JSON can carry."""
    return {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in row.items()}


def _report(args: argparse.Namespace, plan: RunPlan, out: Path, counts: dict[str, int],
            summary: PointSummary | None, wall: float, where: str, setting: str) -> int:
    summary_rows = list(summary.rows()) if summary is not None else []
    paths = [out / 'sweep.csv']
    try:
        if summary_rows:
            paths.append(out / 'sweep_summary.csv')
            with paths[-1].open('w', newline='') as handle:
                writer = csv.DictWriter(handle, fieldnames=list(summary_rows[0]))
                writer.writeheader()
                writer.writerows(summary_rows)
        if args.plot is not None:
            from ..plots.sweep import plot_sweep_table
            paths.append(plot_sweep_table(out / 'sweep.csv', plan, Path(args.plot) if args.plot else out / 'sweep.png',
                                          summary_rows, setting, args.quantity))
    except OSError as err:
        raise CommandError(f'cannot write to {err.filename}: {err.strerror}') from err
    except ValueError as err:
        raise CommandError(f'--plot: {err}') from err
    if args.json:
        tail = {'summary': [_json_row(r) for r in summary_rows], 'counts': counts, 'wall_time_s': wall,
                'where': where}
        sys.stdout.write('], ' + json.dumps(tail)[1:] + '\n')
        return 0
    if len(plan) <= SHOWN_ROWS and not summary_rows:
        _print_table(out / 'sweep.csv', plan)
    for row in summary_rows[:SHOWN_ROWS]:
        point = ', '.join(f'{k} {row[k]:.6g}' for k in plan.design.names)
        print(f"{point}: {row['mean_per_stroke_m'] * 1e6:.4g} ± {row['std_per_stroke_m'] * 1e6:.3g} um per stroke, "
              + ', '.join(f"{r} {row[f'fraction_{r}']:.0%}" for r in ('stuck', 'slides', 'flies'))
              + f", settled {row['fraction_settled']:.0%}")
    regimes = ', '.join(f'{k} {v}' for k, v in sorted(counts.items()))
    print(f'{len(plan)} runs in {wall:.2f} s on {where} ({regimes}); written: {", ".join(map(str, paths))}')
    if counts.get('unsettled'):
        print(f"{counts['unsettled']} runs ended before the part came to rest: no distance given for them "
              '(a longer --duration lets them land)')
    return 0


# Columns of several parts shown in the terminal table when the runs have them: heading, column, scale.
PARTS_SHOWN = (('impacts', 'collisions', 1.0), ('min spacing (um)', 'spacing_min_m', 1e6),
               ('feed rate (1/s)', 'feed_rate_hz', 1.0))


def _print_table(path: Path, plan: RunPlan) -> None:
    names = plan.columns
    with path.open() as handle:
        rows = list(csv.DictReader(handle))
    extra = [(heading, column, scale) for heading, column, scale in PARTS_SHOWN if rows and column in rows[0]]
    print(' '.join(f'{n:>20}' for n in names) + f" {'per stroke (um)':>16} {'regime':>7} {'settled':>8}"
          + ''.join(f' {heading:>16}' for heading, _, _ in extra))
    for row in rows:
        per_stroke = float(row['distance_per_stroke_m']) * 1e6
        shown = f'{per_stroke:.6g}' if math.isfinite(per_stroke) else f"({row['final_mode']})"
        print(' '.join(f'{float(row[n]):>20.6g}' for n in names)
              + f" {shown:>16} {row['regime']:>7} {row['settled']:>8}"
              + ''.join(f' {_scaled_cell(row[column], scale):>16}' for _, column, scale in extra))


def _scaled_cell(text: str, scale: float) -> str:
    """A CSV cell as a number times ``scale`` (6 significant digits), or '-' when empty."""
    return f'{float(text) * scale:.6g}' if text else '-'
