"""``micro-feeder calibrate LOG [LOG...] --fit NAME[,NAME...]``: fit model parameters to recorded runs."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from ..settings import SettingsError, parse_override
from . import CommandError
from ._explore import add_runner_options, runner_from_args


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        'calibrate', help='fit model parameters so that re-simulated logs match their recorded poses',
        description='Re-simulate each log\'s recorded commands as resim does and fit the named model parameters '
                    '(least squares with bounds, scipy.optimize.least_squares) so that the re-simulated part '
                    'position (x, z) matches every recorded pose of every log. Reports the fitted values with '
                    'their 1-sigma uncertainty (from the Jacobian), the residual, and says when the fit does '
                    'not converge or a parameter is not identifiable from the logs (exit status 1).',
        epilog='Example: micro-feeder calibrate out/run1 out/run2 --fit contact.friction_scale,particle.mass '
               '--set contact.friction_scale=0.012 --plot. The logs must be readable at the same path on '
               'every Dask worker when --scheduler is used. docs/explore.md.')
    parser.add_argument('logs', nargs='+', metavar='LOG', help='log directories or .mcap files, fitted together')
    parser.add_argument('--fit', required=True, metavar='NAME[,NAME...]', help='the model parameters to fit')
    parser.add_argument('--set', action='append', default=[], dest='starts', metavar='NAME=START',
                        help='starting value of a fitted parameter (default: the value recorded in the first '
                             'log); repeatable')
    parser.add_argument('--bounds', action='append', default=[], metavar='NAME=LOW:HIGH',
                        help='bounds of a fitted parameter (default: a factor 10 around the start, within the '
                             'parameter\'s own limits); repeatable')
    parser.add_argument('--max-evaluations', type=int, default=60, metavar='N',
                        help='least-squares iterations allowed (default 60)')
    parser.add_argument('--out', metavar='DIR', default='out', help='directory for calibrate.json (and .png)')
    parser.add_argument('--json', action='store_true', help='print one JSON object and nothing else')
    parser.add_argument('--plot', metavar='FILE.png', nargs='?', const='',
                        help='write the overlay plot (default file: DIR/calibrate.png)')
    add_runner_options(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..explore.calibrate import CalibrationError, calibrate, load_recording, resimulate_poses
    from ..explore.designs import parse_range

    names = [n.strip() for n in args.fit.split(',') if n.strip()]
    starts = dict(parse_override(text) for text in args.starts)
    foreign = sorted(set(starts) - set(names))
    if foreign:
        raise SettingsError(f'--set {foreign[0]}: not in --fit (calibrate\'s --set gives starting values)')
    bounds = {name: (lo, hi) for name, lo, hi in (parse_range(text, '--bounds') for text in args.bounds)}
    for path in args.logs:
        if not Path(path).exists():
            raise CommandError(f'{path}: no such log')
    try:
        first = load_recording(args.logs[0])
        start = {name: float(starts.get(name, first.flat.get(name, 0.0))) for name in names}
    except (CalibrationError, TypeError, ValueError) as err:
        raise CommandError(str(err)) from err
    started = time.perf_counter()
    with runner_from_args(args) as runner:
        try:
            result = calibrate(args.logs, start, runner, bounds, args.max_evaluations,
                               progress=None if args.json else _progress)
        except CalibrationError as err:
            raise CommandError(str(err)) from err
        finally:
            if not args.json:
                print(file=sys.stderr)                 # end the progress line
    wall = time.perf_counter() - started
    report = {**result.as_dict(), 'wall_time_s': wall, 'where': runner.where}
    out = Path(args.out)
    plot_path = None
    try:
        out.mkdir(parents=True, exist_ok=True)
        (out / 'calibrate.json').write_text(json.dumps(report, indent=2))
        if args.plot is not None:
            from ..plots.calibrate import plot_calibration
            values = {p.name: p.value for p in result.parameters}
            recordings = [load_recording(p) for p in args.logs]
            plot_path = plot_calibration(args.logs, [r.pose_times for r in recordings], [r.poses for r in recordings],
                                         [resimulate_poses(p, start) for p in args.logs],
                                         [resimulate_poses(p, values) for p in args.logs], values,
                                         Path(args.plot) if args.plot else out / 'calibrate.png')
    except OSError as err:
        raise CommandError(f'cannot write to {err.filename}: {err.strerror}') from err
    ok = result.converged and all(p.identifiable for p in result.parameters)
    if args.json:
        print(json.dumps(report))
        return 0 if ok else 1
    print(f'calibrate: {"fitted" if ok else "NOT FITTED CLEANLY"}: {len(args.logs)} log(s), {result.residual_count} '
          f'residuals, rms {result.rms_start:.3e} m at the start -> {result.rms:.3e} m (max {result.max_abs:.3e} m), '
          f'{result.evaluations} evaluations in {wall:.1f} s on {runner.where}')
    for p in result.parameters:
        value = (f'{p.value:.8g} ± {p.sigma:.2g}' if p.identifiable else f'{p.value:.8g} (not identifiable)')
        print(f'  {p.name:<28} {value}   (start {p.start:.6g})')
    for problem in result.problems:
        print(f'  note: {problem}')
    print(f'written: {out / "calibrate.json"}' + (f', {plot_path}' if plot_path else ''))
    return 0 if ok else 1


def _progress(evaluations: int, rms: float) -> None:
    print(f'\rcalibrate: {evaluations} evaluations, rms residual {rms:.3e} m', end='', file=sys.stderr, flush=True)
