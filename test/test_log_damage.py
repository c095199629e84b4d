"""Damaged logs are read, not fatal: a garbled chunk is skipped with one warning naming it and the messages it
cost, CRCs are verified (a 2-byte change is reported), ``recover`` keeps every undamaged chunk, a damaged
metadata.yaml falls back to the .mcap files, and a log with nothing readable is refused with one line.

The expected messages come from the mcap library's own reader (an implementation we did not write): each
chunk's messages as it reads them from the undamaged original."""

import subprocess
import sys
import warnings
from pathlib import Path

import pytest
from log_fixtures import chunks_of, write_motion_log

from micro_feeder.logs.reader import DamagedLogWarning, LogReader, TruncatedLogWarning
from micro_feeder.logs.recover import recover

BIN = Path(sys.executable).parent


@pytest.fixture(scope='module')
def original(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp('damage') / 'good.mcap'
    write_motion_log(path, n=2000, chunk_size=16_000)
    return path


def damaged_copy(original: Path, tmp_path: Path, offset: int, data: bytes) -> Path:
    raw = bytearray(original.read_bytes())
    raw[offset:offset + len(data)] = data
    path = tmp_path / 'damaged.mcap'
    path.write_bytes(bytes(raw))
    return path


def test_a_garbled_chunk_is_skipped_and_recover_keeps_every_other_chunk(original, tmp_path):
    chunks = chunks_of(original)
    assert len(chunks) > 5
    start, end, lost = chunks[len(chunks) // 2]
    path = damaged_copy(original, tmp_path, (start + end) // 2, b'\xde\xad\xbe\xef')
    with pytest.warns(DamagedLogWarning, match=f'at byte {start:,}') as caught:
        log = LogReader(path)
        messages = [m.data for m in log.messages()]
    assert len([w for w in caught if issubclass(w.category, DamagedLogWarning)]) == 1
    expected = [data for s, _, msgs in chunks if s != start for data in msgs]
    assert sorted(messages) == sorted(expected)
    assert log.lost == len(lost)
    result = recover(path, tmp_path / 'fixed')
    assert result.messages == len(expected) and result.dropped == len(lost)
    assert [d.offset for d in result.damage] == [start]
    with warnings.catch_warnings():
        warnings.simplefilter('error')      # the recovered log is complete and undamaged
        fixed = LogReader(result.output)
        assert sorted(m.data for m in fixed.messages()) == sorted(expected)


@pytest.mark.parametrize('where', ['chunk', 'between chunks', 'summary'])
def test_two_changed_bytes_are_reported(original, tmp_path, where):
    chunks = chunks_of(original)
    offset = {'chunk': chunks[1][0] + 60, 'between chunks': chunks[1][1] + 12,
              'summary': original.stat().st_size - 200}[where]
    raw = original.read_bytes()
    path = damaged_copy(original, tmp_path, offset, bytes(b ^ 0x5A for b in raw[offset:offset + 2]))
    result = subprocess.run([str(BIN / 'micro-feeder'), 'info', str(path)], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr
    assert 'warning:' in result.stderr and ('CRC' in result.stderr or 'damaged' in result.stderr), result.stderr
    assert 'Traceback' not in result.stderr


def test_truncated_and_garbled_file_reads_every_whole_undamaged_chunk(original, tmp_path):
    chunks = chunks_of(original)
    cut = chunks[6][0] + 100                      # inside chunk 6: chunks 0-5 are whole
    raw = bytearray(original.read_bytes()[:cut])
    start = chunks[3][0]
    raw[start + 9:start + 30] = b'\xff' * 21      # chunk 3's header: its length fields are garbage
    path = tmp_path / 'cut.mcap'
    path.write_bytes(bytes(raw))
    with pytest.warns((TruncatedLogWarning, DamagedLogWarning)):
        log = LogReader(path)
        got = sorted(m.data for m in log.messages())
    assert got == sorted(d for i, (_, _, msgs) in enumerate(chunks[:6]) if i != 3 for d in msgs)
    assert log.truncated == [path] and log.damage


def test_damaged_metadata_yaml_falls_back_to_the_mcap_files(tmp_path):
    write_motion_log(tmp_path / 'log', n=50)
    (tmp_path / 'log' / 'metadata.yaml').write_bytes(b'\x00\xff{[not yaml')
    with pytest.warns(DamagedLogWarning, match='metadata'):
        log = LogReader(tmp_path / 'log')
    assert log.topics['/particle/pose'].count == 50


def test_nothing_readable_is_refused_with_one_line(original, tmp_path):
    raw = bytearray(original.read_bytes()[:chunks_of(original)[2][0]])
    raw[8:] = bytes(len(raw) - 8)               # magic, then only zeros
    path = tmp_path / 'zeros.mcap'
    path.write_bytes(bytes(raw))
    for command in (['info', str(path)], ['recover', str(path), str(tmp_path / 'out')]):
        result = subprocess.run([str(BIN / 'micro-feeder'), *command], capture_output=True, text=True, timeout=120)
        assert result.returncode == 2, result.stderr
        assert 'nothing readable' in result.stderr and 'Traceback' not in result.stderr
    assert not (tmp_path / 'out').exists()


def test_replay_of_a_damaged_log_plays_what_is_readable(original, tmp_path):
    chunks = chunks_of(original)
    start, end, _ = chunks[2]
    path = damaged_copy(original, tmp_path, (start + end) // 2, b'\x00\x11\x22\x33')
    result = subprocess.run([str(BIN / 'micro-feeder'), 'replay', str(path), '--rate', '20'], capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert f'at byte {start:,}' in result.stderr and 'Traceback' not in result.stderr
    assert 'messages, timing error' in result.stdout
