"""read_ahead: the same items in the same order, errors where they happened, no thread left."""

from __future__ import annotations

import threading
from collections.abc import Iterator

import pytest
from vd_observer_node.bag.read_ahead import read_ahead


def _counting(n: int, produced: list[int], fail_at: int | None = None) -> Iterator[int]:
    for k in range(n):
        if k == fail_at:
            raise OSError(f'read failed at {k}')
        produced.append(k)
        yield k


def _reading_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name == 'bag-read-ahead']


@pytest.mark.parametrize('depth', [1, 3])
def test_items_come_in_order(depth: int) -> None:
    produced: list[int] = []
    assert list(read_ahead(_counting(50, produced), depth)) == list(range(50))
    assert produced == list(range(50))
    assert not _reading_threads()


def test_an_error_comes_after_the_items_before_it() -> None:
    got: list[int] = []
    with pytest.raises(OSError, match='read failed at 7'):
        for item in read_ahead(_counting(20, [], fail_at=7)):
            got.append(item)
    assert got == list(range(7))
    assert not _reading_threads()


def test_a_consumer_that_stops_early_ends_the_thread() -> None:
    produced: list[int] = []
    items = read_ahead(_counting(1000, produced), depth=2)
    assert [next(items) for _ in range(3)] == [0, 1, 2]
    items.close()  # what a `for` left by an exception does
    assert not _reading_threads()
    assert len(produced) <= 3 + 2 + 1  # read at most depth (+ the one in hand) ahead


def test_depth_must_be_positive() -> None:
    with pytest.raises(ValueError, match='depth'):
        next(read_ahead(iter([1]), depth=0))
