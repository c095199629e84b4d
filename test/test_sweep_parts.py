"""``micro-feeder sweep`` (and ``optimize``) with several parts (issue 28 item 5; docs/parts.md).

Every row of a sweep over a parameter is checked against ``micro-feeder simulate --json`` run at the same
point: the same parts' figures (each part's distance, mode, transitions, largest speed), impacts, spacing
and, with ``--gate``, feed rate, number for number; the row's one-part columns are checked against the
parts they describe (mean distance, summed counters, regime, largest speed).
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from micro_feeder.cli import main
from micro_feeder.explore.evaluate import Job
from micro_feeder.explore.optimize import Problem

SIZE = 100e-6
# Figures simulate --json gives for several parts that a sweep row carries under the same name.
SHARED = ('parts', 'collisions', 'settled', 'sim_time_s', 'spacing_mean_m', 'spacing_min_m')
GATE = ('gate_m', 'crossings', 'feed_rate_hz', 'headway_s')


def set_options(flat: dict) -> list[str]:
    return [arg for name, value in flat.items() for arg in ('--set', f'{name}={value!r}')]


def run_json(args: list[str]) -> dict:
    """``micro-feeder ARGS --json``: its one JSON object."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main([*args, '--json']) == 0
    return json.loads(out.getvalue())


@st.composite
def track_rows(draw) -> dict:
    """Three parts on a vibrating track (Coulomb contact), started with different velocities so that they
    meet, a gate ahead of the last one, and two stroke amplitudes to sweep over."""
    gaps = draw(st.lists(st.floats(0.0, 200e-6), min_size=2, max_size=2))
    starts = [0.0, SIZE + gaps[0], 2 * SIZE + gaps[0] + gaps[1]]
    base = {'surface.kind': 'track', 'contact.model': 'coulomb', 'stroke.waveform': 'sine',
            'stroke.frequency': draw(st.sampled_from([150.0, 300.0])), 'stroke.count': 8,
            'contact.mu': draw(st.floats(0.2, 0.6)), 'track.vibration_angle': 0.5,
            'particle.x0': starts, 'particle.v0': draw(st.lists(st.floats(-0.03, 0.06), min_size=3, max_size=3)),
            'particle.restitution': draw(st.sampled_from([0.0, 0.5, 1.0]))}
    amplitudes = draw(st.lists(st.floats(5e-6, 60e-6), min_size=2, max_size=2, unique=True))
    gate = starts[-1] + draw(st.floats(10e-6, 300e-6))
    return {'base': base, 'amplitudes': amplitudes, 'gate': gate}


