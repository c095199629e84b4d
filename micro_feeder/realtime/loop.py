"""A loop thread that calls a tick function on a fixed wall-clock grid, and the timing it measures.

Why a thread and not an rclpy timer: rclpy's timer dispatch alone costs 12-15 % of a core at 1 kHz and
adds jitter (bench/bench_nodes.py); a thread sleeping to its next deadline costs a fraction of that.
The grid is fixed (steady clock): a late tick skips the grid points it missed instead of catching up.
"""

from __future__ import annotations

import collections
import gc
import math
import threading
import time
from collections.abc import Callable

import numpy as np

TIMING_WINDOW = 4000    # tick periods and work times kept between two reads (4 s at 1 kHz)
# sys.setswitchinterval for a process that runs the loop: a thread busy in Python (the executor under a
# command flood) holds the GIL up to this long before the loop thread gets it (default 5 ms, five ticks).
# Under a 5 kHz trajectory flood: tick p99 1.3 ms instead of 1.8-2.3 ms (test/test_simulator_storms.py).
GIL_SWITCH_INTERVAL = 0.0005
_startup_frozen = False


def freeze_startup_objects() -> None:
    """Collect garbage once, then move every object that exists (the imported modules, the built model, the
    nodes) out of the cyclic garbage collector's reach (:func:`gc.freeze`), so that its full passes look only
    at what was made since. A full pass holds the GIL: over the ~160,000 objects of numpy, scipy, numba and
    rclpy it stopped every thread of ``micro-feeder run --record`` for 58-157 ms (once within the first
    17-30 s of each run measured), and the loop lost that much sim time. Objects freed by reference counting
    are freed as before. Once per process; later calls do nothing."""
    global _startup_frozen
    if not _startup_frozen:
        _startup_frozen = True
        gc.collect()
        gc.freeze()


class TickTiming:
    """Tick periods and work times (s) since the last :meth:`drain`, the overrun count since start, and
    when the tick in progress (if any) started. Thread-safe: the loop writes, diagnostics read."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._periods: collections.deque[float] = collections.deque(maxlen=TIMING_WINDOW)
        self._busy: collections.deque[float] = collections.deque(maxlen=TIMING_WINDOW)
        self.overruns = 0
        self.tick_started: float | None = None   # perf_counter() of the tick in progress, None between ticks

    def record(self, period: float, busy: float, budget: float) -> None:
        """One tick: its period (s since the previous tick or the resume), its work time, its budget."""
        with self._lock:
            self._periods.append(period)
            self._busy.append(busy)
            if busy > budget:
                self.overruns += 1

    def drain(self) -> tuple[np.ndarray, np.ndarray]:
        """(periods, work times) in ms since the last call, and forget them."""
        with self._lock:
            periods, busy = np.asarray(self._periods) * 1e3, np.asarray(self._busy) * 1e3
            self._periods.clear()
            self._busy.clear()
        return periods, busy

    def tick_age(self, now: float) -> float:
        """How long (s) the tick in progress has been working; 0 between ticks."""
        started = self.tick_started
        return 0.0 if started is None else max(0.0, now - started)


class TickLoop:
    """Calls ``tick(elapsed)`` every ``period`` s of wall time on its own (daemon) thread.

    ``elapsed`` is the wall time (s) since the previous tick, or since :meth:`resume`. The loop starts
    paused; :meth:`resume` and :meth:`pause` switch it (a paused loop sleeps without waking), and
    :meth:`stop` ends and joins the thread. An exception in ``tick`` is passed to ``on_error`` and ends
    the loop (a loop that died silently would look like a frozen simulation).
    """

    def __init__(self, period: float, tick: Callable[[float], None],
                 on_error: Callable[[BaseException], None], name: str = 'simulator-loop') -> None:
        self.period = period
        self.timing = TickTiming()
        self._tick = tick
        self._on_error = on_error
        self._running = threading.Event()
        self._stopping = False
        self._last = time.perf_counter()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    @property
    def running(self) -> bool:
        return self._running.is_set() and not self._stopping

    def resume(self) -> None:
        freeze_startup_objects()
        self._last = time.perf_counter()
        self._running.set()

    def pause(self) -> None:
        """The tick in progress (if any) finishes; no further tick starts until :meth:`resume`."""
        self._running.clear()

    def stop(self, timeout: float = 1.0) -> bool:
        """End the thread and wait up to ``timeout`` s for it; False if a tick is still working then (the
        thread is a daemon: it cannot keep the process alive)."""
        self._stopping = True
        self._running.set()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout)
        return not self._thread.is_alive()

    def _run(self) -> None:
        next_tick = time.perf_counter() + self.period
        while not self._stopping:
            if not self._running.is_set():
                self._running.wait()
                next_tick = time.perf_counter() + self.period
                continue
            delay = next_tick - time.perf_counter()
            if delay > 0.0:
                time.sleep(delay)
            if self._stopping:
                return
            if self._running.is_set():
                self._one_tick()
            now = time.perf_counter()
            next_tick += self.period
            if next_tick <= now:
                next_tick += math.ceil((now - next_tick) / self.period) * self.period

    def _one_tick(self) -> None:
        start = time.perf_counter()
        elapsed, self._last = start - self._last, start
        self.timing.tick_started = start
        try:
            self._tick(elapsed)
        except Exception as err:
            self._stopping = True
            self._on_error(err)
            raise
        finally:
            self.timing.tick_started = None
        self.timing.record(elapsed, time.perf_counter() - start, self.period)
