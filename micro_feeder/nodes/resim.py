"""Re-simulating a log: its recorded actuator commands fed into a fresh :class:`~.stepper.Stepper`.

``resim`` answers "does the log's part trajectory follow from its commands?": it rebuilds the simulation
from the parameters the simulator recorded, stops it at the sim times the simulator stopped at, applies
each recorded command at the sim time the simulator received it, and compares the re-simulated part
position (x, z) with every recorded ``particle/pose``.

What it reads from the log (all recorded by default, see docs/logs.md):

* ``simulator/parameters`` (latched ``rcl_interfaces/ParameterEvent``): the model parameters in force
  and the node's ``step_period`` / ``real_time_factor`` / ``start_paused``.
* ``simulator/command_receipts`` (``std_msgs/Header``): one per command the simulator received,
  stamp = sim time of receipt, ``frame_id`` = the command's topic. The i-th receipt naming a topic is
  paired with the i-th recorded message on that topic (per-publisher order is kept by DDS, so the
  pairing is exact with one publisher per command topic). A stamp-0 command applies at its receipt
  time, as does one stamped in the past; a future stamp applies at the stamp (the Stepper decides,
  exactly as in the node). Without receipts (an older log) the receipt time is estimated as the stamp of
  the last pose recorded before the command, which is ambiguous by up to a tick.
* ``particle/pose``: the stop times and the reference trajectory. The simulator stops its integration
  at every published pose; the stamps are rounded to 1 ns, so the exact stop times are rebuilt as
  the simulator computed them, ``t + step_period`` per step (stepped mode, or ``real_time_factor`` 0),
  checked against every stamp. In real time the increments are elapsed wall time × factor, which the
  log only knows to the nanosecond: the re-simulation stops at the rounded times; between commands the
  integrator takes the same steps (a stop never cuts a step) but a pose is evaluated up to 1 ns off on a
  moving surface, so a small difference remains (reported, with why).

Only the run up to the first ``simulator/reset`` is compared (a note says so when the log has more).
Lives in ``nodes`` (not ``logs``) because it drives the simulator's Stepper and the node's command
checks; it needs no rclpy and no running ROS graph, only the message packages the Stepper imports.
"""

from __future__ import annotations

import bisect
import math
from collections import defaultdict
from collections.abc import Callable, Iterator, Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

from ..logs.reader import LogMessage, LogReader
from ..logs.sim_parameters import recorded_parameters, run_mode
from ..physics.dynamics import SimulationError
from .commands import CommandRejected, joint_names, parse_setpoints, parse_trajectory
from .parameters import model_specs
from .stepper import Stepper, build_model
from .transitions import TRANSITION_KINDS

COMMAND_TOPICS = ('actuator/trajectory', 'actuator/command')
MAX_INTERMEDIATE_STEPS = 1_000_000  # unrecorded steps rebuilt between two recorded poses, at most
SIM_SECONDS_PER_WALL_SECOND = 20.0  # resim at 1 kHz poses, measured: 60 s of sim time in 3 s
MAX_ADVANCE = 0.5  # s of sim time per Stepper.advance call across a gap with no known stop (Ctrl-C stays quick)

class ResimError(ValueError):
    """The log cannot be re-simulated (no poses, parameters that build no model ...); says why."""


