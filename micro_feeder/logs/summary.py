"""A log's summary: topics, types, counts, rates, duration, sim time, how the simulator ran, final part
state, recorder loss counters.

The loss counters come from the recorder: its ``micro_feeder.recorder`` metadata record on a clean stop,
or, in a truncated log, the last of its ``/diagnostics`` messages that made it to disk (same keys). They
count only what was lost after the recorder subscribed; what happened before (a recorder that joined late)
is found from the log itself: a first pose later than one tick of sim time, and fewer commands than the
simulator says it received (its ``simulator/command_receipts``, one per command, and the
``commands_received`` of its ``/diagnostics``).
"""

from __future__ import annotations

import datetime
import itertools
import textwrap
from dataclasses import dataclass, field
from pathlib import Path

from ..interface.entity_changes import SPAWNED, read_entity_changes
from ..interface.topics import COMMAND_TOPICS, ENTITY_CHANGES
from ..physics.dynamics import MODES
from .coverage import Coverage, end_line, missing_command_lines, stall_lines
from .reader import LogMessage, LogReader
from .sim_parameters import recorded_parameters, run_mode

RECORDER_STATUS_PREFIX = 'recorder'
RATE_MIN_COUNT = 10  # topics with fewer messages are events (commands, mode changes): no rate shown
DEFAULT_TICK = 2e-3  # s of sim time a tick can advance, without recorded parameters (1 kHz, real time)
SIMULATOR_STATUS_SUFFIX = 'simulator: loop'


@dataclass
class TopicRow:
    """One topic of the summary: name, type, count, average rate [Hz] between its first and last
    message (None for fewer than ``RATE_MIN_COUNT`` messages, where a rate says little)."""

    name: str
    type: str
    count: int
    rate: float | None


@dataclass
class PartState:
    """The part's last recorded state: stamp [s], position x, z [m], contact mode; and its first
    recorded pose (stamp [s], x [m]) to say how far it moved."""

    stamp: float | None = None
    x: float | None = None
    z: float | None = None
    mode: str | None = None
    first_stamp: float | None = None
    first_x: float | None = None
    real_time_factor: float | None = None   # sim time over log time, from the first pose after the held start


@dataclass
class SimulatorRun:
    """How the simulator ran, from its recorded parameters and command receipts (None/0 when absent)."""

    mode: str = 'unknown'
    real_time_factor: float | None = None
    step_period: float | None = None
    commands_received: int = 0


@dataclass
class MissingStart:
    """What the log lacks from before the recorder subscribed: ``first_pose`` [s], the sim time of the first
    pose when it is later than one ``tick`` [s] of sim time (None otherwise); ``commands`` of the
    ``commands_received`` the simulator received are in no way accounted for in the log (neither recorded
    nor counted lost by the recorder): the first ones, sent before the recorder subscribed."""

    tick: float = DEFAULT_TICK
    first_pose: float | None = None
    commands: int = 0
    commands_received: int = 0

    def __bool__(self) -> bool:
        return self.first_pose is not None or self.commands > 0


@dataclass
class LogSummary:
    """Everything ``micro-feeder info`` shows."""

    path: Path
    files: list[Path]
    size_bytes: int
    truncated: list[Path]
    start_ns: int
    duration: float
    topics: list[TopicRow]
    part: PartState
    simulator: SimulatorRun
    recorder: dict[str, str] = field(default_factory=dict)
    recorder_source: str = ''  # 'summary', 'diagnostics' or ''
    start: MissingStart = field(default_factory=MissingStart)
    parts: list[PartState] = field(default_factory=list)    # every part (particles/*), with several
    entity_changes: dict[str, int] = field(default_factory=dict)    # parts 'spawned' / 'deleted' during the run
    publishes_refused: dict[str, int] = field(default_factory=dict)  # the simulator's messages nobody got, per topic

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self.topics)


