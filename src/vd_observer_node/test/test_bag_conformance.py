"""MCAP conformance: the format's official corpus, and the forward-compatibility rules.

1. The corpus (`shared/mcap-conformance`, beside the repository; ``VD_MCAP_CONFORMANCE``
   overrides the location): 416 ``.mcap`` files, each with a ``.json`` listing the records a
   reader must see. Every file must read to what its JSON says through everything vd's reader
   exposes: the messages (topic, type, log and publish time, bytes; in file order and
   log-time order), the topics (type, count, definition, QoS metadata, message and schema
   encodings, from the summary where it is complete, else from a scan), the per-topic arrays
   and the time range, in strict mode and with no damage reported in recover mode. The
   corpus' encodings are not ROS 2 ones, so ``messages()`` must refuse them with a
   ``BagFormatError`` naming the encoding. Not exposed by vd, so not compared: message
   sequence numbers, channel metadata other than ``offered_qos_profiles``, attachments and
   metadata records (checked only to be skipped without complaint).
   Without the corpus the tests skip, except under CI (``CI`` set), where that fails.
2. Forward compatibility, which the corpus does not exercise: records of unknown opcodes
   (in the data section, inside chunks, in the summary) are skipped, and fields after the
   known ones of extensible records (chunks, message indexes, schemas, channels, statistics,
   ...) are ignored, as the specification asks of readers; opcode 0x00 stays damage.
"""

from __future__ import annotations

import json
import os
import struct
import zlib
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NoReturn

import lz4.frame
import numpy as np
import pytest
import zstandard
from mcap.stream_reader import StreamReader
from vd_observer_node.bag import BagCorruptError, BagFormatError, BagReader, RawMessage
from vd_observer_node.bag import mcap_format as fmt
from vd_observer_node.bag.cdr_batch import encode_batch
from vd_observer_node.bag.reader import TopicInfo
from vd_observer_node.bag.typestore import message_definition

CORPUS_ENV = 'VD_MCAP_CONFORMANCE'
CORPUS_FILES = 416  # foxglove/mcap tests/conformance/data at 95d0673 (see its README.md)
REPO_ROOT = Path(__file__).resolve().parents[3]


def _corpus_dir() -> Path:
    override = os.environ.get(CORPUS_ENV)
    if override:
        return Path(override)
    return REPO_ROOT.parent / 'shared' / 'mcap-conformance'


def _in_ci() -> bool:
    return os.environ.get('CI', '').strip().lower() not in ('', '0', 'false', 'no')


CORPUS = _corpus_dir()
FILES = sorted((CORPUS / 'data').rglob('*.mcap')) if (CORPUS / 'data').is_dir() else []


def _missing_corpus() -> NoReturn:
    reason = (
        f'MCAP conformance corpus not found at {CORPUS} (expected data/<Case>/*.mcap; '
        f'set {CORPUS_ENV} to its folder)'
    )
    if _in_ci():
        pytest.fail(f'{reason}; CI must run the conformance tests')
    pytest.skip(reason)


def test_corpus_is_present_and_complete() -> None:
    if not FILES:
        _missing_corpus()
    assert len(FILES) == CORPUS_FILES, f'{len(FILES)} .mcap files in {CORPUS}/data'
    missing = [f.name for f in FILES if not f.with_suffix('.json').is_file()]
    assert not missing, f'no .json for {missing}'


# --- what a corpus JSON says ------------------------------------------------------------


@dataclass(frozen=True)
class Expected:
    """What a reader must see in one corpus file, in vd's terms."""

    messages: list[RawMessage]
    topics: dict[str, TopicInfo]
    refused: dict[str, str]  # topic with messages -> the encoding messages() must name


def _fields(record: dict[str, Any]) -> dict[str, Any]:
    return {name: value for name, value in record['fields']}


