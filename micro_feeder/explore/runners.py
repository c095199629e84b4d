"""Where the runs execute: this process, local worker processes, or a Dask cluster.

Every runner maps a function over an iterable of work items and yields the results **in order**,
keeping at most ``window`` items in flight: the iterable is consumed as results come back, so memory
stays bounded however many runs there are, and a table written as the results arrive is the same
whatever executes them.

* :class:`InProcess`: one process, no pool (``processes=1``).
* :class:`LocalProcesses`: forked worker processes (they inherit the loaded kernel). Workers ignore
  SIGINT and die with this process (Linux PR_SET_PDEATHSIG); on Ctrl-C or any exit they are
  terminated at once, so none outlives the command. A worker that dies mid-run breaks the pool: the
  pool is rebuilt and the items in flight are resubmitted (twice at most).
* :class:`DaskCluster`: ``dask.distributed`` at a scheduler address; the scheduler reruns the tasks
  of a worker that dies, and ``retries`` covers a task that raises on a sick worker.
"""

from __future__ import annotations

import collections
import concurrent.futures as cf
import contextlib
import ctypes
import multiprocessing
import signal
from collections.abc import Callable, Iterable, Iterator
from typing import Any

PR_SET_PDEATHSIG = 1
POOL_RESTARTS = 2
TASK_RETRIES = 2
MANAGER_JOIN_TIMEOUT = 5.0     # s: the pool's manager thread ends within ms once its workers are dead


class RunnerError(RuntimeError):
    """The runner cannot run the work (no scheduler at the address, workers keep dying); says why."""


class Runner:
    """Ordered, bounded map. Use as a context manager: leaving it releases every worker."""

    workers: int = 1
    where: str = 'this process'

    def imap(self, func: Callable[..., Any], items: Iterable[Any], *args: Any) -> Iterator[Any]:
        """``func(*args, item)`` for each item, in order, computed in parallel where the runner can."""
        raise NotImplementedError

    def map(self, func: Callable[..., Any], items: Iterable[Any], *args: Any) -> list[Any]:
        """All results as a list (scipy.optimize's ``workers`` map interface, via :meth:`as_map`)."""
        return list(self.imap(func, items, *args))

    def as_map(self) -> Callable[[Callable[[Any], Any], Iterable[Any]], list[Any]]:
        """A ``map(func, iterable)`` callable for scipy (differential_evolution's ``workers``)."""
        return lambda func, items: self.map(_call, items, func)

    def close(self) -> None:
        """Release the workers (idempotent)."""

    def __enter__(self) -> Runner:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _call(func: Callable[[Any], Any], item: Any) -> Any:
    return func(item)


class InProcess(Runner):
    def imap(self, func: Callable[..., Any], items: Iterable[Any], *args: Any) -> Iterator[Any]:
        for item in items:
            yield func(*args, item)


