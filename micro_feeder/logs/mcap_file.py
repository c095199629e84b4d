"""One MCAP file read record by record, surviving damage: what the log commands read through.

A complete file is opened through its summary (schemas, channels, chunk indexes, statistics), after
checking the summary CRC and, when the writer stored one, the data-section CRC. A file without a usable
summary (its writer was killed, or the summary is damaged) is scanned front to back. Damage never ends
the reading: a chunk that does not decompress, fails its CRC or holds unparsable records is skipped, a
record with an impossible header is skipped by resynchronising on the next chunk that checks out, and
each is reported once as a :class:`Damage` (where, what, how many messages were lost when known).
Only whole chunks are read, so a skipped chunk never yields half its messages.

Every CRC the file has is verified: the chunk CRCs when a chunk is read, the summary CRC at open, and
the data-section CRC at open (a whole-file CRC pass: 6 GB/s measured for the CRC, the disk is the limit);
a data-section mismatch triggers a scan that finds which chunk is damaged, or says that the change lies
outside the messages.
"""

from __future__ import annotations

import array
import contextlib
import heapq
import io
import itertools
import mmap
import struct
import zlib
from collections import OrderedDict
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import zstandard
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, ChunkIndex, Message, MessageIndex, Metadata, Schema, Statistics

MAGIC = b'\x89MCAP0\r\n'
HEAD = 9                    # opcode (1 byte) + record length (8 bytes)
FOOTER_LENGTH = 20          # summary start, summary offset start, summary CRC
MAX_CHUNK_BYTES = 1 << 30   # a declared uncompressed chunk size above this is damage, not data
KNOWN_OPCODES = frozenset(int(op) for op in Opcode)
RELEASE_BYTES = 1 << 22    # bytes read through a file's map between two unmappings of its pages
CHUNK_CACHE = 4            # uncompressed chunks kept (a replay reads ~4 topics side by side, each chunk once)
MESSAGE_HEAD = struct.Struct('<HIQQ')   # a message record's channel id, sequence, log time, publish time
# Parsing a damaged record can raise almost anything (struct, UTF-8, zstd, short reads, MemoryError).
PARSE_ERRORS = (Exception,)


class NotMcapError(ValueError):
    """The file does not start with the MCAP magic."""


@dataclass(frozen=True)
class Damage:
    """A damaged part of a file: byte ``offset`` (None: not one place), what is wrong, messages ``lost``
    (None: unknown)."""

    path: Path
    offset: int | None
    what: str
    lost: int | None = None

    def __str__(self) -> str:
        lost = '' if self.lost is None else f'; {self.lost} message{"s" * (self.lost != 1)} lost'
        where = '' if self.offset is None else f' at byte {self.offset:,}'
        return f'{self.path}{where}: {self.what}{lost}'


@dataclass
class ChunkRef:
    """Where a chunk (or a run of messages outside chunks) is: record offset, record length (head
    included), log-time span [ns], channel ids (None: unknown), message count (None: unknown)."""

    offset: int
    length: int
    start_ns: int
    end_ns: int
    channels: frozenset[int] | None = None
    count: int | None = None
    index_offsets: dict[int, int] = field(default_factory=dict)
    loose: list[Message] | None = None  # messages written outside chunks (no compression)


def _stream(data: bytes | memoryview) -> ReadDataStream:
    return ReadDataStream(io.BytesIO(bytes(data)))


