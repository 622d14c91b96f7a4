"""MCAP record encoding and bounds-checked decoding (the subset rosbag2 uses).

Own codec rather than the ``mcap`` package so that (a) the writer can hand whole batches of
messages to one chunk with little per-message overhead and flush chunks on a time bound, and
(b) the reader turns every malformed byte into a :class:`MalformedRecordError` with an offset
instead of whatever exception a generic parser raises (struct.error, UnicodeDecodeError,
zstd errors ...). The ``mcap`` package is used in the tests as an independent check.

Layouts follow the MCAP specification (https://mcap.dev/spec): little endian, strings are a
uint32 byte length + UTF-8, maps a uint32 byte length + key/value pairs. As the specification
asks of readers, the parsers read the fields they know and ignore any bytes after them (fields
a later version of the format may add); the reader skips records of unknown opcodes.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass
from enum import IntEnum

__all__ = [
    'MAGIC',
    'RECORD_PREFIX',
    'ChannelRecord',
    'ChunkIndexRecord',
    'ChunkRecord',
    'Cursor',
    'FooterRecord',
    'MalformedRecordError',
    'Op',
    'SchemaRecord',
    'StatisticsRecord',
    'encode_channel',
    'encode_chunk',
    'encode_chunk_index',
    'encode_data_end',
    'encode_footer',
    'encode_header',
    'encode_message_index',
    'encode_metadata',
    'encode_metadata_index',
    'encode_schema',
    'encode_statistics',
    'encode_summary_offset',
    'parse_channel',
    'parse_chunk',
    'parse_footer',
    'parse_schema',
    'parse_statistics',
    'record',
]

MAGIC = b'\x89MCAP0\r\n'

# opcode (uint8) + record length (uint64)
RECORD_PREFIX = struct.Struct('<BQ')


class Op(IntEnum):
    """MCAP record opcodes."""

    HEADER = 0x01
    FOOTER = 0x02
    SCHEMA = 0x03
    CHANNEL = 0x04
    MESSAGE = 0x05
    CHUNK = 0x06
    MESSAGE_INDEX = 0x07
    CHUNK_INDEX = 0x08
    ATTACHMENT = 0x09
    ATTACHMENT_INDEX = 0x0A
    STATISTICS = 0x0B
    METADATA = 0x0C
    METADATA_INDEX = 0x0D
    SUMMARY_OFFSET = 0x0E
    DATA_END = 0x0F


class MalformedRecordError(Exception):
    """A record body does not parse; ``offset`` is relative to the start of the parsed bytes."""

    def __init__(self, offset: int, reason: str) -> None:
        self.offset = offset
        self.reason = reason
        super().__init__(f'at +{offset}: {reason}')


_U16 = struct.Struct('<H')
_U32 = struct.Struct('<I')
_U64 = struct.Struct('<Q')


def record(op: int, body: bytes) -> bytes:
    """Frame a record body with its opcode and length."""
    return RECORD_PREFIX.pack(op, len(body)) + body


def _string(text: str) -> bytes:
    raw = text.encode()
    return _U32.pack(len(raw)) + raw


def _string_map(items: dict[str, str]) -> bytes:
    body = b''.join(_string(k) + _string(v) for k, v in items.items())
    return _U32.pack(len(body)) + body


def encode_header(profile: str, library: str) -> bytes:
    """Header record (first record of every MCAP file)."""
    return record(Op.HEADER, _string(profile) + _string(library))


def encode_schema(schema_id: int, name: str, encoding: str, data: bytes) -> bytes:
    """Schema record: the message definition of one type."""
    body = _U16.pack(schema_id) + _string(name) + _string(encoding) + _U32.pack(len(data)) + data
    return record(Op.SCHEMA, body)


def encode_channel(
    channel_id: int, schema_id: int, topic: str, message_encoding: str, metadata: dict[str, str]
) -> bytes:
    """Channel record: one topic with its schema and rosbag2 metadata (QoS, type hash)."""
    body = (
        _U16.pack(channel_id)
        + _U16.pack(schema_id)
        + _string(topic)
        + _string(message_encoding)
        + _string_map(metadata)
    )
    return record(Op.CHANNEL, body)


_CHUNK_HEAD = struct.Struct('<QQQI')


def encode_chunk(
    start_ns: int,
    end_ns: int,
    uncompressed: bytes | memoryview,
    compression: str,
    compressed: bytes,
) -> bytes:
    """Chunk record holding (compressed) message records; CRC is over the uncompressed data."""
    body = (
        _CHUNK_HEAD.pack(start_ns, end_ns, len(uncompressed), zlib.crc32(uncompressed))
        + _string(compression)
        + _U64.pack(len(compressed))
        + compressed
    )
    return record(Op.CHUNK, body)


def encode_message_index(channel_id: int, entries: list[tuple[int, int]] | bytes) -> bytes:
    """Message index of one channel in the preceding chunk.

    Args:
        channel_id: the channel.
        entries: (log_time_ns, offset_in_chunk) pairs, or those already packed as
            little-endian uint64 pairs.
    """
    if isinstance(entries, bytes):
        packed = entries
    else:
        packed = b''.join(_U64.pack(t) + _U64.pack(o) for t, o in entries)
    return record(Op.MESSAGE_INDEX, _U16.pack(channel_id) + _U32.pack(len(packed)) + packed)


@dataclass(frozen=True)
class ChunkIndexRecord:
    """A chunk index record of the summary section: where a chunk is and what it holds.

    Attributes:
        start_ns, end_ns: [ns] the chunk's first and last log time.
        chunk_offset, chunk_length: [bytes] the chunk record's place in the file.
        message_index_offsets: each channel's message index record's offset [bytes].
        message_index_length: [bytes] the message index records after the chunk.
        compression: '' | 'zstd' | 'lz4'.
        compressed_size, uncompressed_size: [bytes] the chunk's records.
    """

    start_ns: int
    end_ns: int
    chunk_offset: int
    chunk_length: int
    message_index_offsets: dict[int, int]
    message_index_length: int
    compression: str
    compressed_size: int
    uncompressed_size: int


def encode_chunk_index(index: ChunkIndexRecord) -> bytes:
    """Chunk index record of the summary section."""
    offsets = b''.join(_U16.pack(c) + _U64.pack(o) for c, o in index.message_index_offsets.items())
    body = (
        struct.pack('<QQQQ', index.start_ns, index.end_ns, index.chunk_offset, index.chunk_length)
        + _U32.pack(len(offsets))
        + offsets
        + _U64.pack(index.message_index_length)
        + _string(index.compression)
        + struct.pack('<QQ', index.compressed_size, index.uncompressed_size)
    )
    return record(Op.CHUNK_INDEX, body)


def encode_statistics(
    message_count: int,
    schema_count: int,
    channel_count: int,
    metadata_count: int,
    chunk_count: int,
    start_ns: int,
    end_ns: int,
    channel_message_counts: dict[int, int],
) -> bytes:
    """Statistics record of the summary section (no attachments are ever written)."""
    counts = b''.join(_U16.pack(c) + _U64.pack(n) for c, n in channel_message_counts.items())
    body = struct.pack(
        '<QHIIIIQQI',
        message_count,
        schema_count,
        channel_count,
        0,
        metadata_count,
        chunk_count,
        start_ns,
        end_ns,
        len(counts),
    )
    return record(Op.STATISTICS, body + counts)


def encode_metadata(name: str, items: dict[str, str]) -> bytes:
    """Metadata record (rosbag2 stores its serialized bag metadata in one named 'rosbag2')."""
    return record(Op.METADATA, _string(name) + _string_map(items))


def encode_metadata_index(offset: int, length: int, name: str) -> bytes:
    """Metadata index record of the summary section."""
    return record(Op.METADATA_INDEX, struct.pack('<QQ', offset, length) + _string(name))


def encode_summary_offset(group_op: int, start: int, length: int) -> bytes:
    """Summary offset record: where the summary group of ``group_op`` records lies."""
    return record(Op.SUMMARY_OFFSET, struct.pack('<BQQ', group_op, start, length))


def encode_data_end(data_crc: int) -> bytes:
    """Data end record closing the data section, with the CRC of everything before it."""
    return record(Op.DATA_END, _U32.pack(data_crc))


def encode_footer(summary_start: int, summary_offset_start: int, summary_bytes: bytes) -> bytes:
    """Footer record; its CRC covers the summary sections and the footer's own first fields."""
    head = RECORD_PREFIX.pack(Op.FOOTER, 20) + struct.pack(
        '<QQ', summary_start, summary_offset_start
    )
    crc = zlib.crc32(head, zlib.crc32(summary_bytes))
    return head + _U32.pack(crc)


