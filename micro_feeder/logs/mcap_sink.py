"""The file an MCAP writer writes to, kept so that a file whose writing failed can still be finished.

:class:`McapSink` is the stream given to ``mcap.writer.Writer``: every write goes straight to the file
descriptor (no buffer that a failed write would leave half-flushed), and what a summary needs of the bytes
that reached the file is kept as they go by: the message counts per channel (from the message indexes), the
data-section CRC, the number of chunks and the time span they cover, and what cutting the file back needs of
the last :data:`RECENT_CHUNKS` chunks. The chunk indexes themselves are not kept: the summary reads them back
from the file (each chunk's header and message index records, never its data) when the file is finished, so
the memory used stays the same whatever the log's length (a 1 MiB chunk goes out every ~0.2 s at 1 kHz).
The *safe point* is the end of the last record group that reached the file whole (a chunk with its message
indexes). When a write fails (disk full, file too large, I/O
error) or the file is deleted under the writer, :meth:`McapSink.finish_at_safe_point` cuts the file back
to the safe point (freeing what the failed chunk took) and writes a metadata record, the data end, a
summary and the footer there, or :meth:`McapSink.restore` first copies the safe prefix of a deleted file
(still open, so still readable) to its path again. The result is a complete MCAP file that every reader
opens: nothing readable is lost but the chunk whose writing failed.

Schemas and channels live inside the compressed chunks, so the writer hands them over as it registers
them (:meth:`McapSink.add_schema`, :meth:`McapSink.add_channel`).
"""

from __future__ import annotations

import os
import struct
import zlib
from collections import defaultdict, deque
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Channel,
    ChunkIndex,
    DataEnd,
    Footer,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

MAGIC = b'\x89MCAP0\r\n'
HEAD = 9              # opcode (1 byte) + record length (8 bytes)
COPY_PIECE = 1 << 20  # bytes copied at a time when restoring a deleted file
CRC = struct.Struct('<I')
RECORD_HEAD = struct.Struct('<BQ')  # a record's opcode and length
CHUNK_HEAD = struct.Struct('<QQQII')  # a Chunk record's first fields: message start/end time, sizes, CRC, name length
RECENT_CHUNKS = 8     # whole chunks the safe point can be moved back over (the writer drops at most 3)


class _Chunk:
    """What moving the safe point back to a whole chunk's start needs: where it starts, the data CRC there,
    its messages per channel, and the time span of the chunks before it. Only the last :data:`RECENT_CHUNKS`
    are kept."""

    __slots__ = ('counts', 'crc_before', 'span_before', 'start_offset')

    def __init__(self, start_offset: int, crc_before: int, counts: dict[int, int],
                 span_before: tuple[int, int] | None):
        self.start_offset = start_offset
        self.crc_before = crc_before
        self.counts = tuple(counts.items())
        self.span_before = span_before


@dataclass
class _State:
    """What a summary needs of the file up to one position, in memory that does not grow with the file: the
    number of whole chunks, the span of their messages' log times, the messages per channel, the data CRC, the
    last :data:`RECENT_CHUNKS` chunks (:class:`_Chunk`); and the chunk being written (its index filled in as
    its message indexes go by, its messages per channel, the data CRC where it starts). The chunk indexes of
    the summary are read back from the file (:meth:`McapSink._chunk_indexes`)."""

    position: int = 0
    crc: int = 0
    chunk_count: int = 0
    span: tuple[int, int] | None = None
    recent: deque[_Chunk] = field(default_factory=lambda: deque(maxlen=RECENT_CHUNKS))
    counts: dict[int, int] = field(default_factory=lambda: defaultdict(int))
    open: tuple[ChunkIndex, dict[int, int], int] | None = None

    def seal(self) -> None:
        """The chunk being written is whole: count it, keep what cutting back to its start needs."""
        if self.open is not None:
            index, counts, crc_before = self.open
            self.recent.append(_Chunk(index.chunk_start_offset, crc_before, counts, self.span))
            start, end = index.message_start_time, index.message_end_time
            self.span = (start, end) if self.span is None else (min(self.span[0], start), max(self.span[1], end))
            self.chunk_count += 1
            self.open = None

    def copy(self) -> _State:
        return _State(self.position, self.crc, self.chunk_count, self.span,
                      deque(self.recent, maxlen=RECENT_CHUNKS), defaultdict(int, self.counts), None)


