"""Reading rosbag2 MCAP bags (ours and rosbag2's), strictly or leniently.

The data section is scanned record by record with bounds checks and chunk CRCs, so damage is
reported as :class:`BagCorruptError` naming the file and byte offset, after the messages of
every intact chunk before the damage have been yielded. With ``recover=True`` damage is
collected in :attr:`BagReader.problems` instead: a damaged chunk whose framing is intact is
skipped and reading goes on; damaged framing ends the file.

Messages come in file order (chunk by chunk), which is log-time order for bags recorded live.
Files are memory-mapped, and the pages behind the read position are handed back to the OS as
the scan goes on, so a pass over a bag of any size holds a bounded part of it in memory;
:meth:`BagReader.topic_array_blocks` gives the messages in blocks for the same reason.
"""

from __future__ import annotations

import mmap
import os
import struct
import zlib
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import lz4.frame
import numpy as np
import zstandard

from vd_observer_node.bag import mcap_format as fmt
from vd_observer_node.bag.errors import (
    BagCorruptError,
    BagFormatError,
    BagNotFoundError,
    BagUsageError,
)
from vd_observer_node.bag.metadata import read_metadata_file_paths
from vd_observer_node.bag.packed import PackedMessages, windows
from vd_observer_node.bag.typestore import decoding_type, deserialize, register_definition

__all__ = [
    'BagReader',
    'RawMessage',
    'TopicArrays',
    'TopicInfo',
    'find_mcap_files',
]

_PREFIX = fmt.RECORD_PREFIX
_MAX_CHUNK = 1 << 31  # [B] refuse to inflate a chunk claiming more (damaged size field)
#: the only opcode that is never valid: records of 0x01-0x7F (official, later versions of the
#: format) and 0x80-0xFF (application extensions) that we do not know are skipped, as the
#: specification asks; a 0x00 is damage (a zero-filled tail after a crash, typically)
_INVALID_OP = 0x00
#: [B] read pages are given back to the OS in steps of this size (bounded resident memory)
_RELEASE_STEP = 32 << 20


def _map_file(file: Path) -> bytes | mmap.mmap:
    """The file's bytes, memory-mapped (b'' for an empty file, which mmap refuses)."""
    with file.open('rb') as handle:
        if os.fstat(handle.fileno()).st_size == 0:
            return b''
        return mmap.mmap(handle.fileno(), 0, access=mmap.ACCESS_READ)


class RawMessage(NamedTuple):
    """One message as stored: CDR bytes and times [ns]."""

    topic: str
    msgtype: str
    log_time_ns: int
    data: bytes
    publish_time_ns: int


@dataclass(frozen=True)
class TopicInfo:
    """A topic of a bag: type, embedded definition, rosbag2 QoS metadata, message count.

    ``msgtype`` and ``definition`` are the name and data (as text) of the channel's schema,
    '' for a channel without one; ``message_encoding`` and ``schema_encoding`` are those of
    the channel and its schema (rosbag2: 'cdr' and 'ros2msg'; '' where not given).
    """

    name: str
    msgtype: str
    message_count: int
    definition: str
    qos_profiles_yaml: str
    message_encoding: str = ''
    schema_encoding: str = ''


@dataclass(frozen=True)
class TopicArrays:
    """All messages of one topic: log times [ns], shape (N,) int64, and CDR bytes (N).

    ``decode_as`` is the type to decode ``datas`` with (`typestore.decoding_type`):
    ``msgtype`` unless the bag embeds an older definition of it ('' means ``msgtype``).
    The reader gives ``datas`` as a :class:`~vd_observer_node.bag.packed.PackedMessages`
    (a sequence of bytes kept in one buffer, which the batch coders and the writer use
    without a Python object per message); any sequence of bytes will do.
    """

    msgtype: str
    log_time_ns: np.ndarray
    datas: Sequence[bytes]
    decode_as: str = ''

    @property
    def decoding_type(self) -> str:
        """The type to decode ``datas`` with."""
        return self.decode_as or self.msgtype