class Cursor:
    """Bounds-checked little-endian reader over a byte buffer.

    Every read past the end raises :class:`MalformedRecordError` with the offset relative to the
    buffer start, so callers translate it to an absolute file offset.
    """

    __slots__ = ('buf', 'pos')

    def __init__(self, buf: bytes | memoryview, pos: int = 0) -> None:
        self.buf = buf
        self.pos = pos

    def _take(self, size: int, what: str) -> int:
        start = self.pos
        if size < 0 or start + size > len(self.buf):
            raise MalformedRecordError(
                start, f'{what} needs {size} bytes, {len(self.buf) - start} left'
            )
        self.pos = start + size
        return start

    def u8(self, what: str = 'uint8') -> int:
        return int(self.buf[self._take(1, what)])

    def u16(self, what: str = 'uint16') -> int:
        return int(_U16.unpack_from(self.buf, self._take(2, what))[0])

    def u32(self, what: str = 'uint32') -> int:
        return int(_U32.unpack_from(self.buf, self._take(4, what))[0])

    def u64(self, what: str = 'uint64') -> int:
        return int(_U64.unpack_from(self.buf, self._take(8, what))[0])

    def raw(self, size: int, what: str = 'bytes') -> bytes:
        start = self._take(size, what)
        return bytes(self.buf[start : start + size])

    def view(self, size: int, what: str = 'bytes') -> memoryview:
        start = self._take(size, what)
        return memoryview(self.buf)[start : start + size]

    def string(self, what: str = 'string') -> str:
        size = self.u32(what)
        at = self.pos
        try:
            return self.raw(size, what).decode()
        except UnicodeDecodeError as exc:
            raise MalformedRecordError(at, f'{what} is not UTF-8') from exc

    def string_map(self, what: str = 'map') -> dict[str, str]:
        size = self.u32(what)
        end = self._take(size, what) + size
        self.pos -= size
        items: dict[str, str] = {}
        while self.pos < end:
            key = self.string(f'{what} key')
            items[key] = self.string(f'{what} value')
        if self.pos != end:
            raise MalformedRecordError(self.pos, f'{what} overruns its declared length')
        return items

    def at_end(self) -> bool:
        return self.pos >= len(self.buf)


