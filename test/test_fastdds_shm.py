"""Issue 30 item 5: Fast DDS shared-memory files of a killed process are removed by the next node process's
start (micro_feeder/nodes/fastdds_shm.py), and only those: files of live processes are never touched."""

from __future__ import annotations

import fcntl
import os
import signal
import time
from pathlib import Path

import pytest
from node_helpers import start_process, stop_process
from rclpy.context import Context
from rclpy.node import Node
from ros_helpers import wait_until

from micro_feeder.nodes import fastdds_shm

SHM = Path('/dev/shm')


def _shm_files(pid: int) -> set[str]:
    """Names under /dev/shm that process ``pid`` maps or holds open."""
    names = {line.rsplit('/dev/shm/', 1)[1].split(' ')[0].strip()
             for line in Path(f'/proc/{pid}/maps').read_text().splitlines() if '/dev/shm/' in line}
    for fd in Path(f'/proc/{pid}/fd').iterdir():
        try:
            target = os.readlink(fd)
        except OSError:
            continue
        if target.startswith('/dev/shm/'):
            names.add(target[len('/dev/shm/'):])
    return {name for name in names if 'fastdds' in name}


def _segments(pid: int) -> list[str]:
    """The Fast DDS segments (``fastdds_<16 hex>``) process ``pid`` has created or opened."""
    try:
        return [name for name in _shm_files(pid) if fastdds_shm._SEGMENT_LOCK.match(f'{name}_el')]
    except OSError:
        return []


def _stale(name: str) -> bool:
    """A file of a dead owner: its lock (the file itself, or ``<name>_el``/``_sl``) exists and nobody holds it."""
    base = name.removeprefix('sem.').removesuffix('_mutex')
    base = base[:-3] if base.endswith(('_el', '_sl')) else base
    for lock in (SHM / f'{base}_el', SHM / f'{base}_sl'):
        try:
            fd = os.open(lock, os.O_RDONLY)
        except OSError:
            continue
        try:
            if not fastdds_shm._held(fd):
                return True
        finally:
            os.close(fd)
    return False


@pytest.mark.skipif(not SHM.is_dir(), reason='Fast DDS shared memory lives in /dev/shm on Linux')
def test_a_killed_simulators_shared_memory_is_removed_by_the_next_start(ros_context: Context) -> None:
    """SIGKILL a simulator (Fast DDS cannot remove its 0.55 MB segment and port files), start the next one:
    once it runs, none of the killed process's files is left unowned."""
    graph = Node('graph', context=ros_context)
    try:
        first = start_process('simulator')
        try:
            wait_until(lambda: graph.get_publishers_info_by_topic('/particle/pose'), 120, what='the first simulator')
            first_gids = [info.endpoint_gid for info in graph.get_publishers_info_by_topic('/particle/pose')]
            files = _shm_files(first.pid)
            time.sleep(fastdds_shm.MIN_AGE_S)       # older than the age a lock of a starting process may have
        finally:
            first.send_signal(signal.SIGKILL)
            first.wait(timeout=10)
        # its own segments: those whose lock it held (it also maps the segments of the participants it sends
        # to, and one of the test process's own, shut down meanwhile, had gone: CI, 1 run of 6)
        segments = [name for name in files if fastdds_shm._SEGMENT_LOCK.match(f'{name}_el') and f'{name}_el' in files]
        assert segments and all((SHM / name).exists() for name in segments), (files, 'no segment left to clean')
        second = start_process('simulator')
        try:
            # its participant exists (the clean-up runs before rclpy.init), and it is on the graph
            wait_until(lambda: second.poll() is not None or (_segments(second.pid) and any(
                info.node_name == 'simulator' for info in graph.get_publishers_info_by_topic('/particle/pose')
                if info.endpoint_gid not in first_gids)), 120, what='the second simulator')
            left = sorted(name for name in files if (SHM / name).exists() and _stale(name))
        finally:
            code, out = stop_process(second)
    finally:
        graph.destroy_node()
    assert code == 0, out
    assert not left, f'files of the killed simulator left unowned: {left}'


def test_stale_files_are_recognised_by_their_free_lock(tmp_path: Path) -> None:
    """The cleaner on a directory of its own: a segment and a port whose locks nobody holds are removed with
    their lock (and the port's semaphore); a held lock, a fresh lock and files without a lock are kept."""
    dead_segment, held_segment, fresh_segment = 'fastdds_0123456789abcdef', 'fastdds_fedcba9876543210', \
        'fastdds_00000000000000aa'
    names = [dead_segment, f'{dead_segment}_el', held_segment, f'{held_segment}_el', fresh_segment,
             f'{fresh_segment}_el', 'fastdds_port7411', 'fastdds_port7411_el', 'sem.fastdds_port7411_mutex',
             'fastdds_port7413', 'other_file']
    for name in names:
        (tmp_path / name).write_bytes(b'')
    old = time.time() - 60
    for name in names:
        if name != f'{fresh_segment}_el':
            os.utime(tmp_path / name, (old, old))
    with open(tmp_path / f'{held_segment}_el', 'rb') as held:
        fcntl.flock(held, fcntl.LOCK_EX)
        removed = fastdds_shm.remove_stale_files(tmp_path)
    assert sorted(removed) == sorted([dead_segment, f'{dead_segment}_el', 'fastdds_port7411', 'fastdds_port7411_el',
                                      'sem.fastdds_port7411_mutex'])
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        [held_segment, f'{held_segment}_el', fresh_segment, f'{fresh_segment}_el', 'fastdds_port7413', 'other_file'])
