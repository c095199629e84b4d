"""Replaying a log's commands into a :class:`~.stepper.Stepper`: the one loop ``resim`` and calibration share.

A log gives, independent of the model: the model parameters the simulator recorded, the simulator's stops
(rebuilt from the ``particle/pose`` header stamps, the one rule for pose time) with the recorded pose at
each, and the commands paired with the sim times the simulator received them
(``simulator/command_receipts``). :func:`replay` drives a stepper through them exactly as the simulator
ran: commands received before a stop, the stop, then the commands received at it.

:class:`LogRecording` streams them from the log in stamp order, so that a replay holds one chunk of the
log at a time whatever its length (``resim`` of an hour at 1 kHz); :func:`read_recording` reads them into
a :class:`Recording` once, for calibration, which replays a short log many times.

What it reads from the log (all recorded by default, see docs/logs.md):

* ``simulator/parameters`` (latched ``rcl_interfaces/ParameterEvent``): the model parameters in force
  and the node's ``step_period`` / ``real_time_factor`` / ``start_paused``.
* ``simulator/command_receipts`` (``std_msgs/Header``): one per command the simulator received,
  stamp = sim time of receipt, ``frame_id`` = the command's topic, then ``#`` and the command's identity
  when it has one (the actuator names every trajectory). A receipt with an identity is paired with the
  recorded message of that identity; one without, with the next recorded message on its topic that has
  none (per-publisher order is kept by DDS, so the pairing is exact with one such publisher per topic).
  A stamp-0 command applies at its receipt time, as does one stamped in the past (when it joins the
  stroke without a jump); a future stamp applies at the stamp (the Stepper decides, exactly as in the
  node). Without receipts (an older log) the receipt time is estimated as the stamp of the last pose
  recorded before the command, which is ambiguous by up to a tick.
* ``simulator/trajectories_received``: the simulator's copy of every trajectory it received, when the log
  has it (whatever senders the recorder had discovered), else ``actuator/trajectory`` as recorded; and
  ``actuator/command``.
* ``simulator/entity_changes``: parts spawned and deleted (SpawnEntity, DeleteEntity), applied at their sim
  time as the simulator did: after the pose of the stop they were made at.
* ``particle/pose``: the stop times and the reference trajectory. The simulator stops its integration
  at every published pose; the stamps are rounded to 1 ns, so the exact stop times are rebuilt as
  the simulator computed them, ``t + step_period`` per step (stepped mode, or ``real_time_factor`` 0),
  checked against every stamp. In real time the increments are elapsed wall time × factor, which the
  log only knows to the nanosecond: the replay stops at the rounded times.

Only the run up to the first ``simulator/reset`` is replayed (``reset`` says when there is more).

Messages are read from their bytes where the layout is the plain one (a pose's x and z, a trajectory's
knots: what the simulator itself reads), else decoded; one that does not decode is skipped and counted,
as ``LogReader.messages(..., decoded=True)`` does.
"""

from __future__ import annotations

import heapq
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from ..interface import trajectory_cdr
from ..interface.cdr import read_pose_xz
from ..interface.entity_changes import SPAWNED, read_entity_changes
from ..interface.names import joint_names, split_receipt_frame
from ..interface.stamps import header_frame_id, to_ns
from ..interface.topics import COMMAND_TOPICS, ENTITY_CHANGES
from ..logs.reader import LogMessage, LogReader
from ..logs.sim_parameters import recorded_parameters
from ..physics.dynamics import Observation, SimulationError
from ..settings import model_specs
from .commands import (
    MAX_POINTS,
    CommandRejected,
    needs_deserializing,
    parse_setpoints,
    parse_trajectory_cdr,
)
from .stepper import Stepper

