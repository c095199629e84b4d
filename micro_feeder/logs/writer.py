"""Writing logs: MCAP with the ROS 2 profile in a rosbag2 directory, crash-safe by periodic flushes.

Messages are CDR bytes as they came off the wire (no decode). Log time is the receive time given by the
caller; publish time is the message's ``header.stamp`` when its type starts with a ``std_msgs/Header``,
else the log time. Chunks are zstd-compressed; the open chunk is closed and written out at least every
``flush_period`` seconds (checked on every write and by :meth:`LogWriter.flush_if_due`), so a killed
process loses at most that much. :meth:`LogWriter.close` writes the MCAP summary and ``metadata.yaml``.

With ``stop_on_error`` (the recorder), a failure to write (any ``OSError``: disk full, file too large, an
I/O error) or a log file deleted or moved under the writer (checked at every flush and at most every
``CHECK_PERIOD`` s) does not raise: the writer stops, cuts the file back to its last whole chunk, finishes it
there (summary and footer, so every reader opens it) with a ``micro_feeder.recorder`` record saying where
and why the recording ended, writes ``metadata.yaml`` the same way, and keeps the :class:`WriteFault` in
:attr:`LogWriter.fault`; later writes are ignored. A deleted file (a removed log directory) is first
restored from the still-open file. To have room for that on a full disk, a directory log holds a
``RESERVE_BYTES`` file (``.reserve``) that is removed when the log is closed or fails.
"""

from __future__ import annotations

import contextlib
import errno
import os
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from mcap.records import Channel, Schema
from mcap.well_known import MessageEncoding, Profile, SchemaEncoding
from mcap.writer import CompressionType

from ..interface.stamps import header_stamp_ns
from .mcap_fast import FastWriter
from .mcap_sink import McapSink
from .metadata import BagMetadata, FileInfo, TopicInfo
from .schemas import has_header, normalize_type, schema_text

RECORDER_METADATA = 'micro_feeder.recorder'
LIBRARY = 'micro_feeder'
CHUNK_SIZE = 1 << 20
SIZE_CHECK_EVERY = 1000  # messages between two checks of the file size for splitting
CHECK_PERIOD = 0.25      # s: at most this often, check that the log file is still where it was written
REMOVAL_SETTLE = 0.5     # s: a log file deleted in a directory still there: wait this long for the directory to go
REMOVAL_POLL = 0.01      # s: and look this often (a directory removal unlinks the files first)
RESERVE_FILE = '.reserve'
RESERVE_BYTES = 1 << 20  # room freed on a full disk to finish the log (its summary grows ~250 B per chunk)
MAX_CHUNKS_DROPPED = 3   # whole chunks a file at its size limit may lose to make room for its summary
STAMPS_KEPT = 8 * (MAX_CHUNKS_DROPPED + 1)   # (chunks, last stamp) pairs kept: a fault cuts back that far at most

# Keys of the recorder metadata record (and metadata.yaml custom_data) of a log whose recording stopped early.
STOPPED_EARLY = 'stopped_early'          # 'true'
STOP_REASON = 'stop_reason'              # one phrase: 'No space left on device', 'log directory removed'
STOP_DETAIL = 'stop_detail'              # what failed, where
STOPPED_AT_NS = 'stopped_at_ns'          # log time [ns] (wall clock) the fault was found
READABLE_UNTIL_NS = 'readable_until_ns'  # log time [ns] of the last message kept
READABLE_UNTIL_STAMP_NS = 'readable_until_stamp_ns'   # header stamp [ns] of the last kept message of stamp_topic
STOPPED_AT_STAMP_NS = 'stopped_at_stamp_ns'           # header stamp [ns] of the last message of stamp_topic received
CUT_MESSAGES = 'messages_cut'            # messages written after the last whole chunk, cut off with it
FILES_LOST = 'files_lost'                # earlier files of the log removed with its directory


