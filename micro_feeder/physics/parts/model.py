"""Many parts on one feeder: every part integrated exactly as it would be alone, impacts between neighbours
located as events, trains of parts pressed together (docs/parts.md).

Typical use::

    parts = PartsModel.from_settings(flat)               # particle.x0 = [x_0, x_1, ...]
    state = parts.initial_state()
    events = parts.advance(state, t_target)              # one EventList per part; state.impacts grows
    result = parts.run()                                 # positions of every part against time

Each part keeps its own :class:`~micro_feeder.physics.dynamics.FeederState`; all advance together in
chunks. A chunk is first taken by every part alone; it is kept when no two neighbours can have met in it
(how far each part can have gone is bounded by its largest speed and the positions of its events), and
otherwise shortened, or cut at the first impact, located on the gap between the two parts to
``integration.event_tolerance``. Parts far apart therefore take the very steps they would take alone.
SI units.
"""

from __future__ import annotations

import threading
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from ..dynamics import MODES, EventList, FeederModel, FeederState, SimulationError
from ..dynamics.model import StateRows
from ..waveforms import StrokeSchedule, StrokeTable
from .apart import CONTACT_GAP, REACH_SAFETY, REACHED, advance_apart, near_end, next_chunk
from .impacts import common_velocity, newton_impact, packed_positions, pooled_velocities

Source = StrokeTable | StrokeSchedule | None

APPROACH = 1e-12            # relative: a rear part faster than the front one by more than this fraction approaches


class Impact(NamedTuple):
    """One impact at sim time ``t`` (s) between the parts ``parts`` (indices, in order: two neighbours, or a
    touching row struck plastically), with the approach speed of the two that met (m/s), the restitution
    applied and every involved part's velocity before and after (m/s)."""

    t: float
    parts: tuple[int, ...]
    approach: float
    restitution: float
    before: tuple[float, ...]
    after: tuple[float, ...]


class PartsState:
    """The parts' states (one :class:`FeederState` each, in order along the feeder, all at one sim time), the
    impacts so far and the chunk length to try next.

    The states are kept as the rows of one :class:`~micro_feeder.physics.dynamics.model.StateRows` between
    chunks (one compiled call advances them all); :attr:`parts` are views of those rows, so changing a part
    changes the rows. Add and remove parts with :meth:`insert` and :meth:`remove`, not on the list."""

    def __init__(self, parts: Sequence[FeederState]):
        self._parts: list[FeederState] | None = list(parts)
        self._rows: StateRows | None = None
        self.impacts: list[Impact] = []
        self.chunk_hint = 0.0

    @property
    def parts(self) -> list[FeederState]:
        """Every part's state, in order along the feeder."""
        if self._parts is None:
            self._parts = self._rows.views()
        return self._parts

    @property
    def rows(self) -> StateRows:
        """The parts as rows (:attr:`parts` become views of them)."""
        rows, parts = self._rows, self._parts
        if rows is None or (parts is not None and len(parts) != len(rows)):
            rows = self._rows = StateRows.of(parts)
            self._parts = rows.views()
        elif parts is not None:
            rows.ons[:] = [part.ahead_on for part in parts]   # a part advanced on its own keeps what it was on
        return rows

    def take(self, rows: StateRows) -> None:
        """Make ``rows`` the parts' states."""
        self._rows, self._parts = rows, None

    def changed_in_place(self) -> None:
        """The rows' arrays and ``ons`` were changed in place: the parts (views of the arrays) take ``ons``."""
        if self._parts is not None:
            for part, on in zip(self._parts, self._rows.ons, strict=True):
                part.ahead_on = on

    def insert(self, index: int, part: FeederState) -> None:
        """Add ``part`` at ``index`` (its place along the feeder)."""
        self.parts.insert(index, part)
        self._rows = None

    def remove(self, index: int) -> None:
        """Remove part ``index``."""
        del self.parts[index]
        self._rows = None

    def __len__(self) -> int:
        return len(self._rows) if self._parts is None else len(self._parts)

    @property
    def t(self) -> float:
        """Sim time (s)."""
        return self._rows.t if self._rows is not None else self._parts[0].t

    @property
    def positions(self) -> np.ndarray:
        """Every part's x (m)."""
        return self._rows.y[:, 0].copy() if self._rows is not None else np.array([part.x for part in self._parts])

    @property
    def velocities(self) -> np.ndarray:
        """Every part's ẋ (m/s)."""
        return np.array([part.xdot for part in self.parts])

    @property
    def collisions(self) -> int:
        """Number of impacts so far."""
        return len(self.impacts)

    def copy(self) -> PartsState:
        """An independent copy (to branch a run)."""
        other = PartsState([])
        if self._rows is not None:
            other.take(self.rows.copy())
        else:
            other._parts = [part.copy() for part in self.parts]
        other.impacts, other.chunk_hint = list(self.impacts), self.chunk_hint
        return other


