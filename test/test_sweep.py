"""``micro-feeder sweep``: grids, sampled designs, Monte Carlo, the settled flag and regimes, plots.

Every row is checked against an independent single run of the model (FeederModel.advance), not against
the sweep's own earlier output.
"""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

from micro_feeder.cli import main
from micro_feeder.explore.designs import Grid, RunPlan, Sampled, parse_axis, parse_perturbation
from micro_feeder.explore.evaluate import Job
from micro_feeder.explore.runners import InProcess, LocalProcesses
from micro_feeder.explore.sweep import run_plan
from micro_feeder.physics.dynamics import FeederModel
from micro_feeder.settings import known_parameters


def single_run(**changes: float) -> tuple[float, str, dict[str, int]]:
    """Distance (m), final mode and counters of one plain run (2 strokes), continued until it settles."""
    flat = {'stroke.count': 2, **changes}
    model = FeederModel.from_settings(flat)
    state = model.initial_state()
    model.advance(state, model.default_duration())
    model.settle(state)
    return state.distance, state.mode, state.transitions


def read_csv(path) -> list[dict[str, str]]:
    with open(path) as handle:
        return list(csv.DictReader(handle))


def test_two_vary_options_build_the_full_grid_and_match_single_runs(tmp_path, capsys):
    code = main(['sweep', '--vary', 'stroke.frequency=600,1000,3000', '--vary', 'stroke.amplitude=60e-6:120e-6:2',
                 '--set', 'stroke.count=2', '--processes', '2', '--json', '--out', str(tmp_path)])
    assert code == 0
    table = json.loads(capsys.readouterr().out)
    rows = table['rows']
    assert table['parameters'] == ['stroke.frequency', 'stroke.amplitude'] and len(rows) == 3 * 2
    assert [(r['stroke.frequency'], r['stroke.amplitude']) for r in rows] == [
        (f, a) for f in (600.0, 1000.0, 3000.0) for a in (60e-6, 120e-6)]
    for row in rows:
        distance, mode, counts = single_run(**{'stroke.frequency': row['stroke.frequency'],
                                               'stroke.amplitude': row['stroke.amplitude']})
        assert row['final_mode'] == mode and row['final_offset_m'] == distance
        assert {k: row[k] for k in counts} == counts
        assert row['settled'] == (mode == 'stuck')
        if row['settled']:
            assert row['distance_m'] == distance and row['distance_per_stroke_m'] == distance / 2
        else:
            assert row['distance_m'] is None and row['distance_per_stroke_m'] is None   # no mid-flight distance
        expected = 'flies' if counts['take_off'] else 'slides' if counts['stick_to_slip'] else 'stuck'
        assert row['regime'] == expected
    assert {r['regime'] for r in rows} == {'stuck', 'slides', 'flies'}
    assert len(read_csv(tmp_path / 'sweep.csv')) == 6


def test_grid_rows_are_the_product_in_order() -> None:
    grid = Grid([parse_axis('stroke.frequency=100:5000:4'), parse_axis('particle.x0=1e-4,2e-4,3e-4'),
                 parse_axis('stroke.count=1:3:3')])
    assert len(grid) == 36
    assert grid.point(0) == (100.0, 1e-4, 1) and grid.point(35) == (5000.0, 3e-4, 3)
    assert grid.point(1 * 9 + 2 * 3 + 1)[0] == pytest.approx(np.linspace(100, 5000, 4)[1], abs=0)


def test_a_huge_axis_is_never_materialised() -> None:
    axis = parse_axis('stroke.frequency=100:5000:100000000')
    assert len(Grid([axis])) == 100_000_000 and axis.value(99_999_999) == 5000.0


def test_latin_hypercube_is_reproducible_from_its_seed_and_stratified() -> None:
    ranges = [('stroke.frequency', 500.0, 3000.0), ('stroke.amplitude', 20e-6, 200e-6)]
    a, b, c = Sampled(ranges, 50, seed=7), Sampled(ranges, 50, seed=7), Sampled(ranges, 50, seed=8)
    assert np.array_equal(a.points, b.points) and not np.array_equal(a.points, c.points)
    for j, (_, low, high) in enumerate(ranges):
        strata = np.floor((a.points[:, j] - low) / (high - low) * 50).astype(int)
        assert sorted(strata) == list(range(50))           # one point per stratum: a Latin hypercube
    r = Sampled(ranges, 50, seed=7, method='random')
    assert np.array_equal(r.points, Sampled(ranges, 50, seed=7, method='random').points)


def test_sampled_sweep_cli_rows_match_the_design(tmp_path, capsys):
    assert main(['sweep', '--vary', 'stroke.frequency=500:3000', '--vary', 'stroke.amplitude=20e-6:200e-6',
                 '--samples', '8', '--seed', '3', '--set', 'stroke.count=2', '--processes', '1', '--json',
                 '--out', str(tmp_path)]) == 0
    rows = json.loads(capsys.readouterr().out)['rows']
    design = Sampled([('stroke.frequency', 500.0, 3000.0), ('stroke.amplitude', 20e-6, 200e-6)], 8, seed=3)
    assert [(r['stroke.frequency'], r['stroke.amplitude']) for r in rows] == [design.point(i) for i in range(8)]


