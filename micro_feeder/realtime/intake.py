"""Bounded command intake: raw commands queued by the executor, parsed and applied by a worker thread,
with superseded commands coalesced and refusals reported in throttled lines.

Why: parsing a command costs tens of microseconds to milliseconds of Python; done on the executor thread
and under the simulator's lock for every message, a flood (5 kHz of trajectories) or one huge trajectory
held the loop off for seconds. Here a subscription callback only queues the serialized message (cheap);
a worker thread takes everything queued at once and, newest first, parses only what can still take
effect: a command is **coalesced** (counted, acknowledged, never parsed) when a later valid command of
the same batch starts at or before its start, because that one replaces everything from its start on
(docs/interface.md, *Commands*). Commands that survive are applied in arrival order.

Bounds: a message larger than ``max_message_bytes`` is refused on arrival, unparsed; the queue holds at
most ``max_queued_bytes`` of messages (the oldest are dropped, counted, beyond that). Nothing here knows
ROS: the simulator's engine passes in how to parse and apply.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

REFUSAL_LOG_PERIOD = 5.0    # s (wall clock) between two summary lines of repeated refusals


@dataclass
class Received:
    """One command message as it arrived: its topic, its serialized bytes (None once dropped or when
    refused on arrival), its start stamp (s, sim time; 0 = on receipt) read without parsing the rest, and
    the reason it was refused on arrival (too large), if it was."""

    topic: str
    data: bytes | None
    stamp: float
    refused: str = ''
    command_id: str = ''      # the sender's identity for the command (a trajectory's header.frame_id)


@dataclass
class Outcome:
    """What became of a :class:`Received`: ``command`` (parsed, to apply) or ``refused`` (the reason) or
    neither (``coalesced`` or ``dropped``)."""

    received: Received
    command: Any = None
    refused: str = ''
    coalesced: bool = False

    @property
    def dropped(self) -> bool:
        return self.received.data is None and not self.received.refused


@dataclass
class IntakeCounters:
    """Since start: messages received, coalesced (superseded before parsing), dropped (queue full),
    refused (invalid or too large: the node's ``rejected_commands``), repeated (a copy of a trajectory
    already applied, by its identity: not applied again, not a fault), late (a trajectory stamped before
    the sim time it was applied at: its knots before that time were dropped)."""

    received: int = 0
    coalesced: int = 0
    dropped: int = 0
    refused: int = 0
    repeated: int = 0
    late: int = 0
    last_refusal: str = ''

    def as_items(self) -> dict[str, str]:
        return {'commands_received': str(self.received), 'commands_coalesced': str(self.coalesced),
                'commands_dropped': str(self.dropped), 'rejected_commands': str(self.refused),
                'commands_repeated': str(self.repeated), 'commands_late': str(self.late),
                'last_rejection': self.last_refusal}


class ThrottledLog:
    """Repeated refusals in few lines: the first at once, then at most one summary line per ``period``
    (s) saying how many more there were and the last reason. Returns the line to log, or None.
    ``label`` says what happened to the commands (``rejected``, ``late``)."""

    def __init__(self, period: float = REFUSAL_LOG_PERIOD, clock: Callable[[], float] = time.monotonic,
                 label: str = 'rejected'):
        self.period = period
        self.label = label
        self._clock = clock
        self._next = -float('inf')
        self._unreported = 0
        self._last = ''

    def note(self, reason: str) -> str | None:
        self._unreported += 1
        self._last = reason
        return self.flush()

    def flush(self) -> str | None:
        """The summary line when one is due (call it periodically so the last refusals get reported)."""
        now = self._clock()
        if not self._unreported or now < self._next:
            return None
        n, self._unreported = self._unreported, 0
        self._next = now + self.period
        if n == 1:
            return f'command {self.label}: {self._last}'
        return f'{n} commands {self.label} in the last {self.period:g} s; last: {self._last}'


def plan(batch: list[Received], now: float, start_time: Callable[[float, float], float],
         parse: Callable[[Received], Any], coalesce: bool = True) -> list[Outcome]:
    """Decide each message of ``batch`` (arrival order) at sim time ``now``: newest first, a message is
    coalesced (with ``coalesce``) when a later valid one starts at or before its start
    (``start_time(stamp, now)``), else parsed (``parse`` returns the command or raises ``ValueError``
    with the reason)."""
    outcomes = [Outcome(r, refused=r.refused) for r in batch]
    horizon = float('inf')      # earliest start of a valid command later in the batch
    for outcome in reversed(outcomes):
        received = outcome.received
        if received.data is None:
            continue
        start = start_time(received.stamp, now)
        if coalesce and start >= horizon:
            outcome.coalesced = True
            continue
        try:
            outcome.command = parse(received)
        except ValueError as err:
            outcome.refused = str(err)
            continue
        horizon = start
    return outcomes


@dataclass
class _Queue:
    items: list[Received] = field(default_factory=list)
    queued_bytes: int = 0


class CommandIntake:
    """Queue of :class:`Received` with a worker thread that plans and applies batches.

    ``process(batch)``: called with the intake's lock held (never concurrently with itself), with the
    batch in arrival order; the node plans, applies under its own lock, publishes receipts and counts.
    :meth:`submit` queues for the worker, or, when ``synchronous()`` is true (paused, lockstep),
    processes at once on the caller's thread (everything still queued first). :meth:`drain` processes
    what is queued now (before a step or a reset).
    """

    def __init__(self, process: Callable[[list[Received]], None], synchronous: Callable[[], bool], *,
                 max_message_bytes: int, max_queued_bytes: int, batch_interval: float = 0.0,
                 name: str = 'simulator-intake'):
        self.max_message_bytes = max_message_bytes
        self.max_queued_bytes = max_queued_bytes
        self.dropped = 0
        self.batch_interval = batch_interval
        self._process = process
        self._synchronous = synchronous
        self._queue = _Queue()
        self._cv = threading.Condition()
        self.busy = threading.RLock()      # held while a batch is processed
        self._stopping = False
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def submit(self, received: Received) -> None:
        size = len(received.data or b'')
        if size > self.max_message_bytes:
            received.data = None
            received.refused = (f'{received.topic}: message of {size} B over max_command_bytes '
                                f'({self.max_message_bytes} B): send long strokes in windows')
        with self._cv:
            self._queue.items.append(received)
            self._queue.queued_bytes += len(received.data or b'')
            self._bound()
            self._cv.notify()
        if self._synchronous():
            self.drain()

    def drain(self) -> None:
        """Process everything queued now, on this thread."""
        with self.busy:
            batch = self._take()
            if batch:
                self._process(batch)

    def stop(self, timeout: float = 1.0) -> None:
        with self._cv:
            self._stopping = True
            self._cv.notify()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout)

    def _bound(self) -> None:
        """Drop the oldest messages' bytes (the receipts stay) while the queue holds too much."""
        for item in self._queue.items:
            if self._queue.queued_bytes <= self.max_queued_bytes:
                return
            if item.data is not None:
                self._queue.queued_bytes -= len(item.data)
                item.data = None
                self.dropped += 1

    def _take(self) -> list[Received]:
        with self._cv:
            batch, self._queue = self._queue.items, _Queue()
        return batch

    def _run(self) -> None:
        while True:
            with self._cv:
                while not self._queue.items and not self._stopping:
                    self._cv.wait()
                if self._stopping:
                    return
            self.drain()
            time.sleep(self.batch_interval)
