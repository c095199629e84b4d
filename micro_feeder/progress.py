"""A progress line on stderr for work that takes more than a few seconds: done / total, rate and ETA.

Nothing is shown for work that ends within ``delay`` seconds. On a terminal the line is rewritten in place
(``\\r``) every ``TTY_PERIOD``; otherwise (a log file, a pipe) one line is printed every ``PIPE_PERIOD``.
"""

from __future__ import annotations

import sys
import time
from typing import TextIO

TTY_PERIOD = 0.5   # s between two updates on a terminal
PIPE_PERIOD = 5.0  # s between two lines when stderr is not a terminal


class Progress:
    """``progress(done[, total])`` reports ``done`` of ``total`` ``unit`` for ``label``; :meth:`close` ends
    the line."""

    def __init__(self, label: str, total: int, unit: str, *, delay: float = 2.0, stream: TextIO | None = None):
        self.label, self.total, self.unit, self.delay = label, max(total, 1), unit, delay
        self.stream = stream or sys.stderr
        self.tty = self.stream.isatty()
        self.start = time.monotonic()
        self.last: float | None = None  # time of the last line shown
        self.first: tuple[float, int] | None = None  # (time, done) of the first report: the rate's origin

    def __call__(self, done: int, total: int | None = None) -> None:
        if total is not None:
            self.total = max(total, 1)
        now = time.monotonic()
        if self.first is None:
            self.first = (now, done)
        elapsed = now - self.start
        period = TTY_PERIOD if self.tty else PIPE_PERIOD
        if elapsed < self.delay or done == self.first[1] or (self.last is not None and now - self.last < period):
            return
        self.last = now
        rate = (done - self.first[1]) / (now - self.first[0])
        eta = f'{(self.total - done) / rate:.0f} s left'
        line = (f'{self.label}: {100 * done / self.total:5.1f} % ({done:,} of {self.total:,} {self.unit}, '
                f'{rate:,.0f}/s, {eta}; Ctrl-C stops)')
        print(('\r' + line) if self.tty else line, end='' if self.tty else '\n', file=self.stream, flush=True)

    def close(self) -> None:
        if self.tty and self.last is not None:
            print(file=self.stream)
