"""A bag writer's file that runs out of space after a given number of bytes (shared by the
repair and background-writer tests)."""

from __future__ import annotations

import errno
from typing import Any

from vd_observer_node.bag import BagWriter


def fill_disk_after(writer: BagWriter, budget_bytes: int, monkeypatch: Any) -> None:
    """Make `writer`'s file fail with ENOSPC once `budget_bytes` more bytes were written; the
    write that crosses the limit writes its first part, as a real full disk does."""
    real_write = writer._file.write
    budget = {'bytes': budget_bytes}

    def limited_write(data: bytes) -> int:
        if budget['bytes'] < len(data):
            real_write(data[: budget['bytes']])  # a partial record
            budget['bytes'] = 0
            raise OSError(errno.ENOSPC, 'No space left on device')
        budget['bytes'] -= len(data)
        return int(real_write(data))

    monkeypatch.setattr(writer._file, 'write', limited_write)
