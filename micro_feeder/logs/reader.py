"""Reading logs: a rosbag2 directory, a bare ``.mcap``, a truncated file left by a crash, or a damaged one.

Files are read through :class:`~.mcap_file.McapFile`, which verifies every CRC the file has and skips
what is damaged: a truncated file (no summary) is read up to its last whole chunk with a
:class:`TruncatedLogWarning`; a damaged chunk or record is skipped with one :class:`DamagedLogWarning`
naming it, and ``damage`` / ``lost`` say what and how much. A damaged ``metadata.yaml`` falls back to the
directory's ``.mcap`` files. Messages come as :class:`LogMessage`: the CDR bytes plus a lazily decoded
``message`` (mcap-ros2-support's decoder: attribute access like the ROS message); ``messages(...,
decoded=True)`` skips (and reports) messages that do not decode.

Sim time is the messages' ``header.stamp`` (:attr:`LogMessage.stamp_ns`, read from the CDR bytes for
types whose first field is a ``std_msgs/Header``), never the MCAP publish time, which recorders fill in
differently (ours with the stamp, ``rosbags`` and others with the receive time).

Example, what ``resim`` needs::

    log = LogReader('out/run1')
    for m in log.messages([log.command_source('actuator/trajectory')], decoded=True):
        print(m.topic, m.log_time, m.message)
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mcap.records import Channel, Message, Schema
from mcap_ros2.decoder import DecoderFactory

from ..interface.stamps import header_stamp_ns
from ..interface.topics import RECEIVED_COPIES
from .mcap_file import Damage, McapFile, NotMcapError
from .metadata import LogFormatError, read_file_list
from .writer import RECORDER_METADATA

__all__ = ['DamagedLogWarning', 'LogFormatError', 'LogMessage', 'LogReader', 'LogTopic', 'LogWarning',
           'TruncatedLogWarning']


HEADER_TYPES = ('std_msgs/msg/Header', 'std_msgs/Header')  # a Header message is its own stamp
_UNDECODED = object()  # LogMessage.message not decoded yet


class LogWarning(UserWarning):
    """Something about a log the reader worked around (the log commands print these on stderr)."""


class TruncatedLogWarning(LogWarning):
    """A log file has no summary (its writer was killed): read up to its last whole chunk."""


class DamagedLogWarning(LogWarning):
    """Part of a log is damaged (CRC mismatch, unreadable chunk or record, bad metadata.yaml): skipped."""


class UndecodableMessage(ValueError):
    """A message whose bytes do not decode with its schema."""


@dataclass(slots=True)
class LogMessage:
    """One recorded message: topic, ``pkg/msg/Type``, times [ns], CDR bytes, and ``message`` decoded on
    first access (:class:`UndecodableMessage` when the bytes do not decode)."""

    topic: str
    type: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes
    decode: Callable[[bytes], Any] = field(repr=False)
    stamped: bool = False
    _decoded: Any = field(default=_UNDECODED, init=False, repr=False, compare=False)

    @property
    def message(self) -> Any:
        """The decoded message (attributes named as the ROS message's fields), decoded once."""
        if self._decoded is _UNDECODED:
            try:
                self._decoded = self.decode(self.data)
            except Exception as err:  # damaged bytes make the decoder raise anything
                raise UndecodableMessage(f'{self.topic} message at log time {self.log_time_ns} does not decode as '
                                         f'{self.type}: {err}') from None
        return self._decoded

    @property
    def log_time(self) -> float:
        """Receive time [s]."""
        return self.log_time_ns * 1e-9

    @property
    def stamp_ns(self) -> int | None:
        """``header.stamp`` [ns] for types that start with a ``std_msgs/Header``, else None."""
        return header_stamp_ns(self.data) if self.stamped and len(self.data) >= 12 else None

    @property
    def publish_time(self) -> float:
        """MCAP publish time [s] (recorder-dependent: use :attr:`stamp_ns` for sim time)."""
        return self.publish_time_ns * 1e-9


@dataclass
class LogTopic:
    """A topic in a log: name, type, readable message count, channel metadata (``offered_qos_profiles`` ...)."""

    name: str
    type: str
    count: int = 0
    metadata: dict[str, str] = field(default_factory=dict)


def _is_stamped(schema: Schema) -> bool:
    """True when the schema's first field is a ``std_msgs/Header`` (read from the log's own schema text)."""
    for line in schema.data.decode(errors='replace').splitlines():
        line = line.split('#', 1)[0].strip()
        if line and '=' not in line.split()[0]:
            return line.split()[0] in (*HEADER_TYPES, 'Header')
    return False


class LogReader:
    """A log opened for reading: ``files``, ``topics``, ``start_ns``/``end_ns``, ``truncated`` files,
    ``damage`` found so far and ``lost`` messages, the recorder's ``recorder_info`` (loss counters ...),
    and :meth:`messages`."""

    def __init__(self, path: Path | str, progress: Callable[[int, int], None] | None = None) -> None:
        """Open the log at ``path``; ``progress(bytes, total bytes)`` is called as the opening reads the files
        through (their CRC check, or the scan of a file without summary: seconds for an hour at 1 kHz).
        Afterwards, :attr:`on_read` (when set) is called with the compressed size of each chunk read."""
        self.path = Path(path)
        self.on_read: Callable[[int], None] | None = None
        self.damage: list[Damage] = []
        self.undecodable: dict[str, int] = {}
        self.files = self._find_files()
        self._decoders: dict[int, Callable[[bytes], Any]] = {}
        self._stamped: dict[int, bool] = {}
        try:
            self._mcaps = [McapFile(p, self._on_damage, self._file_progress(i, progress), self._chunk_read)
                           for i, p in enumerate(self.files)]
        except NotMcapError as err:
            raise LogFormatError(str(err)) from None
        self.truncated = [f.path for f in self._mcaps if f.truncated]
        for f in self._mcaps:
            if f.truncated:
                warnings.warn(
                    f'{f.path} is truncated (no summary; its writer did not finish): read up to its last '
                    f'whole chunk, {f.readable_bytes} of {f.size} bytes', TruncatedLogWarning, stacklevel=2)
        self.topics: dict[str, LogTopic] = {}
        for f in self._mcaps:
            for cid, channel in f.channels.items():
                schema = f.schemas.get(channel.schema_id)
                if schema is None:
                    continue
                topic = self.topics.setdefault(channel.topic, LogTopic(channel.topic, schema.name, 0,
                                                                       dict(channel.metadata)))
                topic.count += f.counts.get(cid, 0)
        starts = [f.start_ns for f in self._mcaps if f.start_ns is not None]
        ends = [f.end_ns for f in self._mcaps if f.end_ns is not None]
        self.start_ns = min(starts, default=0)
        self.end_ns = max(ends, default=0)
        self.recorder_info: dict[str, str] = {}
        for f in self._mcaps:
            self.recorder_info.update(f.metadata.get(RECORDER_METADATA, {}))

    # -- queries ------------------------------------------------------------------------------------
    @property
    def duration(self) -> float:
        """Span of the log times [s]."""
        return (self.end_ns - self.start_ns) * 1e-9

    def chunk_bytes(self, topics: Iterable[str] | None = None) -> int:
        """Bytes of the chunks that hold messages of ``topics`` (all when None): what a pass over their
        messages reads (:attr:`on_read` counts up to it)."""
        wanted = None if topics is None else {r for r in map(self.resolve, topics) if r}
        total = 0
        for f in self._mcaps:
            ids = None if wanted is None else {cid for cid, c in f.channels.items() if c.topic in wanted}
            total += sum(c.length for c in f.chunks if ids is None or c.channels is None or c.channels & ids)
        return total

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self.topics.values())

    @property
    def lost(self) -> int | None:
        """Messages lost to damage found so far (None when some damage has an unknown count)."""
        counts = [d.lost for d in self.damage]
        return None if None in counts else sum(counts) + sum(self.undecodable.values())

    def damage_report(self) -> str:
        """One line on the damage found so far ('' when none)."""
        if not self.damage and not self.undecodable:
            return ''
        lost = self.lost
        parts = [f'{len(self.damage)} damaged part{"s" * (len(self.damage) != 1)}'] if self.damage else []
        parts += [f'{n} undecodable {t} message{"s" * (n != 1)}' for t, n in sorted(self.undecodable.items())]
        return ', '.join(parts) + ('; messages lost: ' + ('unknown' if lost is None else f'{lost:,}'))

    def resolve(self, topic: str) -> str | None:
        """The recorded name of ``topic``: exact, or a relative name matched to ``/<ns>/topic`` (the
        first in sorted order when several namespaces match); None when absent."""
        if topic in self.topics:
            return topic
        if '/' + topic in self.topics:
            return '/' + topic
        matches = sorted(t for t in self.topics if t.endswith('/' + topic.lstrip('/')))
        return matches[0] if matches else None

    def command_source(self, topic: str) -> str | None:
        """The recorded topic that holds the commands sent on ``topic`` (``actuator/trajectory``): the
        simulator's copy of each one it received (``simulator/trajectories_received``) when the log has it,
        complete whatever senders the recorder had discovered, else ``topic`` itself; None when neither."""
        copy = RECEIVED_COPIES.get(topic)
        return (self.resolve(copy) if copy is not None else None) or self.resolve(topic)

    def messages(self, topics: Iterable[str] | None = None, *, start_ns: int | None = None,
                 end_ns: int | None = None, decoded: bool = False, reverse: bool = False) -> Iterator[LogMessage]:
        """Readable messages of the given topics (all when None; relative names resolved), log time in
        ``[start_ns, end_ns)``, in log-time order within each file and files in order (``reverse``: from
        the end). With ``decoded``, each is decoded first and one that does not decode is skipped and
        counted."""
        wanted = None if topics is None else {r for r in map(self.resolve, topics) if r}
        if wanted is not None and not wanted:
            return
        for f in (reversed(self._mcaps) if reverse else self._mcaps):
            ids = None if wanted is None else {cid for cid, c in f.channels.items() if c.topic in wanted}
            if ids is not None and not ids:
                continue
            for msg in f.messages(ids, start_ns, end_ns, reverse=reverse):
                m = self._message(f, msg)
                if m is not None and (not decoded or self._decodes(m)):
                    yield m

    def first(self, topic: str) -> LogMessage | None:
        """The first decodable message (in log time) of ``topic``, None when it has none."""
        return self._edge(topic, last=False)

    def last(self, topic: str) -> LogMessage | None:
        """The last decodable message (in log time) of ``topic``, None when it has none."""
        return self._edge(topic, last=True)

    # -- internals ----------------------------------------------------------------------------------
    def _chunk_read(self, size: int) -> None:
        if self.on_read is not None:
            self.on_read(size)

    def _on_damage(self, damage: Damage) -> None:
        self.damage.append(damage)
        warnings.warn(str(damage), DamagedLogWarning, stacklevel=3)

    def _file_progress(self, i: int, progress: Callable[[int, int], None] | None) -> Callable[[int], None] | None:
        """``progress`` over all files, for the i-th one's pass."""
        if progress is None:
            return None
        sizes = [p.stat().st_size for p in self.files]
        before, total = sum(sizes[:i]), sum(sizes)
        return lambda pos: progress(before + pos, total)

    def _find_files(self) -> list[Path]:
        if self.path.is_file():
            return [self.path]
        if not self.path.is_dir():
            raise FileNotFoundError(f'no log at {self.path}')
        found = sorted(self.path.glob('*.mcap'), key=lambda p: (len(p.name), p.name))
        try:
            listed = read_file_list(self.path)
        except LogFormatError as err:
            if not found:
                raise FileNotFoundError(f'{self.path} holds no .mcap file, and {err}') from None
            listed = None
            warnings.warn(f'{err}; reading the .mcap files of {self.path} instead', DamagedLogWarning, stacklevel=3)
        if listed is not None:
            missing = [p for p in listed if not p.is_file()]
            if missing:
                warnings.warn(f'{self.path}/metadata.yaml lists {", ".join(p.name for p in missing)}, which '
                              f'{"is" if len(missing) == 1 else "are"} missing: reading the .mcap files present',
                              DamagedLogWarning, stacklevel=3)
                listed = None
        files = listed if listed is not None else found
        if not files:
            raise FileNotFoundError(f'{self.path} holds no .mcap file')
        return files

    def _edge(self, topic: str, last: bool) -> LogMessage | None:
        name = self.resolve(topic)
        if name is None:
            return None
        for f in (reversed(self._mcaps) if last else self._mcaps):
            ids = {cid for cid, c in f.channels.items() if c.topic == name}
            if not ids:
                continue
            for msg in f.messages(ids, reverse=last):
                m = self._message(f, msg)
                if m is not None and self._decodes(m):
                    return m
        return None

    def decodes(self, m: LogMessage) -> bool:
        """Decode ``m`` (once) and say whether it decodes; one that does not is counted and reported as
        ``messages(..., decoded=True)`` does. For readers that take the fields they need from the bytes and
        decode only a message whose layout they do not read."""
        return self._decodes(m)

    def _decodes(self, m: LogMessage) -> bool:
        try:
            m.message  # noqa: B018 - decode now
        except UndecodableMessage as err:
            n = self.undecodable.get(m.topic, 0)
            self.undecodable[m.topic] = n + 1
            if not n:
                warnings.warn(f'{err}: skipped (further ones on this topic are counted, not shown)',
                              DamagedLogWarning, stacklevel=4)
            return False
        return True

    def _message(self, f: McapFile, msg: Message) -> LogMessage | None:
        channel: Channel | None = f.channels.get(msg.channel_id)
        schema = f.schemas.get(channel.schema_id) if channel is not None else None
        if schema is None:
            f.report(None, f'messages of channel {msg.channel_id}, whose channel or schema record was lost with a '
                           'damaged chunk, skipped', f.counts.get(msg.channel_id), key=('channel', msg.channel_id))
            return None
        key = (id(f), schema.id)
        decode = self._decoders.get(key)
        if decode is None:
            try:
                decode = DecoderFactory().decoder_for(channel.message_encoding, schema)
            except Exception as err:  # a damaged schema text makes the parser raise anything
                error = f'schema {schema.name} does not parse: {err}'

                def decode(_: bytes, error: str = error) -> Any:
                    raise ValueError(error)
            if decode is None:
                def decode(_: bytes, encoding: str = channel.message_encoding) -> Any:
                    raise ValueError(f'no decoder for message encoding {encoding!r}')
            self._decoders[key] = decode
            self._stamped[key] = schema.name in HEADER_TYPES or _is_stamped(schema)
        return LogMessage(channel.topic, schema.name, msg.log_time, msg.publish_time, msg.data, decode,
                          self._stamped[key])
