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