def _expected(json_path: Path) -> Expected:
    records = json.loads(json_path.read_text())['records']
    schemas: dict[int, dict[str, Any]] = {}
    channels: dict[int, dict[str, Any]] = {}
    messages: list[RawMessage] = []
    for record in records:
        kind, f = record['type'], _fields(record)
        if kind == 'Schema':
            schemas[int(f['id'])] = f
        elif kind == 'Channel':
            channels[int(f['id'])] = f
        elif kind == 'Message':
            channel = channels[int(f['channel_id'])]
            schema = schemas.get(int(channel['schema_id']))
            messages.append(
                RawMessage(
                    channel['topic'],
                    schema['name'] if schema else '',
                    int(f['log_time']),
                    bytes(int(b) for b in f['data']),
                    int(f['publish_time']),
                )
            )
    counts = Counter(m.topic for m in messages)
    topics: dict[str, TopicInfo] = {}
    refused: dict[str, str] = {}
    for channel in channels.values():
        schema = schemas.get(int(channel['schema_id']))
        topic = channel['topic']
        topics[topic] = TopicInfo(
            topic,
            schema['name'] if schema else '',
            counts[topic],
            bytes(int(b) for b in schema['data']).decode(errors='replace') if schema else '',
            channel['metadata'].get('offered_qos_profiles', ''),
            channel['message_encoding'],
            schema['encoding'] if schema else '',
        )
        assert channel['message_encoding'] != 'cdr', 'a corpus file vd could decode: compare'
        if counts[topic]:
            refused[topic] = channel['message_encoding']
    return Expected(messages, topics, refused)


# one case per file, so that a failure names it; without the corpus one case that says so
CASES = [pytest.param(f, id=f.stem) for f in FILES] or [pytest.param(None, id='no-corpus')]


@pytest.mark.parametrize('path', CASES)
def test_corpus_file_reads_as_its_json_says(path: Path | None) -> None:
    if path is None:
        _missing_corpus()
    expected = _expected(path.with_suffix('.json'))

    reader = BagReader(path)  # strict: any damage raises
    assert reader.topics == expected.topics  # first: from the summary where it is complete
    assert list(reader.raw_messages()) == expected.messages
    ordered = sorted(expected.messages, key=lambda m: m.log_time_ns)  # stable, as the reader
    assert list(reader.raw_messages(ordered=True)) == ordered
    assert reader.topics == expected.topics

    arrays = reader.topic_arrays()
    assert sorted(arrays) == sorted({m.topic for m in expected.messages})
    for topic, got in arrays.items():
        mine = [m for m in expected.messages if m.topic == topic]
        assert got.msgtype == mine[0].msgtype
        assert got.log_time_ns.tolist() == [m.log_time_ns for m in mine]
        assert got.datas == [m.data for m in mine]
    times = [m.log_time_ns for m in expected.messages]
    assert reader.time_range_ns() == ((min(times), max(times)) if times else None)

    for topic, encoding in expected.refused.items():
        with pytest.raises(BagFormatError, match=f'message encoding {encoding!r}'):
            next(reader.messages([topic]))
    assert list(reader.messages(['/not/in/the/file'])) == []

    lenient = BagReader(path, recover=True)
    assert list(lenient.raw_messages()) == expected.messages
    assert lenient.topics == expected.topics
    assert lenient.problems == []


# --- forward compatibility: unknown opcodes and trailing fields ---------------------------

N = 40  # messages per topic
TOPICS = {'/a': 'vd_msgs/msg/WheelAngles', '/s': 'vd_msgs/msg/Slope'}
UNKNOWN_OPS = (0x10, 0x7F, 0x80, 0xFF)  # a future official record; application extensions


def _extend(framed: bytes, extra: bytes) -> bytes:
    """The record ``framed`` with ``extra`` bytes after its fields (a later format version)."""
    return fmt.record(framed[0], framed[fmt.RECORD_PREFIX.size :] + extra)


def _unknown(op: int, k: int) -> bytes:
    return fmt.record(op, bytes(range(k, k + 7)))


def _messages() -> list[tuple[int, int, bytes]]:
    """(channel id, log ns, CDR) of both topics, interleaved in log-time order."""
    rng = np.random.default_rng(30)
    stamps = np.arange(N, dtype=np.int64) * 1_000_000 + 5_000_000_000
    angles = encode_batch(TOPICS['/a'], stamps, 'base_link', {'angle': rng.normal(size=(N, 4))})
    slopes = encode_batch(
        TOPICS['/s'],
        stamps,
        'base_link',
        {
            'angle': rng.normal(size=N),
            'valid': rng.integers(0, 2, N).astype(bool),
            'torque_source': rng.integers(0, 3, N),
            'sources': np.arange(N) % 4,
        },
    )
    out = []
    for k in range(N):
        out += [(1, int(stamps[k]), angles[k]), (2, int(stamps[k]) + 1, slopes[k])]
    return out