@dataclass(frozen=True)
class PartsResult:
    """Positions of every part against time: ``t`` (s, n), ``x`` (m, n × parts), ``modes`` (n × parts, codes
    of :data:`~micro_feeder.physics.dynamics.MODES`), with every impact and the final state."""

    t: np.ndarray
    x: np.ndarray
    modes: np.ndarray
    state: PartsState
    events: list[EventList] = field(default_factory=list)

    def summary(self) -> dict[str, Any]:
        """Per part: ``distance_m``, ``final_mode``, ``transitions``, ``max_speed_mps``; ``collisions`` (impacts),
        ``settled`` (every part stuck at the end) and ``sim_time_s``."""
        parts = [{'distance_m': p.distance, 'final_mode': p.mode, 'transitions': p.transitions,
                  'max_speed_mps': p.max_speed} for p in self.state.parts]
        return {'parts': parts, 'collisions': self.state.collisions,
                'settled': all(p.mode == 'stuck' for p in self.state.parts), 'sim_time_s': self.state.t}


@dataclass
class _Trial:
    """Every part taken alone from the chunk's start to its end (copies, as rows), the events of the parts that
    had some (by part index), with how far each may have gone."""

    rows: StateRows
    events: dict[int, EventList]
    reach: np.ndarray


class PartsModel:
    """Several identical parts on one feeder (``particle.x0`` a list): the parts' model, their size along
    the feeder and the restitution between them (docs/parts.md)."""

    def __init__(self, model: FeederModel):
        self.model = model
        self.size = model.particle.size
        self.restitution = model.particle.restitution
        self.near_chunk = model.integration.dt          # s: the longest chunk while two parts are near
        self.event_tolerance = model.integration.event_tolerance
        self.compiled_chunks = True                     # False: every chunk in Python (to compare the two)
        self.trials = 0                                 # chunks tried so far (every part alone over one)

    @classmethod
    def from_settings(cls, flat: Mapping[str, Any], **overrides: Any) -> PartsModel:
        """The parts of a flat ``{dotted name: value}`` mapping (:meth:`FeederModel.from_settings`)."""
        return cls(FeederModel.from_settings(flat, **overrides))

    @property
    def n_parts(self) -> int:
        return self.model.particle.n_parts

    def initial_state(self) -> PartsState:
        """t = 0, every part at its ``particle.x0`` with its ``particle.v0`` (stuck when 0, else sliding)."""
        particle = self.model.particle
        return PartsState([self.model.initial_state(x0, v0) for x0, v0 in
                           zip(particle.start_positions, particle.start_velocities, strict=True)])

    def gaps(self, positions: np.ndarray) -> np.ndarray:
        """Free space between neighbours (m): x_{i+1} − x_i − size."""
        return positions[1:] - positions[:-1] - self.size

    # ------------------------------------------------------------------------------------------------

    def advance(self, state: PartsState, t_target: float, source: Source = None) -> list[EventList]:
        """Integrate every part to ``t_target`` (s), impacts included; returns each part's mode changes.

        A chunk ends where the stroke table in force ends (a part alone stops there too), so that one compiled
        call takes the chunks of each table (the 20-ms windows a streaming actuator sends).

        Raises :class:`~micro_feeder.physics.dynamics.SimulationError` as a single part's run does."""
        events: list[list[EventList]] = [[] for _ in range(len(state))]
        self._cascade(state, range(len(state) - 1), True, source, events)     # e.g. a v0 into a touching part
        for t_end, _, _ in self.model.segments(state.t, t_target, source):
            while state.t < t_end:
                if self.compiled_chunks and self._advance_apart(state, t_end, source, events):
                    break
                t = state.t
                hint = state.chunk_hint or self.near_chunk
                t1 = self._near_end(t) if hint <= self.near_chunk else t + hint
                self._chunk(state, min(t1, t_end), source, events, planned=t1 - t)
        return [EventList.concatenate(part_events) for part_events in events]

    def run(self, duration: float | None = None, source: Source = None, output_step: float | None = None
            ) -> PartsResult:
        """Simulate from the initial state for ``duration`` (s); with none, to the end of the strokes plus
        ``integration.settling_time``, then on until every part is stuck, for at most
        ``integration.settle_max`` more. Positions are sampled every ``output_step`` (s; default each call's
        end only) and at every impact."""
        state = self.initial_state()
        model = self.model
        t_end = model.default_duration() if duration is None else duration
        step = output_step or t_end
        samples = [self._sample(state)]
        events: list[list[EventList]] = [[] for _ in state.parts]

        def go_to(t_stop: float) -> None:
            for i, part_events in enumerate(self.advance(state, t_stop, source)):
                events[i].append(part_events)
            samples.append(self._sample(state))

        for t_stop in [*np.arange(step, t_end, step).tolist(), t_end]:
            go_to(t_stop)
        if duration is None:
            t_cap = state.t + model.integration.settle_max
            piece = output_step or model.integration.settling_time or 1e-3
            while any(part.mode != 'stuck' for part in state.parts) and state.t < t_cap:
                go_to(min(state.t + piece, t_cap))
        t, x, modes = (np.array(column) for column in zip(*samples, strict=True))
        return PartsResult(t, x, modes, state, [EventList.concatenate(e) for e in events])

    # ------------------------------------------------------------------------------------------------

    def _advance_apart(self, state: PartsState, t_target: float, source: Source, events: list[list[EventList]]
                       ) -> bool:
        """Take the chunks towards ``t_target`` in which no two parts touch or meet in one compiled call
        (:func:`.apart.advance_apart`: the chunks :meth:`_chunk` would take, bit for bit); True when it got
        there, False when the next chunk is :meth:`_chunk`'s."""
        if len(state) < 2 or (self.gaps(state.positions) <= CONTACT_GAP).any():
            return False
        rows = state.rows
        kernel = self.model.rows_on_one_table(rows, t_target, source)
        if kernel is None:
            return False
        model, src, t_limit, work, records = kernel
        space = _APART_WORK.arrays(rows)
        space.hint[0] = state.chunk_hint
        code = advance_apart(rows.y, rows.iv, rows.fs, rows.ahead, t_target, t_limit, self.size, self.near_chunk,
                             space.hint, model, src, *space.trial, *space.per_part, work.batch_ev_i,
                             work.batch_ev_f, *space.out, records, 0, work.scratch, work.st, work.aux, work.cur)
        state.changed_in_place()
        state.chunk_hint = float(space.hint[0])
        self.trials += int(space.trials[0])
        space.deal(events)
        return code == REACHED

    def _sample(self, state: PartsState) -> tuple[float, np.ndarray, np.ndarray]:
        return state.t, state.positions, np.array([MODES.index(p.mode) for p in state.parts])

    def _trial(self, state: PartsState, t1: float, source: Source) -> _Trial:
        self.trials += 1
        advanced = self.model.advance_rows(state.rows, t1, source)
        reach = REACH_SAFETY * advanced.peak_speed * (t1 - state.t) + advanced.path
        return _Trial(advanced.rows, advanced.events, reach)

    def _chunk(self, state: PartsState, t1: float, source: Source, events: list[list[EventList]],
               planned: float = 0.0) -> None:
        """Advance every part to ``t1`` or to the first impact before it (then apply it). ``planned`` (s): the
        chunk meant, of which the caller's end left ``t1 - state.t``; the next chunk grows from the longer of
        the two, so that the 1-ms calls of a real-time loop do not keep the chunks below a tick."""
        t0 = state.t
        t1_given = t1
        gap0 = self.gaps(state.positions)
        touching = gap0 <= CONTACT_GAP
        pending = -1                                # the pair whose impact ends the chunk
        while True:
            trial = self._trial(state, t1, source)
            chunk = t1 - t0
            gap1 = self.gaps(trial.rows.y[:, 0])
            reach = trial.reach[:-1] + trial.reach[1:]
            crossed = (gap1 < 0.0) & ~touching
            if pending >= 0:
                crossed[pending] = False
            pressed = (gap1 < -CONTACT_GAP) & (gap1 < gap0) & touching     # not an overlap within rounding
            near = (reach > 0.0) & (gap0 <= reach)
            if pending >= 0:
                near[pending] = False
            if crossed.any():
                t_first, pair = min((self._locate_impact(state, int(i), t1, gap0[i], gap1[i], source), int(i))
                                    for i in np.flatnonzero(crossed))
                if t_first <= t0:               # cannot happen with gap0 > 0; guards an endless loop
                    t_first = t0 + self.event_tolerance
                t1, pending = t_first, pair
                continue
            if (near.any() or pressed.any()) and t1 > self._near_end(t0) * (1 + 1e-15):
                ratio = float(np.min(gap0[near] / reach[near])) if near.any() else 0.0
                cut = 0.5 * ratio * chunk
                t1, pending = (t0 + cut if cut > self.near_chunk else self._near_end(t0)), -1
                continue
            break
        state.take(trial.rows)
        for i, part_events in trial.events.items():
            events[i].append(part_events)
        trains = bool(pressed.any())
        if trains:
            self._press_trains(state, pressed, source, events)
        # a pair that closed its gap in this chunk hits; pairs that touched all along and approach now press on
        # each other: plastic, and not an impact
        closed = ~touching & ((self.gaps(state.positions) if trains else gap1) <= CONTACT_GAP)
        arrived = np.flatnonzero(closed).tolist()
        if pending >= 0:                            # located: within the event tolerance of contact
            self._put_in_contact(state, pending)
            arrived.append(pending)
        self._cascade(state, sorted(set(arrived)), True, source, events)
        self._cascade(state, np.flatnonzero(touching), False, source, events)
        grown_from = max(chunk, planned) if t1 == t1_given else chunk
        state.chunk_hint = next_chunk(gap1, reach, bool((near | pressed).any()), chunk, grown_from, self.near_chunk)

    def _near_end(self, t0: float) -> float:
        """The end (s) of a near chunk starting at ``t0``: the next multiple of ``integration.dt``, so that a train
        is stepped at the same instants whichever calls (ticks, one run) a path advances by, as long as they end
        on that grid too (a 1 ms tick is 10 chunks of the default 0.1 ms)."""
        return near_end(t0, self.near_chunk)

    def _locate_impact(self, state: PartsState, rear: int, t1: float, gap0: float, gap1: float,
                       source: Source) -> float:
        """The time (s) the gap between parts ``rear`` and ``rear + 1`` closes in (t, t1], found by Illinois
        regula falsi on the gap of copies advanced from the chunk's start, to the event tolerance; the time
        returned has the gap >= 0 (the parts never overlap)."""
        a, b, g_a, g_b = state.t, t1, gap0, gap1
        pair = [state.parts[rear].copy(), state.parts[rear + 1].copy()]
        side = 0
        while b - a > self.event_tolerance:
            m = (a * g_b - b * g_a) / (g_b - g_a)
            m = min(max(m, a + 0.01 * (b - a)), b - 0.01 * (b - a))
            trial = [p.copy() for p in pair]
            for p in trial:
                self.model.advance(p, m, source)
            g_m = trial[1].x - trial[0].x - self.size
            if g_m >= 0.0:
                a, g_a, pair = m, g_m, trial
                if g_m <= CONTACT_GAP:
                    break
                if side == 1:
                    g_b *= 0.5
                side = 1
            else:
                b, g_b = m, g_m
                if side == -1:
                    g_a *= 0.5
                side = -1
        return a

    def _approaching(self, state: PartsState, rear: int) -> bool:
        back, front = state.parts[rear].xdot, state.parts[rear + 1].xdot
        return back - front > APPROACH * (abs(back) + abs(front))

    def _touching(self, state: PartsState, rear: int) -> bool:
        return state.parts[rear + 1].x - state.parts[rear].x - self.size <= CONTACT_GAP

    def _set_velocities(self, state: PartsState, members: Sequence[int], velocities: Sequence[float], source: Source,
                        events: list[list[EventList]]) -> None:
        for k, velocity in zip(members, velocities, strict=True):
            change = self.model.set_velocity(state.parts[k], velocity, source)
            if len(change):
                events[k].append(change)

    def _impact(self, state: PartsState, rear: int, source: Source, events: list[list[EventList]]) -> None:
        """Newton's restitution between parts ``rear`` and ``rear + 1`` (which approach), putting them exactly in
        contact (the gap left is at most the event tolerance times their approach speed; an overlap as small
        comes from the integration's error)."""
        back, front = state.parts[rear], state.parts[rear + 1]
        before = (back.xdot, front.xdot)
        after = newton_impact(*before, self.restitution)
        self._set_velocities(state, (rear, rear + 1), after, source, events)
        self._put_in_contact(state, rear)
        state.impacts.append(Impact(back.t, (rear, rear + 1), before[0] - before[1], self.restitution, before, after))

    def _press(self, state: PartsState, rear: int, counted: bool, source: Source,
               events: list[list[EventList]]) -> list[int]:
        """Plastic contact of the touching row holding the pair ``rear``: no part faster than the one ahead,
        momentum conserved (:func:`.impacts.pooled_velocities`); an impact when ``counted``. Returns the
        row's parts."""
        lo, hi = rear, rear + 1
        while lo > 0 and self._touching(state, lo - 1):
            lo -= 1
        while hi < len(state.parts) - 1 and self._touching(state, hi):
            hi += 1
        members = list(range(lo, hi + 1))
        before = tuple(state.parts[k].xdot for k in members)
        after = pooled_velocities(before)
        approach = state.parts[rear].xdot - state.parts[rear + 1].xdot
        self._set_velocities(state, members, after, source, events)
        self._put_in_contact(state, rear)
        if counted:
            state.impacts.append(Impact(state.t, tuple(members), approach, 0.0, before, tuple(after)))
        return members

    def _cascade(self, state: PartsState, pairs: Iterable[int], counted: bool, source: Source,
                 events: list[list[EventList]]) -> None:
        """Contacts at this instant, starting from ``pairs`` (rear indices): a touching pair that approaches
        hits (``counted``: an impact with ``particle.restitution``, then its neighbours are looked at in turn,
        so a row at e = 1 passes the velocity on: Newton's cradle) or presses plastically. A rebound that would
        not open the gap beyond contact within a near chunk is plastic too (chatter ends)."""
        todo = [int(rear) for rear in pairs]
        if not todo or not (self.gaps(state.positions)[todo] <= CONTACT_GAP).any():
            return                                  # no pair touches: none is looked at again
        last = len(state.parts) - 2
        for _ in range(100 * (last + 2) ** 2):
            if not todo:
                return
            rear = todo.pop(0)
            if not (self._touching(state, rear) and self._approaching(state, rear)):
                continue
            approach = state.parts[rear].xdot - state.parts[rear + 1].xdot
            if counted and self.restitution * approach * self.near_chunk > CONTACT_GAP:
                self._impact(state, rear, source, events)
                touched = [rear, rear + 1]
            else:
                touched = self._press(state, rear, counted, source, events)
            todo += [k for k in (touched[0] - 1, touched[-1]) if 0 <= k <= last and k not in todo]
        raise SimulationError(f'impacts between parts at t = {state.t:.9g} s do not end (positions '
                              f'{state.positions.tolist()} m, velocities {state.velocities.tolist()} m/s)')

    def _press_trains(self, state: PartsState, pressed: np.ndarray, source: Source,
                      events: list[list[EventList]]) -> None:
        """Parts that touched and were pushed into each other over the chunk move on as one train: one
        velocity (momentum conserved) and centres ``size`` apart; a train that its friction can hold stops."""
        for lo, hi in _runs(pressed):
            members = list(range(lo, hi + 2))
            parts = [state.parts[k] for k in members]
            velocity = common_velocity([p.xdot for p in parts])
            if self._train_holds(parts, velocity, source):
                velocity = 0.0
                stuck = [k for k, p in enumerate(parts) if p.mode == 'stuck']
                fixed = stuck[-1] if stuck else None
            else:
                fixed = None
            positions = packed_positions([p.x for p in parts], self.size, fixed)
            for k, part, x in zip(members, parts, positions, strict=True):
                self.model.move_to(part, x)
                change = self.model.set_velocity(part, velocity, source)
                if len(change):
                    events[k].append(change)
        self._keep_apart(state)

    def _train_holds(self, parts: list[FeederState], velocity: float, source: Source) -> bool:
        """Whether static friction summed over the train can hold it at rest and stop its motion within a near
        chunk: |Σ T_req| <= Σ Q_max, with the reserve removing the train's momentum."""
        required = limit = 0.0
        for part in parts:
            friction_required, friction_limit = self.model.friction_at_rest(part, source)
            required += friction_required
            limit += friction_limit
        reserve = limit - abs(required)
        return reserve >= 0.0 and reserve * self.near_chunk >= len(parts) * self.model.particle.mass * abs(velocity)

    def _put_in_contact(self, state: PartsState, rear: int) -> None:
        """Move parts ``rear`` and ``rear + 1`` symmetrically (their centre of mass stays) so that they touch
        exactly: at an impact they are apart by at most the event tolerance times their approach speed, or
        overlap by as little (the integration's error); then push out any neighbour this makes overlap."""
        back, front = state.parts[rear], state.parts[rear + 1]
        gap = front.x - back.x - self.size
        if gap != 0.0:
            self.model.move_to(back, back.x + 0.5 * gap)
            self.model.move_to(front, front.x - 0.5 * gap)
        self._keep_apart(state)

    def _keep_apart(self, state: PartsState) -> None:
        """Push a part out of a neighbour it overlaps after a train was packed (by at most a near chunk's motion)."""
        for rear in range(len(state.parts) - 1):
            back, front = state.parts[rear], state.parts[rear + 1]
            if front.x - back.x < self.size:
                self.model.move_to(front, back.x + self.size)


