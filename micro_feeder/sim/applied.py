"""Which commands were applied, by identity, in memory that does not grow with a stream's length.

A simulator refuses a command whose identity was applied before (each command applies once, whoever resends
it). A stream sends ~35 windows a second for hours, each with its own identity (``<stream>:w<k>``), so
identities that end in a number are kept as runs of consecutive numbers per stem: a stream whose windows
were all applied is one run, whatever its length. Other identities, and the sim time of the most recent
ones (for the refusal's message), are kept in bounded first-in-first-out memories.
"""

from __future__ import annotations

import bisect
import re
from collections import OrderedDict

NUMBERED = re.compile(r'^(?P<stem>.*?)(?P<number>0|[1-9]\d*)$')   # stem + the number as written (x007: x00, 7)
REMEMBERED_OTHER = 100_000      # identities without a trailing number kept (first in, first out)
REMEMBERED_TIMES = 1_024        # recent identities whose sim time of application is kept


class AppliedCommands:
    """The identities of the commands applied, and the sim time (s) of the recent ones."""

    def __init__(self) -> None:
        self._runs: dict[str, list[list[int]]] = {}     # stem: sorted, disjoint [first, last] number runs
        self._other: OrderedDict[str, None] = OrderedDict()
        self._times: OrderedDict[str, float] = OrderedDict()
        self._count = 0

    def add(self, command_id: str, t: float) -> None:
        """Remember that ``command_id`` was applied at sim time ``t`` (s)."""
        if command_id in self:
            return
        self._count += 1
        self._times[command_id] = t
        if len(self._times) > REMEMBERED_TIMES:
            self._times.popitem(last=False)
        match = NUMBERED.match(command_id)
        if match is None:
            self._other[command_id] = None
            if len(self._other) > REMEMBERED_OTHER:
                self._other.popitem(last=False)
            return
        _insert(self._runs.setdefault(match['stem'], []), int(match['number']))

    def __contains__(self, command_id: object) -> bool:
        if not isinstance(command_id, str):
            return False
        match = NUMBERED.match(command_id)
        if match is None:
            return command_id in self._other
        runs = self._runs.get(match['stem'])
        if not runs:
            return False
        number = int(match['number'])
        i = bisect.bisect_right(runs, [number, float('inf')]) - 1
        return i >= 0 and runs[i][0] <= number <= runs[i][1]

    def __len__(self) -> int:
        """How many distinct identities were applied (including those no longer remembered)."""
        return self._count

    def applied_at(self, command_id: str) -> float | None:
        """Sim time (s) ``command_id`` was applied, when it is among the recent ones; None otherwise."""
        return self._times.get(command_id)

    def runs(self) -> int:
        """How many runs of numbered identities are kept (the memory used grows with this, not with windows)."""
        return sum(len(r) for r in self._runs.values())


def _insert(runs: list[list[int]], number: int) -> None:
    """Add ``number`` (not in ``runs``) to the sorted disjoint runs, merging the neighbours it joins."""
    i = bisect.bisect_right(runs, [number, float('inf')])      # runs[:i] start at or before number
    joins_left = i > 0 and runs[i - 1][1] == number - 1
    joins_right = i < len(runs) and runs[i][0] == number + 1
    if joins_left and joins_right:
        runs[i - 1][1] = runs[i][1]
        del runs[i]
    elif joins_left:
        runs[i - 1][1] = number
    elif joins_right:
        runs[i][0] = number
    else:
        runs.insert(i, [number, number])