def test_monte_carlo_with_zero_spread_equals_the_plain_run() -> None:
    job = Job({'stroke.count': 2})
    plain = list(run_plan(job, RunPlan(Grid([parse_axis('stroke.frequency=800,1200')])), InProcess()))
    plan = RunPlan(Grid([parse_axis('stroke.frequency=800,1200')]),
                   (parse_perturbation('contact.friction_scale=normal:0'),), replicates=3, seed=5)
    mc = list(run_plan(job, plan, InProcess()))
    assert len(mc) == 6 and [r['point'] for r in mc] == [0, 0, 0, 1, 1, 1]
    for row in mc:
        reference = plain[row['point']]
        assert row['contact.friction_scale'] == known_parameters()['contact.friction_scale'][1]
        assert row['distance_m'] == reference['distance_m'] and row['stick_to_slip'] == reference['stick_to_slip']


def test_monte_carlo_draws_do_not_depend_on_the_workers() -> None:
    plan = RunPlan(Grid([parse_axis('stroke.frequency=900,1300')]),
                   (parse_perturbation('contact.friction_scale=lognormal:0.3'),
                    parse_perturbation('particle.x0=uniform:20%')), replicates=4, seed=11)
    job = Job({'stroke.count': 2})
    here = list(run_plan(job, plan, InProcess()))
    with LocalProcesses(2, window=2) as runner:
        there = list(run_plan(job, plan, runner))
    assert here == there
    scales = [r['contact.friction_scale'] for r in here]
    assert len(set(scales)) == 8 and all(0.010814 * math.exp(-2) < s < 0.010814 * math.exp(2) for s in scales)
    assert all(0.4e-3 <= r['particle.x0'] <= 0.6e-3 for r in here)


def test_monte_carlo_cli_summary_and_bands(tmp_path, capsys):
    assert main(['sweep', '--vary', 'stroke.frequency=600:1400:5', '--perturb', 'contact.friction_scale=normal:15%',
                 '--replicates', '6', '--set', 'stroke.count=2', '--processes', '2', '--out', str(tmp_path),
                 '--plot']) == 0
    out = capsys.readouterr().out
    assert 'um per stroke' in out and (tmp_path / 'sweep.png').stat().st_size > 10_000
    rows, summary = read_csv(tmp_path / 'sweep.csv'), read_csv(tmp_path / 'sweep_summary.csv')
    assert len(rows) == 30 and len(summary) == 5
    for point in summary:
        mine = [r for r in rows if r['point'] == point['point']]
        settled = [float(r['distance_per_stroke_m']) for r in mine if r['settled'] == 'True']
        assert float(point['mean_per_stroke_m']) == pytest.approx(np.mean(settled), rel=1e-12, abs=1e-18)
        assert float(point['fraction_slides']) == sum(r['regime'] == 'slides' for r in mine) / 6


def test_map_and_curve_plots(tmp_path, capsys):
    assert main(['sweep', '--vary', 'stroke.frequency=400:3000:6', '--vary', 'stroke.amplitude=30e-6:150e-6:5',
                 '--set', 'stroke.count=2', '--out', str(tmp_path), '--plot', str(tmp_path / 'map.png')]) == 0
    assert (tmp_path / 'map.png').stat().st_size > 10_000
    assert main(['sweep', '--vary', 'stroke.amplitude=20e-6:200e-6:6', '--set', 'stroke.count=2',
                 '--out', str(tmp_path), '--plot']) == 0
    assert (tmp_path / 'sweep.png').stat().st_size > 10_000
    capsys.readouterr()
    assert main(['sweep', '--vary', 'stroke.amplitude=20e-6:200e-6:2', '--vary', 'stroke.frequency=1e3,2e3',
                 '--vary', 'particle.x0=1e-4,2e-4', '--out', str(tmp_path), '--plot']) == 2
    assert '1 or 2 varied parameters' in capsys.readouterr().err


@pytest.mark.parametrize('args, message', [
    (['--vary', 'stroke.frequency=1e3,2e3', '--vary', 'stroke.frequency=3e3'], 'given twice'),
    (['--vary', 'surface.centers=0:1:3'], 'scalar'),
    (['--vary', 'stroke.frequency=1:2', '--samples', '5', '--vary', 'nonsense=1:2'], 'not a parameter'),
    (['--vary', 'stroke.frequency=3000:1000', '--samples', '5'], 'LOW < HIGH'),
    (['--vary', 'stroke.frequency=1000:3000:5', '--samples', '5'], 'NAME=LOW:HIGH'),
    (['--perturb', 'contact.beta=normal:1%', '--samples', '5'], '--samples needs'),
    (['--vary', 'stroke.frequency=1e3', '--perturb', 'contact.beta=gauss:1'], 'normal:SD'),
    (['--vary', 'stroke.frequency=-5,1000'], 'stroke.frequency'),
    (['--vary', 'stroke.frequency=100:5000:100000000'], '--force'),
    ([], '--vary'),
])
def test_bad_sweeps_are_refused_with_a_reason(args, message, tmp_path, capsys):
    assert main(['sweep', *args, '--processes', '1', '--out', str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert message in err, err
