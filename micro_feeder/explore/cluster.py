"""A Dask cluster on this machine, started as a user would (``dask scheduler``, ``dask worker``), for the
benchmark and the tests; everything binds to 127.0.0.1 on ports the OS picks."""

from __future__ import annotations

import contextlib
import json
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

DASK = str(Path(sys.executable).parent / 'dask')


@dataclass
class LocalCluster:
    address: str
    scheduler: subprocess.Popen
    workers: list[subprocess.Popen]


def _start(args: list[str], log: Path) -> subprocess.Popen:
    with log.open('w') as handle:
        return subprocess.Popen([DASK, *args], stdout=subprocess.DEVNULL, stderr=handle)


@contextlib.contextmanager
def local_cluster(folder: Path, workers: int = 2, timeout: float = 60.0) -> Iterator[LocalCluster]:
    """Scheduler + ``workers`` single-threaded workers without nanny (a killed worker stays dead), logs in
    ``folder``; stopped (terminate, then kill) on leaving."""
    info = folder / 'scheduler.json'
    info.unlink(missing_ok=True)
    scheduler = _start(['scheduler', '--host', '127.0.0.1', '--port', '0', '--scheduler-file', str(info),
                        '--no-dashboard'], folder / 'scheduler.log')
    procs = [scheduler]
    try:
        deadline = time.monotonic() + timeout
        while not info.exists():
            if time.monotonic() > deadline or scheduler.poll() is not None:
                raise RuntimeError(f'the Dask scheduler did not start (see {folder / "scheduler.log"})')
            time.sleep(0.1)
        procs += [_start(['worker', '--scheduler-file', str(info), '--host', '127.0.0.1', '--nthreads', '1',
                          '--no-nanny', '--no-dashboard', '--name', f'w{i}'], folder / f'worker{i}.log')
                  for i in range(workers)]
        address = json.loads(info.read_text())['address']
        from distributed import Client
        with Client(address, timeout=timeout) as client:
            client.wait_for_workers(workers, timeout=timeout)
        yield LocalCluster(address, scheduler, procs[1:])
    finally:
        for proc in procs:
            proc.terminate()
        for proc in procs:
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