def recorder_counters(log: LogReader) -> tuple[dict[str, str], str]:
    """The recorder's counters and where they came from."""
    if log.recorder_info:
        return dict(log.recorder_info), 'summary'
    for m in log.messages(['/diagnostics'], decoded=True, reverse=True):   # the last one: read from the end
        for status in reversed(m.message.status):
            if status.name.startswith(RECORDER_STATUS_PREFIX):
                counters = {kv.key: kv.value for kv in status.values}
                return counters, 'diagnostics' if counters else ''
    return {}, ''


def _rate(log: LogReader, topic: str, count: int) -> float | None:
    """Messages per second between the first and the last message of a topic (None for an event topic)."""
    if count < RATE_MIN_COUNT:
        return None
    span = (log.last(topic).log_time_ns - log.first(topic).log_time_ns) * 1e-9
    return (count - 1) / span if span > 0 else None


def simulator_run(log: LogReader) -> SimulatorRun:
    """The simulator's run mode and settings (first recorded snapshot) and the commands it received."""
    snapshots = recorded_parameters(log)
    receipts = log.resolve('simulator/command_receipts')
    run = SimulatorRun(commands_received=log.topics[receipts].count if receipts else 0)
    if snapshots:
        first = snapshots[0]
        run.mode, run.real_time_factor, run.step_period = (run_mode(first), first.get('real_time_factor'),
                                                           first.get('step_period'))
    return run


def tick_length(params: dict | None) -> float:
    """The most sim time [s] one simulator tick advances: two loop periods × the real-time factor in real time
    (what a tick after a late wake-up catches up), else one ``step_period``; :data:`DEFAULT_TICK` unknown."""
    if params is None:
        return DEFAULT_TICK
    if run_mode(params) == 'real time':
        return 2.0 * float(params.get('real_time_factor', 1.0)) / float(params.get('publish_rate', 1000.0))
    return float(params.get('step_period', DEFAULT_TICK))


def simulator_statuses(log: LogReader) -> dict[str, dict[str, str]]:
    """The key/values of each simulator's last ``/diagnostics`` status in the log, by status name."""
    last: dict[str, dict[str, str]] = {}
    for m in log.messages(['/diagnostics'], decoded=True):
        for status in m.message.status:
            if status.name.endswith(SIMULATOR_STATUS_SUFFIX):
                last[status.name] = {kv.key: kv.value for kv in status.values}
    return last


def _commands_received(log: LogReader, statuses: dict[str, dict[str, str]]) -> int:
    """Commands the simulator says it received: its receipts in the log, or the ``commands_received`` of
    its last ``/diagnostics`` (``statuses``) when that is more (a counter since its start); 0 with neither."""
    receipts = log.resolve('simulator/command_receipts')
    received = log.topics[receipts].count if receipts else 0
    counts = [int(v) for values in statuses.values() if (v := values.get('commands_received', '')).isdigit()]
    if len(counts) == 1:        # several simulators on one log: their counters cannot be told apart here
        received = max(received, *counts)
    return received


def publishes_refused(statuses: dict[str, dict[str, str]]) -> dict[str, int]:
    """Messages the middleware refused to take from the simulators (no subscriber, the recorder included, got
    them), per topic, as their last ``/diagnostics`` (``statuses``) count them."""
    refused: dict[str, int] = {}
    for values in statuses.values():
        for key, value in values.items():
            if key.startswith('publishes_refused.') and value.isdigit():
                topic = key.split('.', 1)[1]
                refused[topic] = refused.get(topic, 0) + int(value)
    return refused


def missing_start(log: LogReader, part: PartState, recorder: dict[str, str],
                  statuses: dict[str, dict[str, str]]) -> MissingStart:
    """What the log lacks from before the recorder subscribed (:class:`MissingStart`); ``statuses``: the
    simulators' last ``/diagnostics`` (:func:`simulator_statuses`)."""
    snapshots = recorded_parameters(log)
    start = MissingStart(tick=tick_length(snapshots[0] if snapshots else None))
    if part.first_stamp is not None and part.first_stamp > start.tick + 1e-9:
        start.first_pose = part.first_stamp
    start.commands_received = _commands_received(log, statuses)
    held = lost = 0
    for topic in filter(None, map(log.command_source, COMMAND_TOPICS)):
        held += log.topics[topic].count
        lost += int(recorder.get(f'lost.{topic}', 0))
    start.commands = max(start.commands_received - held - lost, 0)
    return start