@dataclass(frozen=True)
class SchemaRecord:
    """A parsed schema record."""

    id: int
    name: str
    encoding: str
    data: bytes


@dataclass(frozen=True)
class ChannelRecord:
    """A parsed channel record."""

    id: int
    schema_id: int
    topic: str
    message_encoding: str
    metadata: dict[str, str]


@dataclass(frozen=True)
class ChunkRecord:
    """A parsed chunk record; ``payload`` is still compressed."""

    start_ns: int
    end_ns: int
    uncompressed_size: int
    uncompressed_crc: int
    compression: str
    payload: memoryview
    payload_offset: int  # within the record body, to report absolute offsets


@dataclass(frozen=True)
class StatisticsRecord:
    """The counts of the summary section."""

    message_count: int
    schema_count: int
    channel_count: int
    chunk_count: int
    start_ns: int
    end_ns: int
    channel_message_counts: dict[int, int]


@dataclass(frozen=True)
class FooterRecord:
    """The footer: where the summary section starts (0 = no summary)."""

    summary_start: int
    summary_offset_start: int
    summary_crc: int


def parse_schema(body: bytes | memoryview) -> SchemaRecord:
    """Parse a schema record body."""
    cur = Cursor(body)
    schema_id = cur.u16('schema id')
    name = cur.string('schema name')
    encoding = cur.string('schema encoding')
    data = cur.raw(cur.u32('schema data length'), 'schema data')
    return SchemaRecord(schema_id, name, encoding, data)


def parse_channel(body: bytes | memoryview) -> ChannelRecord:
    """Parse a channel record body."""
    cur = Cursor(body)
    channel_id = cur.u16('channel id')
    schema_id = cur.u16('schema id')
    topic = cur.string('topic')
    encoding = cur.string('message encoding')
    metadata = cur.string_map('channel metadata')
    return ChannelRecord(channel_id, schema_id, topic, encoding, metadata)


def parse_chunk(body: memoryview) -> ChunkRecord:
    """Parse a chunk record body without decompressing it (unknown trailing fields ignored)."""
    cur = Cursor(body)
    start = cur.u64('chunk start time')
    end = cur.u64('chunk end time')
    size = cur.u64('chunk uncompressed size')
    crc = cur.u32('chunk crc')
    compression = cur.string('chunk compression')
    length = cur.u64('chunk records length')
    offset = cur.pos
    payload = cur.view(length, 'chunk records')
    # Bytes after the records are fields of a later version of the format: ignored, as the
    # specification requires of readers ("Records may be extended by adding new fields at
    # the end of existing fields. Readers should ignore any unknown fields.").
    return ChunkRecord(start, end, size, crc, compression, payload, offset)


def parse_statistics(body: bytes | memoryview) -> StatisticsRecord:
    """Parse a statistics record body."""
    cur = Cursor(body)
    message_count = cur.u64()
    schema_count = cur.u16()
    channel_count = cur.u32()
    cur.u32()  # attachments
    cur.u32()  # metadata
    chunk_count = cur.u32()
    start = cur.u64()
    end = cur.u64()
    size = cur.u32('channel message counts')
    stop = cur.pos + size
    counts: dict[int, int] = {}
    while cur.pos < stop:
        channel_id = cur.u16()
        counts[channel_id] = cur.u64()
    return StatisticsRecord(
        message_count, schema_count, channel_count, chunk_count, start, end, counts
    )


def parse_footer(body: bytes | memoryview) -> FooterRecord:
    """Parse a footer record body."""
    cur = Cursor(body)
    return FooterRecord(cur.u64(), cur.u64(), cur.u32())