@dataclass
class ResimReport:
    """The comparison: poses compared, largest differences [m] and where [s, sim time], what was
    applied, whether the stop times were exact, and notes explaining any difference.

    ``max_error`` is the largest Euclidean distance between recorded and re-simulated (x, z);
    ``max_dx``/``max_dz`` the largest absolute component differences (each at its own pose).
    """

    log: str
    mode: str                  # 'stepped', 'as fast as possible', 'real time' or 'unknown'
    parameters: str            # where the model parameters came from
    overrides: dict[str, Any]
    poses: int
    sim_time: float            # last compared stamp [s]
    max_error: float
    max_dx: float
    max_dz: float
    t_max_error: float | None
    commands_applied: int
    commands_rejected: int
    exact_stop_times: bool
    receipts: str              # 'recorded' or 'estimated'
    notes: list[str] = field(default_factory=list)
    transitions: dict[str, int] = field(default_factory=dict)   # re-simulated, up to the last compared pose
    recorded_transitions: dict[str, int] | None = None          # particle/transitions up to then (None: not logged)

    @property
    def identical(self) -> bool:
        return self.poses > 0 and self.max_error == 0.0

    def as_dict(self) -> dict[str, Any]:
        return {**asdict(self), 'identical': self.identical}

    def verdict(self) -> str:
        """One line for people."""
        total = self.commands_applied + self.commands_rejected
        what = (f'{self.poses} poses, {self.sim_time:.6f} s sim time, {total} command{"s" * (total != 1)}'
                + (f' ({self.commands_rejected} refused, as by the simulator)' if self.commands_rejected else '')
                + f'; {self.mode} run' + (f', changed: {", ".join(sorted(self.overrides))}' if self.overrides else ''))
        if self.recorded_transitions is not None:
            same = self.recorded_transitions == self.transitions
            what += '; transitions ' + ('as recorded' if same else f'DIFFER: re-simulated {self.transitions}, '
                                                                   f'recorded {self.recorded_transitions}')
        if self.identical:
            return f'resim: IDENTICAL: re-simulated bit for bit ({what})'
        where = f' at t = {self.t_max_error:.6f} s' if self.t_max_error is not None else ''
        return (f'resim: DIFFERENT: largest difference {self.max_error:.3e} m{where} (max |dx| {self.max_dx:.3e} m, '
                f'max |dz| {self.max_dz:.3e} m; {what})')


@dataclass
class _Stop:
    """One stop of the re-simulation: time [s] (exact float when rebuilt), its stamp [ns], and the
    recorded pose (x, z) [m] to compare with there (None for an unrecorded step)."""

    t: float
    ns: int
    pose: tuple[float, float] | None


def _ns(t: float) -> int:
    """A sim time as the simulator stamps it (nodes.messages.to_time rounds the same way)."""
    return round(t * 1e9)


def stop_times(poses: list[tuple[int, float, float]], step_periods: list[float]) -> tuple[list[_Stop], bool]:
    """The simulator's stops up to each recorded pose ``(stamp ns, x, z)``, and whether all are exact.

    From t = 0, each recorded stamp is reached by ``n`` additions of a recorded step period (the
    simulator's own ``t + step_period``, so the floats are the simulator's bit for bit) when one fits
    the stamp to the nanosecond; otherwise the stop is the stamp itself (real time: exact only to 1 ns).
    """
    stops: list[_Stop] = []
    t, exact = 0.0, True
    for ns, x, z in poses:
        path = _steps_to(t, ns, step_periods)
        if path is None:
            exact = False
            path = [ns / 1e9]
        stops += [_Stop(s, _ns(s), None) for s in path[:-1]]
        stops.append(_Stop(path[-1], ns, (x, z)))
        t = path[-1]
    return stops, exact


def _steps_to(t: float, ns: int, step_periods: list[float]) -> list[float] | None:
    """The times ``t + dt``, ``t + dt + dt`` ... ending exactly at stamp ``ns`` for a ``dt`` of
    ``step_periods``; ``[t]`` when ``t`` already has that stamp; None when no step period fits."""
    if _ns(t) == ns:
        return [t]
    for dt in step_periods:
        n = round((ns - _ns(t)) / (dt * 1e9))
        if not 1 <= n <= MAX_INTERMEDIATE_STEPS:
            continue
        path, s = [], t
        for _ in range(n):
            s += dt
            path.append(s)
        if _ns(s) == ns:
            return path
    return None


@dataclass
class _Command:
    """A recorded command and the sim time [ns] the simulator received it at."""

    receipt_ns: int
    topic: str
    message: Any


def _first_segment(items: list[tuple[int, Any]]) -> tuple[list[tuple[int, Any]], bool]:
    """``(stamp ns, item)`` up to the first stamp that goes back in time (a reset); and whether there
    was one."""
    for i in range(1, len(items)):
        if items[i][0] < items[i - 1][0]:
            return items[:i], True
    return items, False


