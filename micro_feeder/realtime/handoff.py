"""A thread that runs the calls handed to it in the order they were handed over: what lets the real-time loop
publish a tick's state while it integrates the next one.

Publishing is Python and middleware work that holds the GIL (~0.2 ms a tick for 16 parts), while the
compiled integration releases it; on the loop thread the two add up, on two threads they overlap.
:meth:`Handoff.flush` waits until every call handed over has run: a caller that publishes on its own
thread (a lockstep step, a reset) or changes what the calls use (the messages of a new number of parts)
flushes first, so that the order of what is published never changes.
"""

from __future__ import annotations

import collections
import threading
from collections.abc import Callable


class Handoff:
    """Runs ``call(*args)`` handed over with :meth:`put` on a thread of its own, in order. An exception a call
    raises goes to ``on_error`` (on that thread) and the calls after it still run. At most ``max_pending``
    calls wait: :meth:`put` then waits for room, so a publisher that cannot keep up slows the loop (its
    real-time factor says so) instead of piling up states."""

    def __init__(self, on_error: Callable[[BaseException], None], name: str = 'simulator-publish',
                 max_pending: int = 8) -> None:
        self.max_pending = max_pending
        self._calls: collections.deque[tuple[Callable[..., None], tuple]] = collections.deque()
        self._wake = threading.Condition()
        self._running = 0           # calls taken off the queue and not finished
        self._stopping = False
        self._on_error = on_error
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def put(self, call: Callable[..., None], *args: object) -> None:
        """Run ``call(*args)`` after the calls handed over before it (once fewer than ``max_pending`` wait)."""
        with self._wake:
            self._wake.wait_for(lambda: len(self._calls) < self.max_pending or self._stopping)
            self._calls.append((call, args))
            self._wake.notify_all()

    def flush(self, timeout: float | None = None) -> bool:
        """Wait until every call handed over so far has run (False: ``timeout`` s passed first). From the
        handoff's own thread, returns at once."""
        if threading.current_thread() is self._thread:
            return True
        with self._wake:
            return self._wake.wait_for(lambda: not self._calls and not self._running, timeout)

    def stop(self, timeout: float = 1.0) -> bool:
        """Run what was handed over, then end the thread (waiting up to ``timeout`` s); False if it is still
        working then (a daemon: it cannot keep the process alive)."""
        with self._wake:
            self._stopping = True
            self._wake.notify_all()
        self._thread.join(timeout)
        return not self._thread.is_alive()

    def _run(self) -> None:
        while True:
            with self._wake:
                self._wake.wait_for(lambda: self._calls or self._stopping)
                if not self._calls:
                    return
                call, args = self._calls.popleft()
                self._running += 1
            try:
                call(*args)
            except Exception as err:     # reported; the calls after it still run
                self._on_error(err)
            finally:
                with self._wake:
                    self._running -= 1
                    self._wake.notify_all()
