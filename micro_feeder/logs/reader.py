"""Reading logs: a rosbag2 directory, a bare ``.mcap``, or a truncated file left by a crash.

A complete file is read through its summary and indexes (messages in log-time order). A file without a
summary (the recorder was killed) is read front to back up to its last whole chunk, with a
:class:`TruncatedLogWarning` saying so. Messages come as :class:`LogMessage`: the CDR bytes plus a
lazily decoded ``message`` (mcap-ros2-support's decoder: attribute access like the ROS message).

Example, what ``resim`` needs::

    log = LogReader('out/run1')
    for m in log.messages(['actuator/trajectory', 'actuator/command']):
        print(m.topic, m.log_time, m.message)
"""

from __future__ import annotations

import struct
import warnings
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader, make_reader
from mcap.records import Channel, Message, Schema
from mcap_ros2.decoder import DecoderFactory

from .metadata import LogFormatError, read_file_list
from .writer import RECORDER_METADATA

READ_ERRORS = (McapError, EOFError, ValueError, OSError, struct.error)
MAGIC = b'\x89MCAP0\r\n'  # the first 8 bytes of every MCAP file

__all__ = ['READ_ERRORS', 'LogFormatError', 'LogMessage', 'LogReader', 'LogTopic', 'TruncatedLogWarning']


_UNDECODED = object()  # LogMessage.message not decoded yet


class TruncatedLogWarning(UserWarning):
    """A log file has no summary (its writer was killed): read up to its last whole chunk."""


@dataclass(slots=True)
class LogMessage:
    """One recorded message: topic, ``pkg/msg/Type``, times [ns], CDR bytes, and ``message`` decoded on
    first access."""

    topic: str
    type: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes
    decode: Callable[[bytes], Any] = field(repr=False)
    _decoded: Any = field(default=_UNDECODED, init=False, repr=False, compare=False)

    @property
    def message(self) -> Any:
        """The decoded message (attributes named as the ROS message's fields), decoded once."""
        if self._decoded is _UNDECODED:
            self._decoded = self.decode(self.data)
        return self._decoded

    @property
    def log_time(self) -> float:
        """Receive time [s]."""
        return self.log_time_ns * 1e-9

    @property
    def publish_time(self) -> float:
        """Header stamp [s] for stamped types, else the receive time."""
        return self.publish_time_ns * 1e-9


@dataclass
class LogTopic:
    """A topic in a log: name, type, message count, channel metadata (``offered_qos_profiles`` ...)."""

    name: str
    type: str
    count: int = 0
    metadata: dict[str, str] = field(default_factory=dict)


@dataclass
class _FileIndex:
    """What a first look at one MCAP file found."""

    path: Path
    complete: bool
    start_ns: int | None = None
    end_ns: int | None = None
    counts: dict[str, int] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    readable_bytes: int = 0


def _iter_stream(path: Path, topics: Iterable[str] | None = None) -> Iterator[tuple[Schema, Channel, Message]]:
    """Messages of a file in file order, stopping quietly at the first incomplete or damaged record."""
    with open(path, 'rb') as stream:
        reader = NonSeekingReader(stream, validate_crcs=True)
        try:
            yield from reader.iter_messages(topics=topics, log_time_order=False)
        except READ_ERRORS:
            return


