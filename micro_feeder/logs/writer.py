"""Writing logs: MCAP with the ROS 2 profile in a rosbag2 directory, crash-safe by periodic flushes.

Messages are CDR bytes as they came off the wire (no decode). Log time is the receive time given by the
caller; publish time is the message's ``header.stamp`` when its type starts with a ``std_msgs/Header``,
else the log time. Chunks are zstd-compressed; the open chunk is closed and written out at least every
``flush_period`` seconds (checked on every write and by :meth:`LogWriter.flush_if_due`), so a killed
process loses at most that much. :meth:`LogWriter.close` writes the MCAP summary and ``metadata.yaml``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

from mcap.well_known import MessageEncoding, Profile, SchemaEncoding
from mcap.writer import CompressionType, Writer

from ..interface.stamps import header_stamp_ns
from .metadata import BagMetadata, FileInfo, TopicInfo
from .schemas import has_header, normalize_type, schema_text

RECORDER_METADATA = 'micro_feeder.recorder'
LIBRARY = 'micro_feeder'
CHUNK_SIZE = 1 << 20
SIZE_CHECK_EVERY = 1000  # messages between two checks of the file size for splitting


@dataclass
class _Topic:
    """A topic registered with the writer: its MCAP channel metadata and running count."""

    info: TopicInfo
    stamped: bool
    channel_id: int = -1  # in the current file, -1 until first written there


class LogWriter:
    """Writes a log: a rosbag2 directory (``metadata.yaml`` + ``<dir>_<i>.mcap``), or a bare ``.mcap``
    file when ``path`` ends in ``.mcap`` (no split then).

    ``flush_period`` [s] bounds what a crash loses; ``split_size`` [bytes] and ``split_duration`` [s]
    (0 = never) start a new file of the directory when the current one gets that big or that long.
    """

    def __init__(self, path: Path | str, *, flush_period: float = 1.0, split_size: int = 0,
                 split_duration: float = 0.0, chunk_size: int = CHUNK_SIZE) -> None:
        self.path = Path(path)
        self.bare = self.path.suffix == '.mcap'
        if self.bare:
            if self.path.exists():
                raise FileExistsError(f'{self.path} exists: give a new file name (a log is never overwritten)')
            self.path.parent.mkdir(parents=True, exist_ok=True)
        else:
            if self.path.exists() and not self.path.is_dir():
                raise FileExistsError(f'{self.path} exists and is not a directory: give a new directory name '
                                      '(or a file name ending in .mcap)')
            if self.path.exists() and any(self.path.iterdir()):
                raise FileExistsError(f'log directory {self.path} exists and is not empty')
            self.path.mkdir(parents=True, exist_ok=True)
        self.flush_period = flush_period
        self.split_size = 0 if self.bare else split_size
        self.split_duration_ns = 0 if self.bare else int(split_duration * 1e9)
        self.chunk_size = chunk_size
        self.custom_data: dict[str, str] = {}
        self._topics: dict[str, _Topic] = {}
        self._files: list[FileInfo] = []
        self._stream: BinaryIO | None = None
        self._writer: Writer | None = None
        self._schemas: dict[str, int] = {}
        self._last_flush = time.monotonic()
        self._since_size_check = 0
        self._open_file()

    # -- topics and messages ------------------------------------------------------------------
    def add_topic(self, topic: str, type_name: str, offered_qos_profiles: str = '') -> None:
        """Declare a topic (absolute name, ``pkg/msg/Type``, offered QoS YAML); idempotent."""
        if topic not in self._topics:
            type_name = normalize_type(type_name)
            schema_text(type_name)  # fail now, not on the first message, when the definition is missing
            self._topics[topic] = _Topic(TopicInfo(topic, type_name, offered_qos_profiles), has_header(type_name))

    @property
    def topics(self) -> dict[str, TopicInfo]:
        """Declared topics with their counts so far."""
        return {name: t.info for name, t in self._topics.items()}

    def write(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int | None = None) -> None:
        """Append one CDR message of a declared topic, received at ``log_time_ns``."""
        entry = self._topics[topic]
        file = self._files[-1]
        if self.split_duration_ns and file.message_count and \
                log_time_ns - file.start_ns >= self.split_duration_ns:
            self._next_file()
            file = self._files[-1]
        if entry.channel_id < 0:
            entry.channel_id = self._register(entry.info)
        if publish_time_ns is None:
            publish_time_ns = header_stamp_ns(data) if entry.stamped and len(data) >= 12 else log_time_ns
        self._writer.add_message(entry.channel_id, log_time_ns, data, publish_time_ns)
        entry.info.message_count += 1
        if file.message_count == 0:
            file.start_ns = log_time_ns
        file.message_count += 1
        file.duration_ns = max(file.duration_ns, log_time_ns - file.start_ns)
        self._since_size_check += 1
        if self._since_size_check >= SIZE_CHECK_EVERY:
            self._since_size_check = 0
            self._split_if_big()
        self.flush_if_due()

    def flush_if_due(self) -> bool:
        """Flush when ``flush_period`` has passed since the last flush; True when it flushed."""
        if time.monotonic() - self._last_flush < self.flush_period:
            return False
        self.flush()
        return True

    def flush(self) -> None:
        """Close the open chunk and hand everything to the OS (survives a process kill, not a power cut)."""
        self._writer.flush()
        self._last_flush = time.monotonic()
        self._split_if_big()

    def close(self) -> None:
        """Write the summary (with ``custom_data`` as the ``micro_feeder.recorder`` metadata record) and
        ``metadata.yaml``. Idempotent."""
        if self._writer is None:
            return
        self._finish_file()
        if not self.bare:
            BagMetadata(self._files, [t.info for t in self._topics.values()], self.custom_data).write(self.path)

    @property
    def files(self) -> list[Path]:
        """The MCAP files written so far."""
        return [self.path] if self.bare else [self.path / f.path for f in self._files]

    @property
    def message_count(self) -> int:
        return sum(f.message_count for f in self._files)

    # -- files ------------------------------------------------------------------------------------
    def _open_file(self) -> None:
        if self.bare:
            target, name = self.path, self.path.name
        else:
            name = f'{self.path.name}_{len(self._files)}.mcap'
            target = self.path / name
        self._stream = open(target, 'wb')  # noqa: SIM115 - lives until _finish_file
        self._writer = Writer(self._stream, chunk_size=self.chunk_size, compression=CompressionType.ZSTD,
                              enable_data_crcs=True)  # so that readers detect any changed byte
        self._writer.start(profile=Profile.ROS2, library=LIBRARY)
        self._files.append(FileInfo(name))
        self._schemas = {}
        for entry in self._topics.values():
            entry.channel_id = -1
        self._stream.flush()

    def _finish_file(self) -> None:
        if self.custom_data:
            self._writer.add_metadata(RECORDER_METADATA, dict(self.custom_data))
        self._writer.finish()
        self._stream.close()
        self._writer = None

    def _next_file(self) -> None:
        self._finish_file()
        self._open_file()

    def _split_if_big(self) -> None:
        if self.split_size and self._files[-1].message_count and self._stream.tell() >= self.split_size:
            self._next_file()

    def _register(self, info: TopicInfo) -> int:
        schema_id = self._schemas.get(info.type)
        if schema_id is None:
            schema_id = self._writer.register_schema(info.type, SchemaEncoding.ROS2,
                                                     schema_text(info.type).encode())
            self._schemas[info.type] = schema_id
        metadata = {'offered_qos_profiles': info.offered_qos_profiles} if info.offered_qos_profiles else {}
        return self._writer.register_channel(info.name, MessageEncoding.CDR, schema_id, metadata)