def summarize(log: LogReader) -> LogSummary:
    """Summarise an opened log (reads the last pose/contact state and, when needed, the diagnostics)."""
    rows = [TopicRow(t.name, t.type, t.count, _rate(log, t.name, t.count))
            for t in sorted(log.topics.values(), key=lambda t: t.name)]
    part = PartState()
    pose = log.last('particle/pose')
    if pose is not None:
        p = pose.message.pose.position
        part.stamp, part.x, part.z = (pose.stamp_ns or 0) * 1e-9, p.x, p.z
        first = log.first('particle/pose')
        part.first_stamp, part.first_x = (first.stamp_ns or 0) * 1e-9, first.message.pose.position.x
        part.real_time_factor = _pace(log, first, pose)
    state = log.last('particle/contact_state')
    if state is not None:
        part.mode = state.message.data
    counters, source = recorder_counters(log)
    changes = _entity_changes(log)
    parts = _parts(log)
    if changes:         # part k at the end is not part k at the start: no distance by index
        part.first_x = None
        for q in parts:
            q.first_x = None
    statuses = simulator_statuses(log)
    return LogSummary(log.path, log.files, sum(f.stat().st_size for f in log.files), log.truncated,
                      log.start_ns, log.duration, rows, part, simulator_run(log), counters, source,
                      missing_start(log, part, counters, statuses), parts, changes, publishes_refused(statuses))


def _pace(log: LogReader, first: LogMessage, last: LogMessage) -> float | None:
    """Sim time per log time between the first pose past the first one's stamp and the last pose; None when
    the poses never move on. The simulator publishes its held start (t = 0) when it is built, before the
    loop runs: measured from it, the pace would count the start-up as time the run fell behind."""
    moving = next((m for m in itertools.islice(log.messages(['particle/pose']), 1000)
                   if (m.stamp_ns or 0) > (first.stamp_ns or 0)), None)
    if moving is None or last.log_time_ns <= moving.log_time_ns:
        return None
    return ((last.stamp_ns or 0) - (moving.stamp_ns or 0)) / (last.log_time_ns - moving.log_time_ns)


def _entity_changes(log: LogReader) -> dict[str, int]:
    """Parts spawned and deleted during the run, counted by kind (``simulator/entity_changes``)."""
    counts: dict[str, int] = {}
    for m in log.messages([ENTITY_CHANGES] if log.resolve(ENTITY_CHANGES) else [], decoded=True):
        try:
            for change in read_entity_changes(m.message):
                counts[change.kind] = counts.get(change.kind, 0) + 1
        except ValueError:
            counts['unreadable'] = counts.get('unreadable', 0) + 1
    return counts


def _parts(log: LogReader) -> list[PartState]:
    """Every part's first and last recorded pose and last mode, from ``particles/poses`` and ``particles/states``
    (empty with one part or without those topics)."""
    last, first = log.last('particles/poses'), log.first('particles/poses')
    if last is None or first is None or len(last.message.poses) < 2:
        return []
    states = log.last('particles/states')
    modes: list[str | None] = [None] * len(last.message.poses)
    if states is not None and len(states.message.layout.dim) == 2:
        fields = states.message.layout.dim[1].label.split(',')
        width = states.message.layout.dim[1].size
        if 'mode' in fields:
            codes = states.message.data[fields.index('mode')::width]
            modes = [MODES[int(c)] if 0 <= int(c) < len(MODES) else None for c in codes][:len(modes)]
    first_x: list[float | None] = [p.position.x for p in first.message.poses]
    first_x += [None] * (len(modes) - len(first_x))         # more parts at the end than at the start: spawned
    return [PartState((last.stamp_ns or 0) * 1e-9, q.position.x, q.position.z, mode, (first.stamp_ns or 0) * 1e-9,
                      x0) for q, mode, x0 in zip(last.message.poses, modes, first_x, strict=False)]


