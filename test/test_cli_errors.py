"""Bad input to the commands that start nodes: exit status 2, the reason on stderr, no traceback."""

import subprocess
import sys
from pathlib import Path

import pytest

BIN = Path(sys.executable).parent


@pytest.mark.parametrize(('args', 'reason'), [
    (['micro-feeder', 'run', '--duration', '0.1', '--set', 'contact.beta=abc'], 'contact.beta'),
    (['micro-feeder', 'run', '--duration', '0.1', '--set', 'stroke.frequency=-5'], 'stroke.frequency'),
    (['micro-feeder', 'run', '--duration', '0.1', '--set', 'stroke.phases=[0.0,0.5]'], 'stroke.phases'),
    (['micro-feeder', 'hil', '--set', 'feed.amplitude_start=1'], 'feed.amplitude_start'),
    (['simulator', '--ros-args', '-p', 'contact.beta:=-1.0'], 'contact.beta'),
    (['simulator', '--ros-args', '-p', 'integration.check_step:=1.0e-15'], 'integration.check_step'),  # froze it
    (['simulator', '--ros-args', '-p', 'particle.mass:=1.0e300'], 'particle.mass'),  # ignored Ctrl-C
])
def test_refused_parameter_exits_2_with_its_reason(args, reason, tmp_path):
    result = subprocess.run([str(BIN / args[0]), *args[1:]], capture_output=True, text=True, timeout=120,
                            cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    assert reason in result.stderr and 'error' in result.stderr
    assert 'Traceback' not in result.stderr + result.stdout


@pytest.mark.parametrize(('args', 'reason'), [
    (['run', '--duration', '0.1', '--set', 'contact.beta=-1.0'], 'contact.beta'),
    (['hil', '--set', 'feed.amplitude_start=1'], 'feed.amplitude_start'),
])
def test_refused_parameter_leaves_no_log_behind(args, reason, tmp_path):
    log = tmp_path / 'log'
    result = subprocess.run([str(BIN / 'micro-feeder'), *args, '--record', str(log)], capture_output=True,
                            text=True, timeout=120, cwd=tmp_path)
    assert result.returncode == 2 and reason in result.stderr, result.stderr
    assert not log.exists()


@pytest.mark.parametrize(('args', 'reason'), [
    (['simulate', '--set', 'particle.x0=1e300'], 'particle.x0'),          # was a SimulationError traceback
    (['simulate', '--set', 'surface.widths=[1e-300]'], 'surface.widths'),  # was a SimulationError traceback
    (['run', '--duration', '0.1', '--set', 'particle.x0=1e300'], 'particle.x0'),
    (['simulate', '--params', 'binary.yaml'], 'binary.yaml is not text'),  # was UnicodeDecodeError
    (['run', '--duration', '0.1', '--record', 'afile'], 'afile exists'),   # was NotADirectoryError
    (['run', '--duration', '0.1', '--record', '/proc/nope/log'], '/proc'),  # was FileNotFoundError
    (['simulate', '--set', 'stroke.count=100000000'], 'stroke.count'),     # was a hang
    (['run', '--duration', 'inf'], '--duration inf'),                      # was a hang
    (['hil', '--timeout', 'inf'], '--timeout inf'),
    (['simulate', '--set', 'integration.check_step=1e-15'], 'integration.check_step'),  # froze the node
    (['simulate', '--set', 'integration.tolerance=1e-300'], 'integration.tolerance'),   # ignored Ctrl-C
    (['simulate', '--set', 'particle.mass=1e300'], 'particle.mass'),                    # ignored Ctrl-C
    (['simulate', '--duration', '1e6'], '--duration'),                     # ~days of computing: refused
])
def test_user_mistakes_are_one_line_and_status_2(args, reason, tmp_path, monkeypatch, capsys):
    from micro_feeder.cli import main
    monkeypatch.chdir(tmp_path)
    (tmp_path / 'binary.yaml').write_bytes(bytes(range(256)) * 4)
    (tmp_path / 'afile').write_text('not a log directory\n')
    assert main(args) == 2
    err = capsys.readouterr().err
    assert reason in err and err.count('\n') == 1 and 'Traceback' not in err, err


def test_long_work_a_user_could_mean_runs_with_force(tmp_path, monkeypatch, capsys):
    from micro_feeder.cli import main
    monkeypatch.chdir(tmp_path)
    assert main(['simulate', '--duration', '1e6']) == 2
    assert '--force' in capsys.readouterr().err
    import argparse

    from micro_feeder.cli._cost import check_cost
    check_cost(argparse.Namespace(command='simulate', duration=1e6, force=True), {})   # no refusal


def test_a_simulation_failure_names_the_parameters_the_user_set():
    from micro_feeder.cli import user_error
    from micro_feeder.cli._common import _CHANGED
    from micro_feeder.physics.dynamics import SimulationError
    _CHANGED[:] = ['surface.widths', 'stroke.amplitude']
    text = user_error(SimulationError('the state became non-finite at t = 0 s; try a smaller integration.dt'))
    assert text.startswith('the simulation failed: the state became non-finite')
    assert 'surface.widths, stroke.amplitude' in text and 'docs/parameters.md' in text
