"""Writing rosbag2 bags with MCAP storage: zstd chunks, embedded ``ros2msg`` definitions.

Crash safety: messages are buffered in the current chunk in memory; a chunk is written to
the file (and handed to the OS) once it holds ``chunk_size`` bytes or its first message is
``chunk_duration_s`` old (checked on every write and by :meth:`BagWriter.flush_if_due`, which a
recorder should call from a timer so a quiet topic cannot keep data in memory). So a SIGKILL
loses at most the open chunk, i.e. at most ``chunk_duration_s`` seconds of data (plus the
time between two ``flush_if_due`` calls when no message arrives); with ``fsync=True`` the
same bound holds for power loss. ``vd bag repair`` restores the summary and metadata.
"""

from __future__ import annotations

import errno
import functools
import itertools
import os
import struct
import time
import zlib
from collections import deque
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import IO

import numpy as np
import zstandard

from vd_observer_node.bag import mcap_format as fmt
from vd_observer_node.bag.errors import (
    BagDiskFullError,
    BagError,
    BagExistsError,
    BagPathError,
    BagUsageError,
)
from vd_observer_node.bag.metadata import (
    BagSummary,
    TopicSummary,
    normalize_qos_profiles,
    render_metadata,
    write_metadata,
)
from vd_observer_node.bag.packed import PackedMessages, PackedParts
from vd_observer_node.bag.typestore import message_definition, type_hash

__all__ = [
    'DEFAULT_CHUNK_DURATION_S',
    'DEFAULT_CHUNK_SIZE',
    'BagWriter',
]

DEFAULT_CHUNK_SIZE = 256 * 1024  # [B] uncompressed
DEFAULT_CHUNK_DURATION_S = 0.5  # [s] wall-clock age of a chunk before it is written

_LIBRARY = 'vd_observer_node.bag'
# Message record prefix: opcode, record length, channel id, sequence, log time, publish time.
_MESSAGE_HEAD = struct.Struct('<BQHIQQ')
_MESSAGE_FIXED = 22  # channel id + sequence + log time + publish time [B]
_MESSAGE_DTYPE = np.dtype(
    [
        ('op', 'u1'),
        ('length', '<u8'),
        ('channel', '<u2'),
        ('sequence', '<u4'),
        ('log', '<u8'),
        ('publish', '<u8'),
    ]
)  # unaligned: the same 31 bytes as _MESSAGE_HEAD
_DISK_FULL = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG}
# zstd level 1, not 3: on a replay's output (200 MB of records in 256 kB chunks) 0.25 s
# instead of 0.60 s of compression for a ratio of 5.22 instead of 5.23; on the simulator's
# sensor bag 4.23 instead of 4.33.
_ZSTD_LEVEL = 1
# Chunks a background writer may hold before the producer waits (about 16 MB uncompressed).
_MAX_PENDING = 64


@dataclass
class _Topic:
    channel_id: int
    name: str
    msgtype: str
    qos_profiles_yaml: str
    count: int = 0


@dataclass
class _OpenChunk:
    data: bytearray = field(default_factory=bytearray)
    index: dict[int, list[tuple[int, int]]] = field(default_factory=dict)
    start_ns: int = 2**64 - 1
    end_ns: int = 0
    opened_at: float = 0.0