MAX_INTERMEDIATE_STEPS = 1_000_000  # unrecorded steps rebuilt between two recorded poses, at most
MAX_ADVANCE = 0.5  # s of sim time per Stepper.advance call across a gap with no known stop (Ctrl-C stays quick)
PROGRESS_EVERY = 256  # recorded poses between two progress calls
PAIRING_WINDOW_NS = 10_000_000_000  # a receipt is paired with a command logged at most this far from it (ns)


class ReplayError(ValueError):
    """The log cannot be replayed (no poses, unreadable parameters); says why."""


@dataclass(frozen=True)
class Stop:
    """One stop of the replay: time [s] (exact float when rebuilt), its stamp [ns], and the recorded pose
    (x, z) [m] to compare with there (None for an unrecorded step)."""

    t: float
    ns: int
    pose: tuple[float, float] | None


@dataclass(frozen=True)
class Command:
    """A recorded command (its log message: the bytes, decoded only when needed) and the sim time [ns]
    the simulator received it at."""

    receipt_ns: int
    topic: str
    recorded: LogMessage

    @property
    def message(self) -> Any:
        """The decoded message."""
        return self.recorded.message


class Replayable(Protocol):
    """What :func:`replay` drives a stepper through: stops and commands in order, and the count of
    recorded poses (for progress)."""

    @property
    def pose_count(self) -> int: ...

    def iter_stops(self) -> Iterator[Stop]: ...

    def iter_commands(self) -> Iterator[Command]: ...


@dataclass(frozen=True)
class Recording:
    """What a log gives a replay, independent of the model, read into memory (:func:`read_recording`).

    ``flat``: the recorded model parameters (only model parameters; empty when not recorded);
    ``snapshots``: every recorded ``simulator/parameters`` snapshot (node settings too); ``stops``: the
    simulator's stops with the recorded poses, ``exact`` when rebuilt bit for bit; ``commands`` in receipt
    order; ``receipts``: ``'recorded'`` or ``'estimated'``; ``reset``: the log continues after a reset that
    is not replayed; ``notes``: what the reader should know about the log.
    """

    path: str
    flat: dict[str, Any]
    snapshots: list[dict[str, Any]]
    stops: list[Stop]
    exact: bool
    commands: list[Command]
    receipts: str
    reset: bool
    notes: list[str]

    @property
    def posed_stops(self) -> list[Stop]:
        """The stops that have a recorded pose."""
        return [s for s in self.stops if s.pose is not None]

    @property
    def pose_count(self) -> int:
        return len(self.posed_stops)

    @property
    def poses(self) -> np.ndarray:
        """(n, 2) recorded (x, z) in m."""
        return np.array([s.pose for s in self.posed_stops])

    @property
    def pose_times(self) -> np.ndarray:
        """(n,) sim times of the recorded poses (s)."""
        return np.array([s.t for s in self.posed_stops])

    def iter_stops(self) -> Iterator[Stop]:
        return iter(self.stops)

    def iter_commands(self) -> Iterator[Command]:
        return iter(self.commands)


class StopTimes:
    """The simulator's stops rebuilt from recorded pose stamps, one pose at a time; ``exact`` stays True
    while every stop is rebuilt bit for bit.

    From t = 0, each recorded stamp is reached by ``n`` additions of a recorded step period (the
    simulator's own ``t + step_period``, so the floats are the simulator's bit for bit) when one fits
    the stamp to the nanosecond; otherwise the stop is the stamp itself (real time: exact only to 1 ns).
    """

    def __init__(self, step_periods: list[float]):
        self.step_periods = step_periods
        self.exact = True

    def stops(self, poses: Iterable[tuple[int, float, float]]) -> Iterator[Stop]:
        """The stops up to each recorded pose ``(stamp ns, x, z)``, unrecorded steps included."""
        t = 0.0
        for ns, x, z in poses:
            steps = _steps_to(t, ns, self.step_periods)
            if steps is None:
                self.exact = False
                t = ns / 1e9
            else:
                dt, n = steps
                for _ in range(n - 1):
                    t += dt
                    yield Stop(t, to_ns(t), None)
                if n:
                    t += dt
            yield Stop(t, ns, (x, z))


