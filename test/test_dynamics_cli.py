"""micro-feeder simulate (sweep: test_sweep.py): options, JSON keys, CSV and PNG outputs, refused values."""

import csv
import json

import pytest

from micro_feeder.cli import main


def test_simulate_json_csv_and_plot(tmp_path, capsys):
    assert main(['simulate', '--json', '--out', str(tmp_path), '--plot']) == 0
    summary = json.loads(capsys.readouterr().out)
    assert set(summary) == {'distance_m', 'settled', 'final_mode', 'transitions', 'max_speed_mps', 'sim_time_s',
                            'wall_time_s', 'mean_velocity_mps', 'throw_number'}
    assert summary['mean_velocity_mps'] is None and summary['throw_number'] is None   # one stroke, no track
    assert set(summary['transitions']) == {'stick_to_slip', 'slip_to_stick', 'take_off', 'landing'}
    assert summary['final_mode'] == 'stuck' and summary['sim_time_s'] == pytest.approx(3e-3)
    with (tmp_path / 'simulate.csv').open() as handle:
        rows = list(csv.DictReader(handle))
    assert {'t', 'mode', 'x', 'friction', 'normal_load', 'stroke_0'} <= set(rows[0])
    assert float(rows[-1]['x']) - float(rows[0]['x']) == pytest.approx(summary['distance_m'], rel=1e-12)
    assert {r['mode'] for r in rows} == {'stuck', 'sliding'}
    assert (tmp_path / 'simulate.png').stat().st_size > 10_000


def test_simulate_refuses_bad_values(tmp_path, capsys):
    assert main(['simulate', '--out', str(tmp_path), '--set', 'surface.widths=[1e-3, 2e-3]']) == 2
    assert 'surface.widths' in capsys.readouterr().err
    assert main(['simulate', '--out', str(tmp_path), '--set', 'stroke.frequency=-5']) == 2
    assert 'stroke.frequency' in capsys.readouterr().err
