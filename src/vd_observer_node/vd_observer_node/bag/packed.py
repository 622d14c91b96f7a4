"""Messages stored back to back in one byte string, moved with numpy instead of per message.

A :class:`PackedMessages` is N serialized messages: one ``bytes`` object and, per message,
where it starts and how long it is. It is a ``Sequence[bytes]`` (indexing, iteration and
comparison give each message's bytes, as a list would), but the offline paths never make
those per-message objects: selecting messages only selects offsets, and copying them into a
new buffer (:meth:`PackedMessages.compact`, :func:`scatter`) copies all messages of one
length with one numpy fancy-indexing operation over fixed-width windows of the buffer.
Messages of a topic nearly always share one length (fixed-layout types, one frame id), so
that is one operation per topic.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import Any, overload

import numpy as np

__all__ = ['PackedMessages', 'PackedParts', 'Scatter', 'scatter', 'windows']

#: A function copying message k to ``out[at[k]:]``: (out, at, src, starts, lengths), the
#: signature of :func:`scatter` and of the compiled `.copy_kernel.copy_ranges`.
Scatter = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray], None]


def windows(buf: np.ndarray, width: int) -> np.ndarray:
    """Every ``width``-byte window of ``buf`` as one element: shape (len - width + 1,).

    The view overlaps itself (stride 1 byte), so ``windows(buf, w)[starts]`` copies the
    ``w`` bytes at each start with one indexing operation, and assigning to it writes them.

    Args:
        buf: 1-D uint8 array (C-contiguous).
        width: window size [B], >= 1.
    """
    count = max(buf.size - width + 1, 0)
    return np.ndarray((count,), dtype=np.dtype((np.void, width)), buffer=buf, strides=(1,))


def _groups(lengths: np.ndarray) -> Iterator[tuple[int, np.ndarray | slice]]:
    """(length, selection) for each distinct non-zero length; one group without a search
    when all lengths are equal (the usual case)."""
    if not lengths.size:
        return
    low, high = int(lengths.min()), int(lengths.max())
    if low == high:
        if low:
            yield low, slice(None)
        return
    for length in np.unique(lengths).tolist():
        if length:
            yield int(length), np.flatnonzero(lengths == length)


def scatter(
    out: np.ndarray,
    at: np.ndarray,
    src: np.ndarray,
    starts: np.ndarray,
    lengths: np.ndarray,
) -> None:
    """Copy message k, ``src[starts[k] : starts[k] + lengths[k]]``, to ``out[at[k]:]``.

    Args:
        out: 1-D uint8 destination (writeable, C-contiguous).
        at: shape (N,) int64 destination offsets.
        src: 1-D uint8 source.
        starts, lengths: shape (N,) int64 source offsets and lengths [B].
    """
    for length, sel in _groups(lengths):
        windows(out, length)[at[sel]] = windows(src, length)[starts[sel]]


class PackedMessages(Sequence[bytes]):
    """N messages in one byte string: message k is ``data[starts[k] : starts[k] + lengths[k]]``.

    Args:
        data: the bytes holding the messages (other bytes may lie between them).
        starts: shape (N,) int64 offsets into ``data``.
        lengths: shape (N,) int64 message lengths [B].
    """

    __slots__ = ('_array', 'data', 'lengths', 'starts')

    def __init__(self, data: bytes, starts: np.ndarray, lengths: np.ndarray) -> None:
        self.data = data
        self.starts = np.asarray(starts, dtype=np.int64)
        self.lengths = np.asarray(lengths, dtype=np.int64)
        self._array: np.ndarray | None = None

    @classmethod
    def from_list(cls, datas: Iterable[bytes]) -> PackedMessages:
        """Pack messages given one by one (one join; a PackedMessages is returned as is)."""
        if isinstance(datas, PackedMessages):
            return datas
        items = datas if isinstance(datas, Sequence) else list(datas)
        n = len(items)
        lengths = np.fromiter(map(len, items), dtype=np.int64, count=n)
        starts = np.zeros(n, dtype=np.int64)
        np.cumsum(lengths[:-1], out=starts[1:])
        return cls(b''.join(items), starts, lengths)

    @classmethod
    def fixed(cls, data: bytes, size: int) -> PackedMessages:
        """``len(data) // size`` messages of ``size`` bytes each, back to back."""
        n = len(data) // size if size else 0
        return cls(data, np.arange(n, dtype=np.int64) * size, np.full(n, size, dtype=np.int64))

    @classmethod
    def concat(cls, parts: Sequence[PackedMessages]) -> PackedMessages:
        """One PackedMessages of all messages of ``parts`` in order, back to back."""
        if len(parts) == 1:
            return parts[0].compact()
        return cls._copy(parts)

    @classmethod
    def _copy(cls, parts: Sequence[PackedMessages]) -> PackedMessages:
        lengths = np.concatenate([p.lengths for p in parts]) if parts else np.zeros(0, np.int64)
        out = np.empty(int(lengths.sum()), dtype=np.uint8)
        starts = np.zeros(lengths.size, dtype=np.int64)
        np.cumsum(lengths[:-1], out=starts[1:])
        first = 0
        for part in parts:
            n = len(part)
            scatter(out, starts[first : first + n], part.array, part.starts, part.lengths)
            first += n
        return cls(out.tobytes(), starts, lengths)

    @property
    def array(self) -> np.ndarray:
        """``data`` as a read-only uint8 array (no copy)."""
        if self._array is None:
            self._array = np.frombuffer(self.data, dtype=np.uint8)
        return self._array

    def compact(self) -> PackedMessages:
        """The same messages back to back from offset 0 in a buffer of just them (self if
        they are already)."""
        if not len(self):
            return self if not self.data else PackedMessages(b'', self.starts, self.lengths)
        if int(self.starts[0]) == 0 and int(self.lengths.sum()) == len(self.data):
            ends = self.starts + self.lengths
            if np.array_equal(ends[:-1], self.starts[1:]):
                return self
        return PackedMessages._copy([self])

    def take(self, index: np.ndarray | slice) -> PackedMessages:
        """The messages at ``index`` (offsets selected, bytes shared)."""
        return PackedMessages(self.data, self.starts[index], self.lengths[index])

    def scatter_into(self, out: np.ndarray, at: np.ndarray, copy: Scatter = scatter) -> None:
        """Copy message k to ``out[at[k]:]`` with `copy` (default :func:`scatter`)."""
        copy(out, at, self.array, self.starts, self.lengths)

    def __len__(self) -> int:
        return int(self.starts.size)

    @overload
    def __getitem__(self, index: int) -> bytes: ...

    @overload
    def __getitem__(self, index: slice) -> PackedMessages: ...

    def __getitem__(self, index: int | slice) -> bytes | PackedMessages:
        if isinstance(index, slice):
            return self.take(index)
        start = int(self.starts[index])
        return self.data[start : start + int(self.lengths[index])]

    def __iter__(self) -> Iterator[bytes]:
        return iter(self.to_list())

    def to_list(self) -> list[bytes]:
        """The messages as a list of bytes objects (one object per message)."""
        data = self.data
        return [
            data[start : start + length]
            for start, length in zip(self.starts.tolist(), self.lengths.tolist(), strict=True)
        ]

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Sequence) or isinstance(other, (str, bytes)):
            return NotImplemented
        return len(self) == len(other) and all(a == b for a, b in zip(self, other, strict=True))

    __hash__: Any = None  # mutable-looking sequence semantics: not hashable

    def __repr__(self) -> str:
        return f'PackedMessages({len(self)} messages, {int(self.lengths.sum())} bytes)'


