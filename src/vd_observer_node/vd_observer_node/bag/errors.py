"""Exceptions of the bag core: every failure of writing, reading or repairing a bag.

All derive from :class:`BagError`, so callers (the ``vd`` CLI, the recorder and player nodes)
can report any bag problem as one line without catching unrelated bugs.
"""

from __future__ import annotations

from pathlib import Path

from vd_observer_node.errors import ObserverError

__all__ = [
    'BagCorruptError',
    'BagDiskFullError',
    'BagError',
    'BagExistsError',
    'BagFormatError',
    'BagNotFoundError',
    'BagPathError',
    'BagUsageError',
    'ReplayInputError',
    'UnknownMessageTypeError',
]


class BagError(ObserverError):
    """Base class of every bag error (a kind of the package-wide ObserverError)."""


class BagNotFoundError(BagError):
    """The bag folder or MCAP file does not exist or holds no ``.mcap`` file."""


class BagExistsError(BagError):
    """A writer was asked to create a bag where a non-empty folder already exists."""


class BagPathError(BagError):
    """The bag location cannot be created or written (permissions, read-only file system)."""


class BagDiskFullError(BagError):
    """The file system ran out of space while writing; complete chunks stay recoverable."""


class BagUsageError(BagError):
    """The writer or reader was used against its contract (unknown topic, closed writer)."""


class UnknownMessageTypeError(BagError):
    """A message type is neither registered nor described by the bag's embedded schema."""


class BagFormatError(BagError):
    """The file is not an MCAP rosbag2 file (bad magic, unsupported encoding or profile)."""


class BagCorruptError(BagError):
    """An MCAP file is truncated or corrupted at a known byte offset.

    Attributes:
        path: the MCAP file.
        offset: byte offset [B] from the start of the file where the damage was detected.
        reason: what was wrong there.
    """

    def __init__(self, path: Path | str, offset: int, reason: str) -> None:
        self.path = Path(path)
        self.offset = offset
        self.reason = reason
        super().__init__(f'{self.path}: corrupt or truncated at byte {offset}: {reason}')


class ReplayInputError(BagError):
    """The input bag of an offline replay lacks the sensor topics the cascade needs."""