def stop_times(poses: list[tuple[int, float, float]], step_periods: list[float]) -> tuple[list[Stop], bool]:
    """The simulator's stops up to each recorded pose ``(stamp ns, x, z)``, and whether all are exact
    (:class:`StopTimes`)."""
    rebuilt = StopTimes(step_periods)
    stops = list(rebuilt.stops(poses))
    return stops, rebuilt.exact


def _steps_to(t: float, ns: int, step_periods: list[float]) -> tuple[float, int] | None:
    """``(dt, n)``: ``n`` additions of ``dt`` (one of ``step_periods``) take ``t`` exactly to stamp ``ns``;
    ``(0.0, 0)`` when ``t`` already has that stamp; None when no step period fits."""
    if to_ns(t) == ns:
        return 0.0, 0
    for dt in step_periods:
        n = round((ns - to_ns(t)) / (dt * 1e9))
        if not 1 <= n <= MAX_INTERMEDIATE_STEPS:
            continue
        s = t
        for _ in range(n):
            s += dt
        if to_ns(s) == ns:
            return dt, n
    return None


class LogRecording:
    """A log's recording streamed from the log: what :func:`replay` needs, read as it goes (nothing is read
    ahead, so that a replay answers at once whatever the log's length).

    Known when opened: ``path``, ``flat`` (the recorded model parameters), ``snapshots``, ``receipts``
    (``'recorded'`` or ``'estimated'``), ``pose_count`` (recorded poses, from the log's statistics) and
    ``last_ns`` (the stamp of the last one: the end of the replay when the log has no reset). Known once
    the stops and the commands have been iterated to their ends (as :func:`replay` does): ``exact`` (every
    stop rebuilt bit for bit), ``reset`` (the log continues after a ``simulator/reset`` that is not
    replayed), ``first_ns`` (the first pose's stamp) and ``notes``. Each iteration reads the log afresh.

    Raises :class:`ReplayError` when the log has no pose or its parameters cannot be read.
    """

    def __init__(self, log: LogReader):
        self.log = log
        self.path = str(log.path)
        specs = model_specs()
        try:
            self.snapshots = recorded_parameters(log)
        except ValueError as err:
            raise ReplayError(f'simulator/parameters unreadable: {err}') from err
        self.flat = {name: value for name, value in (self.snapshots[0] if self.snapshots else {}).items()
                     if name in specs}
        self.step_periods = sorted({float(s['step_period']) for s in self.snapshots if 'step_period' in s}) or [1e-3]
        last = log.last('particle/pose')
        if last is None:
            raise ReplayError('the log has no particle/pose')
        self.last_ns = last.stamp_ns or 0
        self.pose_count = log.topics[log.resolve('particle/pose')].count
        self.first_ns: int | None = None
        self.reset = False
        self.receipts = 'recorded' if log.resolve('simulator/command_receipts') is not None else 'estimated'
        self._stop_times = StopTimes(self.step_periods)
        self._counts: dict[str, int] = {}   # commands: 'recorded', 'paired', 'missing'; receipts: 'reset'

    @property
    def exact(self) -> bool:
        return self._stop_times.exact

    @property
    def notes(self) -> list[str]:
        """What the reader should know about the log (complete once stops and commands were iterated)."""
        notes = []
        if self.reset:
            notes.append('the log holds a simulator/reset: only the run before it is replayed')
        c = self._counts
        if self.receipts == 'estimated':
            if c.get('recorded'):
                notes.append('the log has no simulator/command_receipts (recorded by an older simulator): receipt '
                             'times estimated from the last pose recorded before each command, ambiguous by a tick')
        else:
            if c.get('missing'):
                notes.append(f'{c["missing"]} commands the simulator received are not in the log (the recorder '
                             'missed them, e.g. it started after them): replayed without them')
            unacknowledged = c.get('recorded', 0) - c.get('paired', 0)
            if unacknowledged and not c.get('reset'):
                notes.append(f'{unacknowledged} recorded commands have no receipt from the simulator (sent after it '
                             'stopped, or it missed them): not applied')
        if self.first_ns:
            notes.append(f'the first recorded pose is at t = {self.first_ns * 1e-9:.6f} s, not 0 (the recorder '
                         'joined late): earlier stops unknown, started from t = 0')
        return notes

    def iter_stops(self) -> Iterator[Stop]:
        """The simulator's stops with the recorded poses, in stamp order, up to the reset."""
        self._stop_times = StopTimes(self.step_periods)
        return self._stop_times.stops(self._first_run())

    def iter_commands(self) -> Iterator[Command]:
        """The commands in receipt order with their receipt times, and the parts spawned and deleted at their
        sim times (topic ``simulator/entity_changes``; the counts behind :attr:`notes` are final when the
        iterator ends)."""
        self._counts = {}
        commands = self._paired() if self.receipts == 'recorded' else self._estimated()
        return heapq.merge(commands, self._entity_changes(), key=lambda cmd: cmd.receipt_ns)

    def _entity_changes(self) -> Iterator[Command]:
        """The recorded entity changes in stamp order, up to the first that goes back in time (a reset)."""
        last = 0
        for m in self.log.messages([ENTITY_CHANGES] if self.log.resolve(ENTITY_CHANGES) else [], decoded=True):
            ns = m.stamp_ns or 0
            if ns < last:
                return
            last = ns
            yield Command(ns, ENTITY_CHANGES, m)

    # -- reading --------------------------------------------------------------------------------------
    def _first_run(self) -> Iterator[tuple[int, float, float]]:
        """The recorded poses up to the first stamp that goes back in time (a reset)."""
        self.first_ns, self.reset, last = None, False, None
        for ns, x, z in self._poses():
            if last is None:
                self.first_ns = ns
            elif ns < last:
                self.reset = True
                return
            last = ns
            yield ns, x, z

    def _poses(self) -> Iterator[tuple[int, float, float]]:
        """``(stamp ns, x, z)`` of every readable recorded pose, in log order."""
        for m in self.log.messages(['particle/pose']):
            xz = read_pose_xz(m.data)
            if xz is None:
                if not self.log.decodes(m):
                    continue
                p = m.message.pose.position
                xz = p.x, p.z
            yield m.stamp_ns or 0, xz[0], xz[1]

    def _recorded(self, topic: str) -> Iterator[LogMessage]:
        """The readable messages of a command topic, in log order (a trajectory's knots are read from its
        bytes when they have the actuator's layout; anything else must decode)."""
        source = self.log.command_source(topic)
        for m in self.log.messages([source] if source else []):
            fast = topic == 'actuator/trajectory' and not needs_deserializing(trajectory_cdr.decode(m.data, MAX_POINTS))
            if fast or self.log.decodes(m):
                self._counts['recorded'] = self._counts.get('recorded', 0) + 1
                yield m

    def _paired(self) -> Iterator[Command]:
        """Each receipt paired with the recorded command it names: by identity (a trajectory's
        ``header.frame_id``) when it has one, else the next unnamed recorded message of its topic. A recorded
        command is looked for among those logged within :data:`PAIRING_WINDOW_NS` of its receipt, so that
        memory stays bounded whatever the log's length."""
        counts = self._counts
        pending = {topic: _Pending(self._recorded(topic)) for topic in COMMAND_TOPICS}
        last = None
        for r in self.log.messages(['simulator/command_receipts'], decoded=True):
            ns = r.stamp_ns
            if last is not None and ns < last:        # a reset: the receipts of the next run are not paired
                counts['reset'] = 1
                break
            last = ns
            topic, command_id = split_receipt_frame(r.message.frame_id)
            queue = pending.get(topic)
            m = queue.take(command_id, r.log_time_ns) if queue is not None else None
            if m is None:
                counts['missing'] = counts.get('missing', 0) + 1
            else:
                counts['paired'] = counts.get('paired', 0) + 1
                yield Command(ns, topic, m)
        for queue in pending.values():               # counted: recorded commands without a receipt
            queue.drain()

    def _estimated(self) -> Iterator[Command]:
        """A log without receipts: each command at the stamp of the last pose logged at or before it, in log
        order, up to the first command whose estimate goes back in time (after a reset)."""
        order = sorted((first.log_time_ns, i, topic) for i, topic in enumerate(COMMAND_TOPICS)
                       if (first := self.log.first(topic)) is not None)
        recorded = heapq.merge(*(self._tagged(topic) for _, _, topic in order), key=lambda pair: pair[1].log_time_ns)
        poses = ((m.log_time_ns, m.stamp_ns or 0) for m in self.log.messages(['particle/pose'])
                 if read_pose_xz(m.data) is not None or self.log.decodes(m))
        pose = next(poses, None)
        log_ns, stamp, last = None, 0, 0
        for topic, m in recorded:
            while pose is not None and pose[0] <= m.log_time_ns:
                # the largest (log time, stamp) logged at or before the command: ties in log time by stamp
                stamp = pose[1] if log_ns is None or pose[0] > log_ns else max(stamp, pose[1])
                log_ns = pose[0]
                pose = next(poses, None)
            if stamp < last:
                return
            last = stamp
            yield Command(stamp, topic, m)

    def _tagged(self, topic: str) -> Iterator[tuple[str, LogMessage]]:
        for m in self._recorded(topic):
            yield topic, m