def _commands(log: LogReader, pose_log: list[tuple[int, int]], notes: list[str]) -> tuple[list[_Command], str]:
    """The commands of the log in receipt order, paired with their receipt sim times [ns]."""
    recorded: dict[str, list[LogMessage]] = defaultdict(list)
    for m in log.messages(COMMAND_TOPICS, decoded=True):
        recorded[next(t for t in COMMAND_TOPICS if m.topic.endswith(t))].append(m)
    if log.resolve('simulator/command_receipts') is None:
        if recorded:
            notes.append('the log has no simulator/command_receipts (recorded by an older simulator): receipt '
                         'times estimated from the last pose recorded before each command, ambiguous by a tick')
        return _estimated(recorded, pose_log), 'estimated'
    receipts, reset = _first_segment([(m.stamp_ns, m.message.frame_id)
                                      for m in log.messages(['simulator/command_receipts'], decoded=True)])
    queues = {topic: iter(msgs) for topic, msgs in recorded.items()}
    out, missing = [], 0
    for ns, topic in receipts:
        m = next(queues.get(topic, iter(())), None)
        if m is None:
            missing += 1
        else:
            out.append(_Command(ns, topic, m.message))
    if missing:
        notes.append(f'{missing} commands the simulator received are not in the log (the recorder missed them, '
                     'e.g. it started after them): the re-simulation runs without them')
    unacknowledged = sum(len(msgs) for msgs in recorded.values()) - len(out)
    if unacknowledged and not reset:
        notes.append(f'{unacknowledged} recorded commands have no receipt from the simulator (sent after it '
                     'stopped, or it missed them): not applied')
    return out, 'recorded'


def _estimated(recorded: dict[str, list[LogMessage]], pose_log: list[tuple[int, int]]) -> list[_Command]:
    """Receipt times for a log without receipts: the stamp of the last pose logged before each command."""
    pose_log = sorted(pose_log)
    log_times = [log_ns for log_ns, _ in pose_log]
    out = []
    for topic, msgs in recorded.items():
        for m in msgs:
            i = bisect.bisect_right(log_times, m.log_time_ns)
            out.append((m.log_time_ns, _Command(pose_log[i - 1][1] if i else 0, topic, m.message)))
    return [c for _, c in sorted(out, key=lambda pair: pair[0])]


def _apply(stepper: Stepper, cmd: _Command) -> bool:
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


def resimulate(log: LogReader, overrides: Mapping[str, Any] | None = None, *,
               progress: Callable[[int, int], None] | None = None, max_sim_time: float | None = None) -> ResimReport:
    """Re-simulate ``log`` (with model parameters ``overrides`` on top of the recorded ones) and compare;
    ``progress(stops done, stops)`` is called as it goes.

    Raises :class:`ResimError` when the log has no pose, an override is not a model parameter, the
    parameters build no model, or the poses reach beyond ``max_sim_time`` [s] (a cost the caller refuses).
    """
    overrides = dict(overrides or {})
    notes: list[str] = []
    specs = model_specs()
    foreign = sorted(name for name in overrides if name not in specs)
    if foreign:
        raise ResimError(f'not a model parameter: {", ".join(foreign)} (resim changes only the simulated model; '
                         'see docs/parameters.md)')
    try:
        snapshots = recorded_parameters(log)
    except ValueError as err:
        raise ResimError(f'simulator/parameters unreadable: {err}') from err
    if snapshots:
        first = snapshots[0]
        flat = {name: value for name, value in first.items() if name in specs}
        source = 'recorded (simulator/parameters)'
    else:
        first = None
        flat = {name: default for name, (_, default) in specs.items()}
        source = 'defaults (the log has no simulator/parameters)'
        notes.append('the log does not record the simulator\'s parameters: defaults assumed (use --params/--set '
                     'to give the run\'s)')
    flat.update(overrides)
    try:
        model = build_model(flat)
    except ValueError as err:
        raise ResimError(f'the parameters build no model: {err}') from err

    pose_msgs = list(log.messages(['particle/pose'], decoded=True))
    pose_log = [(m.log_time_ns, m.stamp_ns or 0) for m in pose_msgs]
    poses, reset = _first_segment([(m.stamp_ns or 0, m) for m in pose_msgs])
    if not poses:
        raise ResimError('the log has no particle/pose to compare with')
    last_s = poses[-1][0] * 1e-9
    if max_sim_time is not None and last_s > max_sim_time:
        raise ResimError(f'the poses reach t = {last_s:.6g} s of sim time, and resim integrates from t = 0: about '
                         f'{last_s / SIM_SECONDS_PER_WALL_SECOND:.3g} s of computing (stamps in wall-clock time are '
                         'not sim time); add --force if you mean it')
    if reset:
        notes.append('the log holds a simulator/reset: only the run before it is compared')
    step_periods = sorted({float(s['step_period']) for s in snapshots if 'step_period' in s}) or [1e-3]
    stops, exact = stop_times([(ns, m.message.pose.position.x, m.message.pose.position.z) for ns, m in poses],
                              step_periods)
    real_time_note = None if exact else (
        'real-time run: the simulator stopped at sums of elapsed wall times x real_time_factor, '
        'which the stamps give rounded to 1 ns, so the re-simulation stops within 1 ns of them, not '
        'bit for bit; between commands it takes the same integration steps (a stop does not cut a step), but '
        'each pose is evaluated up to 1 ns off on a moving surface, and a difference at the 1e-14 m level '
        '(4.8e-14 m in z, x identical, measured over a 20-slip run) comes from this, not from the commands or '
        'the model')
    commands, receipts = _commands(log, pose_log, notes)
    if poses[0][0] != 0:
        notes.append(f'the first recorded pose is at t = {poses[0][0] * 1e-9:.6f} s, not 0 (the recorder joined '
                     'late): earlier stops unknown, started from t = 0')

    stepper = Stepper(model)
    report = ResimReport(str(log.path), run_mode(first), source, overrides, 0, 0.0, 0.0, 0.0, 0.0, None, 0, 0,
                         exact, receipts, notes)
    _run(stepper, stops, sorted(commands, key=lambda c: c.receipt_ns), report, progress)  # stable: receipt order
    report.transitions = stepper.state.transitions
    report.recorded_transitions = _recorded_transitions(log, round(report.sim_time * 1e9))
    if real_time_note is not None and report.max_error != 0.0:  # explains a difference; none when there is none
        notes.append(real_time_note)
    return report