@settings(max_examples=4, derandomize=True, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(case=track_rows())
def test_sweep_rows_are_simulate_of_the_same_point(case, tmp_path_factory):
    out = tmp_path_factory.mktemp('sweep')
    common = [*set_options(case['base']), '--duration', '0.04', '--gate', repr(case['gate']), '--out', str(out)]
    amplitudes = ','.join(repr(a) for a in case['amplitudes'])
    table = run_json(['sweep', *common, '--vary', f'stroke.amplitude={amplitudes}', '--processes', '1'])
    rows = table['rows']
    assert [row['stroke.amplitude'] for row in rows] == case['amplitudes']
    for row in rows:
        alone = run_json(['simulate', *common, '--set', f"stroke.amplitude={row['stroke.amplitude']!r}"])
        assert {name: row[name] for name in (*SHARED, *GATE)} == {name: alone[name] for name in (*SHARED, *GATE)}
        parts = alone['parts']
        assert len(parts) == 3 and row['error'] == ''
        counts = {name: sum(p['transitions'][name] for p in parts) for name in parts[0]['transitions']}
        assert {name: row[name] for name in counts} == counts
        assert row['regime'] == ('flies' if counts['take_off'] else 'slides' if counts['stick_to_slip'] else 'stuck')
        assert row['final_offset_m'] == pytest.approx(sum(p['distance_m'] for p in parts) / 3, rel=1e-15, abs=0)
        assert row['max_speed_mps'] == max(p['max_speed_mps'] for p in parts)
        if row['settled']:
            assert row['distance_m'] == row['final_offset_m']
        else:
            assert row['distance_m'] is None
    with (out / 'sweep.csv').open() as handle:
        written = list(csv.DictReader(handle))
    assert [json.loads(line['parts']) for line in written] == [row['parts'] for row in rows]
    assert [int(line['collisions']) for line in written] == [row['collisions'] for row in rows]


TRAVELLING_WAVE = ['--params', 'config/travelling_wave.yaml', '--set', 'stroke.count=10',
                   '--set', 'particle.x0=[0.4e-3,0.55e-3,0.7e-3,0.85e-3,1.0e-3]']


def test_a_wave_sweep_maps_impacts_and_feed_rate(tmp_path, capsys):
    """Over the travelling wave's amplitude the parts meet and pass the gate: the curve of the feed rate and
    the map of the impacts are drawn, and the terminal table shows the impacts."""
    args = [*TRAVELLING_WAVE, '--gate', '0.9e-3', '--out', str(tmp_path), '--processes', '2']
    assert main(['sweep', *args, '--vary', 'stroke.amplitude=100e-6:200e-6:3', '--plot', str(tmp_path / 'rate.png'),
                 '--quantity', 'feed_rate_hz']) == 0
    out = capsys.readouterr().out
    assert 'impacts' in out and 'feed rate (1/s)' in out
    rows = list(csv.DictReader((tmp_path / 'sweep.csv').open()))
    assert any(int(r['collisions']) > 0 for r in rows) and any(int(r['crossings']) > 0 for r in rows)
    assert all(len(json.loads(r['parts'])) == 5 for r in rows)
    assert (tmp_path / 'rate.png').stat().st_size > 10_000
    assert main(['sweep', *args, '--vary', 'stroke.amplitude=100e-6:200e-6:3', '--vary', 'stroke.frequency=800,1000',
                 '--plot', str(tmp_path / 'impacts.png'), '--quantity', 'collisions']) == 0
    assert (tmp_path / 'impacts.png').stat().st_size > 10_000


def test_one_part_with_a_gate_gives_simulates_gate_figures(tmp_path):
    common = ['--set', 'stroke.count=3', '--gate', '0.45e-3', '--out', str(tmp_path)]
    rows = run_json(['sweep', *common, '--vary', 'stroke.frequency=800,1500', '--processes', '1'])['rows']
    assert 'collisions' not in rows[0] and 'parts' not in rows[0]
    for row in rows:
        alone = run_json(['simulate', *common, '--set', f"stroke.frequency={row['stroke.frequency']!r}"])
        assert {name: row[name] for name in GATE} == {name: alone[name] for name in GATE}
        assert row['final_offset_m'] == pytest.approx(alone['distance_m'], rel=1e-12, abs=1e-18)


@pytest.mark.parametrize('args, message', [
    (['--vary', 'stroke.frequency=800,900', '--plot', '--quantity', 'feed_rate_hz'], 'not a column'),
    ([*TRAVELLING_WAVE, '--vary', 'stroke.frequency=800,900', '--quantity', 'collisions'], 'needs --plot'),
    ([*TRAVELLING_WAVE, '--vary', 'particle.x0=1e-4,2e-4'], 'a list in the base settings cannot be swept'),
    ([*TRAVELLING_WAVE, '--vary', 'stroke.frequency=800,900', '--perturb', 'contact.friction_scale=normal:1%',
      '--replicates', '2', '--plot', '--quantity', 'collisions'], 'Monte Carlo'),
])
def test_refused_with_the_reason(args, message, tmp_path, capsys):
    assert main(['sweep', *args, '--out', str(tmp_path), '--processes', '1']) != 0
    assert message in capsys.readouterr().err


def test_an_objective_of_the_feed_rate_reads_the_parts_row(tmp_path):
    """``optimize`` shares the rows: a user objective sees the feed rate of several parts past the gate."""
    module = tmp_path / 'feed_objective.py'
    module.write_text('def negative_feed_rate(row):\n    return -row["feed_rate_hz"]\n')
    job = Job({'surface.kind': 'track', 'contact.model': 'coulomb', 'contact.mu': 0.3, 'stroke.amplitude': 0.0,
               'particle.x0': [0.0, 3e-4], 'particle.v0': [0.05, 0.0], 'particle.restitution': 1.0}, 0.05, 4e-4)
    problem = Problem(job, ('contact.mu',), ((0.2, 0.5),), objective=f'{module}:negative_feed_rate')
    score, row = problem.evaluate([0.3])
    assert row['collisions'] == 1 and row['crossings'] == 1 and math.isclose(row['feed_rate_hz'], 1 / 0.05)
    assert score == -row['feed_rate_hz']