class _Pending:
    """The recorded messages of one command topic near the receipt being paired: read ahead up to
    :data:`PAIRING_WINDOW_NS` of log time past it, forgotten that long behind it (never paired, they count
    as recorded without a receipt)."""

    def __init__(self, recorded: Iterator[LogMessage]):
        self._recorded = recorded
        self._next: LogMessage | None = next(recorded, None)
        self._named: dict[str, deque[LogMessage]] = {}
        self._unnamed: deque[LogMessage] = deque()
        self._order: deque[tuple[int, str]] = deque()   # (log time, identity) of the named ones, as read

    def take(self, command_id: str, receipt_log_ns: int) -> LogMessage | None:
        """The recorded message named ``command_id`` (the next unnamed one for ''), or None."""
        while self._next is not None and self._next.log_time_ns <= receipt_log_ns + PAIRING_WINDOW_NS:
            m, self._next = self._next, next(self._recorded, None)
            name = _command_id(m)
            if name:
                self._named.setdefault(name, deque()).append(m)
                self._order.append((m.log_time_ns, name))
            else:
                self._unnamed.append(m)
        while self._order and self._order[0][0] < receipt_log_ns - PAIRING_WINDOW_NS:
            _, name = self._order.popleft()
            if self._named.get(name):
                self._named[name].popleft()
                if not self._named[name]:
                    del self._named[name]
        if not command_id:
            return self._unnamed.popleft() if self._unnamed else None
        same = self._named.get(command_id)
        if not same:
            return None
        m = same.popleft()
        if not same:
            del self._named[command_id]
        return m

    def drain(self) -> None:
        """Read the rest (the reader counts what it reads)."""
        for _ in self._recorded:
            pass