class BagWriter:
    """Write one rosbag2 MCAP bag folder (``metadata.yaml`` + ``<name>_0.mcap``).

    Use as a context manager; :meth:`close` (also run on exceptions) writes the MCAP summary
    and ``metadata.yaml``. Messages are raw CDR bytes, exactly what ``rclpy`` hands a
    subscription created with ``raw=True``.

    Args:
        path: bag folder to create; must not exist or be empty.
        chunk_size: uncompressed chunk size [B] that triggers writing a chunk.
        chunk_duration_s: wall-clock age [s] of the open chunk that triggers writing it.
        compression: 'zstd' or '' (none).
        fsync: fsync after every chunk (power-loss safety at some throughput cost).
        clock: monotonic clock [s] for the chunk age, injectable for tests.
        file_name: MCAP file name inside the folder; default ``<folder name>_0.mcap`` like
            rosbag2.
        background: compress, checksum and write the chunks on a thread of their own
            (offline tools: zstd, zlib and the file write release the GIL, so they run on a
            second core while the caller builds the next chunks). The file is the same byte
            for byte; a write error is raised by the next call after it (or by
            :meth:`close`). A recorder keeps the default, so a chunk is in the file when
            :meth:`flush` returns.

    Raises:
        BagExistsError: ``path`` exists and is not an empty folder.
        BagPathError: the folder or file cannot be created.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        chunk_size: int = DEFAULT_CHUNK_SIZE,
        chunk_duration_s: float = DEFAULT_CHUNK_DURATION_S,
        compression: str = 'zstd',
        fsync: bool = False,
        clock: Callable[[], float] = time.monotonic,
        file_name: str | None = None,
        background: bool = False,
    ) -> None:
        if compression not in ('zstd', ''):
            raise BagUsageError(f"compression must be 'zstd' or '', not {compression!r}")
        if chunk_size <= 0 or chunk_duration_s <= 0:
            raise BagUsageError('chunk_size and chunk_duration_s must be positive')
        self.path = Path(path)
        self.mcap_path = self.path / (file_name or f'{self.path.name}_0.mcap')
        self._chunk_size = chunk_size
        self._chunk_duration_s = chunk_duration_s
        self._compression = compression
        self._compressor = zstandard.ZstdCompressor(level=_ZSTD_LEVEL) if compression else None
        self._fsync = fsync
        self._clock = clock
        self._topics: dict[str, _Topic] = {}
        self._schemas: dict[str, tuple[int, bytes]] = {}  # msgtype -> (id, schema record)
        self._channel_records: list[bytes] = []
        self._chunk_indexes: list[bytes] = []
        self._chunk = _OpenChunk()
        self._crc = 0  # running CRC of the data section written so far
        self._offset = 0
        self._start_ns = 2**64 - 1
        self._end_ns = 0
        self._closed = False
        self._failed = False
        self._file = self._create()
        self._write_out(fmt.MAGIC + fmt.encode_header('ros2', _LIBRARY))
        self._file.flush()
        # one worker: the jobs run in the order they were given, as the file needs
        self._worker = ThreadPoolExecutor(1, 'bag-writer') if background else None
        self._pending: deque[Future[None]] = deque()

    # -- creation and raw output ---------------------------------------------------------

    def _create(self) -> IO[bytes]:
        if self.path.exists() and (not self.path.is_dir() or any(self.path.iterdir())):
            raise BagExistsError(f'{self.path}: already exists (choose a new bag name)')
        try:
            self.path.mkdir(parents=True, exist_ok=True)
            return self.mcap_path.open('xb')
        except FileExistsError as exc:
            raise BagExistsError(f'{self.mcap_path}: already exists') from exc
        except OSError as exc:
            raise BagPathError(f'{self.path}: cannot create bag: {exc.strerror or exc}') from exc

    def _write_out(self, data: bytes) -> None:
        try:
            self._file.write(data)
        except OSError as exc:
            self._failed = True
            if exc.errno in _DISK_FULL:
                raise BagDiskFullError(
                    f'{self.mcap_path}: disk full after {self._offset} bytes; the complete '
                    'chunks before are kept, run `vd bag repair` on the bag'
                ) from exc
            raise BagPathError(f'{self.mcap_path}: write failed: {exc.strerror or exc}') from exc
        self._crc = zlib.crc32(data, self._crc)
        self._offset += len(data)

    def _write_synced(self, data: bytes) -> None:
        self._write_out(data)
        self._sync()

    def _sync(self) -> None:
        try:
            self._file.flush()
            if self._fsync:
                os.fsync(self._file.fileno())
        except OSError as exc:
            self._failed = True
            if exc.errno in _DISK_FULL:
                raise BagDiskFullError(f'{self.mcap_path}: disk full while flushing') from exc
            raise BagPathError(f'{self.mcap_path}: flush failed: {exc.strerror or exc}') from exc

    def _check_open(self) -> None:
        if self._closed:
            raise BagUsageError(f'{self.path}: writer is closed')
        self._collect(keep=_MAX_PENDING)
        if self._failed:
            raise BagUsageError(f'{self.path}: writer failed earlier; run `vd bag repair`')

    def _output(self, job: Callable[[], None]) -> None:
        """Run one piece of file output now, or queue it on the background worker."""
        if self._worker is None:
            job()
            return
        self._pending.append(self._worker.submit(job))
        self._collect(keep=_MAX_PENDING)

    def _collect(self, keep: int) -> None:
        """Forget the finished background jobs, waiting until at most `keep` are left.

        Raises:
            BagError: the first job that failed (the rest are cancelled).
        """
        pending = self._pending
        while pending and (len(pending) > keep or pending[0].done()):
            error = pending.popleft().exception()  # waits for the job if it runs
            if error is not None:
                self._failed = True
                self._cancel_pending()
                raise error

    def _cancel_pending(self) -> None:
        """Drop the queued jobs (only after a failure: the output stops there)."""
        for job in self._pending:
            job.cancel()
        self._pending.clear()

    # -- topics ------------------------------------------------------------------------------

    def add_topic(
        self,
        name: str,
        msgtype: str,
        qos_profiles_yaml: str = '',
        *,
        definition: str | None = None,
    ) -> None:
        """Declare a topic before writing to it (repeating an identical call is a no-op).

        Args:
            name: topic name, e.g. '/vd/sensors/wheel_angles'.
            msgtype: ROS 2 type name 'pkg/msg/Type'.
            qos_profiles_yaml: offered QoS profiles as rosbag2 stores them in MCAP channel
                metadata (a YAML list of profile mappings, see
                :func:`.metadata.format_qos_profiles`); '' for none (player defaults).
                Integer policies (metadata <= 8 style) are converted to version-9 names.
            definition: full ``ros2msg`` definition; default: from the vd typestore.

        Raises:
            BagUsageError: the topic exists with another type, or the QoS text is not a list.
            UnknownMessageTypeError: no definition given and the type is unknown.
        """
        self._check_open()
        known = self._topics.get(name)
        if known is not None:
            if known.msgtype != msgtype:
                raise BagUsageError(
                    f'topic {name} already has type {known.msgtype}, cannot add {msgtype}'
                )
            return
        # '[]' rather than '': an empty YAML document is not a list for rosbag2's parser.
        qos = normalize_qos_profiles(qos_profiles_yaml) if qos_profiles_yaml.strip() else '[]'
        text = definition if definition is not None else message_definition(msgtype)
        digest = type_hash(msgtype) if self._has_hash(msgtype) else ''
        out = b''
        if msgtype not in self._schemas:
            schema_id = len(self._schemas) + 1
            record = fmt.encode_schema(schema_id, msgtype, 'ros2msg', text.encode())
            self._schemas[msgtype] = (schema_id, record)
            out += record
        channel_id = len(self._topics) + 1
        metadata = {'offered_qos_profiles': qos}
        if digest:
            metadata['topic_type_hash'] = digest
        channel = fmt.encode_channel(channel_id, self._schemas[msgtype][0], name, 'cdr', metadata)
        self._channel_records.append(channel)
        self._topics[name] = _Topic(channel_id, name, msgtype, qos)
        # Straight to the file, outside chunks, so a repair finds every topic declared so far.
        self._output(functools.partial(self._write_synced, out + channel))

    @property
    def topics(self) -> dict[str, str]:
        """Declared topics: name -> message type."""
        return {t.name: t.msgtype for t in self._topics.values()}

    @property
    def message_count(self) -> int:
        """Messages written so far (all topics)."""
        return sum(t.count for t in self._topics.values())

    # -- messages ----------------------------------------------------------------------------

    def _topic(self, name: str) -> _Topic:
        topic = self._topics.get(name)
        if topic is None:
            raise BagUsageError(f'topic {name} was not added to {self.path}')
        return topic

    def write(
        self,
        topic: str,
        data: bytes | bytearray | memoryview,
        log_time_ns: int,
        publish_time_ns: int | None = None,
    ) -> None:
        """Append one raw CDR message.

        Args:
            topic: a topic declared with :meth:`add_topic`.
            data: serialized message (CDR with its 4-byte encapsulation header).
            log_time_ns: receive/log time [ns] (the time rosbag2 plays back by).
            publish_time_ns: send time [ns]; defaults to ``log_time_ns``.
        """
        self._check_open()
        entry = self._topic(topic)
        chunk = self._chunk
        if not chunk.data:
            chunk.opened_at = self._clock()
        publish = log_time_ns if publish_time_ns is None else publish_time_ns
        offset = len(chunk.data)
        try:
            head = _MESSAGE_HEAD.pack(
                fmt.Op.MESSAGE,
                _MESSAGE_FIXED + len(data),
                entry.channel_id,
                entry.count & 0xFFFFFFFF,
                log_time_ns,
                publish,
            )
        except struct.error as exc:
            raise BagUsageError(
                f'{topic}: times must be integers in [0, 2**64) ns, got {log_time_ns}, {publish}'
            ) from exc
        chunk.data += head
        chunk.data += data
        chunk.index.setdefault(entry.channel_id, []).append((log_time_ns, offset))
        entry.count += 1
        chunk.start_ns = min(chunk.start_ns, log_time_ns)
        chunk.end_ns = max(chunk.end_ns, log_time_ns)
        if (
            len(chunk.data) >= self._chunk_size
            or self._clock() - chunk.opened_at >= self._chunk_duration_s
        ):
            self.flush()

    def write_batch(
        self,
        topic: str,
        datas: Sequence[bytes],
        log_times_ns: Sequence[int],
        publish_times_ns: Sequence[int] | None = None,
    ) -> None:
        """Append many raw CDR messages of one topic (offline tools; same rules as write).

        Args:
            topic: a declared topic.
            datas: serialized messages, length N.
            log_times_ns: log times [ns], length N.
            publish_times_ns: publish times [ns], length N; default the log times.
        """
        self._check_open()
        if len(datas) != len(log_times_ns) or (
            publish_times_ns is not None and len(publish_times_ns) != len(datas)
        ):
            raise BagUsageError('write_batch: datas and times must have the same length')
        publish = log_times_ns if publish_times_ns is None else publish_times_ns
        for data, log_ns, pub_ns in zip(datas, log_times_ns, publish, strict=True):
            self.write(topic, data, int(log_ns), int(pub_ns))
        self.flush_if_due()

    def flush_if_due(self) -> bool:
        """Write the open chunk if it is older than ``chunk_duration_s``; True if written."""
        self._check_open()
        chunk = self._chunk
        if chunk.data and self._clock() - chunk.opened_at >= self._chunk_duration_s:
            self.flush()
            return True
        return False

    def flush(self) -> None:
        """Write the open chunk (if any) and its message indexes to the file now."""
        self._check_open()
        chunk = self._chunk
        if not chunk.data:
            return
        self._chunk = _OpenChunk()
        self._emit_chunk(bytes(chunk.data), chunk.start_ns, chunk.end_ns, chunk.index)

    def _emit_chunk(
        self,
        raw: bytes | memoryview,
        start_ns: int,
        end_ns: int,
        index: dict[int, list[tuple[int, int]]] | dict[int, bytes],
    ) -> None:
        """Write one chunk of message records and its per-channel message indexes."""
        self._output(functools.partial(self._write_chunk, raw, start_ns, end_ns, index))

    def _write_chunk(
        self,
        raw: bytes | memoryview,
        start_ns: int,
        end_ns: int,
        index: dict[int, list[tuple[int, int]]] | dict[int, bytes],
    ) -> None:
        compressed = self._compressor.compress(raw) if self._compressor else bytes(raw)
        chunk_record = fmt.encode_chunk(start_ns, end_ns, raw, self._compression, compressed)
        chunk_offset = self._offset
        index_offsets: dict[int, int] = {}
        index_records = []
        at = chunk_offset + len(chunk_record)
        for channel_id in sorted(index):
            index_offsets[channel_id] = at
            record = fmt.encode_message_index(channel_id, index[channel_id])
            index_records.append(record)
            at += len(record)
        indexes = b''.join(index_records)
        self._write_out(chunk_record + indexes)
        self._sync()
        self._chunk_indexes.append(
            fmt.encode_chunk_index(
                fmt.ChunkIndexRecord(
                    start_ns,
                    end_ns,
                    chunk_offset,
                    len(chunk_record),
                    index_offsets,
                    len(indexes),
                    self._compression,
                    len(compressed),
                    len(raw),
                )
            )
        )
        self._start_ns = min(self._start_ns, start_ns)
        self._end_ns = max(self._end_ns, end_ns)

    def write_interleaved(
        self,
        topics: Sequence[str],
        which: np.ndarray,
        datas: Sequence[bytes],
        log_times_ns: np.ndarray,
        publish_times_ns: np.ndarray | None = None,
    ) -> None:
        """Write N messages of several topics in the given order, vectorized (offline tools).

        The open chunk is written first, then the N messages go to new chunks of about
        ``chunk_size`` bytes, built with numpy instead of per-message Python.

        Args:
            topics: declared topic names.
            which: shape (N,), int, index into ``topics`` of each message.
            datas: N serialized messages.
            log_times_ns: shape (N,), int64 log times [ns].
            publish_times_ns: shape (N,), int64; default the log times.

        Raises:
            BagUsageError: unknown topic, or inconsistent lengths.
        """
        self._check_open()
        n = len(datas)
        which = np.asarray(which, dtype=np.int64)
        log_signed = np.asarray(log_times_ns, dtype=np.int64)
        pub_signed = log_signed if publish_times_ns is None else np.asarray(publish_times_ns)
        if (log_signed < 0).any() or (pub_signed < 0).any():
            raise BagUsageError('write_interleaved: times must be >= 0 ns')
        log = log_signed.astype(np.uint64)
        pub = pub_signed.astype(np.uint64)
        if which.shape != (n,) or log.shape != (n,) or pub.shape != (n,):
            raise BagUsageError('write_interleaved: which, datas and times differ in length')
        if n == 0:
            return
        if which.min() < 0 or which.max() >= len(topics):
            raise BagUsageError('write_interleaved: topic index out of range')
        entries = [self._topic(t) for t in topics]
        self.flush()
        channel = np.array([e.channel_id for e in entries], dtype=np.uint16)[which]
        sequence = np.empty(n, dtype=np.int64)
        for k, entry in enumerate(entries):
            members = np.flatnonzero(which == k)
            sequence[members] = entry.count + np.arange(members.size)
            entry.count += members.size
        packed = datas if isinstance(datas, PackedParts) else PackedMessages.from_list(datas)
        lengths = packed.lengths
        ends = np.cumsum(lengths + _MESSAGE_HEAD.size)
        starts = ends - (lengths + _MESSAGE_HEAD.size)
        heads = np.zeros(n, dtype=_MESSAGE_DTYPE)
        heads['op'] = fmt.Op.MESSAGE
        heads['length'] = lengths + _MESSAGE_FIXED
        heads['channel'] = channel
        heads['sequence'] = sequence & 0xFFFFFFFF
        heads['log'] = log
        heads['publish'] = pub
        # Every 31-byte record head, then every message's bytes, copied into place by one
        # compiled loop each (per part): no Python object per message.
        out = np.empty(int(ends[-1]), dtype=np.uint8)
        # compiled: numba is loaded by the offline tools that write this way anyway
        from vd_observer_node.bag.copy_kernel import copy_ranges

        size = _MESSAGE_HEAD.size
        head_at = np.arange(n, dtype=np.int64) * size
        copy_ranges(out, starts, heads.view(np.uint8), head_at, np.full(n, size, np.int64))
        packed.scatter_into(out, starts + size, copy_ranges)
        records = out.data  # chunks are compressed and CRC'd from it, not copied
        # A new chunk starts at the first message beginning past each chunk_size multiple.
        bucket = starts // self._chunk_size
        firsts = np.concatenate([[0], np.flatnonzero(np.diff(bucket)) + 1])
        marks = np.zeros(n, dtype=np.int64)
        marks[firsts] = 1
        chunk = np.cumsum(marks) - 1  # the chunk of each message
        # The message indexes of all chunks at once: (log time, offset in its chunk) pairs
        # ordered by chunk, channel and position; each (chunk, channel) is one slice.
        order = np.lexsort((channel, chunk))  # stable: positions stay in order
        pairs = np.empty((n, 2), dtype='<u8')
        pairs[:, 0] = log[order]
        pairs[:, 1] = starts[order] - starts[firsts][chunk[order]]
        packed_pairs = pairs.tobytes()
        key = chunk[order] * 65536 + channel[order]
        groups = np.concatenate([[0], np.flatnonzero(np.diff(key)) + 1, [n]]).tolist()
        group_chunk = chunk[order][groups[:-1]].tolist()
        group_channel = channel[order][groups[:-1]].tolist()
        indexes: list[dict[int, bytes]] = [{} for _ in range(firsts.size)]
        for g, (a, b) in enumerate(itertools.pairwise(groups)):
            indexes[group_chunk[g]][group_channel[g]] = packed_pairs[16 * a : 16 * b]
        low = np.minimum.reduceat(log, firsts).tolist()
        high = np.maximum.reduceat(log, firsts).tolist()
        bounds = [*starts[firsts].tolist(), int(ends[-1])]
        for k in range(firsts.size):
            raw = records[bounds[k] : bounds[k + 1]]
            self._emit_chunk(raw, low[k], high[k], indexes[k])

    # -- closing -----------------------------------------------------------------------------

    def summary(self) -> BagSummary:
        """What ``metadata.yaml`` will state (counts and times of the chunks written)."""
        count = self.message_count
        return BagSummary(
            file_name=self.mcap_path.name,
            start_ns=self._start_ns if count else 0,
            end_ns=self._end_ns if count else 0,
            topics=[
                TopicSummary(
                    t.name,
                    t.msgtype,
                    t.count,
                    t.qos_profiles_yaml,
                    type_hash(t.msgtype) if self._has_hash(t.msgtype) else '',
                )
                for t in self._topics.values()
            ],
            compression=self._compression,
        )

    @staticmethod
    def _has_hash(msgtype: str) -> bool:
        try:
            type_hash(msgtype)
        except BagError:
            return False
        return True

    def close(self) -> None:
        """Write the last chunk, the MCAP summary and footer, then ``metadata.yaml``.

        Idempotent. After a failed write (e.g. disk full) it only closes the file, leaving a
        bag for ``vd bag repair``.
        """
        if self._closed:
            return
        if self._failed:
            self._closed = True
            self._stop_worker()
            self._file.close()
            return
        try:
            self.flush()
            self._collect(keep=0)  # every chunk in the file before the summary
            self._stop_worker()
            summary = self.summary()
            metadata_offset = self._offset
            metadata_record = fmt.encode_metadata(
                'rosbag2', {'serialized_metadata': render_metadata(summary, inner=True)}
            )
            self._write_out(metadata_record)
            self._write_out(fmt.encode_data_end(self._crc))
            summary_start = self._offset
            groups: list[tuple[int, bytes]] = [
                (fmt.Op.SCHEMA, b''.join(r for _, r in self._schemas.values())),
                (fmt.Op.CHANNEL, b''.join(self._channel_records)),
                (fmt.Op.CHUNK_INDEX, b''.join(self._chunk_indexes)),
                (
                    fmt.Op.METADATA_INDEX,
                    fmt.encode_metadata_index(metadata_offset, len(metadata_record), 'rosbag2'),
                ),
                (
                    fmt.Op.STATISTICS,
                    fmt.encode_statistics(
                        summary.message_count,
                        len(self._schemas),
                        len(self._topics),
                        1,
                        len(self._chunk_indexes),
                        summary.start_ns,
                        summary.end_ns,
                        {t.channel_id: t.count for t in self._topics.values()},
                    ),
                ),
            ]
            body = b''
            offsets = b''
            at = summary_start
            for op, data in groups:
                if data:
                    offsets += fmt.encode_summary_offset(op, at, len(data))
                    body += data
                    at += len(data)
            summary_bytes = body + offsets
            footer = fmt.encode_footer(summary_start, summary_start + len(body), summary_bytes)
            self._write_out(summary_bytes + footer + fmt.MAGIC)
            self._fsync = True
            self._sync()
            self._file.close()
            self._closed = True
            write_metadata(self.path, summary)
        except OSError as exc:
            raise BagPathError(f'{self.path}: cannot finish bag: {exc.strerror or exc}') from exc
        finally:
            self._stop_worker()
            if not self._file.closed:
                self._file.close()
            self._closed = True

    def _stop_worker(self) -> None:
        if self._worker is not None:
            self._cancel_pending()
            self._worker.shutdown(wait=True)
            self._worker = None

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