def _message(channel_id: int, log_ns: int, data: bytes, sequence: int) -> bytes:
    body = struct.pack('<HIQQ', channel_id, sequence, log_ns, log_ns) + data
    return fmt.record(fmt.Op.MESSAGE, body)


def _compress(records: bytes, compression: str) -> bytes:
    if compression == 'zstd':
        return zstandard.ZstdCompressor().compress(records)
    if compression == 'lz4':
        return bytes(lz4.frame.compress(records))
    return records


def build_file(
    *, unknown: bool, trailing: bool, compression: str, summary: bool, channel_counts: bool = True
) -> bytes:
    """An MCAP file with two ROS 2 topics: one declared in the data section, one in a chunk.

    Its messages are in one chunk (all but the last two) and after it, unchunked. Offsets,
    lengths and CRCs (chunk, data section, summary) are those of the file as built.

    Args:
        unknown: records of unknown opcodes in the data section, inside the chunk and in the
            summary.
        trailing: bytes after the known fields of every extensible record (all but footer
            and messages, whose layout cannot grow), inside the chunk too.
        compression: of the chunk: '', 'zstd' or 'lz4'.
        summary: write the summary (schemas, channels, statistics, chunk index, summary
            offsets); else the footer says there is none.
        channel_counts: the statistics' per-channel message counts (an empty map means
            "not available").
    """
    extra = b'\x01\xff\xff\x00future field' if trailing else b''

    def ext(framed: bytes) -> bytes:
        return _extend(framed, extra) if trailing else framed

    def unk(op: int) -> bytes:
        return _unknown(op, op & 0x3F) if unknown else b''

    schema = {
        cid: fmt.encode_schema(cid, t, 'ros2msg', message_definition(t).encode())
        for cid, t in ((1, TOPICS['/a']), (2, TOPICS['/s']))
    }
    channel = {
        cid: fmt.encode_channel(cid, cid, topic, 'cdr', {'offered_qos_profiles': f'q{cid}'})
        for cid, topic in ((1, '/a'), (2, '/s'))
    }
    messages = _messages()
    chunked, loose = messages[:-2], messages[-2:]

    out = bytearray(fmt.MAGIC)
    out += ext(fmt.encode_header('ros2', 'vd conformance test'))
    out += unk(0x10) + unk(0x80)
    out += ext(schema[1]) + ext(channel[1])

    # the chunk: the second topic's schema and channel, an unknown record, the messages
    records = bytearray(ext(schema[2]) + unk(0x7F) + ext(channel[2]))
    index: dict[int, list[tuple[int, int]]] = {1: [], 2: []}
    for seq, (cid, log_ns, data) in enumerate(chunked):
        index[cid].append((log_ns, len(records)))
        records += _message(cid, log_ns, data, seq)
    records += unk(0xFF)
    payload = _compress(bytes(records), compression)
    start_ns, end_ns = chunked[0][1], max(t for _, t, _ in chunked)
    chunk_at = len(out)
    out += ext(fmt.encode_chunk(start_ns, end_ns, bytes(records), compression, payload))
    chunk_length = len(out) - chunk_at
    index_offsets: dict[int, int] = {}
    for cid, entries in index.items():
        index_offsets[cid] = len(out)
        out += ext(fmt.encode_message_index(cid, entries))
    index_length = len(out) - chunk_at - chunk_length
    out += unk(0x11)
    for seq, (cid, log_ns, data) in enumerate(loose, start=len(chunked)):
        out += _message(cid, log_ns, data, seq)
    out += ext(fmt.encode_metadata('rosbag2', {'serialized_metadata': ''}))
    out += ext(fmt.encode_data_end(zlib.crc32(out)))

    if not summary:
        return bytes(out + fmt.encode_footer(0, 0, b'') + fmt.MAGIC)
    summary_start = len(out)
    groups: list[tuple[int, int, int]] = []

    def group(op: int, body: bytes) -> None:
        groups.append((op, len(out), len(body)))
        out.extend(body)

    group(fmt.Op.SCHEMA, ext(schema[1]) + ext(schema[2]))
    group(fmt.Op.CHANNEL, ext(channel[1]) + ext(channel[2]))
    if unknown:
        group(0x12, unk(0x12) + unk(0x12))
    counts = Counter(cid for cid, _, _ in messages) if channel_counts else Counter()
    last = max(t for _, t, _ in messages)
    group(
        fmt.Op.STATISTICS,
        ext(fmt.encode_statistics(len(messages), 2, 2, 1, 1, start_ns, last, dict(counts))),
    )
    group(
        fmt.Op.CHUNK_INDEX,
        ext(
            fmt.encode_chunk_index(
                fmt.ChunkIndexRecord(
                    start_ns,
                    end_ns,
                    chunk_at,
                    chunk_length,
                    index_offsets,
                    index_length,
                    compression,
                    len(payload),
                    len(records),
                )
            )
        ),
    )
    offsets_start = len(out)
    for op, start, length in groups:
        out += ext(fmt.encode_summary_offset(op, start, length))
    out += unk(0x13)
    footer = fmt.encode_footer(summary_start, offsets_start, bytes(out[summary_start:]))
    return bytes(out + footer + fmt.MAGIC)


