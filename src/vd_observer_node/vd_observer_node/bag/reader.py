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

import os
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from vd_observer_node.bag.errors import (
    BagCorruptError,
    BagFormatError,
    BagNotFoundError,
    BagUsageError,
)
from vd_observer_node.bag.file_scan import FileScan, map_file
from vd_observer_node.bag.metadata import read_metadata_file_paths
from vd_observer_node.bag.packed import PackedMessages
from vd_observer_node.bag.typestore import decoding_type, deserialize, register_definition

__all__ = [
    'BagReader',
    'RawMessage',
    'TopicArrays',
    'TopicInfo',
    'find_mcap_files',
]


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


class _ChannelSelector:
    """Decides per channel id (once) whether its topic is wanted; remembers topic and type."""

    def __init__(self, scan: FileScan, selected: set[str] | None) -> None:
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

    def _scans(self, problems: list[BagCorruptError] | None = None) -> Iterator[FileScan]:
        for file in self.files:
            try:
                buf = map_file(file)
            except OSError as exc:
                raise BagNotFoundError(f'{file}: cannot read: {exc.strerror or exc}') from exc
            yield FileScan(
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
    def _topic_infos(scans: list[FileScan]) -> dict[str, TopicInfo]:
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