def _recorded_transitions(log: LogReader, until_ns: int) -> dict[str, int] | None:
    """Mode changes on ``particle/transitions`` stamped up to ``until_ns`` (sim time), counted by kind as
    the simulator's counters count them; None when the log does not have the topic."""
    if log.resolve('particle/transitions') is None:
        return None
    counts = dict.fromkeys(TRANSITION_KINDS, 0)
    for m in log.messages(['particle/transitions'], decoded=True):
        if m.stamp_ns is not None and m.stamp_ns <= until_ns:
            for status in m.message.status:
                if status.message in counts:
                    counts[status.message] += 1
    return counts


def _run(stepper: Stepper, stops: list[_Stop], commands: list[_Command], report: ResimReport,
         progress: Callable[[int, int], None] | None = None) -> None:
    """Step through ``stops``, applying ``commands`` at their receipt times and comparing the poses."""
    pending: Iterator[_Command] = iter(commands)
    next_cmd = next(pending, None)
    for i, stop in enumerate(stops):
        if progress is not None and not i % 256:
            progress(i, len(stops))
        while next_cmd is not None and next_cmd.receipt_ns < stop.ns:  # received between two known stops
            if not _advance(stepper, next_cmd.receipt_ns / 1e9, report):
                return
            next_cmd = _receive(stepper, next_cmd, pending, report)
        if not _advance(stepper, stop.t, report):
            return
        if stop.pose is not None:
            _compare(stepper, stop, report)
        while next_cmd is not None and next_cmd.receipt_ns == stop.ns:
            next_cmd = _receive(stepper, next_cmd, pending, report)


def _advance(stepper: Stepper, t: float, report: ResimReport) -> bool:
    """Integrate to ``t``; a long gap with no known stop (a late-joining recorder, a pause in the poses) in
    pieces of ``MAX_ADVANCE``, so that Ctrl-C is answered within a second."""
    if t == stepper.t:
        return True
    try:
        while t - stepper.t > MAX_ADVANCE:
            stepper.advance(stepper.t + MAX_ADVANCE)
        stepper.advance(t)
    except SimulationError as err:
        report.notes.append(f'the re-simulation failed at t = {stepper.t:.6f} s: {err}; compared up to there')
        return False
    return True


def _receive(stepper: Stepper, cmd: _Command, pending: Iterator[_Command], report: ResimReport) -> _Command | None:
    if _apply(stepper, cmd):
        report.commands_applied += 1
    else:
        report.commands_rejected += 1
    return next(pending, None)


def _compare(stepper: Stepper, stop: _Stop, report: ResimReport) -> None:
    obs = stepper.observe()
    x, z = stop.pose
    dx, dz = abs(obs.x - x), abs(obs.z - z)
    error = math.hypot(dx, dz)
    report.poses += 1
    report.sim_time = stop.ns / 1e9
    report.max_dx, report.max_dz = max(report.max_dx, dx), max(report.max_dz, dz)
    if error > report.max_error or math.isnan(error):
        report.max_error, report.t_max_error = error, stop.ns / 1e9
