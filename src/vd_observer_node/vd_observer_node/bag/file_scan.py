"""One MCAP file of a bag, scanned record by record: the reader's engine.

:class:`FileScan` walks a memory-mapped file's data section with bounds checks and chunk CRCs
(inflating lz4 and zstd chunks), yields its messages in batches (:class:`Batch`: one chunk's
message records as arrays, without a Python object per message), loads the summary where it
is intact, and reports damage with the byte offset, strictly or, in recovery, as a list of
problems. `reader.BagReader` combines the scans of a bag's files and selects the topics.
Split from `reader` so that each stays small enough to read (#40).
"""

from __future__ import annotations

import mmap
import os
import struct
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import lz4.frame
import numpy as np
import zstandard

from vd_observer_node.bag import mcap_format as fmt
from vd_observer_node.bag.errors import (
    BagCorruptError,
    BagFormatError,
)
from vd_observer_node.bag.packed import PackedMessages, windows

__all__ = ['Batch', 'FileScan', 'map_file']

_PREFIX = fmt.RECORD_PREFIX
_MAX_CHUNK = 1 << 31  # [B] refuse to inflate a chunk claiming more (damaged size field)
#: the only opcode that is never valid: records of 0x01-0x7F (official, later versions of the
#: format) and 0x80-0xFF (application extensions) that we do not know are skipped, as the
#: specification asks; a 0x00 is damage (a zero-filled tail after a crash, typically)
_INVALID_OP = 0x00
#: [B] read pages are given back to the OS in steps of this size (bounded resident memory)
_RELEASE_STEP = 32 << 20


def map_file(file: Path) -> bytes | mmap.mmap:
    """The file's bytes, memory-mapped (b'' for an empty file, which mmap refuses)."""
    with file.open('rb') as handle:
        if os.fstat(handle.fileno()).st_size == 0:
            return b''
        return mmap.mmap(handle.fileno(), 0, access=mmap.ACCESS_READ)


_MESSAGE_FIELDS = np.dtype(
    [('channel', '<u2'), ('sequence', '<u4'), ('log', '<u8'), ('publish', '<u8')]
)  # message record body after opcode and length, unaligned (22 bytes)


@dataclass
class Batch:
    """Messages of one chunk: channel ids, log and publish times [ns] (shape (N,)), data."""

    channel: np.ndarray
    log: np.ndarray
    publish: np.ndarray
    datas: PackedMessages

    def tuples(self) -> Iterator[tuple[int, int, int, bytes]]:
        return zip(
            self.channel.tolist(),
            self.log.tolist(),
            self.publish.tolist(),
            self.datas,
            strict=True,
        )


class _Decompressors:
    def __init__(self) -> None:
        self._zstd = zstandard.ZstdDecompressor()

    def get(self, name: str) -> Callable[[memoryview, int], bytes] | None:
        if name == '':
            return lambda data, _size: bytes(data)
        if name == 'zstd':
            # Streaming: never trust a (possibly damaged) frame content size to allocate.
            return lambda data, _size: bytes(self._zstd.decompressobj().decompress(data))
        if name == 'lz4':
            return lambda data, _size: bytes(lz4.frame.decompress(bytes(data)))
        return None