def find_mcap_files(path: Path) -> list[Path]:
    """The MCAP files of a bag folder (per metadata.yaml, else ``*.mcap``) or the file itself.

    Raises:
        BagNotFoundError: nothing readable at ``path``.
        BagFormatError: metadata.yaml names a non-MCAP storage.
    """
    if path.is_file():
        return [path]
    if not path.is_dir():
        raise BagNotFoundError(f'{path}: no such bag')
    listed = read_metadata_file_paths(path)
    if listed is not None:
        files = [path / name for name in listed]
        missing = [f for f in files if not f.is_file()]
        if not missing:
            return files
    files = sorted(path.glob('*.mcap'))
    if not files:
        raise BagNotFoundError(f'{path}: no .mcap file in the bag folder')
    return files


_MESSAGE_FIELDS = np.dtype(
    [('channel', '<u2'), ('sequence', '<u4'), ('log', '<u8'), ('publish', '<u8')]
)  # message record body after opcode and length, unaligned (22 bytes)


@dataclass
class _Batch:
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


class _FileScan:
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
    ) -> Iterator[_Batch]:
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
                        yield _Batch(
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
    ) -> _Batch | None:
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
            return self._messages_at(
                data, raw, at, sizes, chunk, payload_at, wanted, start_ns, stop_ns
            )
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
        return self._messages_at(
            data, raw, at, sizes, chunk, payload_at, wanted, start_ns, stop_ns
        )

    def _messages_at(
        self,
        data: bytes,
        raw: np.ndarray,
        at: np.ndarray,
        sizes: np.ndarray,
        chunk: fmt.ChunkRecord,
        payload_at: int,
        wanted: Callable[[int], bool],
        start_ns: int | None,
        stop_ns: int | None,
    ) -> _Batch | None:
        """Decode the message records at offsets ``at`` (record lengths ``sizes``) at once."""
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
        return _Batch(
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


class _ChannelSelector:
    """Decides per channel id (once) whether its topic is wanted; remembers topic and type."""

    def __init__(self, scan: _FileScan, selected: set[str] | None) -> None:
        self._scan = scan
        self._selected = selected
        self._keep: dict[int, bool] = {}
        self.names: dict[int, tuple[str, str]] = {}

    def __call__(self, channel_id: int) -> bool:
        keep = self._keep.get(channel_id)
        if keep is None:
            channel = self._scan.channels[channel_id]
            schema = self._scan.schemas.get(channel.schema_id)
            keep = self._selected is None or channel.topic in self._selected
            self._keep[channel_id] = keep
            self.names[channel_id] = (channel.topic, schema.name if schema else '')
        return keep


class BagReader:
    """Read a rosbag2 MCAP bag: a bag folder (with or without metadata.yaml) or a .mcap file.

    Args:
        path: bag folder or ``.mcap`` file.
        recover: collect damage in :attr:`problems` and read on, instead of raising
            :class:`BagCorruptError` at the first damage.

    Raises:
        BagNotFoundError: nothing at ``path``.
    """

    def __init__(self, path: str | os.PathLike[str], *, recover: bool = False) -> None:
        self.path = Path(path)
        self.files = find_mcap_files(self.path)
        self.recover = recover
        self.problems: list[BagCorruptError] = []
        self._topics: dict[str, TopicInfo] | None = None
        #: damage found by the pass of :attr:`topics` (kept for the passes after it)
        self._topic_problems: list[BagCorruptError] = []

    def _scans(self, problems: list[BagCorruptError] | None = None) -> Iterator[_FileScan]:
        for file in self.files:
            try:
                buf = _map_file(file)
            except OSError as exc:
                raise BagNotFoundError(f'{file}: cannot read: {exc.strerror or exc}') from exc
            yield _FileScan(
                file,
                buf,
                recover=self.recover,
                problems=self.problems if problems is None else problems,
                schemas={},
                channels={},
            )

    def raw_messages(
        self,
        topics: Iterable[str] | None = None,
        *,
        start_ns: int | None = None,
        stop_ns: int | None = None,
        ordered: bool = False,
    ) -> Iterator[RawMessage]:
        """Iterate stored messages, optionally only some topics and log times [start, stop).

        Args:
            topics: topic names to keep; None keeps all.
            start_ns: first log time [ns] to keep (inclusive).
            stop_ns: log time [ns] to stop before (exclusive).
            ordered: strictly by log time (stable). This holds the selection in memory
                before the first message; without it messages come in file order.

        Raises:
            BagCorruptError: damage found (strict mode), after the messages before it.
            BagFormatError: a file is not MCAP.
        """
        if ordered:
            selection = list(self.raw_messages(topics, start_ns=start_ns, stop_ns=stop_ns))
            selection.sort(key=lambda m: m.log_time_ns)
            yield from selection
            return
        selected = None if topics is None else set(topics)
        self.problems.clear()
        for scan in self._scans():
            select = _ChannelSelector(scan, selected)
            names = select.names
            for channel_id, log_ns, pub_ns, data in scan.messages(select, start_ns, stop_ns):
                topic, msgtype = names[channel_id]
                yield RawMessage(topic, msgtype, log_ns, data, pub_ns)

    def messages(
        self,
        topics: Iterable[str] | None = None,
        *,
        start_ns: int | None = None,
        stop_ns: int | None = None,
        ordered: bool = False,
    ) -> Iterator[tuple[str, str, int, Any]]:
        """Iterate decoded messages: (topic, msgtype, log_time_ns, rosbags message object).

        Types unknown to the vd typestore are registered from the bag's embedded definitions.

        Raises:
            BagFormatError: a selected topic is not decodable by vd: its message encoding is
                not 'cdr', it has no schema, or its schema encoding is not 'ros2msg'
                (:meth:`raw_messages` gives its bytes).
        """
        decode_as: dict[str, str] = {}
        selection = self.raw_messages(topics, start_ns=start_ns, stop_ns=stop_ns, ordered=ordered)
        for msg in selection:
            name = decode_as.get(msg.topic)
            if name is None:
                self._check_decodable(msg.topic)
                self._register(msg.msgtype)
                name = decode_as[msg.topic] = self.decoding_type(msg.topic)
            yield msg.topic, msg.msgtype, msg.log_time_ns, deserialize(msg.data, name)

    def _check_decodable(self, topic: str) -> None:
        """Raise BagFormatError if vd cannot decode the topic's messages (see messages())."""
        info = self.topics.get(topic)
        if info is None:
            return
        where = f'{self.path}: topic {topic!r}'
        if info.message_encoding != 'cdr':
            raise BagFormatError(
                f'{where}: message encoding {info.message_encoding!r} is not supported (vd '
                "decodes 'cdr' only; raw_messages() gives the bytes)"
            )
        if not info.msgtype:
            raise BagFormatError(f'{where}: no schema, so its CDR messages cannot be decoded')
        if info.schema_encoding != 'ros2msg':
            raise BagFormatError(
                f'{where}: schema encoding {info.schema_encoding!r} is not supported (vd '
                "reads 'ros2msg' definitions only; raw_messages() gives the bytes)"
            )

    def decoding_type(self, topic: str) -> str:
        """The type to decode a topic's messages with (`typestore.decoding_type`): its type,
        or an alias of the older definition the bag embeds for it."""
        info = self.topics.get(topic)
        if info is None:
            return ''
        return decoding_type(info.msgtype, info.definition)

    def _register(self, msgtype: str) -> None:
        info = next((t for t in self.topics.values() if t.msgtype == msgtype), None)
        if info is not None and info.definition:
            register_definition(msgtype, info.definition)

    def topic_arrays(self, topics: Iterable[str] | None = None) -> dict[str, TopicArrays]:
        """All messages grouped per topic (for batch processing such as offline replay)."""
        return next(self.topic_array_blocks(topics, block_messages=None), {})

    def topic_array_blocks(
        self, topics: Iterable[str] | None = None, *, block_messages: int | None = 65536
    ) -> Iterator[dict[str, TopicArrays]]:
        """The selected messages grouped per topic, in blocks of about `block_messages`.

        Blocks follow file order (chunk by chunk, file by file): a block ends at the first
        chunk boundary after `block_messages` selected messages, so it holds at most that
        many plus one chunk's worth, whatever the bag's size; together with the released
        pages of the memory map this bounds the resident memory of a pass. A topic appears
        in a block only if the block has messages of it. Concatenated, the blocks are
        :meth:`topic_arrays` (tested).

        Args:
            topics: topic names to keep; None keeps all.
            block_messages: messages per block (>= 1); None: one block with everything.
                An empty selection gives no block.

        Raises:
            BagUsageError: block_messages < 1.
            BagCorruptError: damage found (strict mode), after the blocks before it.
            BagFormatError: a file is not MCAP.
        """
        if block_messages is not None and block_messages < 1:
            raise BagUsageError(f'block_messages must be >= 1, got {block_messages}')
        selected = None if topics is None else set(topics)
        times: dict[str, list[np.ndarray]] = {}
        datas: dict[str, list[PackedMessages]] = {}
        types: dict[str, str] = {}
        held = 0
        infos = self.topics  # before the scan: a first pass must not add its damage twice
        self.problems.clear()
        for scan in self._scans():
            select = _ChannelSelector(scan, selected)
            for batch in scan.batches(select, None, None):
                channels = np.unique(batch.channel).tolist()
                # A chunk mostly selected stays as it is until the block is joined; of one
                # mostly not, only the selected bytes are kept (bounded memory).
                sparse = 2 * int(batch.datas.lengths.sum()) < len(batch.datas.data)
                for channel_id in channels:
                    topic, msgtype = select.names[channel_id]
                    if topic not in times:
                        times[topic], datas[topic] = [], []
                        types.setdefault(topic, msgtype)
                    if len(channels) == 1:
                        times[topic].append(batch.log)
                        part = batch.datas
                    else:
                        members = np.flatnonzero(batch.channel == channel_id)
                        times[topic].append(batch.log[members])
                        part = batch.datas.take(members)
                    datas[topic].append(part.compact() if sparse else part)
                held += len(batch.datas)
                if block_messages is not None and held >= block_messages:
                    yield self._block(times, datas, types, infos)
                    times, datas, held = {}, {}, 0
        self._add_problems(self._topic_problems)
        if times:
            yield self._block(times, datas, types, infos)

    @staticmethod
    def _block(
        times: dict[str, list[np.ndarray]],
        datas: dict[str, list[PackedMessages]],
        types: dict[str, str],
        infos: dict[str, TopicInfo],
    ) -> dict[str, TopicArrays]:
        return {
            t: TopicArrays(
                types[t],
                np.concatenate(times[t]).astype(np.int64),
                PackedMessages.concat(datas[t]),
                decoding_type(types[t], infos[t].definition if t in infos else ''),
            )
            for t in times
        }

    @property
    def topics(self) -> dict[str, TopicInfo]:
        """Topics of the bag with message counts (one pass over the data if not yet read)."""
        if self._topics is None:
            found: list[BagCorruptError] = []
            scans = []
            for scan in self._scans(found):
                if not scan.load_summary():
                    for _ in scan.batches(lambda _c: False, None, None):
                        pass
                scans.append(scan)
            self._topics = self._topic_infos(scans)
            self._topic_problems = found
            self._add_problems(found)
        return self._topics

    def _add_problems(self, found: list[BagCorruptError]) -> None:
        """Add to :attr:`problems` those of `found` not yet in it (same file, offset, reason)."""
        known = {(str(p.path), p.offset, p.reason) for p in self.problems}
        self.problems.extend(p for p in found if (str(p.path), p.offset, p.reason) not in known)

    @staticmethod
    def _topic_infos(scans: list[_FileScan]) -> dict[str, TopicInfo]:
        infos: dict[str, TopicInfo] = {}
        for scan in scans:
            for channel in scan.channels.values():
                schema = scan.schemas.get(channel.schema_id)
                count = scan.channel_counts.get(channel.id, 0)
                old = infos.get(channel.topic)
                infos[channel.topic] = TopicInfo(
                    channel.topic,
                    schema.name if schema else '',
                    count + (old.message_count if old else 0),
                    schema.data.decode(errors='replace') if schema else '',
                    channel.metadata.get('offered_qos_profiles', ''),
                    channel.message_encoding,
                    schema.encoding if schema else '',
                )
        return infos

    def time_range_ns(self) -> tuple[int, int] | None:
        """(first, last) log time [ns] of all messages, None for an empty bag."""
        first: int | None = None
        last = 0
        for msg in self.raw_messages():
            first = msg.log_time_ns if first is None else min(first, msg.log_time_ns)
            last = max(last, msg.log_time_ns)
        return None if first is None else (first, last)
