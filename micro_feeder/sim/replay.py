"""Replaying a log's commands into a :class:`~.stepper.Stepper`: the one loop ``resim`` and calibration share.

A :class:`Recording` is what a log gives, independent of the model: the model parameters the simulator
recorded, the simulator's stops (rebuilt from the ``particle/pose`` header stamps, the one rule for pose
time) with the recorded pose at each, and the commands paired with the sim times the simulator received
them (``simulator/command_receipts``). :func:`replay` drives a stepper through it exactly as the simulator
ran: commands received before a stop, the stop, then the commands received at it.

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
* ``particle/pose``: the stop times and the reference trajectory. The simulator stops its integration
  at every published pose; the stamps are rounded to 1 ns, so the exact stop times are rebuilt as
  the simulator computed them, ``t + step_period`` per step (stepped mode, or ``real_time_factor`` 0),
  checked against every stamp. In real time the increments are elapsed wall time × factor, which the
  log only knows to the nanosecond: the replay stops at the rounded times.

Only the run up to the first ``simulator/reset`` is replayed (``Recording.reset`` says when there is more).
"""

from __future__ import annotations

import bisect
from collections import defaultdict
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..interface.names import joint_names, split_receipt_frame
from ..interface.stamps import to_ns
from ..logs.reader import LogMessage, LogReader
from ..logs.sim_parameters import recorded_parameters
from ..physics.dynamics import Observation, SimulationError
from ..settings import model_specs
from .commands import CommandRejected, parse_setpoints, parse_trajectory
from .stepper import Stepper

COMMAND_TOPICS = ('actuator/trajectory', 'actuator/command')
MAX_INTERMEDIATE_STEPS = 1_000_000  # unrecorded steps rebuilt between two recorded poses, at most
MAX_ADVANCE = 0.5  # s of sim time per Stepper.advance call across a gap with no known stop (Ctrl-C stays quick)


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
    """A recorded command and the sim time [ns] the simulator received it at."""

    receipt_ns: int
    topic: str
    message: Any