class McapFile:
    """An MCAP file opened for damage-tolerant reading.

    ``schemas``/``channels`` by id; ``chunks`` (file order); ``counts`` per channel id of readable
    messages (from the statistics of an intact file); ``start_ns``/``end_ns``; ``metadata`` records;
    ``complete`` (a summary was read); ``truncated`` (the file ends inside a record); ``damage``.
    ``on_damage`` is called once with each new :class:`Damage`; ``progress(bytes)`` with how far the
    opening's pass over the file got (the CRC check of a complete file, the scan of one without summary);
    ``on_read(bytes)`` with the size of each chunk read afterwards.
    """

    def __init__(self, path: Path, on_damage: Callable[[Damage], None] | None = None,
                 progress: Callable[[int], None] | None = None, on_read: Callable[[int], None] | None = None) -> None:
        self.path = path
        self.on_damage = on_damage
        self.on_read = on_read
        self._progress = progress
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self.chunks: list[ChunkRef] = []
        self.counts: dict[int, int] = {}
        self.metadata: dict[str, dict[str, str]] = {}
        self.start_ns: int | None = None
        self.end_ns: int | None = None
        self.complete = False
        self.truncated = False
        self.readable_bytes = 0
        self.damage: list[Damage] = []
        self._damaged_offsets: set[int] = set()
        self._reported: set[object] = set()
        self._unreleased = 0   # bytes read through the map since its pages were last unmapped
        self._chunk_cache: OrderedDict[int, tuple[bytes, dict[int | None, array.array]]] = OrderedDict()
        with open(path, 'rb') as f:
            self.size = f.seek(0, io.SEEK_END)
            f.seek(0)
            head = f.read(len(MAGIC))
            if not MAGIC.startswith(head):
                raise NotMcapError(f'{path} is not an MCAP file (no MCAP magic at its start): not a log')
            self._map = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) if self.size else b''
        if len(head) < len(MAGIC):
            self.truncated = True
            return
        if not self._open_summary():
            self._scan()
        self._progress = None

    # -- reading ------------------------------------------------------------------------------------
    def messages(self, channel_ids: set[int] | None = None, start_ns: int | None = None,
                 end_ns: int | None = None, reverse: bool = False) -> Iterator[Message]:
        """Readable messages of ``channel_ids`` (all when None) with log time in ``[start_ns, end_ns)``,
        in log-time order (chunks whose spans overlap are merged); ``reverse`` from the end."""
        refs = [c for c in self.chunks
                if (channel_ids is None or c.channels is None or c.channels & channel_ids)
                and (start_ns is None or c.end_ns >= start_ns) and (end_ns is None or c.start_ns < end_ns)]
        refs.sort(key=lambda c: (c.start_ns, c.offset), reverse=reverse)
        group: list[ChunkRef] = []
        for ref in refs:
            if group and not self._overlap(group, ref):
                yield from self._group_messages(group, channel_ids, start_ns, end_ns, reverse)
                group = []
            group.append(ref)
        if group:
            yield from self._group_messages(group, channel_ids, start_ns, end_ns, reverse)

    @staticmethod
    def _overlap(group: list[ChunkRef], ref: ChunkRef) -> bool:
        lo, hi = min(c.start_ns for c in group), max(c.end_ns for c in group)
        return ref.start_ns <= hi and ref.end_ns >= lo

    def _group_messages(self, group: list[ChunkRef], channel_ids: set[int] | None, start_ns: int | None,
                        end_ns: int | None, reverse: bool) -> Iterator[Message]:
        lists = []
        for ref in group:
            msgs = [m for m in self.read_chunk(ref, channel_ids)
                    if (start_ns is None or m.log_time >= start_ns) and (end_ns is None or m.log_time < end_ns)]
            msgs.sort(key=lambda m: m.log_time, reverse=reverse)
            lists.append(msgs)
        if len(lists) == 1:
            yield from lists[0]
        else:
            yield from heapq.merge(*lists, key=lambda m: m.log_time, reverse=reverse)

    def read_chunk(self, ref: ChunkRef, channel_ids: set[int] | None = None) -> list[Message]:
        """The messages of one chunk (of ``channel_ids`` only, when given), or [] (and one :class:`Damage`)
        when it is damaged."""
        if ref.loose is not None:
            return [m for m in ref.loose if channel_ids is None or m.channel_id in channel_ids]
        if ref.offset in self._damaged_offsets:
            return []
        try:
            records = self._chunk_records(ref.offset, channel_ids)
        except PARSE_ERRORS as err:
            self.report(ref.offset, f'damaged chunk ({_reason(err)}), log time {ref.start_ns * 1e-9:.3f}–'
                                     f'{ref.end_ns * 1e-9:.3f} s: skipped', self._indexed_count(ref))
            return []
        return records

    # -- opening --------------------------------------------------------------------------------------
    def _open_summary(self) -> bool:
        """Read the summary of a complete file; False when it has none or it is damaged."""
        tail = self.size - len(MAGIC) - HEAD - FOOTER_LENGTH
        if tail < len(MAGIC) or self._map[self.size - len(MAGIC):] != MAGIC:
            return False
        if self._map[tail] != Opcode.FOOTER:
            return False
        summary_start, _, summary_crc = struct.unpack_from('<QQI', self._map, tail + HEAD)
        if not len(MAGIC) <= summary_start <= tail:
            return False
        if summary_start == 0:   # no summary written
            return False
        if summary_crc and zlib.crc32(self._map[summary_start:tail + HEAD + 16]) != summary_crc:
            self.report(summary_start, 'summary CRC mismatch: summary ignored, file scanned instead')
            return False
        try:
            records = list(self._records(summary_start, tail))
        except PARSE_ERRORS as err:
            self.report(summary_start, f'unreadable summary ({_reason(err)}): file scanned instead')
            return False
        stats = None
        for record in records:
            if isinstance(record, Schema):
                self.schemas[record.id] = record
            elif isinstance(record, Channel):
                self.channels[record.id] = record
            elif isinstance(record, ChunkIndex):
                self.chunks.append(ChunkRef(record.chunk_start_offset, record.chunk_length, record.message_start_time,
                                            record.message_end_time, frozenset(record.message_index_offsets),
                                            None, dict(record.message_index_offsets)))
            elif isinstance(record, Statistics):
                stats = record
        if stats is None or (stats.message_count and not self.chunks):
            return False      # no statistics, or messages outside chunks: scan to find them
        self.complete = True
        self.readable_bytes = self.size
        self.counts = dict(stats.channel_message_counts)
        if stats.message_count:
            self.start_ns, self.end_ns = stats.message_start_time, stats.message_end_time
        self.metadata = self._read_metadata(summary_start)
        if not self._data_crc_ok(summary_start):
            self._verify_chunks()
        return True

    def _data_crc_ok(self, summary_start: int) -> bool:
        """Check the data-section CRC when the writer stored one (DataEnd just before the summary)."""
        end = summary_start - HEAD - 4
        if end < len(MAGIC) or self._map[end] != Opcode.DATA_END:
            return True
        (expected,) = struct.unpack_from('<I', self._map, end + HEAD)
        return not expected or self._crc(end) == expected

    def _verify_chunks(self) -> None:
        """After a data-section CRC mismatch: find the damaged chunks, recount what is readable."""
        before = len(self.damage)
        counts: dict[int, int] = {}
        for ref in self.chunks:
            for m in self.read_chunk(ref):
                counts[m.channel_id] = counts.get(m.channel_id, 0) + 1
        self.counts = counts
        if len(self.damage) == before:
            self.report(None, 'data-section CRC mismatch outside the messages (a chunk header or index changed): '
                              'every chunk passed its own CRC and was read', 0)

    def _read_metadata(self, summary_start: int) -> dict[str, dict[str, str]]:
        out = {}
        try:
            for record in self._records(len(MAGIC), summary_start, only=Opcode.METADATA):
                out[record.name] = dict(record.metadata)
        except PARSE_ERRORS:
            pass
        return out

    def _scan(self) -> None:
        """Front-to-back read of a file without a usable summary: chunks found, counted, damage skipped."""
        pos = len(MAGIC)
        while pos + HEAD <= self.size:
            op, length = struct.unpack_from('<BQ', self._map, pos)
            end = pos + HEAD + length
            if op in (Opcode.DATA_END, Opcode.FOOTER) and end <= self.size:
                self.readable_bytes = end
                self._scanned_to_end(pos, op)
                return
            if op not in KNOWN_OPCODES or end > self.size:
                following = self._resync(pos + 1)
                if following is None:
                    self.truncated = True
                    if op not in KNOWN_OPCODES:
                        self.report(pos, 'unreadable bytes up to the end of the file (no whole chunk after them)')
                    return
                self.report(pos, f'unreadable record header (opcode {op}, length {length}): skipped '
                                  f'{following - pos:,} bytes to the next whole chunk')
                pos = following
                continue
            self._scan_record(pos, op, length)
            self._read(HEAD + length)
            if self._progress is not None and op == Opcode.CHUNK:
                self._progress(end)
            pos = end
            self.readable_bytes = pos
        self.truncated = True   # no DataEnd: the writer did not finish

    def _scanned_to_end(self, pos: int, op: int) -> None:
        """A scanned file whose data section is whole: its summary or footer is damaged or cut (a writer
        always writes them); the data-section CRC, when stored, says whether anything else changed."""
        before = len(self.damage)
        if op == Opcode.DATA_END:
            (expected,) = struct.unpack_from('<I', self._map, pos + HEAD)
            if expected and self._crc(pos) != expected and len(self.damage) == before:
                self.report(None, 'data-section CRC mismatch outside the messages (a chunk header or index '
                                  'changed): every chunk passed its own CRC and was read', 0)
        if not any('summary' in d.what for d in self.damage):
            self.report(pos + HEAD + 4, 'summary or footer damaged or cut off: messages found by scanning the '
                                        'file instead', 0)

    def _crc(self, end: int) -> int:
        """CRC-32 of the file's first ``end`` bytes, in slices of :data:`RELEASE_BYTES`."""
        crc = 0
        for lo in range(0, end, RELEASE_BYTES):
            hi = min(end, lo + RELEASE_BYTES)
            with memoryview(self._map) as view:      # no copy of the slice
                crc = zlib.crc32(view[lo:hi], crc)
            self._read(hi - lo)
            if self._progress is not None:
                self._progress(hi)
        return crc

    def _read(self, n: int) -> None:
        """Count ``n`` bytes read through the map; every :data:`RELEASE_BYTES`, unmap the pages read so far
        from this process (they stay in the page cache, and a later read maps them again): a pass over a
        long log would otherwise count the whole file, and the pages the kernel maps around those read, in
        the process's resident memory."""
        self._unreleased += n
        if self._unreleased >= RELEASE_BYTES and self.size:
            self._unreleased = 0
            with contextlib.suppress(AttributeError, OSError, ValueError):   # no madvise here: pages stay mapped
                self._map.madvise(mmap.MADV_DONTNEED)

    def _scan_record(self, pos: int, op: int, length: int) -> None:
        body = self._map[pos + HEAD:pos + HEAD + length]
        try:
            if op == Opcode.CHUNK:
                self._add_chunk(pos, HEAD + length, self._chunk_records(pos))
            elif op == Opcode.MESSAGE:
                self._add_loose(pos, Message.read(_stream(body), length))
            elif op in (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.METADATA):
                self._register(_parse(op, body, length))
        except PARSE_ERRORS as err:
            self._damaged_offsets.add(pos)
            self.report(pos, f'damaged {Opcode(op).name.lower()} record ({_reason(err)}): skipped',
                         self._index_count_after(pos, length) if op == Opcode.CHUNK else None)

    def _add_chunk(self, pos: int, length: int, records: list) -> None:
        messages = [r for r in records if isinstance(r, Message)]
        if not messages:
            return
        for m in messages:
            self.counts[m.channel_id] = self.counts.get(m.channel_id, 0) + 1
        times = [m.log_time for m in messages]
        self._extend_span(min(times), max(times))
        self.chunks.append(ChunkRef(pos, length, min(times), max(times),
                                    frozenset(m.channel_id for m in messages), len(messages)))

    def _add_loose(self, pos: int, message: Message) -> None:
        self.counts[message.channel_id] = self.counts.get(message.channel_id, 0) + 1
        self._extend_span(message.log_time, message.log_time)
        last = self.chunks[-1] if self.chunks else None
        if last is not None and last.loose is not None:
            last.loose.append(message)
            last.end_ns, last.start_ns = max(last.end_ns, message.log_time), min(last.start_ns, message.log_time)
            last.channels = last.channels | {message.channel_id}
            last.count += 1
        else:
            self.chunks.append(ChunkRef(pos, 0, message.log_time, message.log_time,
                                        frozenset({message.channel_id}), 1, loose=[message]))

    def _extend_span(self, lo: int, hi: int) -> None:
        self.start_ns = lo if self.start_ns is None else min(self.start_ns, lo)
        self.end_ns = hi if self.end_ns is None else max(self.end_ns, hi)

    def _register(self, record: object) -> None:
        if isinstance(record, Schema):
            self.schemas.setdefault(record.id, record)
        elif isinstance(record, Channel):
            self.channels.setdefault(record.id, record)
        elif isinstance(record, Metadata):
            self.metadata[record.name] = dict(record.metadata)

    def _resync(self, pos: int) -> int | None:
        """The offset of the next chunk at or after ``pos`` that reads whole (CRC checked), or None."""
        while True:
            pos = self._map.find(bytes([Opcode.CHUNK]), pos)
            if pos < 0 or pos + HEAD > self.size:
                return None
            (length,) = struct.unpack_from('<Q', self._map, pos + 1)
            if pos + HEAD + length <= self.size and self._plausible_chunk(pos, length):
                try:
                    self._chunk_records(pos)
                    return pos
                except PARSE_ERRORS:
                    pass
            pos += 1

    def _plausible_chunk(self, pos: int, length: int) -> bool:
        """A chunk header whose sizes add up to its record length (cheap test before decompressing)."""
        body = pos + HEAD
        if length < 40:
            return False
        size, _, clen = struct.unpack_from('<QII', self._map, body + 16)
        if clen > 8 or size > MAX_CHUNK_BYTES or body + 40 + clen > self.size:
            return False
        (dlen,) = struct.unpack_from('<Q', self._map, body + 32 + clen)
        return 40 + clen + dlen == length

    # -- records --------------------------------------------------------------------------------------
    def _records(self, start: int, end: int, only: int | None = None) -> Iterator[object]:
        pos = start
        while pos < end:
            op, length = struct.unpack_from('<BQ', self._map, pos)
            if pos + HEAD + length > end:
                raise ValueError(f'record at byte {pos} runs past its section')
            if only is None or op == only:
                record = _parse(op, self._map[pos + HEAD:pos + HEAD + length], length)
                if record is not None:
                    yield record
            pos += HEAD + length
            self._read(HEAD + length)

    def _chunk_records(self, pos: int, channel_ids: set[int] | None = None) -> list[Message]:
        """The messages (of ``channel_ids`` only, when given) of the chunk record at ``pos``, in record order;
        raises on any damage of the chunk (:meth:`_chunk`)."""
        raw, offsets = self._chunk(pos)
        if channel_ids is None:
            at = offsets[None]
        else:
            lists = [offsets[c] for c in channel_ids if c in offsets]
            at = lists[0] if len(lists) == 1 else sorted(itertools.chain.from_iterable(lists))
        out = []
        for inner in at:
            (rlen,) = struct.unpack_from('<Q', raw, inner + 1)
            channel_id, sequence, log_time, publish_time = MESSAGE_HEAD.unpack_from(raw, inner + HEAD)
            out.append(Message(channel_id=channel_id, log_time=log_time,
                               data=raw[inner + HEAD + MESSAGE_HEAD.size:inner + HEAD + rlen],
                               publish_time=publish_time, sequence=sequence))
        return out

    def _chunk(self, pos: int) -> tuple[bytes, dict[int | None, array.array]]:
        """The uncompressed chunk at ``pos`` and where its message records start (per channel id, and all
        under None), from a cache of the last :data:`CHUNK_CACHE` chunks read: the readers of several
        topics that a replay runs side by side read each chunk once."""
        cached = self._chunk_cache.get(pos)
        if cached is None:
            cached = self._chunk_cache[pos] = self._read_chunk_record(pos)
            if self.on_read is not None:
                self.on_read(HEAD + struct.unpack_from('<Q', self._map, pos + 1)[0])
            while len(self._chunk_cache) > CHUNK_CACHE:
                self._chunk_cache.popitem(last=False)
        else:
            self._chunk_cache.move_to_end(pos)
        return cached

    def _read_chunk_record(self, pos: int) -> tuple[bytes, dict[int | None, array.array]]:
        """Decompress, CRC-check and walk the chunk record at ``pos`` (its schema, channel and metadata
        records registered); raises on any damage."""
        op, length = struct.unpack_from('<BQ', self._map, pos)
        if op != Opcode.CHUNK or pos + HEAD + length > self.size:
            raise ValueError('no chunk record at its indexed offset')
        body = self._map[pos + HEAD:pos + HEAD + length]
        self._read(HEAD + length)
        if length < 40:
            raise ValueError('chunk record too short')
        size, crc, clen = struct.unpack_from('<QII', body, 16)
        if clen > 8 or size > MAX_CHUNK_BYTES:
            raise ValueError(f'impossible chunk header (uncompressed size {size})')
        compression = bytes(body[32:32 + clen]).decode()
        (dlen,) = struct.unpack_from('<Q', body, 32 + clen)
        data = body[40 + clen:40 + clen + dlen]
        if len(data) != dlen:
            raise ValueError('chunk data runs past its record')
        if compression == 'zstd':
            raw = zstandard.ZstdDecompressor().decompress(bytes(data), max_output_size=size)
        elif compression == '':
            raw = bytes(data)
        elif compression == 'lz4':
            import lz4.frame
            raw = lz4.frame.decompress(bytes(data))
        else:
            raise ValueError(f'unknown compression {compression!r}')
        if len(raw) != size:
            raise ValueError(f'decompressed to {len(raw)} bytes, header says {size}')
        if crc and zlib.crc32(raw) != crc:
            raise ValueError('CRC mismatch')
        offsets: dict[int | None, array.array] = {None: array.array('Q')}
        every = offsets[None]
        inner = 0
        while inner < len(raw):
            op, rlen = struct.unpack_from('<BQ', raw, inner)
            if inner + HEAD + rlen > len(raw):
                raise ValueError('record runs past the chunk')
            if op == Opcode.MESSAGE:      # the bulk of a log: only located here, read by _chunk_records
                if rlen < MESSAGE_HEAD.size:
                    raise ValueError('message record too short')
                (channel_id,) = struct.unpack_from('<H', raw, inner + HEAD)
                channel = offsets.get(channel_id)
                if channel is None:
                    channel = offsets[channel_id] = array.array('Q')
                channel.append(inner)
                every.append(inner)
            else:
                record = _parse(op, memoryview(raw)[inner + HEAD:inner + HEAD + rlen], rlen)
                if record is not None:
                    self._register(record)
            inner += HEAD + rlen
        return raw, offsets

    def _indexed_count(self, ref: ChunkRef) -> int | None:
        """How many messages a chunk held, from its message index records (None when unreadable)."""
        if ref.count is not None:
            return ref.count
        total = 0
        try:
            for offset in ref.index_offsets.values():
                op, length = struct.unpack_from('<BQ', self._map, offset)
                if op != Opcode.MESSAGE_INDEX:
                    return None
                total += len(MessageIndex.read(_stream(self._map[offset + HEAD:offset + HEAD + length])).records)
        except PARSE_ERRORS:
            return None
        return total

    def _index_count_after(self, pos: int, length: int) -> int | None:
        """Messages of a damaged chunk counted from the message index records that follow it."""
        total, offset = 0, pos + HEAD + length
        try:
            while offset + HEAD <= self.size:
                op, rlen = struct.unpack_from('<BQ', self._map, offset)
                if op != Opcode.MESSAGE_INDEX or offset + HEAD + rlen > self.size:
                    break
                total += len(MessageIndex.read(_stream(self._map[offset + HEAD:offset + HEAD + rlen])).records)
                offset += HEAD + rlen
        except PARSE_ERRORS:
            return None
        return total or None

    def report(self, offset: int | None, what: str, lost: int | None = None, key: object = None) -> None:
        """Record (once per ``key``, default the offset) and announce one damaged part."""
        key = offset if key is None else key
        if key in self._reported:
            return
        self._reported.add(key)
        if offset is not None:
            self._damaged_offsets.add(offset)
        damage = Damage(self.path, offset, what, lost)
        self.damage.append(damage)
        if self.on_damage is not None:
            self.on_damage(damage)


def _parse(op: int, body: bytes | memoryview, length: int) -> object | None:
    """The record of opcode ``op`` from its ``body`` (None for a kind not needed here)."""
    stream = _stream(body)
    if op == Opcode.MESSAGE:
        if length < 22:
            raise ValueError('message record too short')
        return Message.read(stream, length)
    if op == Opcode.SCHEMA:
        return Schema.read(stream)
    if op == Opcode.CHANNEL:
        return Channel.read(stream)
    if op == Opcode.CHUNK_INDEX:
        return ChunkIndex.read(stream)
    if op == Opcode.STATISTICS:
        return Statistics.read(stream)
    if op == Opcode.METADATA:
        return Metadata.read(stream)
    return None


def _reason(err: BaseException) -> str:
    text = str(err) or type(err).__name__
    return text if len(text) < 80 else text[:77] + '...'