class LogReader:
    """A log opened for reading: ``files``, ``topics``, ``start_ns``/``end_ns``, ``truncated`` files,
    the recorder's ``recorder_info`` (loss counters ...), and :meth:`messages`."""

    def __init__(self, path: Path | str) -> None:
        self.path = Path(path)
        self.files = self._find_files()
        self._channels: dict[str, tuple[Schema, Channel]] = {}
        self._decoders: dict[str, Callable[[bytes], Any]] = {}
        self._index = [self._index_file(p) for p in self.files]
        self.truncated = [i.path for i in self._index if not i.complete]
        for info in self._index:
            if not info.complete:
                warnings.warn(
                    f'{info.path} is truncated (no summary; its writer did not finish): read up to its last '
                    f'whole chunk, {info.readable_bytes} of {info.path.stat().st_size} bytes',
                    TruncatedLogWarning, stacklevel=2)
        self.topics: dict[str, LogTopic] = {}
        for topic, (schema, channel) in self._channels.items():
            count = sum(i.counts.get(topic, 0) for i in self._index)
            self.topics[topic] = LogTopic(topic, schema.name, count, dict(channel.metadata))
        starts = [i.start_ns for i in self._index if i.start_ns is not None]
        ends = [i.end_ns for i in self._index if i.end_ns is not None]
        self.start_ns = min(starts, default=0)
        self.end_ns = max(ends, default=0)
        self.recorder_info: dict[str, str] = {}
        for info in self._index:
            self.recorder_info.update(info.metadata.get(RECORDER_METADATA, {}))

    # -- queries ------------------------------------------------------------------------------------
    @property
    def duration(self) -> float:
        """Span of the log times [s]."""
        return (self.end_ns - self.start_ns) * 1e-9

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self.topics.values())

    def resolve(self, topic: str) -> str | None:
        """The recorded name of ``topic``: exact, or a relative name matched to ``/<ns>/topic`` (the
        first in sorted order when several namespaces match); None when absent."""
        if topic in self.topics:
            return topic
        if '/' + topic in self.topics:
            return '/' + topic
        matches = sorted(t for t in self.topics if t.endswith('/' + topic.lstrip('/')))
        return matches[0] if matches else None

    def messages(self, topics: Iterable[str] | None = None, *, start_ns: int | None = None,
                 end_ns: int | None = None) -> Iterator[LogMessage]:
        """Messages of the given topics (all when None; relative names resolved), log time in
        ``[start_ns, end_ns)``, in log-time order within each file and files in order."""
        wanted = None if topics is None else [r for r in map(self.resolve, topics) if r]
        if wanted is not None and not wanted:
            return
        for info in self._index:
            if info.complete:
                with open(info.path, 'rb') as stream:
                    reader = make_reader(stream)
                    for schema, channel, msg in reader.iter_messages(topics=wanted, starting_at=start_ns,
                                                                     ending_before=end_ns):
                        yield self._message(schema, channel, msg)
            else:
                for schema, channel, msg in _iter_stream(info.path, wanted):
                    if (start_ns is None or msg.log_time >= start_ns) and \
                            (end_ns is None or msg.log_time < end_ns):
                        yield self._message(schema, channel, msg)

    def first(self, topic: str) -> LogMessage | None:
        """The first message (in log time) of ``topic``, None when it has none."""
        return self._edge(topic, last=False)

    def last(self, topic: str) -> LogMessage | None:
        """The last message (in log time) of ``topic``, None when it has none."""
        return self._edge(topic, last=True)

    # -- internals ----------------------------------------------------------------------------------
    def _find_files(self) -> list[Path]:
        if self.path.is_file():
            return [self.path]
        if not self.path.is_dir():
            raise FileNotFoundError(f'no log at {self.path}')
        listed = read_file_list(self.path)
        files = listed if listed is not None else sorted(
            self.path.glob('*.mcap'), key=lambda p: (len(p.name), p.name))
        if not files:
            raise FileNotFoundError(f'{self.path} holds no .mcap file')
        return files

    def _index_file(self, path: Path) -> _FileIndex:
        with open(path, 'rb') as stream:
            head = stream.read(len(MAGIC))
            # A file cut before the end of its magic (even empty) is a truncated log; anything else that
            # does not start with the magic is not a log at all.
            if not MAGIC.startswith(head):
                raise LogFormatError(f'{path} is not an MCAP file (no MCAP magic at its start): not a log')
            stream.seek(0)
            try:
                reader = make_reader(stream)
                summary = reader.get_summary()
            except READ_ERRORS:
                summary = None
            if summary is not None and summary.statistics is not None:
                info = _FileIndex(path, True)
                stats = summary.statistics
                if stats.message_count:
                    info.start_ns, info.end_ns = stats.message_start_time, stats.message_end_time
                for channel in summary.channels.values():
                    self._channels.setdefault(channel.topic, (summary.schemas[channel.schema_id], channel))
                    info.counts[channel.topic] = info.counts.get(channel.topic, 0) + \
                        stats.channel_message_counts.get(channel.id, 0)
                info.metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
                return info
        return self._scan_file(path)

    def _scan_file(self, path: Path) -> _FileIndex:
        info = _FileIndex(path, False)
        with open(path, 'rb') as stream:
            reader = NonSeekingReader(stream, validate_crcs=True)
            try:
                for schema, channel, msg in reader.iter_messages(log_time_order=False):
                    self._channels.setdefault(channel.topic, (schema, channel))
                    info.counts[channel.topic] = info.counts.get(channel.topic, 0) + 1
                    t = msg.log_time
                    info.start_ns = t if info.start_ns is None else min(info.start_ns, t)
                    info.end_ns = t if info.end_ns is None else max(info.end_ns, t)
                    info.readable_bytes = stream.tell()
            except READ_ERRORS:
                pass
        return info

    def _edge(self, topic: str, last: bool) -> LogMessage | None:
        name = self.resolve(topic)
        if name is None:
            return None
        for info in (reversed(self._index) if last else self._index):
            if not info.counts.get(name):
                continue
            if info.complete:
                with open(info.path, 'rb') as stream:
                    for record in make_reader(stream).iter_messages(topics=[name], reverse=last):
                        return self._message(*record)
            found = None
            for found in _iter_stream(info.path, [name]):  # noqa: B007 - keep the last one
                if not last:
                    break
            if found is not None:
                return self._message(*found)
        return None

    def _message(self, schema: Schema, channel: Channel, msg: Message) -> LogMessage:
        decode = self._decoders.get(schema.name)
        if decode is None:
            decode = DecoderFactory().decoder_for(channel.message_encoding, schema)
            self._decoders[schema.name] = decode
        return LogMessage(channel.topic, schema.name, msg.log_time, msg.publish_time, msg.data, decode)
