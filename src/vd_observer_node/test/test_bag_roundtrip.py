"""Round trip of every vd_msgs type (and the standard types we record) through a bag.

Written with BagWriter, read back with our BagReader, rosbags' rosbag2 Reader and the
mcap + mcap-ros2-support decoder; the summary must list zstd chunks.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.rosbag2 import Reader as RosbagsReader
from vd_common.topics import (
    ESTIMATES_SLOPE,
    ESTIMATES_TIRE_FORCES,
    SENSORS_WHEEL_ANGLES,
    TRUTH_NAMESPACE,
    TRUTH_SLOPE,
)
from vd_observer_node.bag import BagReader, BagWriter
from vd_observer_node.bag.typestore import (
    VD_MSG_TYPES,
    deserialize,
    message_class,
    message_definition,
    serialize,
    vd_typestore,
)

STANDARD_TYPES = (
    'geometry_msgs/msg/TwistStamped',
    'geometry_msgs/msg/AccelStamped',
    'rosgraph_msgs/msg/Clock',
    'diagnostic_msgs/msg/DiagnosticArray',
    'std_msgs/msg/Float64',
)
ALL_TYPES = VD_MSG_TYPES + STANDARD_TYPES
_INTS = {'int8': (-128, 127), 'uint8': (0, 255), 'int32': (-(2**31), 2**31 - 1)}
_INTS |= {'uint32': (0, 2**32 - 1), 'int64': (-(2**40), 2**40), 'uint64': (0, 2**40)}
_INTS |= {'int16': (-(2**15), 2**15 - 1), 'uint16': (0, 2**16 - 1), 'byte': (0, 127)}
_NUMPY = {'float64': np.float64, 'float32': np.float32, 'bool': np.bool_, 'int8': np.int8}
_NUMPY |= {'uint8': np.uint8, 'int32': np.int32, 'uint32': np.uint32}


def _value(base: str, rng: np.random.Generator) -> Any:
    if base in ('float64', 'float32'):
        return float(np.float32(rng.normal(0.0, 100.0)))  # exact in both widths
    if base == 'bool':
        return bool(rng.integers(0, 2))
    if base == 'string':
        return ''.join(rng.choice(list('abcxyz_/019'), size=int(rng.integers(0, 12))))
    low, high = _INTS[base]
    return int(rng.integers(low, high, endpoint=True))


def make_message(msgtype: str, rng: np.random.Generator) -> Any:
    """A rosbags message of ``msgtype`` with random field values (recursively)."""
    store = vd_typestore()
    _, fields = store.fielddefs[msgtype]
    kwargs: dict[str, Any] = {}
    for name, (kind, spec) in fields:
        if kind.name == 'BASE':
            kwargs[name] = _value(spec[0], rng)
        elif kind.name == 'NAME':
            kwargs[name] = make_message(spec, rng)
        else:  # ARRAY (fixed) or SEQUENCE
            size = spec[1] if kind.name == 'ARRAY' else int(rng.integers(0, 3))
            sub_kind, sub_spec = spec[0]
            if sub_kind.name == 'BASE' and sub_spec[0] in _NUMPY:
                values = [_value(sub_spec[0], rng) for _ in range(size)]
                kwargs[name] = np.array(values, dtype=_NUMPY[sub_spec[0]])
            elif sub_kind.name == 'BASE':
                kwargs[name] = [_value(sub_spec[0], rng) for _ in range(size)]
            else:
                kwargs[name] = [make_message(sub_spec, rng) for _ in range(size)]
    return message_class(msgtype)(**kwargs)


def assert_same(ours: Any, other: Any, where: str = 'msg') -> None:
    """Compare a rosbags message with another decoding (rosbags or mcap_ros2) field by field."""
    if hasattr(ours, '__dataclass_fields__'):
        for name in ours.__dataclass_fields__:
            if name == '__msgtype__' or name.isupper():
                continue  # constants are not decoded by every reader
            assert_same(getattr(ours, name), getattr(other, name), f'{where}.{name}')
    elif isinstance(ours, (list, tuple, np.ndarray)):
        assert len(ours) == len(other), where
        for k, (a, b) in enumerate(zip(ours, other, strict=True)):
            assert_same(a, b, f'{where}[{k}]')
    elif isinstance(ours, float):
        assert float(other) == ours, where
    else:
        assert ours == other, where


@pytest.fixture(scope='module')
def written(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, list[Any]]]:
    """A bag with 20 random messages of every type on its own topic (seeded)."""
    rng = np.random.default_rng(42)
    path = tmp_path_factory.mktemp('rt') / 'bag'
    sent: dict[str, list[Any]] = {}
    with BagWriter(path, chunk_size=2048) as writer:
        for msgtype in ALL_TYPES:
            writer.add_topic('/t/' + msgtype.replace('/msg/', '_'), msgtype)
        for k in range(20):
            for msgtype in ALL_TYPES:
                topic = '/t/' + msgtype.replace('/msg/', '_')
                msg = make_message(msgtype, rng)
                sent.setdefault(topic, []).append(msg)
                writer.write(topic, serialize(msg), 1_000_000 * k + 7, 1_000_000 * k)
    return path, sent


def test_cdr_round_trip_in_memory() -> None:
    rng = np.random.default_rng(0)
    for msgtype in ALL_TYPES:
        msg = make_message(msgtype, rng)
        assert_same(msg, deserialize(serialize(msg), msgtype), msgtype)


def test_our_reader_decodes_every_type(written: tuple[Path, dict[str, list[Any]]]) -> None:
    path, sent = written
    got: dict[str, list[Any]] = {}
    times: dict[str, list[int]] = {}
    for topic, _msgtype, log_ns, msg in BagReader(path).messages():
        got.setdefault(topic, []).append(msg)
        times.setdefault(topic, []).append(log_ns)
    assert set(got) == set(sent)
    for topic, msgs in sent.items():
        assert len(got[topic]) == len(msgs)
        for a, b in zip(msgs, got[topic], strict=True):
            assert_same(a, b, topic)
        assert times[topic] == [1_000_000 * k + 7 for k in range(20)]


def test_rosbags_reader_reads_our_bag(written: tuple[Path, dict[str, list[Any]]]) -> None:
    path, sent = written
    store = vd_typestore()
    got: dict[str, list[Any]] = {}
    with RosbagsReader(path) as reader:
        assert {c.topic: c.msgcount for c in reader.connections} == {t: 20 for t in sent}
        for conn, _timestamp, data in reader.messages():
            got.setdefault(conn.topic, []).append(store.deserialize_cdr(data, conn.msgtype))
    for topic, msgs in sent.items():
        for a, b in zip(msgs, got[topic], strict=True):
            assert_same(a, b, topic)


def test_mcap_ros2_decodes_with_embedded_definitions(
    written: tuple[Path, dict[str, list[Any]]],
) -> None:
    path, sent = written
    got: dict[str, list[Any]] = {}
    with (path / 'bag_0.mcap').open('rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None
        assert summary.chunk_indexes, 'no chunk index in the summary'
        assert {c.compression for c in summary.chunk_indexes} == {'zstd'}
        assert all(c.compressed_size < c.uncompressed_size for c in summary.chunk_indexes)
        assert {s.encoding for s in summary.schemas.values()} == {'ros2msg'}
        assert summary.statistics is not None
        assert summary.statistics.message_count == 20 * len(ALL_TYPES)
        for schema, channel, _message, decoded in reader.iter_decoded_messages():
            assert schema is not None
            assert channel.message_encoding == 'cdr'
            got.setdefault(channel.topic, []).append(decoded)
    for topic, msgs in sent.items():
        for a, b in zip(msgs, got[topic], strict=True):
            assert_same(a, b, topic)


def test_mcap_stream_reader_validates_our_crcs(
    written: tuple[Path, dict[str, list[Any]]],
) -> None:
    from mcap.records import Chunk, DataEnd, Footer, Message
    from mcap.stream_reader import StreamReader

    path, _ = written
    kinds = []
    for record in StreamReader(str(path / 'bag_0.mcap'), validate_crcs=True).records:
        kinds.append(type(record))
        if isinstance(record, DataEnd):
            assert record.data_section_crc != 0
    assert kinds.count(Message) == 20 * len(ALL_TYPES)  # chunks are broken up, CRC-checked
    assert Chunk not in kinds
    assert kinds[-1] is Footer


@pytest.mark.filterwarnings('ignore::DeprecationWarning')
def test_mcap_ros2_reader_module_decodes(written: tuple[Path, dict[str, list[Any]]]) -> None:
    from mcap_ros2.reader import read_ros2_messages

    path, sent = written
    got: dict[str, list[Any]] = {}
    for item in read_ros2_messages(str(path / 'bag_0.mcap')):
        got.setdefault(item.channel.topic, []).append(item.ros_msg)
    for topic, msgs in sent.items():
        for a, b in zip(msgs, got[topic], strict=True):
            assert_same(a, b, topic)


def test_metadata_yaml_is_rosbag2_version_9(written: tuple[Path, dict[str, list[Any]]]) -> None:
    path, sent = written
    info = yaml.safe_load((path / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['version'] == 9
    assert info['storage_identifier'] == 'mcap'
    assert info['relative_file_paths'] == ['bag_0.mcap']
    assert info['message_count'] == 20 * len(ALL_TYPES)
    assert info['starting_time']['nanoseconds_since_epoch'] == 7
    assert info['duration']['nanoseconds'] == 19_000_000
    topics = {t['topic_metadata']['name']: t for t in info['topics_with_message_count']}
    assert set(topics) == set(sent)
    for entry in topics.values():
        assert entry['message_count'] == 20
        assert entry['topic_metadata']['offered_qos_profiles'] == []
        assert entry['topic_metadata']['type_description_hash'].startswith('RIHS01_')


def test_definitions_embed_dependencies() -> None:
    text = message_definition('vd_msgs/msg/TireForces')
    assert text.startswith('uint8 FL=0')
    assert 'float64[4] fx' in text
    assert 'MSG: std_msgs/Header' in text
    assert 'MSG: builtin_interfaces/Time' in text
    diag = message_definition('diagnostic_msgs/msg/DiagnosticArray')
    assert 'MSG: diagnostic_msgs/KeyValue' in diag


def test_qos_profiles_are_kept(tmp_path: Path) -> None:
    qos = '- history: keep_last\n  depth: 10\n  reliability: reliable\n  durability: volatile\n'
    with BagWriter(tmp_path / 'q') as writer:
        writer.add_topic(SENSORS_WHEEL_ANGLES, 'vd_msgs/msg/WheelAngles', qos)
    info = yaml.safe_load((tmp_path / 'q' / 'metadata.yaml').read_text())
    meta = info['rosbag2_bagfile_information']['topics_with_message_count'][0]['topic_metadata']
    assert meta['offered_qos_profiles'][0]['depth'] == 10
    stored = BagReader(tmp_path / 'q').topics[SENSORS_WHEEL_ANGLES].qos_profiles_yaml
    assert yaml.safe_load(stored)[0].items() >= yaml.safe_load(qos)[0].items()


def test_integer_qos_policies_become_version_9_names(tmp_path: Path) -> None:
    qos = '- history: 1\n  depth: 100\n  reliability: 2\n  durability: 1\n  liveliness: 1\n'
    with BagWriter(tmp_path / 'iq') as writer:
        writer.add_topic(SENSORS_WHEEL_ANGLES, 'vd_msgs/msg/WheelAngles', qos)
    info = yaml.safe_load((tmp_path / 'iq' / 'metadata.yaml').read_text())
    meta = info['rosbag2_bagfile_information']['topics_with_message_count'][0]['topic_metadata']
    (profile,) = meta['offered_qos_profiles']
    assert profile['history'] == 'keep_last' and profile['depth'] == 100
    assert profile['reliability'] == 'best_effort'
    assert profile['durability'] == 'transient_local'
    assert profile['liveliness'] == 'automatic'
    assert profile['deadline'] == {'sec': 9223372036, 'nsec': 854775807}


def test_topic_filter_time_range_and_order(tmp_path: Path) -> None:
    rng = np.random.default_rng(5)
    times = rng.permutation(100) * 1000  # written out of time order
    with BagWriter(tmp_path / 'o', chunk_size=512) as writer:
        writer.add_topic('/a', 'std_msgs/msg/Float64')
        writer.add_topic('/b', 'std_msgs/msg/Float64')
        for k, t in enumerate(times.tolist()):
            msg = message_class('std_msgs/msg/Float64')(data=float(k))
            writer.write('/a' if k % 2 else '/b', serialize(msg), t)
    reader = BagReader(tmp_path / 'o')
    in_file_order = [m.log_time_ns for m in reader.raw_messages()]
    assert in_file_order == times.tolist()
    ordered = [m.log_time_ns for m in reader.raw_messages(ordered=True)]
    assert ordered == sorted(times.tolist())
    window = list(reader.messages(['/a'], start_ns=20_000, stop_ns=60_000, ordered=True))
    expected = sorted(int(t) for k, t in enumerate(times) if k % 2 and 20_000 <= t < 60_000)
    assert [log for _, _, log, _ in window] == expected
    assert {topic for topic, _, _, _ in window} == {'/a'}
    for _, msgtype, log, msg in window:
        assert msgtype == 'std_msgs/msg/Float64'
        assert times[int(msg.data)] == log


def test_reads_bag_written_by_rosbags_writer(tmp_path: Path) -> None:
    # rosbags mimics rosbag2's layout: schemas and channels inside chunks, a metadata record.
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin
    from rosbags.rosbag2 import Writer as RosbagsWriter

    rng = np.random.default_rng(11)
    sent = [make_message('vd_msgs/msg/TireForces', rng) for _ in range(50)]
    writer = RosbagsWriter(tmp_path / 'rb', version=9, storage_plugin=StoragePlugin.MCAP)
    writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    with writer:
        conn = writer.add_connection(
            ESTIMATES_TIRE_FORCES, 'vd_msgs/msg/TireForces', typestore=vd_typestore()
        )
        for k, msg in enumerate(sent):
            writer.write(conn, 1000 * k, serialize(msg))
    reader = BagReader(tmp_path / 'rb')
    assert reader.topics[ESTIMATES_TIRE_FORCES].message_count == 50
    got = list(reader.messages())
    assert [log for _, _, log, _ in got] == [1000 * k for k in range(50)]
    for a, (_, _, _, b) in zip(sent, got, strict=True):
        assert_same(a, b)


def test_reads_bag_written_by_mcap_ros2_writer(tmp_path: Path) -> None:
    from mcap_ros2.writer import Writer as McapRos2Writer

    path = tmp_path / 'plain.mcap'
    with path.open('wb') as stream:
        writer = McapRos2Writer(stream)
        schema = writer.register_msgdef(
            'vd_msgs/msg/Slope', message_definition('vd_msgs/msg/Slope')
        )
        for k in range(30):
            msg = {'header': {'stamp': {'sec': k, 'nanosec': 5}, 'frame_id': 'base_link'}}
            msg |= {'angle': 0.01 * k, 'valid': bool(k % 2)}
            writer.write_message(ESTIMATES_SLOPE, schema, msg, log_time=k, publish_time=k)
        writer.finish()
    got = list(BagReader(path).messages())
    assert len(got) == 30
    for k, (topic, msgtype, log, msg) in enumerate(got):
        assert (topic, msgtype, log) == (ESTIMATES_SLOPE, 'vd_msgs/msg/Slope', k)
        assert msg.angle == 0.01 * k and msg.valid == bool(k % 2)
        assert msg.header.stamp.sec == k and msg.header.frame_id == 'base_link'


def test_format_qos_profiles_round_trips_through_rosbags(tmp_path: Path) -> None:
    from rosbags.rosbag2 import Reader as Rosbag2Reader
    from vd_observer_node.bag.metadata import format_qos_profiles

    text = format_qos_profiles([{'reliability': 'best_effort', 'depth': 5}])
    with BagWriter(tmp_path / 'q2') as writer:
        writer.add_topic(TRUTH_SLOPE, 'vd_msgs/msg/Slope', text)
        writer.add_topic(f'{TRUTH_NAMESPACE}other', 'vd_msgs/msg/Slope')
    with Rosbag2Reader(tmp_path / 'q2') as reader:
        qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
    assert qos[f'{TRUTH_NAMESPACE}other'] == []
    (profile,) = qos[TRUTH_SLOPE]
    assert profile.depth == 5
    assert profile.reliability.name == 'BEST_EFFORT'
    assert profile.durability.name == 'VOLATILE'


def _rosidl_hash(msgtype: str) -> str | None:
    """The RIHS01 hash rosidl generated for ``msgtype`` (its share/<pkg>/msg/<T>.json)."""
    import json
    import sys

    package, _, name = msgtype.split('/')
    candidates = [Path(sys.prefix) / 'share' / package / 'msg' / f'{name}.json']
    try:
        from ament_index_python.packages import get_package_share_directory

        candidates.append(Path(get_package_share_directory(package)) / 'msg' / f'{name}.json')
    except Exception:  # not installed / no ROS environment
        pass
    for path in candidates:
        if path.is_file():
            hashes = json.loads(path.read_text())['type_hashes']
            return next(h['hash_string'] for h in hashes if h['type_name'] == msgtype)
    return None


@pytest.mark.parametrize('msgtype', ALL_TYPES)
def test_type_hashes_match_rosidl(msgtype: str) -> None:
    from vd_observer_node.bag.typestore import type_hash

    expected = _rosidl_hash(msgtype)
    if expected is None:
        pytest.skip(f'no rosidl-generated description of {msgtype} installed here')
    assert type_hash(msgtype) == expected
