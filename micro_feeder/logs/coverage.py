"""How much of a run a log covers: where each topic starts, where and why the log ends, commands the
simulator received that the log lacks, and the times the recorder itself stood still.

* **Start per topic**: the sim time of each topic's first message, read from the ``particle/pose`` received
  at or after it (a topic's own stamp is not always sim time: ``/diagnostics`` carries wall time, a
  trajectory stamped 0 means "on receipt").
* **End**: a recorder that stopped early (disk full, directory removed, storage not responding) wrote why
  and where into its ``micro_feeder.recorder`` record and ``metadata.yaml`` (``logs.writer``); a log whose
  files have no summary and no such record ended abruptly (killed, crashed, power lost).
* **Commands against the receipts**: the simulator acknowledges every command on
  ``simulator/command_receipts`` (stamp = sim time of receipt, ``frame_id`` = the command's topic), so a
  command topic with fewer messages than receipts (and than the recorder counted lost) lacks commands,
  typically a new publisher's first ones, sent before the recorder was matched with it.
* **Stalls**: the recorder counts the times its own process did not run (``stalls`` keys).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from ..interface.names import split_receipt_frame
from ..interface.stamps import header_frame_id
from ..interface.topics import COMMAND_TOPICS
from . import writer as w
from .metadata import read_custom_data
from .reader import LogReader

POSE = 'particle/pose'
RECEIPTS = 'simulator/command_receipts'
RECEIPT_MARGIN_NS = 50_000_000   # a receipt reaches the recorder about when its command does (50 ms margin)


@dataclass
class TopicStart:
    """Where a topic's record starts: the sim time [s] of its first message (None: after the last pose),
    ``before`` when it came before the first pose (its sim time is then at most ``sim``)."""

    sim: float | None
    before: bool = False

    def __str__(self) -> str:
        return '–' if self.sim is None else f'{"≤ " if self.before else ""}{self.sim:.3f} s'


@dataclass
class LogEnd:
    """How a log ends: ``kind`` 'complete' (the recorder closed it), 'early' (the recorder stopped it and
    says why: ``reason``, ``detail``), 'abrupt' (a file without summary and no reason: killed, crashed);
    where it stops, as sim time (the last pose kept) and log time [s] from the log's start; messages
    ``cut`` (received after the last whole chunk), earlier files lost, what could not be written."""

    kind: str = 'complete'
    reason: str = ''
    detail: str = ''
    stopped_at_sim: float | None = None
    stopped_at_log: float | None = None
    readable_until_sim: float | None = None
    readable_until_log: float | None = None
    cut: int = 0
    files_lost: int = 0
    truncated: list[Path] = field(default_factory=list)


@dataclass
class MissingCommands:
    """Commands on ``topic`` the simulator acknowledged (``receipts``) that the log lacks: ``missing`` =
    receipts − ``recorded`` − ``lost`` (counted by the recorder); ``before`` of them acknowledged before the
    first recorded one, between sim times ``first_sim`` and ``last_sim`` [s]."""

    topic: str
    receipts: int
    recorded: int
    lost: int
    missing: int
    before: int = 0
    first_sim: float | None = None
    last_sim: float | None = None


@dataclass
class Stalls:
    """Times the recorder's process did not run: how many, seconds in all, the longest and when it ended
    (log time [s] from the log's start)."""

    count: int
    total_s: float
    longest_s: float
    longest_end_log: float | None


@dataclass
class Coverage:
    """What ``info`` says of a log's coverage (module docstring)."""

    starts: dict[str, TopicStart] = field(default_factory=dict)   # topic -> where its record starts
    end: LogEnd = field(default_factory=LogEnd)
    commands: list[MissingCommands] = field(default_factory=list)
    stalls: Stalls | None = None


def _s(ns: str | int | None, origin: int = 0) -> float | None:
    try:
        return (int(ns) - origin) * 1e-9 if ns not in (None, '') else None
    except ValueError:
        return None


def topic_starts(log: LogReader) -> dict[str, TopicStart]:
    """Topic -> where its record starts (the first pose received at or after its first message); {} without
    poses."""
    pose = log.resolve(POSE)
    first_pose = log.first(pose) if pose is not None else None
    if first_pose is None:
        return {}
    out: dict[str, TopicStart] = {}
    for name in log.topics:
        first = log.first(name)
        if first is None:
            out[name] = TopicStart(None)
        elif name == pose:
            out[name] = TopicStart(_s(first.stamp_ns))
        elif first.log_time_ns < first_pose.log_time_ns:
            out[name] = TopicStart(_s(first_pose.stamp_ns), before=True)
        else:
            after = next(iter(log.messages([pose], start_ns=first.log_time_ns)), None)
            out[name] = TopicStart(_s(after.stamp_ns) if after is not None else None)
    return out


def recorder_record(log: LogReader) -> dict[str, str]:
    """The recorder's own record of the log: its metadata record, else ``metadata.yaml``'s custom data
    (written alone when the MCAP file could not be finished)."""
    if log.recorder_info:
        return dict(log.recorder_info)
    return read_custom_data(log.path) if log.path.is_dir() else {}


def log_end(log: LogReader, record: dict[str, str], last_pose: float | None) -> LogEnd:
    """How and where the log ends (:class:`LogEnd`); ``last_pose``: sim time of its last pose."""
    end = LogEnd(truncated=list(log.truncated))
    last_log = _s(log.end_ns, log.start_ns) if log.message_count else None
    if record.get(w.STOPPED_EARLY) == 'true':
        end.kind, end.reason, end.detail = 'early', record.get(w.STOP_REASON, ''), record.get(w.STOP_DETAIL, '')
        end.stopped_at_sim = _s(record.get(w.STOPPED_AT_STAMP_NS))
        end.stopped_at_log = _s(record.get(w.STOPPED_AT_NS), log.start_ns) if log.message_count else None
        end.readable_until_sim = _s(record.get(w.READABLE_UNTIL_STAMP_NS))
        end.cut = int(record.get(w.CUT_MESSAGES, 0) or 0)
        end.files_lost = int(record.get(w.FILES_LOST, 0) or 0)
    elif log.truncated:
        end.kind = 'abrupt'
    if end.readable_until_sim is None:
        end.readable_until_sim = last_pose
    end.readable_until_log = last_log
    return end


def commands_against_receipts(log: LogReader, record: dict[str, str]) -> list[MissingCommands]:
    """Command topics with commands the simulator acknowledged that the log lacks. A receipt naming the
    command's identity (``actuator/trajectory#<identity>``) is matched with the recorded command of that
    identity, exactly; unnamed ones by count, the missing taken as the first (a publisher's first messages,
    sent before the recorder was matched with it). Commands the recorder counted lost are not missing."""
    receipts_topic = log.resolve(RECEIPTS)
    if receipts_topic is None:
        return []
    receipts: dict[str, list[tuple[int, int, str]]] = {}
    for m in log.messages([receipts_topic], decoded=True):
        topic, command_id = split_receipt_frame(m.message.frame_id)
        receipts.setdefault(topic, []).append((m.log_time_ns, m.stamp_ns or 0, command_id))
    out = []
    for topic in COMMAND_TOPICS:
        acknowledged = receipts.get(topic, [])
        name = log.command_source(topic)
        lost = int(record.get(f'lost.{name}', 0) or 0) if name else 0
        if len(acknowledged) <= (log.topics[name].count if name else 0) + lost:
            continue    # nothing can be missing: the commands are not read (a long log holds thousands)
        recorded = Counter(header_frame_id(m.data) if m.stamped else ''
                           for m in (log.messages([name]) if name else ()))
        named = [r for r in acknowledged if r[2]]
        unnamed = [r for r in acknowledged if not r[2]]
        absent = []
        for receipt in named:
            if recorded[receipt[2]] > 0:
                recorded[receipt[2]] -= 1
            else:
                absent.append(receipt)
        absent += unnamed[:max(len(unnamed) - recorded[''], 0)]
        missing = len(absent) - lost
        if missing <= 0:
            continue
        absent.sort()
        first = log.first(name) if name else None
        limit = first.log_time_ns - RECEIPT_MARGIN_NS if first is not None else None
        before = [stamp for t, stamp, _ in absent if limit is None or t < limit]
        out.append(MissingCommands(topic, len(acknowledged), log.topics[name].count if name else 0,
                                   lost, missing, len(before), _s(before[0]) if before else None,
                                   _s(before[-1]) if before else None))
    return out


def stalls(log: LogReader, record: dict[str, str]) -> Stalls | None:
    """The recorder's stalls from its counters (None when it had none)."""
    count = int(record.get('stalls', 0) or 0)
    if not count:
        return None
    return Stalls(count, float(record.get('stalled_s', 0.0)), float(record.get('longest_stall_s', 0.0)),
                  _s(record.get('longest_stall_end_ns'), log.start_ns))


def coverage(log: LogReader, counters: dict[str, str], last_pose: float | None) -> Coverage:
    """Everything above for ``info``; ``counters``: the recorder counters ``info`` found (record or last
    diagnostics), ``last_pose``: sim time [s] of the last pose."""
    record = recorder_record(log)
    known = {**counters, **record}
    return Coverage(topic_starts(log), log_end(log, record, last_pose), commands_against_receipts(log, known),
                    stalls(log, known))


def end_line(c: Coverage) -> str:
    """``ends       ...``: where and why the log ends ('' for a log its recorder closed)."""
    end = c.end
    if end.kind == 'complete':
        return ''
    until = _where(end.readable_until_sim, end.readable_until_log)
    if end.kind == 'abrupt':
        return (f'ends       abruptly, after {until}: the recorder did not finish the log (killed, crashed or '
                'power lost); what it received in its last flush period before that, and anything later, is '
                'not in it')
    at = _where(end.stopped_at_sim, end.stopped_at_log)
    cut = f'; {end.cut:,} messages received after that were cut' if end.cut else ''
    n = end.files_lost
    lost = f'; {n} earlier file{"s were" if n != 1 else " was"} lost with the directory' if n else ''
    return (f'ends       early: recording stopped at {at}: {end.reason} ({end.detail}); readable up to '
            f'{until}{cut}{lost}; nothing later was recorded')


def missing_command_lines(c: Coverage) -> list[str]:
    """Per command topic, the commands the log lacks against the receipts: a ``start missing`` when they
    were all acknowledged before the first recorded one."""
    lines = []
    for m in c.commands:
        lost = f' and {m.lost} counted lost' if m.lost else ''
        head = (f'{m.topic}: {m.missing} of the {m.receipts} commands the simulator acknowledged '
                f'(simulator/command_receipts) are not in the log ({m.recorded} recorded{lost})')
        span = ('' if not m.before else f'at sim time {m.first_sim:.3f} s' if m.first_sim == m.last_sim else
                f'at sim time {m.first_sim:.3f}–{m.last_sim:.3f} s')
        if m.before and m.before == m.missing:
            lines.append(f'start missing: {head}: acknowledged {span}, before the first recorded one (sent before '
                         'the recorder was matched with their publisher)')
        elif m.before:
            lines.append(f'missing: {head}: {m.before} acknowledged {span}, before the first recorded one, '
                         f'{m.missing - m.before} later')
        else:
            lines.append(f'missing: {head}')
    return lines


def stall_lines(c: Coverage) -> list[str]:
    """The times the recorder did not run."""
    if c.stalls is None:
        return []
    s = c.stalls
    when = (f', the longest {s.longest_s:.1f} s ending at log time +{s.longest_end_log:.1f} s' if s.count > 1 else
            f', ending at log time +{s.longest_end_log:.1f} s') if s.longest_end_log is not None else ''
    return [f'recorder   did not run {s.count} time{"s" * (s.count != 1)}, {s.total_s:.1f} s in all{when} (its '
            'process stopped, or its executor busy or starved of CPU): messages published meanwhile may be '
            'missing (counted lost where the middleware dropped them)']


def _where(sim: float | None, log_s: float | None) -> str:
    parts = []
    if sim is not None:
        parts.append(f'sim time {sim:.3f} s')
    if log_s is not None:
        parts.append(f'log time +{log_s:.2f} s')
    if not parts:
        return 'the start'
    return parts[0] + (f' ({parts[1]})' if len(parts) > 1 else '')