@dataclass(frozen=True)
class Recording:
    """What a log gives a replay, independent of the model.

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
    def poses(self) -> np.ndarray:
        """(n, 2) recorded (x, z) in m."""
        return np.array([s.pose for s in self.posed_stops])

    @property
    def pose_times(self) -> np.ndarray:
        """(n,) sim times of the recorded poses (s)."""
        return np.array([s.t for s in self.posed_stops])


def stop_times(poses: list[tuple[int, float, float]], step_periods: list[float]) -> tuple[list[Stop], bool]:
    """The simulator's stops up to each recorded pose ``(stamp ns, x, z)``, and whether all are exact.

    From t = 0, each recorded stamp is reached by ``n`` additions of a recorded step period (the
    simulator's own ``t + step_period``, so the floats are the simulator's bit for bit) when one fits
    the stamp to the nanosecond; otherwise the stop is the stamp itself (real time: exact only to 1 ns).
    """
    stops: list[Stop] = []
    t, exact = 0.0, True
    for ns, x, z in poses:
        path = _steps_to(t, ns, step_periods)
        if path is None:
            exact = False
            path = [ns / 1e9]
        stops += [Stop(s, to_ns(s), None) for s in path[:-1]]
        stops.append(Stop(path[-1], ns, (x, z)))
        t = path[-1]
    return stops, exact


def _steps_to(t: float, ns: int, step_periods: list[float]) -> list[float] | None:
    """The times ``t + dt``, ``t + dt + dt`` ... ending exactly at stamp ``ns`` for a ``dt`` of
    ``step_periods``; ``[t]`` when ``t`` already has that stamp; None when no step period fits."""
    if to_ns(t) == ns:
        return [t]
    for dt in step_periods:
        n = round((ns - to_ns(t)) / (dt * 1e9))
        if not 1 <= n <= MAX_INTERMEDIATE_STEPS:
            continue
        path, s = [], t
        for _ in range(n):
            s += dt
            path.append(s)
        if to_ns(s) == ns:
            return path
    return None


def first_segment(items: list[tuple[int, Any]]) -> tuple[list[tuple[int, Any]], bool]:
    """``(stamp ns, item)`` up to the first stamp that goes back in time (a reset); and whether there
    was one."""
    for i in range(1, len(items)):
        if items[i][0] < items[i - 1][0]:
            return items[:i], True
    return items, False


def read_recording(log: LogReader) -> Recording:
    """Everything a replay needs from ``log``. Raises :class:`ReplayError` when it has no pose or its
    parameters cannot be read."""
    notes: list[str] = []
    specs = model_specs()
    try:
        snapshots = recorded_parameters(log)
    except ValueError as err:
        raise ReplayError(f'simulator/parameters unreadable: {err}') from err
    flat = {name: value for name, value in (snapshots[0] if snapshots else {}).items() if name in specs}
    pose_msgs = list(log.messages(['particle/pose'], decoded=True))
    poses, reset = first_segment([(m.stamp_ns or 0, m) for m in pose_msgs])
    if not poses:
        raise ReplayError('the log has no particle/pose')
    if reset:
        notes.append('the log holds a simulator/reset: only the run before it is replayed')
    step_periods = sorted({float(s['step_period']) for s in snapshots if 'step_period' in s}) or [1e-3]
    stops, exact = stop_times([(ns, m.message.pose.position.x, m.message.pose.position.z) for ns, m in poses],
                              step_periods)
    commands, receipts = _commands(log, [(m.log_time_ns, m.stamp_ns or 0) for m in pose_msgs], notes)
    if poses[0][0] != 0:
        notes.append(f'the first recorded pose is at t = {poses[0][0] * 1e-9:.6f} s, not 0 (the recorder joined '
                     'late): earlier stops unknown, started from t = 0')
    return Recording(str(log.path), flat, snapshots, stops, exact, sorted(commands, key=lambda c: c.receipt_ns),
                     receipts, reset, notes)


def _commands(log: LogReader, pose_log: list[tuple[int, int]], notes: list[str]) -> tuple[list[Command], str]:
    """The commands of the log in receipt order, paired with their receipt sim times [ns]."""
    recorded: dict[str, list[LogMessage]] = defaultdict(list)
    for m in log.messages(COMMAND_TOPICS, decoded=True):
        recorded[next(t for t in COMMAND_TOPICS if m.topic.endswith(t))].append(m)
    if log.resolve('simulator/command_receipts') is None:
        if recorded:
            notes.append('the log has no simulator/command_receipts (recorded by an older simulator): receipt '
                         'times estimated from the last pose recorded before each command, ambiguous by a tick')
        return _estimated(recorded, pose_log), 'estimated'
    receipts, reset = first_segment([(m.stamp_ns, split_receipt_frame(m.message.frame_id))
                                     for m in log.messages(['simulator/command_receipts'], decoded=True)])
    named: dict[str, list[LogMessage]] = defaultdict(list)       # identity: recorded messages (resent ones too)
    unnamed: dict[str, list[LogMessage]] = defaultdict(list)
    for topic, msgs in recorded.items():
        for m in msgs:
            command_id = _command_id(m.message)
            (named[command_id] if command_id else unnamed[topic]).append(m)
    queues = {topic: iter(msgs) for topic, msgs in unnamed.items()}
    out, missing = [], 0
    for ns, (topic, command_id) in receipts:
        m = (named[command_id].pop(0) if named.get(command_id) else None) if command_id else \
            next(queues.get(topic, iter(())), None)
        if m is None:
            missing += 1
        else:
            out.append(Command(ns, topic, m.message))
    if missing:
        notes.append(f'{missing} commands the simulator received are not in the log (the recorder missed them, '
                     'e.g. it started after them): replayed without them')
    unacknowledged = sum(len(msgs) for msgs in recorded.values()) - len(out)
    if unacknowledged and not reset:
        notes.append(f'{unacknowledged} recorded commands have no receipt from the simulator (sent after it '
                     'stopped, or it missed them): not applied')
    return out, 'recorded'


def _command_id(message: Any) -> str:
    """A recorded command's identity: a trajectory's ``header.frame_id`` ('' for set-points and unnamed)."""
    header = getattr(message, 'header', None)
    return getattr(header, 'frame_id', '') if header is not None else ''


def _estimated(recorded: Mapping[str, list[LogMessage]], pose_log: list[tuple[int, int]]) -> list[Command]:
    """Receipt times for a log without receipts: the stamp of the last pose logged before each command."""
    pose_log = sorted(pose_log)
    log_times = [log_ns for log_ns, _ in pose_log]
    out = []
    for topic, msgs in recorded.items():
        for m in msgs:
            i = bisect.bisect_right(log_times, m.log_time_ns)
            out.append((m.log_time_ns, Command(pose_log[i - 1][1] if i else 0, topic, m.message)))
    return [c for _, c in sorted(out, key=lambda pair: pair[0])]


def apply_command(stepper: Stepper, cmd: Command) -> bool:
    """Apply one command through the simulator's own checks; False when they refuse it."""
    n = stepper.model.n_actuators
    try:
        if cmd.topic == 'actuator/trajectory':
            stepper.command_trajectory(parse_trajectory(cmd.message, joint_names(n), stepper.limits))
        else:
            stepper.command_setpoints(parse_setpoints(cmd.message.data, n, stepper.limits))
    except (CommandRejected, ValueError):
        return False
    return True


def replay(stepper: Stepper, recording: Recording, on_pose: Callable[[Stop, Observation], None], *,
           on_command: Callable[[bool], None] | None = None,
           progress: Callable[[int, int], None] | None = None) -> SimulationError | None:
    """Drive ``stepper`` (fresh, at t = 0) through the recording's stops and commands as the simulator did,
    calling ``on_pose(stop, observation)`` at each recorded pose and ``on_command(applied)`` per command;
    ``progress(stops done, stops)`` now and then. Returns the integration's failure, which ends the replay,
    or None when it reached the last stop."""
    stops = recording.stops
    pending: Iterator[Command] = iter(recording.commands)
    next_cmd = next(pending, None)

    def receive(cmd: Command) -> Command | None:
        applied = apply_command(stepper, cmd)
        if on_command is not None:
            on_command(applied)
        return next(pending, None)

    try:
        for i, stop in enumerate(stops):
            if progress is not None and not i % 256:
                progress(i, len(stops))
            while next_cmd is not None and next_cmd.receipt_ns < stop.ns:  # received between two known stops
                _advance(stepper, next_cmd.receipt_ns / 1e9)
                next_cmd = receive(next_cmd)
            _advance(stepper, stop.t)
            if stop.pose is not None:
                on_pose(stop, stepper.observe())
            while next_cmd is not None and next_cmd.receipt_ns == stop.ns:
                next_cmd = receive(next_cmd)
    except SimulationError as err:
        return err
    if progress is not None:
        progress(len(stops), len(stops))
    return None


def _advance(stepper: Stepper, t: float) -> None:
    """Integrate to ``t``; a long gap with no known stop (a late-joining recorder, a pause in the poses) in
    pieces of ``MAX_ADVANCE``, so that Ctrl-C is answered within a second."""
    if t == stepper.t:
        return
    while t - stepper.t > MAX_ADVANCE:
        stepper.advance(stepper.t + MAX_ADVANCE)
    stepper.advance(t)
