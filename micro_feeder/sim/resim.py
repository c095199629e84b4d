"""Re-simulating a log: its recorded actuator commands fed into a fresh :class:`~.stepper.Stepper`.

``resim`` answers "does the log's part trajectory follow from its commands?": it rebuilds the simulation
from the parameters the simulator recorded, stops it at the sim times the simulator stopped at, applies
each recorded command at the sim time the simulator received it, and compares the re-simulated part
position (x, z) with every recorded ``particle/pose``, and with several parts every part's with the
``particles/poses`` of the same stamp.

The log is read and replayed by :mod:`.replay` (what it reads, the stop times, the receipts), the same
loop calibration fits with. In real time the simulator's stops are known to 1 ns only: between commands
the integrator takes the same steps (a stop never cuts a step) but a pose is evaluated up to 1 ns off on a
moving surface, so a small difference remains (reported, with why).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from ..interface.names import TRANSITION_KINDS
from ..interface.transitions import status_messages
from ..logs.reader import LogReader
from ..logs.sim_parameters import run_mode
from ..physics.dynamics import Observation
from ..settings import model_specs
from .replay import ReplayError, Stop, open_recording, replay
from .stepper import Stepper, build_model

STOP_TIME_RESOLUTION_S = 1e-9     # a real-time log's stop times: stamps, rounded to 1 ns
SIM_SECONDS_PER_WALL_SECOND = 20.0  # resim at 1 kHz poses, measured: 60 s of sim time in 3 s
REAL_TIME_NOTE = (
    'real-time run: the simulator stopped at sums of elapsed wall times x real_time_factor, which the stamps give '
    'rounded to 1 ns, so the re-simulation stops within 1 ns of them, not bit for bit; between commands it takes '
    'the same integration steps (a stop does not cut a step), but each pose is evaluated up to 1 ns off on a '
    'moving surface: a difference up to the part\'s speed x 1 ns (4.8e-14 m in z over a 20-slip run, 1.6e-10 m in z '
    'on a stuck part riding the surface in a 10-minute run) comes from this, not from the commands or the model')

class ResimError(ValueError):
    """The log cannot be re-simulated (no poses, parameters that build no model ...); says why."""


@dataclass
class ResimReport:
    """The comparison: poses compared, largest differences [m] and where [s, sim time], what was
    applied, whether the stop times were exact, and notes explaining any difference.

    ``max_error`` is the largest Euclidean distance between recorded and re-simulated (x, z);
    ``max_dx``/``max_dz`` the largest absolute component differences (each at its own pose);
    ``max_unexplained`` the largest distance beyond what a stop time 1 ns off moves the part (its speed there
    × 1 ns): in a real-time log, whose stop times are known to 1 ns only, the part of a difference that
    the rounding cannot explain (a stuck part rides a surface moving at up to ~0.2 m/s: 2e-10 m a pose).
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
    parts: int = 1             # parts compared at each pose (particles/poses, with several)
    transitions: dict[str, int] = field(default_factory=dict)   # re-simulated, up to the last compared pose
    recorded_transitions: dict[str, int] | None = None          # particle/transitions up to then (None: not logged)
    max_unexplained: float = 0.0

    @property
    def identical(self) -> bool:
        return self.poses > 0 and self.max_error == 0.0

    def as_dict(self) -> dict[str, Any]:
        return {**asdict(self), 'identical': self.identical}

    def verdict(self) -> str:
        """One line for people."""
        total = self.commands_applied + self.commands_rejected
        what = (f'{self.poses} poses' + (f' of {self.parts} parts' if self.parts > 1 else '')
                + f', {self.sim_time:.6f} s sim time, {total} command{"s" * (total != 1)}'
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


def resimulate(log: LogReader, overrides: Mapping[str, Any] | None = None, *,
               progress: Callable[[int, int], None] | None = None, max_sim_time: float | None = None) -> ResimReport:
    """Re-simulate ``log`` (with model parameters ``overrides`` on top of the recorded ones) and compare;
    ``progress(recorded poses done, recorded poses)`` is called as it goes. The log is streamed (one chunk
    at a time, the comparison kept as running maxima), so memory does not grow with its length.

    Raises :class:`ResimError` when the log has no pose, an override is not a model parameter, the
    parameters build no model, or the poses reach beyond ``max_sim_time`` [s] (a cost the caller refuses).
    """
    overrides = dict(overrides or {})
    specs = model_specs()
    foreign = sorted(name for name in overrides if name not in specs)
    if foreign:
        raise ResimError(f'not a model parameter: {", ".join(foreign)} (resim changes only the simulated model; '
                         'see docs/parameters.md)')
    try:
        recording = open_recording(log)
    except ReplayError as err:
        raise ResimError(f'{err} to compare with' if 'particle/pose' in str(err) else str(err)) from err
    notes = []      # after the recording's own, known once it has been read
    if recording.snapshots:
        flat = dict(recording.flat)
        source = 'recorded (simulator/parameters)'
    else:
        flat = {name: default for name, (_, default) in specs.items()}
        source = 'defaults (the log has no simulator/parameters)'
        notes.append('the log does not record the simulator\'s parameters: defaults assumed (use --params/--set '
                     'to give the run\'s)')
    flat.update(overrides)
    try:
        model = build_model(flat)
    except ValueError as err:
        raise ResimError(f'the parameters build no model: {err}') from err
    last_s = recording.last_ns * 1e-9
    if max_sim_time is not None and last_s > max_sim_time:
        raise ResimError(f'the poses reach t = {last_s:.6g} s of sim time, and resim integrates from t = 0: about '
                         f'{last_s / SIM_SECONDS_PER_WALL_SECOND:.3g} s of computing (stamps in wall-clock time are '
                         'not sim time); add --force if you mean it')

    stepper = Stepper(model)
    first = recording.snapshots[0] if recording.snapshots else None
    report = ResimReport(str(log.path), run_mode(first), source, overrides, 0, 0.0, 0.0, 0.0, 0.0, None, 0, 0,
                         True, recording.receipts)

    def count(applied: bool) -> None:
        if applied:
            report.commands_applied += 1
        else:
            report.commands_rejected += 1

    part_poses = _RecordedPartPoses(log) if stepper.n_parts > 1 and log.resolve('particles/poses') else None
    if stepper.n_parts > 1 and part_poses is None:
        notes.append(f'the log has no particles/poses: only part 0 of {stepper.n_parts} compared')
    report.parts = stepper.n_parts if part_poses is not None else 1

    changes = {True: 0, False: 0}
    miscounted: list[float] = []       # stamps where the parts re-simulated and recorded differ in number

    def compare(stop: Stop, obs: Observation) -> None:
        _compare(obs, stop, report)
        recorded = part_poses.at(stop.ns) if part_poses is not None else None
        if recorded is not None:
            parts = stepper.observe_parts()
            if len(parts) != len(recorded):
                miscounted.append(stop.ns * 1e-9)
                return
            for part, (x, z) in zip(parts, recorded, strict=True):
                _compare(part, replace(stop, pose=(x, z)), report, count=False)

    def count_change(applied: bool) -> None:
        changes[applied] += 1

    failure = replay(stepper, recording, compare, on_command=count, on_entity_change=count_change,
                     progress=progress)
    if failure is not None:
        notes.append(f'the re-simulation failed at t = {stepper.t:.6f} s: {failure}; compared up to there')
    if changes[True] or changes[False]:
        notes.append(f'{changes[True]} parts spawned or deleted during the run (simulator/entity_changes), applied '
                     'at their sim times' + (f'; {changes[False]} refused by the model re-simulated' if changes[False]
                                             else ''))
    if miscounted:
        report.max_error, report.t_max_error = math.inf, miscounted[0]
        notes.append(f'{len(miscounted)} poses have a different number of parts re-simulated than recorded (the '
                     f'first at t = {miscounted[0]:.6f} s): not compared')
    report.exact_stop_times = recording.exact
    report.transitions = stepper.state.transitions
    report.recorded_transitions = _recorded_transitions(log, round(report.sim_time * 1e9))
    if not recording.exact and report.max_error != 0.0:  # explains a difference; none when there is none
        notes.append(REAL_TIME_NOTE)
    report.notes = recording.notes + notes
    return report


def _recorded_transitions(log: LogReader, until_ns: int) -> dict[str, int] | None:
    """Mode changes on ``particle/transitions`` stamped up to ``until_ns`` (sim time), counted by kind as
    the simulator's counters count them; None when the log does not have the topic."""
    if log.resolve('particle/transitions') is None:
        return None
    counts = dict.fromkeys(TRANSITION_KINDS, 0)
    for m in log.messages(['particle/transitions']):
        kinds = status_messages(m.data)       # read from the bytes: a log holds ~2 a stroke
        if kinds is None:
            if not log.decodes(m):
                continue
            kinds = [status.message for status in m.message.status]
        if m.stamp_ns is not None and m.stamp_ns <= until_ns:
            for kind in kinds:
                if kind in counts:
                    counts[kind] += 1
    return counts


class _RecordedPartPoses:
    """The log's ``particles/poses``, read as the replay asks for them (in stamp order, one message ahead), so
    memory does not grow with the log (a dict of every message held ~0.5 kB a tick for 16 parts: ~1.7 GB for
    an hour)."""

    def __init__(self, log: LogReader):
        self._messages = (m for m in log.messages(['particles/poses'], decoded=True) if m.stamp_ns is not None)
        self._next = next(self._messages, None)

    def at(self, ns: int) -> np.ndarray | None:
        """(parts, 2) array of (x, z) (m) recorded at stamp ``ns`` (sim time), None when none was; the
        messages stamped before it are passed (the replay asks in increasing stamp order)."""
        while self._next is not None and self._next.stamp_ns < ns:
            self._next = next(self._messages, None)
        if self._next is None or self._next.stamp_ns != ns:
            return None
        return np.array([(p.position.x, p.position.z) for p in self._next.message.poses])


def _compare(obs: Observation, stop: Stop, report: ResimReport, count: bool = True) -> None:
    x, z = stop.pose
    dx, dz = abs(obs.x - x), abs(obs.z - z)
    error = math.hypot(dx, dz)
    if count:
        report.poses += 1
    report.sim_time = stop.ns / 1e9
    report.max_dx, report.max_dz = max(report.max_dx, dx), max(report.max_dz, dz)
    unexplained = error - STOP_TIME_RESOLUTION_S * math.hypot(obs.xdot, obs.zdot)
    if unexplained > report.max_unexplained or math.isnan(unexplained):
        report.max_unexplained = unexplained
    if error > report.max_error or math.isnan(error):
        report.max_error, report.t_max_error = error, stop.ns / 1e9
