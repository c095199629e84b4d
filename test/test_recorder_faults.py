"""Recorder faults with real processes (issue 30, item 3): a full disk, a removed log directory, storage that
stops responding, a ``recorder`` process killed or stopped. What the user must see each time: the run
finishes with its summary and exit status, one line naming the recording fault and no traceback, the log so
far readable by ``micro-feeder info``, and ``info`` saying where and why the log ends.

The disk fills two ways: always with a file size limit (RLIMIT_FSIZE with SIGXFSZ ignored, so writes fail
with EFBIG; 600 kB, above the 549 kB shared-memory segment Fast DDS creates, or its SHM transport fails), and,
where mounting is allowed (root), on a small tmpfs (a real ENOSPC). Frozen storage needs a loop-mounted ext4
and fsfreeze (root). Each test is bounded (< 60 s) and marked ``faults`` (``make test`` runs them).
"""

from __future__ import annotations

import contextlib
import gc
import os
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import warnings
from collections.abc import Iterator
from pathlib import Path

import pytest
from ros_helpers import remove_stale_fastdds_shm, wait_until

from micro_feeder.logs.reader import LogReader, TruncatedLogWarning

pytestmark = pytest.mark.faults

FILE_LIMIT = 600_000    # bytes: above Fast DDS's 549,408-byte SHM segment, reached by a run's log in ~5 s
BIN = Path(sys.executable).parent


def _exe(name: str) -> str:
    exe = shutil.which(name, path=str(BIN))
    assert exe, f'console script {name!r} not installed (pip install -e .)'
    return exe


def _file_limit(limit: int):
    def apply() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)   # a write past the limit fails with EFBIG instead
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return apply