class PackedParts(Sequence[bytes]):
    """Messages drawn from several PackedMessages without copying them into one buffer.

    Message k is ``parts[part[k]][row[k]]``: what a writer needs to copy the messages of
    many topics, interleaved in log-time order, straight from each topic's buffer.

    Args:
        parts: the PackedMessages drawn from.
        part: shape (N,) int64, which part each message is in.
        row: shape (N,) int64, its index within that part.
    """

    __slots__ = ('_groups', 'part', 'parts', 'row')

    def __init__(self, parts: Sequence[PackedMessages], part: np.ndarray, row: np.ndarray) -> None:
        self.parts = tuple(parts)
        self.part = np.asarray(part, dtype=np.int64)
        self.row = np.asarray(row, dtype=np.int64)
        self._groups: list[tuple[int, np.ndarray]] | None = None

    @classmethod
    def join(cls, parts: Sequence[PackedMessages]) -> PackedParts:
        """All messages of ``parts``, in order."""
        sizes = np.array([len(p) for p in parts], dtype=np.int64)
        part = np.repeat(np.arange(sizes.size, dtype=np.int64), sizes)
        first = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
        return cls(parts, part, np.arange(part.size, dtype=np.int64) - first[part])

    @property
    def lengths(self) -> np.ndarray:
        """shape (N,) int64 message lengths [B]."""
        out = np.empty(self.part.size, dtype=np.int64)
        for j, members in self._members():
            out[members] = self.parts[j].lengths[self.row[members]]
        return out

    def _members(self) -> list[tuple[int, np.ndarray]]:
        """(part, positions of its messages) for each part that has messages here."""
        if self._groups is None:
            self._groups = []
            if self.part.size:
                # with fewer than 2**16 parts a 16-bit key: numpy sorts it by radix
                key = self.part.astype(np.uint16) if len(self.parts) <= 2**16 else self.part
                order = np.argsort(key, kind='stable')
                bounds = np.flatnonzero(np.diff(self.part[order])) + 1
                self._groups = [(int(self.part[m[0]]), m) for m in np.split(order, bounds)]
        return self._groups

    def take(self, index: np.ndarray | slice) -> PackedParts:
        """The messages at ``index`` (no bytes copied)."""
        return PackedParts(self.parts, self.part[index], self.row[index])

    def scatter_into(self, out: np.ndarray, at: np.ndarray, copy: Scatter = scatter) -> None:
        """Copy message k to ``out[at[k]:]``, part by part, with `copy` (default
        :func:`scatter`)."""
        for j, members in self._members():
            source = self.parts[j]
            rows = self.row[members]
            copy(out, at[members], source.array, source.starts[rows], source.lengths[rows])

    def compact(self) -> PackedMessages:
        """The messages back to back in one new buffer."""
        lengths = self.lengths
        out = np.empty(int(lengths.sum()), dtype=np.uint8)
        starts = np.zeros(lengths.size, dtype=np.int64)
        np.cumsum(lengths[:-1], out=starts[1:])
        self.scatter_into(out, starts)
        return PackedMessages(out.tobytes(), starts, lengths)

    def __len__(self) -> int:
        return int(self.part.size)

    @overload
    def __getitem__(self, index: int) -> bytes: ...

    @overload
    def __getitem__(self, index: slice) -> PackedParts: ...

    def __getitem__(self, index: int | slice) -> bytes | PackedParts:
        if isinstance(index, slice):
            return self.take(index)
        return self.parts[int(self.part[index])][int(self.row[index])]

    def __iter__(self) -> Iterator[bytes]:
        parts = self.parts
        for j, k in zip(self.part.tolist(), self.row.tolist(), strict=True):
            yield parts[j][k]

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Sequence) or isinstance(other, (str, bytes)):
            return NotImplemented
        return len(self) == len(other) and all(a == b for a, b in zip(self, other, strict=True))

    __hash__: Any = None

    def __repr__(self) -> str:
        return f'PackedParts({len(self)} messages from {len(self.parts)} parts)'