def _command_id(m: LogMessage) -> str:
    """A recorded command's identity: a trajectory's ``header.frame_id`` ('' for set-points and unnamed),
    read from its bytes."""
    return header_frame_id(m.data) if m.stamped else ''


def open_recording(log: LogReader) -> LogRecording:
    """The log's recording, streamed (:class:`LogRecording`)."""
    return LogRecording(log)


def read_recording(log: LogReader) -> Recording:
    """Everything a replay needs from ``log``, read into memory (for a short log replayed many times).
    Raises :class:`ReplayError` when it has no pose or its parameters cannot be read."""
    streamed = LogRecording(log)
    stops = list(streamed.iter_stops())
    commands = list(streamed.iter_commands())
    return Recording(streamed.path, streamed.flat, streamed.snapshots, stops, streamed.exact, commands,
                     streamed.receipts, streamed.reset, streamed.notes)


def apply_command(stepper: Stepper, cmd: Command) -> bool:
    """Apply one command through the simulator's own checks; False when they refuse it. An entity change
    spawns or deletes parts as the simulator did (False when the stepper refuses it: the log and the model
    disagree)."""
    n = stepper.model.n_actuators
    try:
        if cmd.topic == ENTITY_CHANGES:
            for change in read_entity_changes(cmd.message):
                if change.kind == SPAWNED:
                    stepper.spawn_part(change.entity, change.x)
                else:
                    stepper.delete_part(change.entity)
        elif cmd.topic == 'actuator/trajectory':
            stepper.command_trajectory(parse_trajectory_cdr(cmd.recorded.data, joint_names(n), stepper.limits,
                                                            deserialize=lambda _: cmd.message))
        else:
            stepper.command_setpoints(parse_setpoints(cmd.message.data, n, stepper.limits))
    except (CommandRejected, ValueError):
        return False
    return True