def start_run(*args: str, limit: int | None = None) -> subprocess.Popen:
    return subprocess.Popen([_exe('micro-feeder'), 'run', *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, preexec_fn=_file_limit(limit) if limit else None)


def start_recorder(output: Path, limit: int | None = None) -> subprocess.Popen:
    return subprocess.Popen([_exe('recorder'), '--ros-args', '-p', f'output:={output}', '-p', 'flush_period:=0.5'],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=_file_limit(limit) if limit else None)


def finish(proc: subprocess.Popen, timeout: float = 45) -> tuple[int, str, str]:
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        raise AssertionError(f'still running after {timeout} s:\n{out}\n{err}') from None
    return proc.returncode, out, err


def info(log: Path) -> str:
    done = subprocess.run([_exe('micro-feeder'), 'info', str(log)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert 'Traceback' not in done.stderr
    return done.stdout


def size(path: Path) -> int:
    return path.stat().st_size if path.is_file() else 0


def fault_lines(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if 'recording stopped' in line]


def assert_run_summary(status: int, out: str, err: str, log: Path, reason: str) -> str:
    """The run went to its end, said how the recording ended in its summary and once on stderr."""
    assert 'Traceback' not in err, err
    assert status == 1, (out, err)        # the run was asked to record and the recording is incomplete
    assert 'sim time        8.000000 s' in out, out
    summary = next(line for line in out.splitlines() if line.startswith('log  '))
    assert summary.startswith(f'log             {log}: recording stopped at ') and f': {reason} (log readable up to' \
        in summary, summary
    lines = fault_lines(err)
    assert len(lines) == 1 and reason in lines[0], err
    return summary


def assert_log_ends_early(log: Path, reason: str) -> None:
    """The log is complete (summary and footer) and ``info`` says where and why it ends."""
    with warnings.catch_warnings():
        warnings.simplefilter('error', TruncatedLogWarning)
        reader = LogReader(log)
    assert reader.message_count > 0 and reader.first('particle/pose') is not None
    text = info(log)
    ends = next(line for line in text.splitlines() if line.startswith('ends'))
    assert ends.startswith('ends       early: recording stopped at sim time') and reason in ends, ends
    assert f'readable up to sim time {reader.last("particle/pose").stamp_ns * 1e-9:.3f} s' in ends, ends
    assert 'counted only up to where the log ends' in text


@contextlib.contextmanager
def mounted(kind: str, size: str) -> Iterator[Path]:
    """A small file system of its own (root only): 'tmpfs', or 'ext4' on a loop device (fsfreeze works on it)."""
    where = Path(tempfile.mkdtemp(prefix='mf-fault-'))
    image = where.with_suffix('.img')
    try:
        if kind == 'tmpfs':
            command = ['mount', '-t', 'tmpfs', '-o', f'size={size}', 'tmpfs', str(where)]
        else:
            subprocess.run(['truncate', '-s', size, str(image)], check=True)
            subprocess.run(['mkfs.ext4', '-q', str(image)], check=True, capture_output=True)
            command = ['mount', '-o', 'loop', str(image), str(where)]
        if os.geteuid() != 0 or subprocess.run(command, capture_output=True).returncode != 0:
            pytest.skip(f'cannot mount a {kind} here (needs root)')
        try:
            yield where
        finally:
            subprocess.run(['fsfreeze', '-u', str(where)], capture_output=True)
            gc.collect()    # log readers left in reference cycles still map their files
            if subprocess.run(['umount', str(where)], capture_output=True).returncode != 0:
                subprocess.run(['umount', '--lazy', str(where)], check=True)
    finally:
        image.unlink(missing_ok=True)
        where.rmdir()


def test_run_on_a_disk_at_its_file_size_limit_finishes_with_its_summary(tmp_path):
    log = tmp_path / 'log'
    status, out, err = finish(start_run('--duration', '8', '--record', str(log), limit=FILE_LIMIT))
    assert_run_summary(status, out, err, log, 'File too large')
    assert_log_ends_early(log, 'File too large')
    assert not (log / '.reserve').exists()


def test_run_on_a_full_disk_finishes_with_its_summary():
    with mounted('tmpfs', '1600k') as disk:     # 1 MiB of it is the recorder's reserve
        log = disk / 'log'
        status, out, err = finish(start_run('--duration', '8', '--record', str(log)))
        assert_run_summary(status, out, err, log, 'No space left on device')
        assert_log_ends_early(log, 'No space left on device')


def test_run_whose_log_directory_is_removed_keeps_the_log_so_far(tmp_path):
    log = tmp_path / 'log'
    proc = start_run('--duration', '8', '--record', str(log))
    try:
        wait_until(lambda: size(log / 'log_0.mcap') > 20_000, 30,
                   what='the first chunks on disk')
        shutil.rmtree(log)
    finally:
        status, out, err = finish(proc)
    assert_run_summary(status, out, err, log, 'log directory removed')
    assert_log_ends_early(log, 'log directory removed')


def test_run_on_storage_that_stops_responding_goes_on_and_says_so(tmp_path):
    out_file, err_file = tmp_path / 'stdout', tmp_path / 'stderr'
    with mounted('ext4', '32M') as disk:
        log = disk / 'log'
        with out_file.open('w') as out, err_file.open('w') as err:
            proc = subprocess.Popen([_exe('micro-feeder'), 'run', '--duration', '8', '--record', str(log)],
                                    stdout=out, stderr=err, text=True)
        try:
            wait_until(lambda: size(log / 'log_0.mcap') > 20_000, 30,
                       what='the first chunks on disk')
            subprocess.run(['fsfreeze', '-f', str(disk)], check=True)
            # the run goes to its end and prints its summary; the process itself cannot exit before the kernel
            # returns the write it is stuck in, when the storage is back
            wait_until(lambda: 'log             ' in out_file.read_text(), 40, what='the run summary')
        finally:
            subprocess.run(['fsfreeze', '-u', str(disk)], check=True)
            status, _, _ = finish(proc)
        assert_run_summary(status, out_file.read_text(), err_file.read_text(), log, 'storage not responding')
        assert 'has not returned for' in fault_lines(err_file.read_text())[0]
        text = info(log)     # left as far as it got on disk: readable up to its last whole chunk
        assert 'ends       abruptly' in text


def test_a_recorder_process_on_a_full_disk_reports_once_and_exits(tmp_path):
    log = tmp_path / 'log'
    recorder = start_recorder(log, limit=FILE_LIMIT)
    try:
        status, out, err = finish(start_run('--duration', '8'))
        assert status == 0 and 'sim time        8.000000 s' in out, (out, err)
        status, out, err = finish(recorder, timeout=20)     # it ends by itself
    finally:
        if recorder.poll() is None:
            recorder.kill()
            recorder.wait()
    assert 'Traceback' not in err, err
    assert status == 1, (out, err)
    lines = fault_lines(err)
    assert len(lines) == 1 and 'File too large' in lines[0], err
    assert 'ends       early: recording stopped at sim time' in out   # its summary of what is readable
    assert_log_ends_early(log, 'File too large')


def test_a_killed_recorder_process_does_not_disturb_the_run_and_its_log_says_it_ends_abruptly(tmp_path):
    log = tmp_path / 'log'
    recorder = start_recorder(log)
    run = start_run('--duration', '8')
    try:
        wait_until(lambda: size(log / 'log_0.mcap') > 50_000, 30, what='the run recorded')
        recorder.kill()
        recorder.wait()
    finally:
        status, out, err = finish(run)
        if recorder.poll() is None:
            recorder.kill()
            recorder.wait()
        remove_stale_fastdds_shm()
    assert status == 0 and 'sim time        8.000000 s' in out and 'Traceback' not in err, (out, err)
    text = info(log)
    assert 'ends       abruptly, after sim time' in text
    assert 'counted only up to where the log ends' in text


def test_a_stopped_recorder_process_does_not_stop_the_run_and_says_so_when_it_resumes(tmp_path):
    log = tmp_path / 'log'
    recorder = start_recorder(log)
    run = start_run('--duration', '8')
    try:
        wait_until(lambda: size(log / 'log_0.mcap') > 50_000, 30, what='the run recorded')
        recorder.send_signal(signal.SIGSTOP)
        time.sleep(4)
        recorder.send_signal(signal.SIGCONT)
    finally:
        status, out, err = finish(run)
    try:
        assert status == 0 and 'sim time        8.000000 s' in out and 'Traceback' not in err, (out, err)
        time.sleep(1)
        recorder.send_signal(signal.SIGINT)
        rec_status, _, rec_err = finish(recorder, timeout=20)
    finally:
        if recorder.poll() is None:
            recorder.kill()
            recorder.wait()
    assert rec_status == 0 and 'Traceback' not in rec_err, rec_err
    stalls = [line for line in rec_err.splitlines() if 'did not run for' in line]
    assert len(stalls) == 1, rec_err
    text = info(log)
    assert 'recorder   did not run 1 time' in text, text