def _die_with_parent() -> None:
    """Worker initializer: leave Ctrl-C to the parent, and get SIGKILLed if the parent dies."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)


class LocalProcesses(Runner):
    """``processes`` forked workers of this machine."""

    def __init__(self, processes: int, window: int | None = None):
        self.workers = processes
        self.window = window or 4 * processes
        self.where = f'{processes} local processes'
        self._pool: cf.ProcessPoolExecutor | None = None

    def _executor(self) -> cf.ProcessPoolExecutor:
        if self._pool is None:
            methods = multiprocessing.get_all_start_methods()
            context = multiprocessing.get_context('fork' if 'fork' in methods else None)
            self._pool = cf.ProcessPoolExecutor(self.workers, mp_context=context, initializer=_die_with_parent)
        return self._pool

    def imap(self, func: Callable[..., Any], items: Iterable[Any], *args: Any) -> Iterator[Any]:
        source = iter(items)
        flight: collections.deque[tuple[Any, cf.Future]] = collections.deque()
        restarts = 0
        while True:
            while len(flight) < self.window:
                item = next(source, _END)
                if item is _END:
                    break
                flight.append((item, self._executor().submit(func, *args, item)))
            if not flight:
                return
            item, future = flight[0]
            try:
                result = future.result()
            except cf.process.BrokenProcessPool as err:
                restarts += 1
                if restarts > POOL_RESTARTS:
                    raise RunnerError(f'local worker processes keep dying ({err}); giving up') from err
                self._terminate()
                flight = collections.deque((it, self._executor().submit(func, *args, it)) for it, _ in flight)
                continue
            flight.popleft()
            yield result

    def _terminate(self) -> None:
        """Kill the workers, then wait (bounded) for the pool's manager thread to end. Left running, that
        thread met concurrent.futures' exit hook, which wakes and joins it at interpreter exit: it either
        raced the thread's own clean-up (``OSError: [Errno 9] Bad file descriptor`` from ``_python_exit``,
        a traceback after ``interrupted``) or joined it forever, the thread being blocked reading a result a
        killed worker had half written (the result pipe stays open through this process's own write end)."""
        pool, self._pool = self._pool, None
        if pool is None:
            return
        # what shutdown() drops its references to
        processes = list((getattr(pool, '_processes', None) or {}).values())
        manager = getattr(pool, '_executor_manager_thread', None)
        results = getattr(pool, '_result_queue', None)
        pool.shutdown(wait=False, cancel_futures=True)
        for process in processes:
            with contextlib.suppress(Exception):
                process.terminate()
        for process in processes:
            with contextlib.suppress(Exception):
                process.join(timeout=1.0)
                if process.is_alive():
                    process.kill()
                    process.join(timeout=1.0)
        # Every writer of the result pipe is dead: closing ours lets a read of a half-written result end
        # (EOF: the pool is broken, and the manager thread winds down).
        if results is not None:
            with contextlib.suppress(Exception):
                results._writer.close()
        if manager is not None:
            manager.join(timeout=MANAGER_JOIN_TIMEOUT)

    def close(self) -> None:
        self._terminate()


_END = object()


class DaskCluster(Runner):
    """A ``dask.distributed`` scheduler at ``address`` (``tcp://HOST:PORT``); its workers must have this
    package installed (the same version). Items are submitted ``window`` at a time."""

    def __init__(self, address: str, window: int | None = None, timeout: float = 10.0):
        try:
            from distributed import Client
        except ImportError as err:  # pragma: no cover - dask is a dependency of the 'dask' extra
            raise RunnerError('--scheduler needs dask.distributed: pip install "micro_feeder[dask]"') from err
        try:
            self.client = Client(address, timeout=timeout, set_as_default=False)
        except (OSError, TimeoutError) as err:
            raise RunnerError(f'no Dask scheduler answers at {address} ({err}); start one with '
                              '"dask scheduler" and workers with "dask worker ADDRESS" (docs/explore.md)') from err
        self.workers = max(1, sum(w.get('nthreads', 1) for w in self.client.scheduler_info()['workers'].values()))
        self.window = window or 4 * self.workers
        self.where = f'Dask cluster {address} ({self.workers} worker threads)'

    def imap(self, func: Callable[..., Any], items: Iterable[Any], *args: Any) -> Iterator[Any]:
        source = iter(items)
        flight: collections.deque[Any] = collections.deque()
        try:
            while True:
                while len(flight) < self.window:
                    item = next(source, _END)
                    if item is _END:
                        break
                    flight.append(self.client.submit(func, *args, item, pure=False, retries=TASK_RETRIES))
                if not flight:
                    return
                yield flight.popleft().result()
        finally:
            if flight:
                self.client.cancel(list(flight))

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.client.close(timeout=2)


def make_runner(processes: int = 1, scheduler: str | None = None) -> Runner:
    """The runner the options ask for: a Dask cluster when ``scheduler`` is given, else local."""
    if scheduler:
        return DaskCluster(scheduler)
    return LocalProcesses(processes) if processes > 1 else InProcess()
