"""``micro-feeder optimize``: the optimum found equals the one a brute-force grid establishes (within the
grid's spacing), with and without a constraint, and with a user's function."""

from __future__ import annotations

import json

import numpy as np
import pytest

from micro_feeder.cli import main
from micro_feeder.explore.evaluate import Job, evaluate
from micro_feeder.explore.optimize import Problem, optimize, stroke_range
from micro_feeder.explore.runners import InProcess, LocalProcesses
from micro_feeder.physics.dynamics import FeederModel

BASE = {'stroke.count': 2, 'stroke.frequency': 1200.0}


def brute_force(job: Job, name: str, values: np.ndarray, feasible=lambda row: row['settled']) -> tuple[float, float]:
    """(argmin, min) of the distance per stroke over ``values``, among feasible runs."""
    best = (np.nan, np.inf)
    for v in values:
        row = evaluate(job, {name: float(v)})
        if feasible(row) and row['distance_per_stroke_m'] < best[1]:
            best = (float(v), row['distance_per_stroke_m'])
    return best


def test_largest_distance_matches_a_brute_force_grid() -> None:
    job = Job(BASE)
    spacing = 0.01e-3
    x_best, d_best = brute_force(job, 'particle.x0', np.arange(0.1e-3, 1.4e-3 + spacing / 2, spacing))
    assert 0.3e-3 < x_best < 1.2e-3, 'the optimum must be inside the bounds, or the test proves little'
    problem = Problem(job, ('particle.x0',), ((0.1e-3, 1.4e-3),))
    with LocalProcesses(2) as runner:
        result = optimize(problem, runner, seed=1, max_generations=40)
    assert result.feasible and abs(result.optimum['particle.x0'] - x_best) <= spacing
    assert result.row['distance_per_stroke_m'] <= d_best                  # at least as good as the grid
    assert result.row['distance_per_stroke_m'] == pytest.approx(d_best, rel=1e-3)
    assert result.evaluations > 0 and result.history and result.history[-1][0] <= result.evaluations


def test_never_flies_keeps_the_optimum_below_take_off() -> None:
    job = Job({'stroke.count': 2})
    spacing = 10.0
    frequencies = np.arange(800.0, 2500.0 + spacing / 2, spacing)
    f_best, d_best = brute_force(job, 'stroke.frequency', frequencies,
                                 lambda row: row['settled'] and row['take_off'] == 0)
    flies = [f for f in frequencies if evaluate(job, {'stroke.frequency': float(f)})['take_off']]
    assert flies and f_best < min(flies) <= f_best + spacing       # the best contact run is at the take-off edge
    problem = Problem(job, ('stroke.frequency',), ((800.0, 2500.0),), constraints=('never-flies',))
    result = optimize(problem, InProcess(), seed=3, max_generations=40)
    assert result.feasible and result.row['take_off'] == 0
    assert abs(result.optimum['stroke.frequency'] - f_best) <= spacing
    assert result.row['distance_per_stroke_m'] <= 0.95 * d_best < 0    # within 5 % of the grid's best, or better


def test_target_with_the_smallest_amplitude_matches_a_brute_force_grid(tmp_path, capsys) -> None:
    job = Job(BASE)
    target, tolerance, spacing = -3e-6, 0.15e-6, 0.5e-6
    amplitudes = np.arange(40e-6, 200e-6, spacing)
    hits = [a for a in amplitudes if abs(evaluate(job, {'stroke.amplitude': float(a)})['distance_per_stroke_m']
                                         - target) <= tolerance]
    assert hits and hits[0] > 41e-6, 'the answer must lie inside the bounds'
    assert main(['optimize', '--param', 'stroke.amplitude=40e-6:200e-6', f'--target={target}', '--tolerance',
                 str(tolerance), '--set', 'stroke.count=2', '--set', 'stroke.frequency=1200', '--processes', '2',
                 '--generations', '40', '--json', '--out', str(tmp_path)]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result['feasible'] and abs(result['run']['distance_per_stroke_m'] - target) <= tolerance
    assert abs(result['optimum']['stroke.amplitude'] - hits[0]) <= spacing


def test_user_function_and_cli_json(tmp_path, capsys):
    module = tmp_path / 'my_objective.py'
    module.write_text('def closest_to_half_mm(row):\n    return abs(row["particle.x0"] - 0.5e-3)\n')
    code = main(['optimize', '--param', 'particle.x0=0.1e-3:1.4e-3', '--objective', f'{module}:closest_to_half_mm',
                 '--set', 'stroke.count=2', '--processes', '1', '--generations', '40', '--json', '--out', str(tmp_path),
                 '--plot'])
    assert code == 0
    result = json.loads(capsys.readouterr().out)
    assert result['optimum']['particle.x0'] == pytest.approx(0.5e-3, abs=2e-6) and result['evaluations'] > 10
    assert (tmp_path / 'optimize.png').stat().st_size > 10_000 and (tmp_path / 'optimize.json').exists()


def test_within_travel_uses_the_whole_stroke() -> None:
    model = FeederModel.from_settings({'stroke.waveform': 'sine', 'stroke.amplitude': 150e-6})
    low, high = stroke_range(model)
    assert low == pytest.approx(-150e-6, rel=1e-3) and high == pytest.approx(150e-6, rel=1e-3)
    problem = Problem(Job({'stroke.waveform': 'sine', 'stroke.count': 2, 'piezo.stroke_min': 0.0}),
                      ('stroke.amplitude',), ((10e-6, 150e-6),), constraints=('within-travel',))
    assert problem.evaluate([150e-6])[1]['settled']
    assert problem.evaluate([150e-6])[1]['violation'] > 0                   # below piezo.stroke_min = 0
    assert problem.evaluate([150e-6])[0] >= 1e12


@pytest.mark.parametrize('args, message', [
    (['--param', 'stroke.frequency=3000:1000'], 'LOW < HIGH'),
    (['--param', 'stroke.frequency=1000:3000', '--objective', 'no_such_module:f'], 'no_such_module'),
    (['--param', 'stroke.frequency=1000:3000', '--objective', 'target'], '--target'),
])
def test_bad_problems_are_refused(args, message, tmp_path, capsys):
    assert main(['optimize', *args, '--out', str(tmp_path), '--processes', '1']) == 2
    assert message in capsys.readouterr().err
