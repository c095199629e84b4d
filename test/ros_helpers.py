"""Reusable rclpy test helpers: an isolated Context per test, bounded waits, spinning, shm clean-up.

Register the fixtures with ``pytest_plugins = ['ros_helpers']`` in conftest.py. Everything waits with a
deadline and fails loudly when it passes; nothing sleeps in the hope that something happened.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import Executor


@pytest.fixture
def ros_context() -> Iterator[Context]:
    """A fresh, initialised ``Context`` (no signal handlers), shut down after the test."""
    context = Context()
    rclpy.init(context=context)
    try:
        yield context
    finally:
        rclpy.shutdown(context=context)


def wait_until(predicate: Callable[[], bool], timeout: float, *, executor: Executor | None = None,
               what: str = 'condition', slice_s: float = 0.01) -> float:
    """Return the seconds it took for ``predicate()`` to hold, spinning ``executor`` on this thread
    between checks (or polling every ``slice_s`` without one); raise AssertionError at ``timeout``."""
    start = time.monotonic()
    deadline = start + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f'timed out after {timeout} s waiting for {what}')
        if executor is None:
            time.sleep(slice_s)
        else:
            executor.spin_once(timeout_sec=slice_s)
    return time.monotonic() - start


def spin_for(executor: Executor, seconds: float) -> None:
    """Spin ``executor`` on this thread for ``seconds`` (for letting a known-duration activity run)."""
    deadline = time.monotonic() + seconds
    while (left := deadline - time.monotonic()) > 0:
        executor.spin_once(timeout_sec=min(left, 0.01))


def _open_by_any_process() -> set[str]:
    """Names under /dev/shm that a live process maps or has open."""
    used: set[str] = set()
    for proc in Path('/proc').iterdir():
        if not proc.name.isdigit():
            continue
        try:
            used.update(line.rsplit('/dev/shm/', 1)[1].split(' ')[0].strip()
                        for line in (proc / 'maps').read_text().splitlines() if '/dev/shm/' in line)
            for fd in (proc / 'fd').iterdir():
                target = os.readlink(fd)
                if target.startswith('/dev/shm/'):
                    used.add(target[len('/dev/shm/'):])
        except (OSError, IndexError):
            continue
    return used


def remove_stale_fastdds_shm() -> list[str]:
    """Remove Fast DDS shared-memory files left by killed processes (no live process holds them);
    returns the names removed. Files of running processes, ours or others', are left alone."""
    shm = Path('/dev/shm')
    used = _open_by_any_process()
    removed = []
    for path in shm.glob('*fastdds_*'):
        base = path.name.removesuffix('_el')
        if path.name not in used and base not in used and f'sem.{base}' not in used:
            try:
                path.unlink()
                removed.append(path.name)
            except OSError:
                pass
    return removed