VARIANTS = [
    pytest.param(
        unknown,
        trailing,
        compression,
        summary,
        id=f'{name}-{compression or "none"}-{"summary" if summary else "no-summary"}',
    )
    for name, unknown, trailing in (
        ('unknown-ops', True, False),
        ('trailing-fields', False, True),
        ('both', True, True),
    )
    for compression in ('', 'zstd', 'lz4')
    for summary in (True, False)
]


@pytest.mark.parametrize(('unknown', 'trailing', 'compression', 'summary'), VARIANTS)
def test_unknown_records_and_fields_are_skipped(
    tmp_path: Path, unknown: bool, trailing: bool, compression: str, summary: bool
) -> None:
    data = build_file(unknown=unknown, trailing=trailing, compression=compression, summary=summary)
    path = tmp_path / 'future.mcap'
    path.write_bytes(data)
    names = {1: '/a', 2: '/s'}
    sent = [RawMessage(names[c], TOPICS[names[c]], t, d, t) for c, t, d in _messages()]

    # The file is what it claims: the mcap library reads its records with CRCs checked (it
    # skips unknown records and trailing fields of top-level records; chunks left whole,
    # as it does not skip trailing fields of the records inside them).
    with path.open('rb') as f:
        kinds = Counter(
            type(r).__name__ for r in StreamReader(f, emit_chunks=True, validate_crcs=True).records
        )
    assert kinds['Chunk'] == 1 and kinds['Message'] == 2 and kinds['Footer'] == 1

    reader = BagReader(path)
    assert list(reader.raw_messages()) == sent
    infos = reader.topics
    assert {t: (i.msgtype, i.message_count, i.qos_profiles_yaml) for t, i in infos.items()} == {
        '/a': (TOPICS['/a'], N, 'q1'),
        '/s': (TOPICS['/s'], N, 'q2'),
    }
    assert all(
        i.message_encoding == 'cdr' and i.schema_encoding == 'ros2msg' for i in infos.values()
    )
    assert infos['/a'].definition == message_definition(TOPICS['/a'])
    decoded = list(reader.messages())
    assert [(t, log) for t, _, log, _ in decoded] == [(m.topic, m.log_time_ns) for m in sent]
    for (_, msgtype, log_ns, msg), raw in zip(decoded, sent, strict=True):
        assert msgtype == raw.msgtype
        stamp_ns = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        assert stamp_ns == (log_ns - 1 if raw.topic == '/s' else log_ns)  # see _messages
    lenient = BagReader(path, recover=True)
    assert list(lenient.raw_messages()) == sent
    assert lenient.topics == infos
    assert lenient.problems == []