def _size(n: int) -> str:
    for unit in ('B', 'KiB', 'MiB', 'GiB'):
        if n < 1024 or unit == 'GiB':
            return f'{n:.0f} {unit}' if unit == 'B' else f'{n:.1f} {unit}'
        n /= 1024
    return f'{n} B'


def _loss_lines(s: LogSummary, coverage: Coverage | None = None) -> list[str]:
    """The recorder's loss counters, then what they cannot see (:func:`_start_lines`); with ``coverage``, a
    log that ends early says its counts stop there."""
    ends_early = coverage is not None and coverage.end.kind != 'complete'
    if not s.recorder:
        return ['loss       unknown (no recorder counters in this log)', *_refused_lines(s.publishes_refused),
                *_start_lines(s.start, coverage)]
    c = s.recorder
    lost, incompatible = int(c.get('lost_total', 0)), int(c.get('incompatible_qos_total', 0))
    where = 'final summary' if s.recorder_source == 'summary' else 'last recorder diagnostics'
    missing = s.start or (coverage is not None and coverage.commands) or ends_early
    refused = sum(s.publishes_refused.values())
    verdict = (f'{lost + refused} messages lost' if lost or refused or incompatible
               else 'none while recording' if missing else 'none')
    lines = [f'loss       {verdict}  (received {int(c.get("received_total", 0)):,}; counted lost by the '
             f'middleware {lost}, incompatible-QoS events {incompatible}; from the {where})']
    per_topic = {k.split('.', 1)[1]: v for k, v in c.items() if k.startswith('lost.') and v != '0'}
    lines += [f'           {topic}: {n} lost' for topic, n in sorted(per_topic.items())]
    if c.get('recorded_in_process'):
        lines += textwrap.wrap('recorded as published, in the simulator\'s process (not through the middleware): '
                               + ', '.join(c['recorded_in_process'].split(',')), width=110,
                               initial_indent=' ' * 11, subsequent_indent=' ' * 13, break_on_hyphens=False)
    lines += _refused_lines(s.publishes_refused)
    if ends_early:
        lines.append('           counted only up to where the log ends (ends, above): nothing after that is counted')
    return lines + _start_lines(s.start, coverage)


def _refused_lines(refused: dict[str, int]) -> list[str]:
    """What the simulator published and the middleware refused to take: in no subscriber's hands, so in no
    recorder's counters."""
    if not refused:
        return []
    return [f'           refused by the middleware: {sum(refused.values())} of the simulator\'s messages (no '
            'subscriber got them; its /diagnostics):',
            *(f'             {topic}: {n}' for topic, n in sorted(refused.items()))]


def _start_lines(start: MissingStart, coverage: Coverage | None = None) -> list[str]:
    """What the recorder's counters cannot see: what happened before it subscribed, and (with ``coverage``)
    the commands it lacks against the simulator's receipts, per command topic, instead of their total."""
    lines = []
    if start.first_pose is not None:
        lines.append(f'           start missing: first pose at sim time {start.first_pose:.6f} s, not 0 (one tick '
                     f'is at most {start.tick * 1e3:g} ms): the recorder joined late')
    if coverage is not None and coverage.commands:
        lines += [f'           {line}' for line in missing_command_lines(coverage)]
    elif start.commands:
        lines.append(f'           start missing: the first {start.commands} of the {start.commands_received} '
                     'commands the simulator received are not in the log (sent before the recorder subscribed)')
    return lines