@dataclass
class WriteFault:
    """Why and where a recording stopped early: ``reason`` (one phrase), ``detail`` (what failed on which
    file), log times [ns] of the fault and of the last message kept, the header stamps [ns] of the
    ``stamp_topic`` there (None: unknown), messages kept and cut off, and whether the log could be finished
    (``finished``: summary and footer written; else readable up to its last whole chunk by a scanning
    reader) and ``metadata.yaml`` written."""

    reason: str
    detail: str
    at_ns: int
    readable_until_ns: int | None = None
    at_stamp_ns: int | None = None
    readable_until_stamp_ns: int | None = None
    kept: int = 0
    cut: int = 0
    files_lost: int = 0
    finished: bool = False
    metadata_written: bool = False
    problems: str = ''

    def record(self) -> dict[str, str]:
        """The keys this adds to the recorder metadata record and ``metadata.yaml``."""
        out = {STOPPED_EARLY: 'true', STOP_REASON: self.reason, STOP_DETAIL: self.detail,
               STOPPED_AT_NS: str(self.at_ns), CUT_MESSAGES: str(self.cut)}
        if self.readable_until_ns is not None:
            out[READABLE_UNTIL_NS] = str(self.readable_until_ns)
        if self.readable_until_stamp_ns is not None:
            out[READABLE_UNTIL_STAMP_NS] = str(self.readable_until_stamp_ns)
        if self.at_stamp_ns is not None:
            out[STOPPED_AT_STAMP_NS] = str(self.at_stamp_ns)
        if self.files_lost:
            out[FILES_LOST] = str(self.files_lost)
        return out


def _reason(err: OSError) -> str:
    """The phrase a user knows for an OSError: its strerror ('No space left on device')."""
    if err.errno is not None and err.strerror:
        return err.strerror
    return str(err) or type(err).__name__


@dataclass
class _Topic:
    """A topic registered with the writer: its MCAP channel metadata and running count."""

    info: TopicInfo
    stamped: bool
    channel_id: int = -1  # in the current file, -1 until first written there
    in_file: int = 0      # messages written to the current file


