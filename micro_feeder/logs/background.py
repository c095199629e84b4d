"""A :class:`~.writer.LogWriter` run on a thread of its own, so that a slow or frozen disk never blocks
the caller (the recorder's executor, which in ``micro-feeder run`` also runs the simulator's and the
actuator's callbacks).

The caller only queues (:meth:`BackgroundWriter.add_topic`, :meth:`BackgroundWriter.write`); the thread
writes, flushes when due and checks that the file is still there. :meth:`BackgroundWriter.poll`, called
periodically by the caller, watches the thread: a write that has not returned within ``write_timeout``
seconds (storage not responding: a hung network mount, a frozen file system) or more than
``max_queued_bytes`` waiting (a disk slower than the messages) stops the recording: further messages are
not queued, and the thread, if its write ever returns, finishes the log up to its last whole chunk with
that reason (:meth:`~.writer.LogWriter.stop`). :meth:`BackgroundWriter.close` finishes the log, waiting
for the thread only while it makes progress.
"""

from __future__ import annotations

import contextlib
import queue
import threading
import time
import traceback
from typing import Any

from .writer import LogWriter, WriteFault

WRITE_TIMEOUT = 5.0             # s a write may take before the storage counts as not responding
MAX_QUEUED_BYTES = 256 << 20    # message bytes waiting for the thread before the disk counts as too slow
WAKE_PERIOD = 0.1               # s between two looks at the flush and the file when no message comes

_CLOSE = object()


class BackgroundWriter:
    """Queues messages for a :class:`LogWriter` (built with ``stop_on_error``) written by a daemon thread.

    ``fault`` is the writer's :class:`WriteFault` once the recording stopped (or this object's own, for a
    write that never returned); ``error`` the traceback of an unexpected exception in the thread (a bug),
    which also stops the recording. ``dropped`` counts messages given after the stop; ``skipped`` holds
    the topics that cannot be recorded (no message definition) with the reason, their messages dropped.
    """

    def __init__(self, writer: LogWriter, *, write_timeout: float = WRITE_TIMEOUT,
                 max_queued_bytes: int = MAX_QUEUED_BYTES) -> None:
        self.writer = writer
        self.write_timeout = write_timeout
        self.max_queued_bytes = max_queued_bytes
        self.dropped = 0
        self.error = ''
        self.skipped: dict[str, str] = {}
        self._own_fault: WriteFault | None = None
        self._queue: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._queued_bytes = 0
        self._lock = threading.Lock()
        self._busy_since: float | None = None   # monotonic start of the writer call in progress
        self._closed = False
        self._thread = threading.Thread(target=self._run, name='recorder-writer', daemon=True)
        self._thread.start()

    # -- the caller's side ---------------------------------------------------------------------------
    @property
    def fault(self) -> WriteFault | None:
        return self.writer.fault or self._own_fault

    @property
    def stopped(self) -> bool:
        return self.fault is not None or self._closed

    def add_topic(self, topic: str, type_name: str, offered_qos_profiles: str = '') -> None:
        if not self.stopped:
            self._queue.put(('topic', topic, type_name, offered_qos_profiles))

    def write(self, topic: str, data: bytes, log_time_ns: int) -> bool:
        """Queue one message; False (and counted in ``dropped``) once the recording has stopped."""
        if self.stopped:
            self.dropped += 1
            return False
        with self._lock:
            self._queued_bytes += len(data)
        self._queue.put(('message', topic, data, log_time_ns))
        return True

    def poll(self) -> WriteFault | None:
        """Watch the thread (a write stuck for ``write_timeout``, too much waiting); returns :attr:`fault`."""
        if self.fault is None and not self._closed:
            busy = self._busy_since
            now = time.monotonic()
            if busy is not None and now - busy > self.write_timeout:
                self._give_up('storage not responding',
                              f'a write to {self._file()} has not returned for {now - busy:.1f} s')
            elif self._queued_bytes > self.max_queued_bytes:
                self._give_up('disk too slow', f'{self._queued_bytes / 2**20:.0f} MiB of messages waiting to be '
                                               f'written to {self._file()}')
        return self.fault

    def excuse(self) -> None:
        """Restart the write watch (after the whole process was stopped: its writes were not stuck)."""
        if self._busy_since is not None:
            self._busy_since = time.monotonic()

    def close(self) -> bool:
        """Finish the log (summary, metadata.yaml), waiting for the thread as long as it makes progress;
        False when it is stuck in a write (the log is then left as far as it got)."""
        if not self._closed:
            self._closed = True
            self._queue.put(_CLOSE)
        while self._thread.is_alive():
            self._thread.join(WAKE_PERIOD)
            busy = self._busy_since
            if busy is not None and time.monotonic() - busy > self.write_timeout:
                if self.fault is None:
                    self._give_up('storage not responding',
                                  f'a write to {self._file()} has not returned for {time.monotonic() - busy:.1f} s')
                return False
        return True

    # -- the thread ------------------------------------------------------------------------------------
    def _give_up(self, reason: str, detail: str) -> None:
        fault = WriteFault(reason, detail, time.time_ns(), at_stamp_ns=self.writer.last_stamp_ns)
        # the thread is blocked or behind, so its state holds still enough; a racing update would only cost
        # the 'readable up to' figures
        with contextlib.suppress(Exception):
            self.writer.note_progress(fault)
        fault.problems = 'the log could not be finished: readable up to its last whole chunk on disk'
        self._own_fault = fault
        self._queue.put(('stop', reason, detail))

    def _file(self) -> str:
        files = self.writer.files
        return str(files[-1]) if files else str(self.writer.path)

    def _run(self) -> None:
        writer = self.writer
        while True:
            try:
                item = self._queue.get(timeout=WAKE_PERIOD)
            except queue.Empty:
                item = None
            self._busy_since = time.monotonic()
            try:
                if item is _CLOSE:
                    if writer.fault is None and self._own_fault is not None:
                        writer.stop(self._own_fault.reason, self._own_fault.detail)
                    writer.close()
                    return
                if item is None:
                    writer.flush_if_due()
                elif item[0] == 'message':
                    with self._lock:
                        self._queued_bytes -= len(item[2])
                    if self._own_fault is None and item[1] not in self.skipped:
                        writer.write(item[1], item[2], item[3])
                elif item[0] == 'topic':
                    try:
                        writer.add_topic(*item[1:])
                    except ValueError as err:    # no message definition for its type
                        self.skipped[item[1]] = str(err)
                elif item[0] == 'stop' and writer.fault is None:
                    writer.stop(item[1], item[2])
            except Exception as err:   # a bug: stop recording, keep what was written, report the traceback
                self.error = traceback.format_exc()
                if writer.fault is None:
                    try:
                        writer.stop('recorder error', f'{type(err).__name__}: {err}')
                    except Exception:
                        self.error += traceback.format_exc()
            finally:
                self._busy_since = None
