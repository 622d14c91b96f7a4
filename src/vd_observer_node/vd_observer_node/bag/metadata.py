"""rosbag2 ``metadata.yaml`` (version 9, as written by Jazzy and newer) for MCAP bags.

Version 9 is the first to store ``offered_qos_profiles`` as a YAML list instead of a YAML
string; rosbag2 of Jazzy, Kilted and Rolling read it (Humble and Iron do not).
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from rosbags.interfaces import QosDurability, QosHistory, QosLiveliness, QosReliability

from vd_observer_node.bag.errors import BagFormatError, BagUsageError

__all__ = [
    'METADATA_FILE',
    'METADATA_VERSION',
    'BagSummary',
    'TopicSummary',
    'format_qos_profiles',
    'normalize_qos_profiles',
    'parse_qos_profiles',
    'read_metadata_file_paths',
    'render_metadata',
    'write_metadata',
]

METADATA_FILE = 'metadata.yaml'
METADATA_VERSION = 9


@dataclass(frozen=True)
class TopicSummary:
    """One topic of a bag as listed in ``metadata.yaml``."""

    name: str
    msgtype: str
    message_count: int
    qos_profiles_yaml: str = ''
    type_hash: str = ''


@dataclass(frozen=True)
class BagSummary:
    """Everything ``metadata.yaml`` states about a single-file MCAP bag.

    Times are integer nanoseconds (log times of the first and last message).
    """

    file_name: str
    start_ns: int
    end_ns: int
    topics: list[TopicSummary] = field(default_factory=list)
    compression: str = 'zstd'

    @property
    def message_count(self) -> int:
        """Total number of messages of all topics."""
        return sum(t.message_count for t in self.topics)


# rmw's "infinite" duration, as rosbag2 writes it for unset deadline/lifespan/lease.
_INFINITE = {'sec': 9223372036, 'nsec': 854775807}
_QOS_DEFAULTS: dict[str, Any] = {
    'history': 'keep_last',
    'depth': 10,
    'reliability': 'reliable',
    'durability': 'volatile',
    'deadline': _INFINITE,
    'lifespan': _INFINITE,
    'liveliness': 'automatic',
    'liveliness_lease_duration': _INFINITE,
    'avoid_ros_namespace_conventions': False,
}


def format_qos_profiles(profiles: Sequence[Mapping[str, Any]]) -> str:
    """The QoS YAML string rosbag2 (Jazzy+) stores per topic, from profile mappings.

    Args:
        profiles: one mapping per publisher, keys as in rosbag2 metadata version 9:
            history ('keep_last'/'keep_all'), depth, reliability ('reliable'/'best_effort'),
            durability ('volatile'/'transient_local'), deadline/lifespan/
            liveliness_lease_duration ({'sec', 'nsec'}), liveliness ('automatic'/
            'manual_by_topic'), avoid_ros_namespace_conventions. Missing keys take rclpy's
            defaults (reliable, volatile, keep_last 10, infinite durations).

    Raises:
        BagUsageError: an unknown key.
    """
    out = []
    for profile in profiles:
        unknown = set(profile) - set(_QOS_DEFAULTS)
        if unknown:
            raise BagUsageError(f'unknown QoS keys {sorted(unknown)}')
        out.append({**_QOS_DEFAULTS, **profile})
    return str(yaml.safe_dump(out, sort_keys=False, default_flow_style=False)).strip()


_QOS_ENUMS: dict[str, Any] = {
    'history': QosHistory,
    'reliability': QosReliability,
    'durability': QosDurability,
    'liveliness': QosLiveliness,
}


def normalize_qos_profiles(qos_profiles_yaml: str) -> str:
    """QoS YAML in the version-9 form: policy names as strings, all keys present.

    Older rosbag2 (metadata <= 8) and some tools write the policies as rmw enum integers
    (``reliability: 1``); version-9 readers expect names (``reliability: reliable``).

    Raises:
        BagUsageError: not a YAML list of mappings, or an unknown enum value or key.
    """
    profiles = parse_qos_profiles(qos_profiles_yaml)
    out = []
    for profile in profiles:
        fixed = dict(profile)
        for key, enum in _QOS_ENUMS.items():
            value = fixed.get(key)
            if isinstance(value, int) and not isinstance(value, bool):
                try:
                    fixed[key] = enum(value).name.lower()
                except ValueError as exc:
                    raise BagUsageError(f'QoS {key}: unknown value {value}') from exc
        out.append(fixed)
    return format_qos_profiles(out)


def parse_qos_profiles(qos_profiles_yaml: str) -> list[dict[str, Any]]:
    """Parse the QoS profiles YAML string of an MCAP channel into the version-9 list form.

    Raises:
        BagUsageError: the text is not a YAML list of mappings.
    """
    if not qos_profiles_yaml.strip():
        return []
    try:
        value = yaml.safe_load(qos_profiles_yaml)
    except yaml.YAMLError as exc:
        raise BagUsageError(f'offered QoS profiles are not valid YAML: {exc}') from exc
    if value is None:
        return []
    if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
        raise BagUsageError('offered QoS profiles must be a YAML list of mappings')
    return value


def _info(summary: BagSummary) -> dict[str, Any]:
    duration = max(0, summary.end_ns - summary.start_ns) if summary.topics else 0
    start = summary.start_ns if summary.message_count else 0
    return {
        'version': METADATA_VERSION,
        'storage_identifier': 'mcap',
        'duration': {'nanoseconds': duration},
        'starting_time': {'nanoseconds_since_epoch': start},
        'message_count': summary.message_count,
        'topics_with_message_count': [
            {
                'topic_metadata': {
                    'name': t.name,
                    'type': t.msgtype,
                    'serialization_format': 'cdr',
                    'offered_qos_profiles': parse_qos_profiles(t.qos_profiles_yaml),
                    'type_description_hash': t.type_hash,
                },
                'message_count': t.message_count,
            }
            for t in summary.topics
        ],
        # Compression is inside the MCAP chunks ('storage' compression), invisible to rosbag2.
        'compression_format': '',
        'compression_mode': '',
        'relative_file_paths': [summary.file_name],
        'files': [
            {
                'path': summary.file_name,
                'starting_time': {'nanoseconds_since_epoch': start},
                'duration': {'nanoseconds': duration},
                'message_count': summary.message_count,
            }
        ],
        'custom_data': {},
        'ros_distro': os.environ.get('ROS_DISTRO', ''),
    }


def render_metadata(summary: BagSummary, *, inner: bool = False) -> str:
    """YAML text of the metadata; ``inner`` omits the top-level key (MCAP metadata record)."""
    info = _info(summary)
    document = info if inner else {'rosbag2_bagfile_information': info}
    return str(yaml.safe_dump(document, sort_keys=False, default_flow_style=False))


def write_metadata(folder: Path, summary: BagSummary) -> Path:
    """Write ``metadata.yaml`` atomically (temporary file + rename) and return its path."""
    target = folder / METADATA_FILE
    tmp = folder / (METADATA_FILE + '.tmp')
    tmp.write_text(render_metadata(summary), encoding='utf-8')
    tmp.replace(target)
    return target


def read_metadata_file_paths(folder: Path) -> list[str] | None:
    """The storage files listed by ``metadata.yaml`` of ``folder``, or None without the file.

    Raises:
        BagFormatError: the metadata exists but is not rosbag2 metadata or not MCAP storage.
    """
    path = folder / METADATA_FILE
    if not path.is_file():
        return None
    try:
        document = yaml.safe_load(path.read_text(encoding='utf-8'))
        info = document['rosbag2_bagfile_information']
        storage = info.get('storage_identifier', '')
        files = [str(p) for p in info['relative_file_paths']]
    except (yaml.YAMLError, KeyError, TypeError, AttributeError, UnicodeDecodeError) as exc:
        raise BagFormatError(f'{path}: not rosbag2 metadata ({exc!r})') from exc
    if storage != 'mcap':
        raise BagFormatError(f'{path}: storage {storage!r} is not supported, only mcap')
    return files