class LogWriter:
    """Writes a log: a rosbag2 directory (``metadata.yaml`` + ``<dir>_<i>.mcap``), or a bare ``.mcap``
    file when ``path`` ends in ``.mcap`` (no split then).

    ``flush_period`` [s] bounds what a crash loses; ``split_size`` [bytes] and ``split_duration`` [s]
    (0 = never) start a new file of the directory when the current one gets that big or that long.
    ``stop_on_error``: a write failure or a vanished log file stops the recording (module docstring)
    instead of raising; ``stamp_topic`` names the topic whose header stamps say how far the log reaches
    (sim time), and ``metadata`` (called when a file is finished) gives key/values for the recorder
    metadata record and ``metadata.yaml``, on top of ``custom_data``.
    """

    def __init__(self, path: Path | str, *, flush_period: float = 1.0, split_size: int = 0,
                 split_duration: float = 0.0, chunk_size: int = CHUNK_SIZE, stop_on_error: bool = False,
                 stamp_topic: str | None = None, metadata: Callable[[], dict[str, str]] | None = None) -> None:
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
        self.stop_on_error = stop_on_error
        self.stamp_topic = stamp_topic
        self.metadata = metadata
        self.custom_data: dict[str, str] = {}
        self.fault: WriteFault | None = None
        self.ignored = 0      # messages given after the recording stopped
        self._topics: dict[str, _Topic] = {}
        self._files: list[FileInfo] = []
        self._sink: McapSink | None = None
        self._writer: FastWriter | None = None
        self._schemas: dict[str, int] = {}
        self._last_flush = self._last_check = time.monotonic()
        self._since_size_check = 0
        self._pending_stamp: int | None = None  # the last stamp_topic stamp written
        # (whole chunks of the current file, last stamp in them): the recent ones, all a fault can cut back to
        self._stamps: deque[tuple[int, int]] = deque(maxlen=STAMPS_KEPT)
        self._file_start_stamp: int | None = None   # the last stamp in the files before the current one
        self._safe_chunks = 0
        self._reserve = None if self.bare or not stop_on_error else self.path / RESERVE_FILE
        if self._reserve is not None:
            self._make_reserve()
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

    def write(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int | None = None) -> bool:
        """Append one CDR message of a declared topic, received at ``log_time_ns``; False when the
        recording has stopped (:attr:`fault`; only with ``stop_on_error``, else OSError is raised)."""
        if self.fault is not None:
            self.ignored += 1
            return False
        try:
            self._write(topic, data, log_time_ns, publish_time_ns)
        except OSError as err:
            self._failed(err, f'writing {self._current_name()}')
        return self.fault is None

    def flush_if_due(self) -> bool:
        """Flush when ``flush_period`` has passed since the last flush, and (``stop_on_error``) see that
        the file is still there, at most every ``CHECK_PERIOD`` s; True when it flushed."""
        if self.fault is not None:
            return False
        now = time.monotonic()
        if self.stop_on_error and now - self._last_check >= CHECK_PERIOD:
            self._last_check = now
            if self.check() is not None:
                return False
        if now - self._last_flush < self.flush_period:
            return False
        self.flush()
        return self.fault is None

    def flush(self) -> None:
        """Close the open chunk and hand everything to the OS (survives a process kill, not a power cut)."""
        if self.fault is not None:
            return
        try:
            self._writer.flush()
            self._kept()
            self._last_flush = time.monotonic()
            self._split_if_big()
        except OSError as err:
            self._failed(err, f'writing {self._current_name()}')

    def check(self) -> WriteFault | None:
        """With ``stop_on_error``: stop the recording when the log file was deleted (its directory
        removed: the file is restored up to its last whole chunk) or moved; returns :attr:`fault`."""
        if self.fault is not None or self._sink is None or not self.stop_on_error:
            return self.fault
        try:
            deleted = self._sink.deleted()
            moved = not deleted and self._sink.moved()
        except OSError as err:
            self._failed(err, f'checking {self._current_name()}')
            return self.fault
        if deleted:
            gone = not self.bare and self._directory_removed()
            what = 'log directory removed' if gone else 'log file deleted'
            self._stop(what, f'{self.path if gone else self._sink.path} was {"removed" if gone else "deleted"} '
                             'while recording', restore=True)
        elif moved:
            self._stop('log file moved', f'{self._sink.path} was moved or replaced while recording (the moved '
                                         'file was finished where it is now)', restore=False)
        return self.fault

    def _directory_removed(self) -> bool:
        """True when the log directory goes within ``REMOVAL_SETTLE`` s: a directory removal unlinks the files
        before the directory, and restoring the file in between would leave the remover a directory that is not
        empty (``rm -r`` fails) and the log named as a deleted file."""
        deadline = time.monotonic() + REMOVAL_SETTLE
        while self.path.is_dir():
            if time.monotonic() >= deadline:
                return False
            time.sleep(REMOVAL_POLL)
        return True

    def stop(self, reason: str, detail: str) -> WriteFault | None:
        """Stop recording now for a reason found outside the writer (storage not responding ...): the log is
        kept up to its last whole chunk and finished there, as after a write failure. Idempotent; nothing
        happens to a log already closed (returns :attr:`fault`, None after a clean close)."""
        if self.fault is None and self._writer is not None:
            self._stop(reason, detail, restore=False)
        return self.fault

    def note_progress(self, fault: WriteFault) -> WriteFault:
        """Fill in what is readable so far (messages in whole chunks, where they end) without changing
        anything: for a fault found outside the writer while its thread is blocked in a write."""
        sink = self._sink
        files = list(self._files)
        earlier = files[:-1] if sink is not None else files
        fault.kept = sum(f.message_count for f in earlier) + (sink.safe_messages if sink is not None else 0)
        span = sink.safe_span if sink is not None else None
        ends = [f.start_ns + f.duration_ns for f in earlier if f.message_count]
        fault.readable_until_ns = span[1] if span is not None else max(ends, default=None)
        chunks = sink.safe_chunks if sink is not None else 0
        fault.readable_until_stamp_ns = next((stamp for n, stamp in reversed(list(self._stamps)) if n <= chunks),
                                             self._file_start_stamp)
        return fault

    @property
    def last_stamp_ns(self) -> int | None:
        """The header stamp [ns] of the last ``stamp_topic`` message written (None: none yet)."""
        return self._pending_stamp

    def close(self) -> None:
        """Write the summary (with ``custom_data`` as the ``micro_feeder.recorder`` metadata record) and
        ``metadata.yaml``. Idempotent; after a fault the log was finished then, and nothing is written."""
        if self._writer is None:
            return
        if self.stop_on_error and self.check() is not None:
            return
        try:
            self._finish_file()
            if not self.bare:
                BagMetadata(self._files, [t.info for t in self._topics.values()], self._custom()).write(self.path)
            self._drop_reserve()
        except OSError as err:
            if not self.stop_on_error:
                raise
            self._failed(err, f'closing {self._current_name()}')

    @property
    def files(self) -> list[Path]:
        """The MCAP files written so far."""
        return [self.path] if self.bare else [self.path / f.path for f in self._files]

    @property
    def message_count(self) -> int:
        return sum(f.message_count for f in self._files)

    @property
    def start_ns(self) -> int | None:
        """Log time [ns] of the first message written (None: none yet)."""
        return min((f.start_ns for f in list(self._files) if f.message_count), default=None)

    # -- files ------------------------------------------------------------------------------------
    def _write(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int | None) -> None:
        entry = self._topics[topic]
        file = self._files[-1]
        if self.split_duration_ns and file.message_count and \
                log_time_ns - file.start_ns >= self.split_duration_ns:
            self._next_file()
            if self.fault is not None:
                self.ignored += 1
                return
            file = self._files[-1]
        if entry.channel_id < 0:
            entry.channel_id = self._register(entry.info)
        if publish_time_ns is None:
            publish_time_ns = header_stamp_ns(data) if entry.stamped and len(data) >= 12 else log_time_ns
        self._writer.add_message(entry.channel_id, log_time_ns, data, publish_time_ns)
        entry.info.message_count += 1
        entry.in_file += 1
        if topic == self.stamp_topic:
            self._pending_stamp = publish_time_ns
        if file.message_count == 0:
            file.start_ns = log_time_ns
        file.message_count += 1
        file.duration_ns = max(file.duration_ns, log_time_ns - file.start_ns)
        if self._sink.safe_chunks != self._safe_chunks:   # a full chunk went out with this message
            self._kept()
        self._since_size_check += 1
        if self._since_size_check >= SIZE_CHECK_EVERY:
            self._since_size_check = 0
            self._split_if_big()
        self.flush_if_due()

    def _kept(self) -> None:
        """Everything written so far is in whole chunks on disk (after a flush, or a chunk that filled). The
        sink keeps what the summary needs of them; mcap's Writer's list of chunk indexes, which only its
        finish() reads (never called: :meth:`_finish_file`), is emptied so that it does not grow for hours."""
        getattr(self._writer, '_Writer__chunk_indices', []).clear()
        self._safe_chunks = self._sink.safe_chunks
        if self._pending_stamp is not None and (not self._stamps or self._stamps[-1][1] != self._pending_stamp):
            self._stamps.append((self._safe_chunks, self._pending_stamp))

    def _current_name(self) -> str:
        return str(self._sink.path) if self._sink is not None else str(self.path)

    def _open_file(self) -> None:
        if self.bare:
            target, name = self.path, self.path.name
        else:
            name = f'{self.path.name}_{len(self._files)}.mcap'
            target = self.path / name
        self._sink = McapSink(target)
        self._writer = FastWriter(self._sink, chunk_size=self.chunk_size, compression=CompressionType.ZSTD,
                                  enable_data_crcs=True)  # so that readers detect any changed byte
        self._files.append(FileInfo(name))
        self._schemas = {}
        self._safe_chunks = 0
        self._file_start_stamp = self._pending_stamp
        self._stamps = deque(maxlen=STAMPS_KEPT)
        for entry in self._topics.values():
            entry.channel_id = -1
            entry.in_file = 0
        self._writer.start(profile=Profile.ROS2, library=LIBRARY)

    def _custom(self) -> dict[str, str]:
        data = dict(self.custom_data)
        if self.metadata is not None:
            data.update(self.metadata())
        if self.fault is not None:
            data.update(self.fault.record())
        return data

    def _finish_file(self) -> None:
        """Close the last chunk and end the file with the sink's summary (the one a failed file gets too:
        mcap's Writer's own would need every chunk's index kept as objects, ~2 kB a chunk)."""
        data = self._custom()
        self._writer.flush()
        self._kept()
        self._sink.finish_at_safe_point({RECORDER_METADATA: data} if data else {})
        self._sink.close()
        self._writer = None

    def _next_file(self) -> None:
        if self.stop_on_error and self.check() is not None:   # not into a removed directory
            return
        self._finish_file()
        self._open_file()

    def _split_if_big(self) -> None:
        if self.split_size and self._files[-1].message_count and self._sink.tell() >= self.split_size:
            self._next_file()

    def _register(self, info: TopicInfo) -> int:
        schema_id = self._schemas.get(info.type)
        if schema_id is None:
            data = schema_text(info.type).encode()
            schema_id = self._writer.register_schema(info.type, SchemaEncoding.ROS2, data)
            self._sink.add_schema(Schema(id=schema_id, name=info.type, encoding=SchemaEncoding.ROS2, data=data))
            self._schemas[info.type] = schema_id
        metadata = {'offered_qos_profiles': info.offered_qos_profiles} if info.offered_qos_profiles else {}
        channel_id = self._writer.register_channel(info.name, MessageEncoding.CDR, schema_id, metadata)
        self._sink.add_channel(Channel(id=channel_id, topic=info.name, message_encoding=MessageEncoding.CDR,
                                       schema_id=schema_id, metadata=metadata))
        return channel_id

    # -- stopping early -----------------------------------------------------------------------------
    def _make_reserve(self) -> None:
        """Set room aside for finishing the log on a full disk (none when there is no room already)."""
        try:
            fd = os.open(self._reserve, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
            try:
                os.posix_fallocate(fd, 0, RESERVE_BYTES)
            finally:
                os.close(fd)
        except OSError:
            self._drop_reserve()

    def _drop_reserve(self) -> None:
        if self._reserve is not None:
            with contextlib.suppress(OSError):
                self._reserve.unlink()
            self._reserve = None

    def _failed(self, err: OSError, action: str) -> None:
        """A write failed: stop (with ``stop_on_error``) or raise."""
        if not self.stop_on_error:
            raise err
        code = f', errno {errno.errorcode.get(err.errno, err.errno)}' if err.errno else f': {err}'
        self._stop(_reason(err), f'{action}{code}', restore=False)

    def _stop(self, reason: str, detail: str, restore: bool) -> None:
        """Stop recording: keep the current file up to its last whole chunk, finished there, and write
        metadata.yaml, as far as the disk allows; :attr:`fault` says why and what was kept."""
        self._drop_reserve()   # room for the summary and metadata.yaml on a full disk
        fault = self.fault = WriteFault(reason, detail, time.time_ns(), at_stamp_ns=self._pending_stamp)
        problems = []
        sink, file = self._sink, self._files[-1]
        self._writer = self._sink = None
        if sink is not None and sink.fd < 0:
            sink = None    # between two files: the last one is finished, the next one not open
        if not self.bare:
            lost = [f for f in self._files if f is not file and not (self.path / f.path).is_file()]
            fault.files_lost = len(lost)
            self._files = [f for f in self._files if f not in lost]
        if sink is not None and restore:
            try:
                (self.path.parent if self.bare else self.path).mkdir(parents=True, exist_ok=True)
                sink.restore()
            except OSError as err:
                problems.append(f'the log could not be restored ({_reason(err)}): it is lost')
                _close(sink)
                self._files.remove(file)
                sink = None
        if sink is not None and not sink.safe_position:    # the failure came before anything whole
            _close(sink)
            with contextlib.suppress(OSError):
                sink.path.unlink()
            self._files.remove(file)
            sink = None
        if sink is not None:
            error: OSError | None = None
            for _ in range(MAX_CHUNKS_DROPPED + 1):   # a file at its size limit: make room for the summary
                self._account(sink, file)
                try:
                    sink.finish_at_safe_point({RECORDER_METADATA: self._custom()})
                    fault.finished = True
                    break
                except OSError as err:
                    error = err
                    if not sink.drop_last_chunk():
                        break
            if not fault.finished:
                self._account(sink, file)
                problems.append(f'its summary could not be written ({_reason(error)}): readable up to its last '
                                'whole chunk all the same (micro-feeder info; recover rewrites it)')
            _close(sink)
        fault.kept = sum(f.message_count for f in self._files)
        if fault.readable_until_ns is None:
            fault.readable_until_ns = max((f.start_ns + f.duration_ns for f in self._files if f.message_count),
                                          default=None)
        if not self.bare and self._files:
            try:
                BagMetadata(self._files, [t.info for t in self._topics.values()], self._custom()).write(self.path)
                fault.metadata_written = True
            except OSError as err:
                problems.append(f'metadata.yaml could not be written ({_reason(err)})')
        fault.problems = '; '.join(problems)

    def _account(self, sink: McapSink, file: FileInfo) -> None:
        """Counts and times of the current file cut back to its safe point; what was cut and where the log
        now ends go in :attr:`fault`."""
        fault = self.fault
        counts = sink.safe_counts
        kept_total = 0
        for entry in self._topics.values():
            kept = counts.get(entry.channel_id, 0) if entry.channel_id >= 0 else 0
            entry.info.message_count -= entry.in_file - kept
            entry.in_file = kept
            kept_total += kept
        fault.cut += file.message_count - kept_total
        file.message_count = kept_total
        span = sink.safe_span
        if span is not None:
            file.start_ns, file.duration_ns = span[0], span[1] - span[0]
            fault.readable_until_ns = span[1]
        else:
            file.duration_ns = 0
            earlier = [f.start_ns + f.duration_ns for f in self._files if f is not file and f.message_count]
            fault.readable_until_ns = max(earlier, default=None)
        chunks = sink.safe_chunks
        earlier = None if fault.files_lost else self._file_start_stamp   # the last stamp in the earlier files
        fault.readable_until_stamp_ns = next((stamp for n, stamp in reversed(self._stamps) if n <= chunks), earlier)


def _close(sink: McapSink) -> None:
    with contextlib.suppress(OSError):
        sink.close()