class McapSink:
    """An MCAP file written unbuffered, that can be finished at its last whole record group; see the module
    docstring. ``safe_messages`` counts the messages up to the safe point (all chunks written whole)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_TRUNC, 0o644)
        self._written = 0        # bytes written whole (the file offset, as mcap's Writer sees it)
        self._now = _State()     # everything written so far
        self._safe = _State()    # up to the end of the last whole record group
        self._ended = False      # a DataEnd went by: the summary follows, nothing more to track
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}

    # -- the stream interface mcap's Writer uses ------------------------------------------------------
    def write(self, data: bytes) -> int:
        view = memoryview(data)
        done = 0
        while done < len(view):
            done += os.write(self.fd, view[done:])
        self._written += len(view)
        if not self._ended and view:
            self._track(view)
        return len(view)

    def tell(self) -> int:
        return self._written

    def flush(self) -> None:
        """Nothing to do: every write went to the file descriptor."""

    def close(self) -> None:
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1

    # -- what the writer tells us --------------------------------------------------------------------
    def add_schema(self, schema: Schema) -> None:
        self.schemas[schema.id] = schema

    def add_channel(self, channel: Channel) -> None:
        self.channels[channel.id] = channel

    @property
    def safe_position(self) -> int:
        """Where the file can be finished: 0 until its header record is written."""
        return self._safe.position

    @property
    def safe_chunks(self) -> int:
        return self._safe.chunk_count

    @property
    def safe_messages(self) -> int:
        return sum(self._safe.counts.values())

    @property
    def safe_counts(self) -> dict[int, int]:
        """Messages per channel id up to the safe point."""
        return dict(self._safe.counts)

    @property
    def safe_span(self) -> tuple[int, int] | None:
        """First and last log time [ns] of the messages up to the safe point (None: none)."""
        return self._safe.span

    # -- faults --------------------------------------------------------------------------------------
    def deleted(self) -> bool:
        """True when the file has no name left (deleted, or its directory removed): writes still succeed,
        into a file nobody will find."""
        return os.fstat(self.fd).st_nlink == 0

    def moved(self) -> bool:
        """True when the file's path no longer names it (moved or replaced) while it still has a name."""
        try:
            here = os.stat(self.path)
        except FileNotFoundError:
            return True
        mine = os.fstat(self.fd)
        return (here.st_dev, here.st_ino) != (mine.st_dev, mine.st_ino)

    def restore(self) -> None:
        """Copy the file up to its safe point to its path again (a new file; the deleted one, still open,
        is read through its descriptor), and go on with the copy. Raises OSError (FileExistsError when
        something else took the path meanwhile)."""
        old, end = self.fd, self._safe.position
        new = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o644)
        try:
            at = 0
            while at < end:
                piece = memoryview(os.pread(old, min(COPY_PIECE, end - at), at))
                if not piece:
                    raise OSError(f'{self.path}: the deleted file ends at byte {at:,}, before its last whole chunk')
                while piece:
                    done = os.pwrite(new, piece, at)
                    at += done
                    piece = piece[done:]
        except BaseException:
            os.close(new)
            raise
        os.close(old)
        self.fd = new

    def drop_last_chunk(self) -> bool:
        """Move the safe point back to the start of the last whole chunk (to make room for the summary in
        a file that has reached its size limit); False when there is no chunk left, or the safe point was moved
        back over the last :data:`RECENT_CHUNKS` already."""
        safe = self._safe
        if not safe.recent:
            return False
        chunk = safe.recent.pop()
        safe.position, safe.crc, safe.span = chunk.start_offset, chunk.crc_before, chunk.span_before
        safe.chunk_count -= 1
        for channel, n in chunk.counts:
            safe.counts[channel] -= n
        return True

    def finish_at_safe_point(self, metadata: dict[str, dict[str, str]]) -> None:
        """Cut the file back to its safe point and finish it there: ``metadata`` records (name -> key/values),
        the data end, a summary (schemas, channels, statistics, chunk and metadata indexes) and the footer.
        Raises OSError when that cannot be written (the file is then cut back to the safe point again:
        readable up to there by a reader that scans; :meth:`drop_last_chunk` makes room)."""
        safe = self._safe
        os.ftruncate(self.fd, safe.position)
        os.lseek(self.fd, safe.position, os.SEEK_SET)
        self._now = safe.copy()
        self._written = safe.position
        self._ended = True
        try:
            self._write_end(safe, metadata)
        except OSError:
            os.ftruncate(self.fd, safe.position)
            raise

    # -- internals -----------------------------------------------------------------------------------
    def _pread(self, size: int, at: int) -> bytes:
        data = os.pread(self.fd, size, at)
        if len(data) < size:
            raise OSError(f'{self.path}: ends at byte {at + len(data):,}, before its last whole chunk')
        return data

    def _chunk_indexes(self, end: int) -> Iterator[ChunkIndex]:
        """The ChunkIndex of every chunk before ``end`` (the safe point), read back from the file: each chunk
        record's header and the head of each of its message index records (the records after it), never
        their data. Raises OSError."""
        pos, index = len(MAGIC), None
        while pos + HEAD <= end:
            op, length = RECORD_HEAD.unpack(self._pread(HEAD, pos))
            body = pos + HEAD
            if op == Opcode.CHUNK:
                if index is not None:
                    yield index
                head = self._pread(min(length, CHUNK_HEAD.size + 64), body)
                start, stop, size, _crc, name_length = CHUNK_HEAD.unpack_from(head)
                if len(head) < CHUNK_HEAD.size + name_length + 8:
                    head = self._pread(CHUNK_HEAD.size + name_length + 8, body)
                compression = head[CHUNK_HEAD.size:CHUNK_HEAD.size + name_length].decode()
                (records_length,) = struct.unpack_from('<Q', head, CHUNK_HEAD.size + name_length)
                index = ChunkIndex(message_start_time=start, message_end_time=stop, chunk_start_offset=pos,
                                   chunk_length=HEAD + length, message_index_offsets={}, message_index_length=0,
                                   compression=compression, compressed_size=records_length, uncompressed_size=size)
            elif op == Opcode.MESSAGE_INDEX and index is not None:
                (channel_id,) = struct.unpack('<H', self._pread(2, body))
                index.message_index_offsets[channel_id] = pos
                index.message_index_length += HEAD + length
            pos = body + length
        if index is not None:
            yield index

    def _raw(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            view = view[os.write(self.fd, view):]

    def _write_end(self, safe: _State, metadata: dict[str, dict[str, str]]) -> None:
        at = safe.position
        data = RecordBuilder()
        indexes = []
        for name, values in metadata.items():
            start = data.count
            Metadata(name=name, metadata=dict(values)).write(data)
            indexes.append(MetadataIndex(offset=at + start, length=data.count - start, name=name))
        records = data.end()
        crc = zlib.crc32(records, safe.crc)
        end = RecordBuilder()
        DataEnd(crc).write(end)
        records += end.end()
        summary_start = at + len(records)
        summary = RecordBuilder()
        offsets = []

        def group(opcode: int, items: Iterable) -> None:
            start = summary.count
            for item in items:
                item.write(summary)
            offsets.append(SummaryOffset(group_opcode=opcode, group_start=summary_start + start,
                                         group_length=summary.count - start))

        span = safe.span or (0, 0)
        statistics = Statistics(
            message_count=sum(safe.counts.values()), schema_count=len(self.schemas),
            channel_count=len(self.channels), attachment_count=0, metadata_count=len(metadata),
            chunk_count=safe.chunk_count, message_start_time=span[0], message_end_time=span[1],
            channel_message_counts=dict(safe.counts))
        group(Opcode.SCHEMA, list(self.schemas.values()))
        group(Opcode.CHANNEL, list(self.channels.values()))
        group(Opcode.STATISTICS, [statistics])
        group(Opcode.CHUNK_INDEX, self._chunk_indexes(at))
        group(Opcode.METADATA_INDEX, indexes)
        summary_offset_start = summary_start + summary.count
        for offset in offsets:
            offset.write(summary)
        summary_data = summary.end()
        summary_crc = zlib.crc32(summary_data)
        summary_crc = zlib.crc32(struct.pack('<BQQQ', Opcode.FOOTER, 8 + 8 + 4, summary_start,
                                             summary_offset_start), summary_crc)
        footer = RecordBuilder()
        Footer(summary_start=summary_start, summary_offset_start=summary_offset_start,
               summary_crc=summary_crc).write(footer)
        self._raw(records + summary_data + footer.end() + MAGIC)

    def _track(self, view: memoryview) -> None:
        """Note what the bytes just written hold (whole records, as mcap's Writer writes them), and move
        the safe point to their end unless a chunk still waits for its message indexes."""
        now = self._now
        if now.position == 0 and bytes(view[:len(MAGIC)]) == MAGIC:
            now.crc = zlib.crc32(view[:len(MAGIC)], now.crc)
            now.position += len(MAGIC)
            view = view[len(MAGIC):]
            if not view:
                return
        base = now.position
        pos = 0
        open_chunk = False
        while pos + HEAD <= len(view):
            op, length = struct.unpack_from('<BQ', view, pos)
            body = pos + HEAD
            if op == Opcode.CHUNK:
                start, end, size = struct.unpack_from('<QQQ', view, body)
                (name_length,) = struct.unpack_from('<I', view, body + 28)
                compression = bytes(view[body + 32:body + 32 + name_length]).decode()
                (records_length,) = struct.unpack_from('<Q', view, body + 32 + name_length)
                now.seal()
                now.open = (ChunkIndex(
                    message_start_time=start, message_end_time=end, chunk_start_offset=base + pos,
                    chunk_length=HEAD + length, message_index_offsets={}, message_index_length=0,
                    compression=compression, compressed_size=records_length, uncompressed_size=size),
                    {}, zlib.crc32(view[:pos], now.crc))
                open_chunk = True
            elif op == Opcode.MESSAGE_INDEX and now.open is not None:
                channel_id, records_length = struct.unpack_from('<HI', view, body)
                chunk, counts, _ = now.open
                chunk.message_index_offsets[channel_id] = base + pos
                chunk.message_index_length += HEAD + length
                now.counts[channel_id] += records_length // 16
                counts[channel_id] = records_length // 16
                open_chunk = False
            elif op == Opcode.DATA_END:   # the writer is finishing: the data section ends here
                self._ended = True
                view = view[:pos]
                break
            pos = body + length
        now.crc = zlib.crc32(view, now.crc)
        now.position += len(view)
        if not open_chunk:
            now.seal()
            self._safe = now.copy()