def _runs(flags: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) index of each run of consecutive True values."""
    runs: list[tuple[int, int]] = []
    for i in np.flatnonzero(flags):
        if runs and runs[-1][1] == i - 1:
            runs[-1] = (runs[-1][0], int(i))
        else:
            runs.append((int(i), int(i)))
    return runs


class _ApartWork:
    """:func:`.apart.advance_apart`'s work space for one number of parts and state size, and the events it
    leaves (``out``: kinds, times and positions, count, by part), dealt to the parts."""

    EVENTS = 1024           # events of one part in one call (more: the chunk that would overflow is handed back)

    def __init__(self, n: int, rows: StateRows):
        self.hint = np.zeros(1)
        self.trial = (np.empty_like(rows.y), np.empty_like(rows.iv), np.empty_like(rows.fs), np.empty_like(rows.ahead))
        self.per_part = (np.zeros(n, dtype=np.bool_), np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64),
                         *(np.zeros(n) for _ in range(6)))
        self.trials = np.zeros(1, dtype=np.int64)
        self.out = (np.zeros((n, self.EVENTS, 3), dtype=np.int64), np.zeros((n, self.EVENTS, 2)),
                    np.zeros(n, dtype=np.int64), self.trials)

    def deal(self, events: list[list[EventList]]) -> None:
        """Append the events of the last call to each part's list."""
        out_i, out_f, out_count, _ = self.out
        for p in np.flatnonzero(out_count).tolist():
            count = out_count[p]
            events[p].append(EventList(out_i[p, :count].copy(), out_f[p, :count].copy()))


class _ThreadApartWork(threading.local):
    """:class:`_ApartWork` per thread and shape (the compiled call releases the GIL)."""

    def __init__(self) -> None:
        self._by_shape: dict[tuple, _ApartWork] = {}

    def arrays(self, rows: StateRows) -> _ApartWork:
        key = (rows.y.shape, rows.iv.shape, rows.fs.shape, rows.ahead.shape)
        work = self._by_shape.get(key)
        if work is None:
            work = self._by_shape[key] = _ApartWork(len(rows), rows)
        return work


_APART_WORK = _ThreadApartWork()
