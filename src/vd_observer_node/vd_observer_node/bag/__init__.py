"""ROS-free rosbag2 bag core: MCAP writing, reading, repair and CDR coding (a leaf: the
offline replay that uses it lives in `vd_observer_node.tools.replay`).

Public API (see docs/bags.md):

- :class:`BagWriter` writes a rosbag2 folder (``metadata.yaml`` + zstd-chunked ``.mcap``).
- :class:`BagReader` reads ours and rosbag2's bags, strictly or with ``recover=True``.
- :func:`repair_bag` rebuilds the summary and ``metadata.yaml`` of a killed recording.
- :mod:`.typestore` serializes/deserializes vd_msgs and standard types to CDR.
"""

from vd_observer_node.bag.errors import (
    BagCorruptError,
    BagDiskFullError,
    BagError,
    BagExistsError,
    BagFormatError,
    BagNotFoundError,
    BagPathError,
    BagUsageError,
    ReplayInputError,
    UnknownMessageTypeError,
)
from vd_observer_node.bag.reader import BagReader, RawMessage, TopicArrays, TopicInfo
from vd_observer_node.bag.writer import BagWriter

__all__ = [
    'BagCorruptError',
    'BagDiskFullError',
    'BagError',
    'BagExistsError',
    'BagFormatError',
    'BagNotFoundError',
    'BagPathError',
    'BagReader',
    'BagUsageError',
    'BagWriter',
    'RawMessage',
    'ReplayInputError',
    'TopicArrays',
    'TopicInfo',
    'UnknownMessageTypeError',
]