def _data_end_at(data: bytes) -> int:
    """Offset of the data end record of a file built without summary and trailing fields."""
    at = len(data) - len(fmt.MAGIC) - len(fmt.encode_footer(0, 0, b'')) - 13
    assert data[at : at + 9] == fmt.RECORD_PREFIX.pack(fmt.Op.DATA_END, 4)
    return at


def test_opcode_zero_is_still_damage(tmp_path: Path) -> None:
    """0x00 is no opcode at all (a zero-filled tail after a crash): damage, not skipped."""
    data = build_file(unknown=False, trailing=False, compression='zstd', summary=False)
    data_end = _data_end_at(data)
    damaged = data[:data_end] + fmt.record(0x00, b'\x00' * 16) + data[data_end:]
    path = tmp_path / 'zeros.mcap'
    path.write_bytes(damaged)
    reader = BagReader(path)
    with pytest.raises(BagCorruptError, match='invalid record opcode 0x00') as caught:
        list(reader.raw_messages())
    assert caught.value.offset == data_end


def test_unknown_record_running_past_the_end_is_damage(tmp_path: Path) -> None:
    """Skipping an unknown record trusts its length only as far as the file goes."""
    data = build_file(unknown=False, trailing=False, compression='', summary=False)
    data_end = _data_end_at(data)
    record = struct.pack('<BQ', 0x42, len(data)) + b'\x00' * 8
    path = tmp_path / 'long.mcap'
    path.write_bytes(data[:data_end] + record + data[data_end:])
    with pytest.raises(BagCorruptError, match='runs past the end of the file'):
        list(BagReader(path).raw_messages())


def test_summary_without_per_channel_counts_is_not_taken_for_zero(tmp_path: Path) -> None:
    """Statistics whose per-channel counts are "not available" (an empty map): the topic
    listing counts the messages by a scan instead of reporting 0 per topic."""
    path = tmp_path / 'no-counts.mcap'
    path.write_bytes(
        build_file(
            unknown=False, trailing=False, compression='zstd', summary=True, channel_counts=False
        )
    )
    reader = BagReader(path)
    assert {t: i.message_count for t, i in reader.topics.items()} == {'/a': N, '/s': N}
    assert reader.problems == []


def _single_message_file(schema_encoding: str | None) -> bytes:
    """One CDR WheelAngles message on '/a', unchunked; its schema in ``schema_encoding``
    (None: the channel has no schema)."""
    _, log_ns, data = _messages()[0]
    out = bytearray(fmt.MAGIC + fmt.encode_header('ros2', ''))
    schema_id = 0
    if schema_encoding is not None:
        schema_id = 1
        text = message_definition(TOPICS['/a']).encode()
        out += fmt.encode_schema(1, TOPICS['/a'], schema_encoding, text)
    out += fmt.encode_channel(1, schema_id, '/a', 'cdr', {})
    out += _message(1, log_ns, data, 0)
    out += fmt.encode_data_end(zlib.crc32(out))
    return bytes(out + fmt.encode_footer(0, 0, b'') + fmt.MAGIC)


@pytest.mark.parametrize(
    ('schema_encoding', 'reason'),
    [
        (None, 'no schema'),
        ('ros2idl', "schema encoding 'ros2idl' is not supported"),
        ('', "schema encoding '' is not supported"),
    ],
)
def test_messages_refuses_what_it_cannot_decode_and_raw_reading_still_works(
    tmp_path: Path, schema_encoding: str | None, reason: str
) -> None:
    path = tmp_path / 'one.mcap'
    path.write_bytes(_single_message_file(schema_encoding))
    reader = BagReader(path)
    with pytest.raises(BagFormatError, match=reason):
        list(reader.messages())
    (message,) = reader.raw_messages()
    assert message.data == _messages()[0][2]


def test_messages_decodes_a_ros2msg_schema(tmp_path: Path) -> None:
    """The counterpart of the refusals above: the same file with a 'ros2msg' schema."""
    path = tmp_path / 'one.mcap'
    path.write_bytes(_single_message_file('ros2msg'))
    ((topic, msgtype, log_ns, msg),) = BagReader(path).messages()
    assert (topic, msgtype, log_ns) == ('/a', TOPICS['/a'], _messages()[0][1])
    assert len(msg.angle) == 4
