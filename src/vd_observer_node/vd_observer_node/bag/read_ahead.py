"""Reading the next block of a bag on a thread while the caller works on the current one.

Decompressing a chunk (zstd, lz4), checking its CRC (zlib) and numpy's copies release the
GIL, so an offline pass (``vd replay``) reads block k + 1 on the second core while block k
runs through the cascade; what the iterator yields, and in which order, does not change.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Iterator
from typing import TypeVar

__all__ = ['read_ahead']

T = TypeVar('T')

# how long the reading thread waits between looks at whether the consumer stopped [s]
_POLL_S = 0.05


class _End:
    """The reading thread's last item: the iterator's end, or the exception that ended it."""

    def __init__(self, error: BaseException | None) -> None:
        self.error = error


def read_ahead(items: Iterator[T], depth: int = 1) -> Iterator[T]:
    """Yield `items` in order while a thread already produces the next `depth` of them.

    Args:
        items: the iterator to run on the thread (e.g. `BagReader.topic_array_blocks`); it
            must not be used elsewhere meanwhile.
        depth: items produced ahead (>= 1); memory holds up to depth + 1 of them.

    Raises:
        Whatever `items` raised, where it raised it: after the items before it.
    """
    if depth < 1:
        raise ValueError(f'depth must be >= 1, got {depth}')
    ready: queue.Queue[T | _End] = queue.Queue(maxsize=depth)
    stop = threading.Event()

    def offer(item: T | _End) -> bool:
        """Queue `item` once there is room; False if the consumer stopped meanwhile."""
        while not stop.is_set():
            try:
                ready.put(item, timeout=_POLL_S)
                return True
            except queue.Full:
                continue
        return False

    def produce() -> None:
        end = _End(None)
        try:
            for item in items:
                if not offer(item):
                    return
        except BaseException as exc:  # handed to the consumer, raised in its thread
            end = _End(exc)
        offer(end)

    worker = threading.Thread(target=produce, name='bag-read-ahead', daemon=True)
    worker.start()
    try:
        while True:
            item = ready.get()
            if isinstance(item, _End):
                if item.error is not None:
                    raise item.error
                return
            yield item
    finally:
        # the consumer stopped early (an error, or it had enough): let the thread end
        stop.set()
        worker.join()
