"""Bad input to the log commands (info, plot, export, recover, resim, replay) and to the recorder: exit
status 2, the reason on stderr, no traceback."""

import subprocess
import sys
from pathlib import Path

import pytest
from log_fixtures import write_motion_log

BIN = Path(sys.executable).parent


@pytest.fixture
def logs(tmp_path):
    """A good log, a 3-byte file, a text file, and a directory whose metadata.yaml is not rosbag2's."""
    write_motion_log(tmp_path / 'good.mcap', n=20)
    (tmp_path / 'short.mcap').write_bytes(b'abc')
    (tmp_path / 'text.mcap').write_text('hello, this is a text file and not a log at all\n' * 4)
    (tmp_path / 'bag').mkdir()
    (tmp_path / 'bag' / 'metadata.yaml').write_text('foo: 1\n')
    return tmp_path


@pytest.mark.parametrize(('args', 'reason'), [
    (['micro-feeder', 'info', 'short.mcap'], 'not an MCAP file'),
    (['micro-feeder', 'plot', 'short.mcap', '-o', 'x.png'], 'not an MCAP file'),
    (['micro-feeder', 'resim', 'short.mcap'], 'not an MCAP file'),
    (['micro-feeder', 'info', 'text.mcap'], 'not an MCAP file'),
    (['micro-feeder', 'export', 'text.mcap', '--csv', 'csv'], 'not an MCAP file'),
    (['micro-feeder', 'recover', 'text.mcap', 'out'], 'not an MCAP file'),
    (['micro-feeder', 'info', 'bag'], 'rosbag2_bagfile_information'),
    (['micro-feeder', 'plot', 'good.mcap', '-o', '/proc/nope/x.png'], '/proc/nope/x.png'),
    (['micro-feeder', 'export', 'good.mcap', '--csv', '/proc/nope'], '/proc/nope'),
    (['micro-feeder', 'replay', 'good.mcap', '--rate', '0'], '--rate'),
    (['micro-feeder', 'replay', 'good.mcap', '--start-offset', '-1'], '--start-offset'),
    (['micro-feeder', 'replay', 'good.mcap', '--remap', 'foo'], 'FROM:=TO'),
    (['micro-feeder', 'replay', 'text.mcap'], 'not an MCAP file'),
    (['micro-feeder', 'replay', 'good.mcap', '--topic', 'nope'], 'topic "nope"'),
    (['micro-feeder', 'replay', 'good.mcap', '--remap', 'nope:=/x'], 'remap "nope"'),
    (['micro-feeder', 'replay', 'good.mcap', '--loop', '--start-offset', '10'], 'nothing to publish'),
    (['replay', '--ros-args', '-p', 'log:=good.mcap', '-p', 'rate:=0.0'], 'rate'),
    (['replay', '--ros-args', '-p', 'log:=good.mcap', '-p', 'remap:=["foo"]'], 'FROM:=TO'),
    (['recorder', '--ros-args', '-p', 'flush_period:=0.0', '-p', 'output:=rec'], 'flush_period'),
])
def test_bad_input_exits_2_with_its_reason(args, reason, logs):
    result = subprocess.run([str(BIN / args[0]), *args[1:]], capture_output=True, text=True, timeout=120,
                            cwd=logs)
    assert result.returncode == 2, result.stdout + result.stderr
    assert reason in result.stderr and 'error' in result.stderr, result.stderr
    assert 'Traceback' not in result.stderr + result.stdout


def test_a_log_cut_inside_its_magic_is_truncated_not_refused(tmp_path):
    """A recorder killed before it wrote 8 bytes leaves a truncated log (read as empty), not a non-log."""
    path = tmp_path / 'cut.mcap'
    path.write_bytes(b'\x89MCA')
    result = subprocess.run([str(BIN / 'micro-feeder'), 'info', str(path)], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr
    assert 'truncated' in result.stderr and 'Traceback' not in result.stderr
