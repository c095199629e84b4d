"""``micro-feeder optimize``: search model parameters for an objective (differential evolution)."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from tqdm import tqdm

from ..explore.designs import is_integer, parse_range
from ..explore.evaluate import Job
from ..explore.optimize import CONSTRAINTS, DIRECTIONS, OptimizeError, Problem, optimize
from ..explore.runners import RunnerError
from ..settings import SettingsError
from . import CommandError
from ._common import settings_from_args
from ._explore import add_runner_options, runner_from_args
from .simulate import add_run_options


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        'optimize', help='search stroke (or any numeric model) parameters for an objective',
        description='Search the named parameters within their bounds with differential evolution '
                    '(scipy.optimize), each generation run in parallel on local processes or a Dask cluster, '
                    'for the largest distance per stroke, a target distance per stroke with the smallest '
                    'amplitude, or your own function of the run. Reports the optimum, its run, the '
                    'evaluations used, and (--plot) the convergence.',
        epilog='Examples: micro-feeder optimize --param stroke.frequency=500:2500 --param '
               'stroke.amplitude=20e-6:200e-6 --constraint never-flies --set stroke.count=5; '
               'micro-feeder optimize --param stroke.amplitude=20e-6:200e-6 --target=-5e-6 --tolerance 0.2e-6; '
               'micro-feeder optimize --param particle.x0=0:1.5e-3 --objective my_module:score. docs/explore.md.')
    add_run_options(parser, 'optimize')
    parser.add_argument('--param', action='append', default=[], required=True, metavar='NAME=LOW:HIGH',
                        help='a parameter to search, with its bounds; repeatable')
    parser.add_argument('--objective', default='max-distance', metavar='max-distance | target | MODULE:FUNCTION',
                        help='max-distance (default); target (with --target); or a function called with the '
                             'run\'s row (dict of the sweep columns and parameters) returning a number to '
                             'minimise: module:function or path/to/file.py:function')
    parser.add_argument('--direction', choices=DIRECTIONS, default='negative',
                        help='max-distance: toward negative x (default; toward the bump centre), positive, or '
                             'any (largest magnitude)')
    parser.add_argument('--target', type=float, metavar='M',
                        help='target distance per stroke (m): the smallest amplitude that gives it within '
                             '--tolerance (implies --objective target); write --target=-5e-6 for a negative value')
    parser.add_argument('--tolerance', type=float, default=None, metavar='M',
                        help='with --target: accepted deviation (m per stroke; default 2 %% of the target)')
    parser.add_argument('--constraint', action='append', default=[], choices=CONSTRAINTS,
                        help='never-flies (no take-off), settled (part at rest at the end), within-travel '
                             '(stroke inside the piezo limits); repeatable')
    parser.add_argument('--generations', type=int, default=30, metavar='N', help='at most N generations (30)')
    parser.add_argument('--popsize', type=int, default=10, metavar='K',
                        help='population: K × number of parameters (10)')
    parser.add_argument('--seed', type=int, default=0, help='seed of the search (default 0)')
    add_runner_options(parser)
    parser.set_defaults(func=run)


def build_problem(args: argparse.Namespace) -> Problem:
    flat = settings_from_args(args)
    ranges = [parse_range(text, '--param') for text in args.param]
    names = tuple(name for name, _, _ in ranges)
    if len(set(names)) != len(names):
        raise SettingsError('--param: give each parameter once')
    objective = 'target' if args.target is not None else args.objective
    if objective == 'target' and args.target is None:
        raise SettingsError('--objective target needs --target M (distance per stroke, m)')
    tolerance = args.tolerance if args.tolerance is not None else abs(args.target or 0.0) * 0.02
    try:
        return Problem(Job(flat, args.duration, args.gate), names, tuple((lo, hi) for _, lo, hi in ranges), objective,
                       args.direction, args.target or 0.0, tolerance, tuple(dict.fromkeys(args.constraint)),
                       tuple(is_integer(n) for n in names))
    except OptimizeError as err:
        raise SettingsError(str(err)) from err


def run(args: argparse.Namespace) -> int:
    problem = build_problem(args)
    out = Path(args.out)
    runner = runner_from_args(args)
    bar = tqdm(total=args.generations, file=sys.stderr, unit='gen', desc='optimize')

    def progress(evaluations: int, best: float) -> None:
        bar.set_postfix(evaluations=evaluations, best=f'{best:.4g}')
        bar.update()

    started = time.perf_counter()
    with runner:
        try:
            result = optimize(problem, runner, args.seed, args.generations, args.popsize, progress=progress)
        except RunnerError as err:
            raise CommandError(str(err)) from err
        finally:
            bar.close()
    wall = time.perf_counter() - started
    plot_path = None
    try:
        out.mkdir(parents=True, exist_ok=True)
        (out / 'optimize.json').write_text(json.dumps({**result.as_dict(), 'wall_time_s': wall}, indent=2))
        if args.plot is not None:
            from ..plots.sweep import plot_convergence
            plot_path = plot_convergence(result.history, describe_objective(problem),
                                         SCORES.get(problem.objective, 'score'),
                                         Path(args.plot) if args.plot else out / 'optimize.png')
    except OSError as err:
        raise CommandError(f'cannot write to {err.filename}: {err.strerror}') from err
    if args.json:
        print(json.dumps({**result.as_dict(), 'wall_time_s': wall, 'where': runner.where}))
        return 0 if result.feasible else 1
    print(f'objective: {describe_objective(problem)}')
    for name, value in result.optimum.items():
        print(f'  {name} = {value:.6g}')
    row = result.row
    distance = (f"{row['distance_per_stroke_m'] * 1e6:.6g} um per stroke" if row['settled']
                else f"no distance (part {row['final_mode']} at the end of the run)")
    print(f"run at the optimum: {distance}, regime {row['regime']}, score {result.score:.6g}")
    print(f'{result.evaluations} evaluations in {result.generations} generations, {wall:.1f} s on {runner.where}; '
          f'{"converged" if result.converged else "stopped: " + result.message}; written: {out / "optimize.json"}'
          + (f', {plot_path}' if plot_path else ''))
    if not result.feasible:
        print('no run satisfied the constraints: the optimum shown breaks them (widen the bounds?)')
        return 1
    return 0


SCORES = {'max-distance': 'score (µm per stroke; lower is better)', 'target': 'amplitude (µm)'}


def describe_objective(problem: Problem) -> str:
    if problem.objective == 'max-distance':
        what = {'negative': 'largest distance per stroke toward −x', 'positive': 'largest distance per stroke '
                'toward +x', 'any': 'largest distance per stroke (either way)'}[problem.direction]
    elif problem.objective == 'target':
        what = (f'smallest amplitude giving {problem.target * 1e6:g} ± {problem.tolerance * 1e6:g} um per stroke')
    else:
        what = f'minimise {problem.objective}'
    return what + (f' ({", ".join(problem.constraints)})' if problem.constraints else '')