def format_summary(s: LogSummary, coverage: Coverage | None = None) -> str:
    """The summary as aligned text for a terminal; with ``coverage`` (:func:`.coverage.coverage`), also
    where and why the log ends, the sim time each topic starts at, and what the log lacks of the run."""
    start = datetime.datetime.fromtimestamp(s.start_ns * 1e-9).isoformat(sep=' ', timespec='milliseconds')
    lines = [
        f'log        {s.path}',
        f'files      {len(s.files)} ({_size(s.size_bytes)}, zstd chunks)',
        f'start      {start} (receive time, local)',
        f'duration   {s.duration:.3f} s',
        f'messages   {s.message_count:,}',
    ]
    if coverage is not None and end_line(coverage):
        lines.append(end_line(coverage))
    for path in s.truncated:
        lines.append(f'WARNING    {path.name} is truncated (recorder did not stop cleanly); read up to its '
                     'last whole chunk. "micro-feeder recover" rewrites it as a complete log.')
    lines.append('')
    starts = coverage.starts if coverage is not None else {}
    wname = max([len('topic'), *(len(t.name) for t in s.topics)])
    wtype = max([len('type'), *(len(t.type) for t in s.topics)])
    lines.append(f'{"topic":<{wname}}  {"type":<{wtype}}  {"count":>9}  {"rate":>10}'
                 + (f'  {"from (sim)":>12}' if starts else ''))
    lines += [f'{t.name:<{wname}}  {t.type:<{wtype}}  {t.count:>9,}  '
              + (f'{t.rate:>7.1f} Hz' if t.rate is not None else f'{"–":>10}')
              + (f'  {starts.get(t.name, "–")!s:>12}' if starts else '') for t in s.topics]
    lines.append('')
    lines += _simulator_lines(s)
    if coverage is not None:
        lines += stall_lines(coverage)
    p = s.part
    if p.x is None and p.mode is None:
        lines.append('part       no particle/pose or particle/contact_state in this log')
    else:
        where = (f'x = {p.x * 1e3:.4f} mm, z = {p.z * 1e6:.3f} µm at t = {p.stamp:.4f} s'
                 if p.x is not None else 'no pose')
        lines.append(f'part       {where}; mode {p.mode or "unknown"}')
        if p.x is not None and p.first_x is not None:
            lines.append(f'           moved {(p.x - p.first_x) * 1e6:+.3f} µm since t = {p.first_stamp:.4f} s')
    if s.entity_changes:
        lines.append('parts      ' + ', '.join(f'{n} {kind}' for kind, n in sorted(s.entity_changes.items(),
                                                                                 key=lambda item: item[0] != SPAWNED))
                     + ' during the run (simulator/entity_changes): distances by part index not shown')
    if s.parts:
        lines.append(f'parts      {len(s.parts)} (particles/poses) at t = {s.parts[0].stamp:.4f} s:')
        lines += [f'  {k:>7d}  x = {q.x * 1e3:.4f} mm, z = {q.z * 1e6:.3f} µm'
                  + (f', moved {(q.x - q.first_x) * 1e6:+.3f} µm' if q.first_x is not None else '')
                  + f'; mode {q.mode or "unknown"}' for k, q in enumerate(s.parts)]
    lines += _loss_lines(s, coverage)
    return '\n'.join(lines)


def _simulator_lines(s: LogSummary) -> list[str]:
    """Sim time span (pose stamps) with the achieved real-time factor, and how the simulator was driven (the
    commands it counted itself when the log holds fewer of its receipts)."""
    lines = []
    p = s.part
    if p.stamp is not None and p.first_stamp is not None:
        span = p.stamp - p.first_stamp
        stepped = s.simulator.mode == 'stepped'
        pace = p.real_time_factor
        rtf = f', {pace:.2f} × real time' if pace and span > 0 and not stepped else ''
        lines.append(f'sim time   {p.first_stamp:.6f} – {p.stamp:.6f} s (particle/pose stamps{rtf})')
    run = s.simulator
    if run.mode != 'unknown':
        how = {'stepped': f'stepped through simulator/step, {run.step_period:g} s per step',
               'lockstep': f'lockstep, {run.step_period:g} s per simulator/step call or command',
               'real time': f'real time × {run.real_time_factor:g}',
               'as fast as possible': f'as fast as possible, {run.step_period:g} s per step'}.get(run.mode, run.mode)
        n, counted = run.commands_received, s.start.commands_received
        if counted > n:     # its /diagnostics count from its start, the receipts only what was recorded
            lines.append(f'simulator  {how}; {counted} command{"s" * (counted != 1)} received '
                         f'(its /diagnostics), {n} of them acknowledged in the log')
        else:
            lines.append(f'simulator  {how}; {n} command{"s" * (n != 1)} received')
    return lines
