"""A log's summary: topics, types, counts, rates, duration, sim time, how the simulator ran, final part
state, recorder loss counters.

The loss counters come from the recorder: its ``micro_feeder.recorder`` metadata record on a clean stop,
or, in a truncated log, the last of its ``/diagnostics`` messages that made it to disk (same keys).
"""

from __future__ import annotations

import datetime
from dataclasses import dataclass, field
from pathlib import Path

from .reader import LogReader
from .sim_parameters import recorded_parameters, run_mode

RECORDER_STATUS_PREFIX = 'recorder'
RATE_MIN_COUNT = 10  # topics with fewer messages are events (commands, mode changes): no rate shown


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


@dataclass
class SimulatorRun:
    """How the simulator ran, from its recorded parameters and command receipts (None/0 when absent)."""

    mode: str = 'unknown'
    real_time_factor: float | None = None
    step_period: float | None = None
    commands_received: int = 0


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
    state = log.last('particle/contact_state')
    if state is not None:
        part.mode = state.message.data
    counters, source = recorder_counters(log)
    return LogSummary(log.path, log.files, sum(f.stat().st_size for f in log.files), log.truncated,
                      log.start_ns, log.duration, rows, part, simulator_run(log), counters, source)


def _size(n: int) -> str:
    for unit in ('B', 'KiB', 'MiB', 'GiB'):
        if n < 1024 or unit == 'GiB':
            return f'{n:.0f} {unit}' if unit == 'B' else f'{n:.1f} {unit}'
        n /= 1024
    return f'{n} B'


def _loss_lines(s: LogSummary) -> list[str]:
    if not s.recorder:
        return ['loss       unknown (no recorder counters in this log)']
    c = s.recorder
    lost, incompatible = int(c.get('lost_total', 0)), int(c.get('incompatible_qos_total', 0))
    where = 'final summary' if s.recorder_source == 'summary' else 'last recorder diagnostics'
    verdict = 'none' if lost == 0 and incompatible == 0 else f'{lost} messages lost'
    lines = [f'loss       {verdict}  (received {int(c.get("received_total", 0)):,}; QoS message-lost events '
             f'{lost}, incompatible-QoS events {incompatible}; from the {where})']
    per_topic = {k.split('.', 1)[1]: v for k, v in c.items() if k.startswith('lost.') and v != '0'}
    lines += [f'           {topic}: {n} lost' for topic, n in sorted(per_topic.items())]
    return lines


def format_summary(s: LogSummary) -> str:
    """The summary as aligned text for a terminal."""
    start = datetime.datetime.fromtimestamp(s.start_ns * 1e-9).isoformat(sep=' ', timespec='milliseconds')
    lines = [
        f'log        {s.path}',
        f'files      {len(s.files)} ({_size(s.size_bytes)}, zstd chunks)',
        f'start      {start} (receive time, local)',
        f'duration   {s.duration:.3f} s',
        f'messages   {s.message_count:,}',
    ]
    for path in s.truncated:
        lines.append(f'WARNING    {path.name} is truncated (recorder did not stop cleanly); read up to its '
                     'last whole chunk. "micro-feeder recover" rewrites it as a complete log.')
    lines.append('')
    wname = max([len('topic'), *(len(t.name) for t in s.topics)])
    wtype = max([len('type'), *(len(t.type) for t in s.topics)])
    lines.append(f'{"topic":<{wname}}  {"type":<{wtype}}  {"count":>9}  {"rate":>10}')
    lines += [f'{t.name:<{wname}}  {t.type:<{wtype}}  {t.count:>9,}  '
              + (f'{t.rate:>7.1f} Hz' if t.rate is not None else f'{"–":>10}') for t in s.topics]
    lines.append('')
    lines += _simulator_lines(s)
    p = s.part
    if p.x is None and p.mode is None:
        lines.append('part       no particle/pose or particle/contact_state in this log')
    else:
        where = (f'x = {p.x * 1e3:.4f} mm, z = {p.z * 1e6:.3f} µm at t = {p.stamp:.4f} s'
                 if p.x is not None else 'no pose')
        lines.append(f'part       {where}; mode {p.mode or "unknown"}')
        if p.x is not None and p.first_x is not None:
            lines.append(f'           moved {(p.x - p.first_x) * 1e6:+.3f} µm since t = {p.first_stamp:.4f} s')
    lines += _loss_lines(s)
    return '\n'.join(lines)


def _simulator_lines(s: LogSummary) -> list[str]:
    """Sim time span (pose stamps) with the achieved real-time factor, and how the simulator was driven."""
    lines = []
    p = s.part
    if p.stamp is not None and p.first_stamp is not None:
        span = p.stamp - p.first_stamp
        stepped = s.simulator.mode == 'stepped'
        rtf = f', {span / s.duration:.2f} × real time' if s.duration > 0 and span > 0 and not stepped else ''
        lines.append(f'sim time   {p.first_stamp:.6f} – {p.stamp:.6f} s (particle/pose stamps{rtf})')
    run = s.simulator
    if run.mode != 'unknown':
        how = {'stepped': f'stepped through simulator/step, {run.step_period:g} s per step',
               'lockstep': f'lockstep, {run.step_period:g} s per simulator/step call or command',
               'real time': f'real time × {run.real_time_factor:g}',
               'as fast as possible': f'as fast as possible, {run.step_period:g} s per step'}.get(run.mode, run.mode)
        n = run.commands_received
        lines.append(f'simulator  {how}; {n} command{"s" * (n != 1)} received')
    return lines
