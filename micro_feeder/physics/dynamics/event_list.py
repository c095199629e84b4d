"""Mode changes as data: what :meth:`FeederModel.advance` returns.

Like ``scipy.integrate.solve_ivp``'s ``t_events``, the events of a call are kept as numpy arrays (time,
position, kind and mode codes) as the kernel wrote them; an :class:`Event` is built only when an item is
read. A sweep or a benchmark that only counts transitions (``FeederState.transitions``) then pays
nothing per event, where building thousands of Python tuples cost ~12 % of the integration.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from functools import partial
from typing import NamedTuple, overload

import numpy as np

MODES = ('stuck', 'sliding', 'flying')
TRANSITION_KINDS = ('stick_to_slip', 'slip_to_stick', 'take_off', 'landing')   # mode changes, counted
EVENT_KINDS = (*TRANSITION_KINDS, 'reversal')   # and a slide's change of direction


class Event(NamedTuple):
    """One mode change (or slide reversal), at sim time ``t`` (s) and position ``x`` (m)."""

    t: float
    kind: str
    from_mode: str
    to_mode: str
    x: float


# Builds an Event from a tuple in C: half the cost of calling Event(...) (a Python-level __new__).
_new_event = partial(tuple.__new__, Event)


class EventList(Sequence[Event]):
    """A read-only sequence of :class:`Event` backed by arrays: ``codes`` (n, 3) int (kind, from mode,
    to mode: indices into ``EVENT_KINDS`` and ``MODES``) and ``values`` (n, 2) float (t in s, x in m).

    Compares equal to any sequence of the same events (``model.advance(...) == []``); ``t`` and ``x``
    give the columns as arrays without building the events.
    """

    __slots__ = ('_codes', '_values')

    def __init__(self, codes: np.ndarray | None = None, values: np.ndarray | None = None) -> None:
        self._codes = np.zeros((0, 3), dtype=np.int64) if codes is None else codes
        self._values = np.zeros((0, 2)) if values is None else values

    @classmethod
    def concatenate(cls, parts: Sequence[EventList]) -> EventList:
        """One list of the events of ``parts``, in order."""
        if len(parts) == 1:
            return parts[0]
        if not parts:
            return NO_EVENTS
        return cls(np.concatenate([p._codes for p in parts]), np.concatenate([p._values for p in parts]))

    @property
    def t(self) -> np.ndarray:
        """Event times (s)."""
        return self._values[:, 0]

    @property
    def x(self) -> np.ndarray:
        """Positions at the events (m)."""
        return self._values[:, 1]

    def __len__(self) -> int:
        return self._codes.shape[0]

    @overload
    def __getitem__(self, index: int) -> Event: ...

    @overload
    def __getitem__(self, index: slice) -> EventList: ...

    def __getitem__(self, index: int | slice) -> Event | EventList:
        if isinstance(index, slice):
            return EventList(self._codes[index], self._values[index])
        kind, old, new = self._codes[index].tolist()
        t, x = self._values[index].tolist()
        return Event(t, EVENT_KINDS[kind], MODES[old], MODES[new], x)

    def __iter__(self) -> Iterator[Event]:
        kinds, olds, news = self._codes.T.tolist()
        return map(_new_event, zip(self._values[:, 0].tolist(), map(EVENT_KINDS.__getitem__, kinds),
                                   map(MODES.__getitem__, olds), map(MODES.__getitem__, news),
                                   self._values[:, 1].tolist(), strict=True))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Sequence):
            return NotImplemented
        return len(self) == len(other) and all(a == b for a, b in zip(self, other, strict=True))

    __hash__ = None  # type: ignore[assignment]  # a sequence compared by value

    def __repr__(self) -> str:
        return f'EventList({list(self)!r})'


NO_EVENTS = EventList()     # what most calls return (a 1 ms tick rarely holds an event): shared, read-only