class FileScan:
    """One pass over one MCAP file; yields (channel id, log ns, publish ns, data)."""

    def __init__(
        self,
        path: Path,
        buf: bytes | mmap.mmap,
        *,
        recover: bool,
        problems: list[BagCorruptError],
        schemas: dict[int, fmt.SchemaRecord],
        channels: dict[int, fmt.ChannelRecord],
    ) -> None:
        self.path = path
        self.buf = buf
        self.recover = recover
        self.problems = problems
        self.schemas = schemas
        self.channels = channels
        self.message_count = 0
        self.channel_counts: dict[int, int] = {}
        self.reached_end = False
        self._decompressors = _Decompressors()
        self._released = 0

    def _release(self, upto: int) -> None:
        """Give the mapped pages before byte ``upto`` back to the OS (they are re-read from
        the page cache if touched again), so resident memory does not grow with the file."""
        buf = self.buf
        if not isinstance(buf, mmap.mmap) or upto - self._released < _RELEASE_STEP:
            return
        start = self._released - self._released % mmap.PAGESIZE
        stop = upto - upto % mmap.PAGESIZE
        if stop > start and hasattr(buf, 'madvise'):
            buf.madvise(mmap.MADV_DONTNEED, start, stop - start)
        self._released = upto

    def _damage(self, offset: int, reason: str) -> None:
        """Report damage: raise in strict mode, collect in recover mode."""
        error = BagCorruptError(self.path, offset, reason)
        if not self.recover:
            raise error
        self.problems.append(error)

    def _parse(self, offset: int, body_offset: int, parse: Callable[[Any], Any], body: Any) -> Any:
        try:
            return parse(body)
        except fmt.MalformedRecordError as exc:
            self._damage(body_offset + exc.offset, f'malformed record at {offset}: {exc.reason}')
            return None

    def _schema(self, record: fmt.SchemaRecord | None) -> None:
        if record is not None and record.id != 0:
            self.schemas[record.id] = record

    def _channel(self, record: fmt.ChannelRecord | None, offset: int) -> None:
        if record is None:
            return
        if record.schema_id != 0 and record.schema_id not in self.schemas:
            self._damage(offset, f'channel {record.topic} refers to unknown schema')
            return
        self.channels[record.id] = record

    def messages(
        self,
        wanted: Callable[[int], bool],
        start_ns: int | None,
        stop_ns: int | None,
    ) -> Iterator[tuple[int, int, int, bytes]]:
        """Selected messages as (channel id, log ns, publish ns, data), in file order."""
        for batch in self.batches(wanted, start_ns, stop_ns):
            yield from batch.tuples()

    def batches(
        self,
        wanted: Callable[[int], bool],
        start_ns: int | None,
        stop_ns: int | None,
    ) -> Iterator[Batch]:
        """Selected messages chunk by chunk (one batch per chunk): less per-message overhead."""
        buf = self.buf
        size = len(buf)
        if buf[:8] != fmt.MAGIC:
            raise BagFormatError(f'{self.path}: not an MCAP file (bad magic)')
        pos = 8
        while True:
            if pos + _PREFIX.size > size:
                self._damage(pos, 'file ends before the data end record (writer killed?)')
                return
            op, length = _PREFIX.unpack_from(buf, pos)
            body_at = pos + _PREFIX.size
            end = body_at + length
            if op == _INVALID_OP:
                self._damage(pos, f'invalid record opcode 0x{op:02x}')
                return
            if end > size:
                self._damage(pos, f'record of {length} bytes runs past the end of the file')
                return
            body = memoryview(buf)[body_at:end]
            if op == fmt.Op.CHUNK:
                chunk = self._parse(pos, body_at, fmt.parse_chunk, body)
                if chunk is not None:
                    hint = self._indexed_offsets(end)
                    batch = self._chunk(chunk, pos, body_at, wanted, start_ns, stop_ns, hint)
                    if batch is not None and batch.datas:
                        yield batch
            elif op == fmt.Op.MESSAGE:
                if length < 22:
                    self._damage(pos, 'message record too short')
                else:
                    channel_id, _, log_ns, pub_ns = struct.unpack_from('<HIQQ', buf, body_at)
                    if self._count(channel_id, pos) and self._in(
                        channel_id, log_ns, wanted, start_ns, stop_ns
                    ):
                        yield Batch(
                            np.array([channel_id], dtype=np.uint16),
                            # via uint64: a damaged time must not raise OverflowError
                            np.array([log_ns], dtype=np.uint64).astype(np.int64),
                            np.array([pub_ns], dtype=np.uint64).astype(np.int64),
                            PackedMessages.from_list([bytes(buf[body_at + 22 : end])]),
                        )
            elif op == fmt.Op.SCHEMA:
                self._schema(self._parse(pos, body_at, fmt.parse_schema, body))
            elif op == fmt.Op.CHANNEL:
                self._channel(self._parse(pos, body_at, fmt.parse_channel, body), pos)
            elif op == fmt.Op.DATA_END:
                self._data_end(pos, body)
                return
            elif op == fmt.Op.FOOTER:
                # A valid file always closes its data section with a data end record first.
                self._damage(pos, 'footer before the data end record')
                return
            pos = end
            self._release(pos)

    def _count(self, channel_id: int, offset: int) -> bool:
        if channel_id not in self.channels:
            self._damage(offset, f'message on undeclared channel {channel_id}')
            return False
        self.message_count += 1
        self.channel_counts[channel_id] = self.channel_counts.get(channel_id, 0) + 1
        return True

    @staticmethod
    def _in(
        channel_id: int,
        log_ns: int,
        wanted: Callable[[int], bool],
        start_ns: int | None,
        stop_ns: int | None,
    ) -> bool:
        if start_ns is not None and log_ns < start_ns:
            return False
        if stop_ns is not None and log_ns >= stop_ns:
            return False
        return wanted(channel_id)

    def _chunk(
        self,
        chunk: fmt.ChunkRecord,
        offset: int,
        body_at: int,
        wanted: Callable[[int], bool],
        start_ns: int | None,
        stop_ns: int | None,
        hint: np.ndarray | None = None,
    ) -> Batch | None:
        """The selected messages of one chunk; None (and damage reported) if it is damaged.

        ``hint``: record offsets from the message indexes after the chunk. Used only if they
        tile the chunk exactly with message records, which makes them the walk's result.
        """
        payload_at = body_at + chunk.payload_offset
        data = self._inflate(chunk, offset, payload_at)
        if data is None:
            return None
        raw = np.frombuffer(data, dtype=np.uint8)
        tiled = _tile(raw, hint)
        if tiled is not None:
            at, sizes = tiled
            return self._messages_at(data, at, sizes, chunk, payload_at, wanted, start_ns, stop_ns)
        # Walk the record lengths (inherently sequential), then decode headers with numpy.
        unpack_prefix = _PREFIX.unpack_from
        positions: list[int] = []
        lengths: list[int] = []
        pos = 0
        size = len(data)
        while pos < size:
            if pos + 9 > size:
                self._damage(payload_at, f'chunk record header truncated at +{pos}')
                return None
            length = unpack_prefix(data, pos)[1]
            positions.append(pos)
            lengths.append(length)
            pos += 9 + length
        if pos > size:
            self._damage(payload_at, f'last chunk record at +{positions[-1]} overruns the chunk')
            return None
        at = np.asarray(positions, dtype=np.int64)
        ops = raw[at]
        is_message = ops == fmt.Op.MESSAGE
        if not is_message.all():
            for k in np.flatnonzero(~is_message).tolist():
                body = data[positions[k] + 9 : positions[k] + 9 + lengths[k]]
                if ops[k] == fmt.Op.SCHEMA:
                    self._schema(self._parse(offset, payload_at, fmt.parse_schema, body))
                elif ops[k] == fmt.Op.CHANNEL:
                    self._channel(self._parse(offset, payload_at, fmt.parse_channel, body), offset)
            at = at[is_message]
        sizes = np.asarray(lengths, dtype=np.int64)[is_message]
        return self._messages_at(data, at, sizes, chunk, payload_at, wanted, start_ns, stop_ns)

    def _messages_at(
        self,
        data: bytes,
        at: np.ndarray,
        sizes: np.ndarray,
        chunk: fmt.ChunkRecord,
        payload_at: int,
        wanted: Callable[[int], bool],
        start_ns: int | None,
        stop_ns: int | None,
    ) -> Batch | None:
        """Decode the message records at offsets ``at`` (record lengths ``sizes``) at once."""
        raw = np.frombuffer(data, dtype=np.uint8)
        if sizes.size and int(sizes.min()) < 22:
            self._damage(payload_at, 'message record too short')
            return None
        heads = windows(raw, _MESSAGE_FIELDS.itemsize)[at + 9].view(_MESSAGE_FIELDS)
        channel = heads['channel']
        log = heads['log'].astype(np.int64)
        ids, counts = np.unique(channel, return_counts=True)
        keep = []
        for channel_id, count in zip(ids.tolist(), counts.tolist(), strict=True):
            if channel_id not in self.channels:
                self._damage(payload_at, f'message on undeclared channel {channel_id}')
                return None
            self.channel_counts[channel_id] = self.channel_counts.get(channel_id, 0) + count
            if not (
                (start_ns is not None and chunk.end_ns < start_ns)
                or (stop_ns is not None and chunk.start_ns >= stop_ns)
            ) and wanted(channel_id):
                keep.append(channel_id)
        self.message_count += int(at.size)
        mask = np.isin(channel, keep) if len(keep) < ids.size else np.ones(at.size, dtype=bool)
        if start_ns is not None:
            mask &= log >= start_ns
        if stop_ns is not None:
            mask &= log < stop_ns
        chosen = np.flatnonzero(mask)
        if chosen.size != at.size:
            at, sizes = at[chosen], sizes[chosen]
        # the messages stay in the chunk's bytes: offsets, no object per message
        datas = PackedMessages(data, at + 31, sizes - 22)
        return Batch(
            channel[chosen], log[chosen], heads['publish'][chosen].astype(np.int64), datas
        )

    def _indexed_offsets(self, pos: int) -> np.ndarray | None:
        """Message offsets listed by the message index records starting at ``pos``, sorted.

        None when there are none or they do not parse; they are only a hint (see _tile).
        """
        buf = self.buf
        size = len(buf)
        parts = []
        while pos + 15 <= size and buf[pos] == fmt.Op.MESSAGE_INDEX:
            length = _PREFIX.unpack_from(buf, pos)[1]
            count = struct.unpack_from('<I', buf, pos + 11)[0]
            end = pos + 9 + length
            # length > 6 + count: fields of a later format version after the entries
            if end > size or length < 6 + count or count % 16:
                return None
            pairs = np.frombuffer(buf, dtype='<u8', count=count // 8, offset=pos + 15)
            parts.append(pairs[1::2])
            pos = end
        if not parts:
            return None
        return np.sort(np.concatenate(parts))

    def _inflate(self, chunk: fmt.ChunkRecord, offset: int, payload_at: int) -> bytes | None:
        """Decompressed, size- and CRC-checked chunk records; None if damaged."""
        inflate = self._decompressors.get(chunk.compression)
        if inflate is None:
            self._damage(offset, f'unknown chunk compression {chunk.compression!r}')
            return None
        if chunk.uncompressed_size > _MAX_CHUNK:
            self._damage(offset, f'chunk claims {chunk.uncompressed_size} bytes uncompressed')
            return None
        try:
            data = inflate(chunk.payload, chunk.uncompressed_size)
        except Exception as exc:  # zstandard/lz4 raise their own error types
            self._damage(payload_at, f'chunk does not decompress: {exc}')
            return None
        if len(data) != chunk.uncompressed_size:
            self._damage(payload_at, 'chunk size differs from its header')
            return None
        if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
            self._damage(payload_at, 'chunk CRC mismatch')
            return None
        return data

    def _data_end(self, offset: int, body: memoryview) -> None:
        if len(body) >= 4:
            (crc,) = struct.unpack_from('<I', body)
            if crc and self._crc(offset) != crc:
                self._damage(offset, 'data section CRC mismatch')
        self.reached_end = True
        self._check_tail(offset)

    def _crc(self, stop: int) -> int:
        """CRC-32 of bytes [0, stop), in steps whose pages are released after use."""
        crc = 0
        self._released = 0
        view = memoryview(self.buf)
        try:
            for start in range(0, stop, _RELEASE_STEP):
                crc = zlib.crc32(view[start : min(start + _RELEASE_STEP, stop)], crc)
                self._release(min(start + _RELEASE_STEP, stop))
        finally:
            view.release()
        return crc

    def _check_tail(self, data_end_offset: int) -> None:
        """Check the footer and, when present, the summary statistics against what was read."""
        buf = self.buf
        size = len(buf)
        footer_at = size - 8 - (_PREFIX.size + 20)
        if (
            size < data_end_offset + 8 + _PREFIX.size + 20
            or buf[size - 8 :] != fmt.MAGIC
            or buf[footer_at] != fmt.Op.FOOTER
        ):
            self._damage(min(size, data_end_offset), 'summary/footer missing or truncated')
            return
        footer = fmt.parse_footer(memoryview(buf)[footer_at + _PREFIX.size : size - 8])
        if footer.summary_start == 0:
            return
        if not data_end_offset < footer.summary_start <= footer_at:
            self._damage(footer_at, 'footer points outside the summary section')
            return
        if footer.summary_crc:
            crc = zlib.crc32(memoryview(buf)[footer.summary_start : footer_at + _PREFIX.size + 16])
            if crc != footer.summary_crc:
                self._damage(footer.summary_start, 'summary CRC mismatch')
                return
        stats = self._statistics(footer.summary_start, footer_at)
        if stats is not None and stats.message_count != self.message_count:
            self._damage(
                footer.summary_start,
                f'summary counts {stats.message_count} messages, data holds {self.message_count}',
            )

    def load_summary(self) -> bool:
        """Fill schemas, channels and counts from an intact summary; False if unusable.

        Used for topic listings so an intact bag is not scanned; any doubt (no footer, CRC
        mismatch, no statistics, a record that does not parse) answers False. So does a
        summary that is intact but incomplete for a listing, which the specification allows:
        channels whose schemas it does not repeat (they are in the data section only), or
        statistics without per-channel counts (an empty map means "not available").
        """
        buf = self.buf
        size = len(buf)
        footer_at = size - 8 - (_PREFIX.size + 20)
        if footer_at < 8 or buf[:8] != fmt.MAGIC or buf[size - 8 :] != fmt.MAGIC:
            return False
        if buf[footer_at] != fmt.Op.FOOTER:
            return False
        footer = fmt.parse_footer(memoryview(buf)[footer_at + _PREFIX.size : size - 8])
        if not 8 < footer.summary_start <= footer_at or not footer.summary_crc:
            return False
        end_crc = footer_at + _PREFIX.size + 16
        if zlib.crc32(memoryview(buf)[footer.summary_start : end_crc]) != footer.summary_crc:
            return False
        schemas: dict[int, fmt.SchemaRecord] = {}
        channels: dict[int, fmt.ChannelRecord] = {}
        stats: fmt.StatisticsRecord | None = None
        pos = footer.summary_start
        try:
            while pos + _PREFIX.size <= footer_at:
                op, length = _PREFIX.unpack_from(buf, pos)
                end = pos + _PREFIX.size + length
                if end > footer_at:
                    return False
                body = memoryview(buf)[pos + _PREFIX.size : end]
                if op == fmt.Op.SCHEMA:
                    schema = fmt.parse_schema(body)
                    if schema.id != 0:  # id 0 is invalid: ignored, as in the data section
                        schemas[schema.id] = schema
                elif op == fmt.Op.CHANNEL:
                    channel = fmt.parse_channel(body)
                    channels[channel.id] = channel
                elif op == fmt.Op.STATISTICS:
                    stats = fmt.parse_statistics(body)
                pos = end
        except fmt.MalformedRecordError:
            return False
        if stats is None or not channels:
            return False
        if any(c.schema_id != 0 and c.schema_id not in schemas for c in channels.values()):
            return False  # the types are in the data section only: scan for them
        counts = stats.channel_message_counts
        if sum(counts.values()) != stats.message_count or not counts.keys() <= channels.keys():
            return False  # per-channel counts not available (or not of these channels)
        self.schemas.update(schemas)
        self.channels.update(channels)
        self.channel_counts.update(stats.channel_message_counts)
        self.message_count = stats.message_count
        return True

    def _statistics(self, start: int, stop: int) -> fmt.StatisticsRecord | None:
        pos = start
        while pos + _PREFIX.size <= stop:
            op, length = _PREFIX.unpack_from(self.buf, pos)
            end = pos + _PREFIX.size + length
            if end > stop:
                self._damage(pos, 'summary record overruns the summary section')
                return None
            if op == fmt.Op.STATISTICS:
                body = memoryview(self.buf)[pos + _PREFIX.size : end]
                return self._parse(pos, pos + _PREFIX.size, fmt.parse_statistics, body)  # type: ignore[no-any-return]
            pos = end
        return None


def _tile(raw: np.ndarray, hint: np.ndarray | None) -> tuple[np.ndarray, np.ndarray] | None:
    """(offsets, record lengths) if ``hint`` tiles ``raw`` exactly with message records."""
    size = raw.size
    if hint is None or not hint.size or hint[0] != 0 or int(hint[-1]) + 9 > size:
        return None
    at = hint.astype(np.int64)
    if not (raw[at] == fmt.Op.MESSAGE).all():
        return None
    lengths = windows(raw, 8)[at + 1].view('<u8')
    if int(lengths.max()) > size:
        return None
    sizes = lengths.astype(np.int64)
    ends = at + 9 + sizes
    if int(ends[-1]) != size or not np.array_equal(ends[:-1], at[1:]):
        return None
    return at, sizes
