"""Fast DDS shared-memory files left in /dev/shm by processes that died without shutting ROS down (SIGKILL,
a crash), removed when the next node process starts.

Why they are there at all: with ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` (mandatory here) rmw_fastrtps
replaces Fast DDS's transports with its own pair, shared memory and UDPv4, so neither an XML profile nor
``FASTDDS_BUILTIN_TRANSPORTS=UDPv4`` turns shared memory off (measured, docs/interface.md *Running*). A
participant that shuts down removes its files; one that is killed leaves them: a 0.55 MB segment
``fastdds_<16 hex digits>`` with its lock ``..._el``, and its port files ``fastdds_port<N>``, ``..._el``
(or ``_sl``) and ``sem.fastdds_port<N>_mutex`` (52 kB). Fast DDS reuses a dead process's port when a new
participant takes the same port number, but never its segment (a random name): those piled up, 0.6 MB per
killed run.

How a file is known to be stale: Fast DDS's own rule (its ``fastdds shm clean`` tool, not on PyPI). The
owner of a segment or port holds a ``flock`` on its lock file (``_el`` exclusive, ``_sl`` shared) for as
long as it lives; the kernel drops it when the process dies. A lock file nobody holds belongs to a dead
process. Files of live processes, this user's or another's, are never touched; neither are lock files
younger than :data:`MIN_AGE_S` (a participant being created right now may not have locked its file yet),
nor files this user may not remove.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import re
import time
from pathlib import Path

SHM_DIR = Path('/dev/shm')
MIN_AGE_S = 5.0     # a lock file younger than this is left alone, held or not

_SEGMENT_LOCK = re.compile(r'^fastdds_[0-9a-f]{16}_(el|sl)$')
_PORT_LOCK = re.compile(r'^fastdds_port\d{1,5}_(el|sl)$')


def _held(fd: int) -> bool:
    """Whether some process holds a flock on the open file ``fd`` (ours is taken and kept when not)."""
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return True
    return False


def _unlink(path: Path, removed: list[str]) -> None:
    with contextlib.suppress(FileNotFoundError, PermissionError):
        path.unlink()
        removed.append(path.name)


def remove_stale_files(directory: Path = SHM_DIR, min_age: float = MIN_AGE_S) -> list[str]:
    """Remove the Fast DDS shared-memory files of dead processes from ``directory``; returns the names
    removed. Never raises: a directory that cannot be read (not Linux) removes nothing."""
    removed: list[str] = []
    try:
        names = os.listdir(directory)
    except OSError:
        return removed
    now = time.time()
    for name in sorted(names):
        segment = _SEGMENT_LOCK.match(name)
        port = _PORT_LOCK.match(name)
        if not (segment or port):
            continue
        lock = directory / name
        try:
            fd = os.open(lock, os.O_RDONLY | os.O_NOFOLLOW)
        except OSError:
            continue
        try:
            info = os.fstat(fd)
            if now - info.st_mtime < min_age or _held(fd):
                continue
            # The lock is ours now; remove it only if the name is still this file (not a new owner's).
            try:
                if os.stat(lock, follow_symlinks=False).st_ino != info.st_ino:
                    continue
            except OSError:
                continue
            base = name[:-3]
            _unlink(directory / base, removed)
            if port:
                _unlink(directory / f'sem.{base}_mutex', removed)
            _unlink(lock, removed)
        finally:
            os.close(fd)
    return removed