def replay(stepper: Stepper, recording: Replayable, on_pose: Callable[[Stop, Observation], None], *,
           on_command: Callable[[bool], None] | None = None,
           on_entity_change: Callable[[bool], None] | None = None,
           progress: Callable[[int, int], None] | None = None) -> SimulationError | None:
    """Drive ``stepper`` (fresh, at t = 0) through the recording's stops and commands as the simulator did,
    calling ``on_pose(stop, observation)`` at each recorded pose, ``on_command(applied)`` per command and
    ``on_entity_change(applied)`` per recorded spawn or delete;
    ``progress(recorded poses done, recorded poses)`` now and then. Returns the integration's failure,
    which ends the replay, or None when it reached the last stop. The stops and the commands are read to
    their ends either way (what a :class:`LogRecording` says about the log counts them all)."""
    pending = recording.iter_commands()
    next_cmd = next(pending, None)
    total, done = recording.pose_count, 0

    def receive(cmd: Command) -> Command | None:
        applied = apply_command(stepper, cmd)
        counter = on_entity_change if cmd.topic == ENTITY_CHANGES else on_command
        if counter is not None:
            counter(applied)
        return next(pending, None)

    failure = None
    stops = recording.iter_stops()
    try:
        for stop in stops:
            while next_cmd is not None and next_cmd.receipt_ns < stop.ns:  # received between two known stops
                _advance(stepper, next_cmd.receipt_ns / 1e9)
                next_cmd = receive(next_cmd)
            _advance(stepper, stop.t)
            if stop.pose is not None:
                if progress is not None and not done % PROGRESS_EVERY:
                    progress(done, total)
                done += 1
                on_pose(stop, stepper.observe())
            while next_cmd is not None and next_cmd.receipt_ns == stop.ns:
                next_cmd = receive(next_cmd)
    except SimulationError as err:
        failure = err
    for _ in stops:         # after a failure, the rest: read for what a LogRecording says (exact, reset)
        pass
    for _ in pending:       # the commands not applied: read for the counts
        pass
    if progress is not None and failure is None:
        progress(done, total)
    return failure


def _advance(stepper: Stepper, t: float) -> None:
    """Integrate to ``t``; a long gap with no known stop (a late-joining recorder, a pause in the poses) in
    pieces of ``MAX_ADVANCE``, so that Ctrl-C is answered within a second."""
    if t == stepper.t:
        return
    while t - stepper.t > MAX_ADVANCE:
        stepper.advance(stepper.t + MAX_ADVANCE)
    stepper.advance(t)
