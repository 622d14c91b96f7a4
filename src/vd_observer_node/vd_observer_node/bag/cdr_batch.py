"""Vectorized CDR coding of header-stamped fixed-layout messages (numpy, no per-field Python).

Messages such as ``vd_msgs/msg/WheelAngles`` or ``geometry_msgs/msg/TwistStamped`` are a
``std_msgs/Header`` followed by fixed-size numbers. Their CDR bytes differ between messages
only by the length of ``header.frame_id``, so all messages with the same total length and
frame-id length share one numpy structured dtype: a batch decodes with one ``frombuffer``
per group and encodes with one ``tobytes``. This is what makes offline replay run at
hundreds of thousands of messages per second: rosbags' per-message ``deserialize_cdr`` is
20-130x slower (35-50x for most types) and its ``serialize_cdr`` 11-35x slower
(``scripts/bench_bag_codec.py``, figures in docs/bags.md).

Layout (little-endian CDR, XCDR1 as produced by rmw): 4-byte encapsulation header, then each
primitive aligned to min(its size, 8) relative to the end of the encapsulation header.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from vd_observer_node.bag.errors import BagFormatError, BagUsageError, UnknownMessageTypeError
from vd_observer_node.bag.packed import PackedMessages
from vd_observer_node.bag.typestore import store_with

__all__ = [
    'BatchFields',
    'decode_batch',
    'encode_batch',
    'encode_packed',
    'flat_fields',
    'upgrade_batch',
]

_HEADER_TYPE = 'std_msgs/msg/Header'
_PRIMITIVES = {
    'bool': '?',
    'byte': 'u1',
    'char': 'u1',
    'int8': 'i1',
    'uint8': 'u1',
    'int16': '<i2',
    'uint16': '<u2',
    'int32': '<i4',
    'uint32': '<u4',
    'int64': '<i8',
    'uint64': '<u8',
    'float32': '<f4',
    'float64': '<f8',
}
_ENCAPSULATION_LE = b'\x00\x01\x00\x00'


@dataclass(frozen=True)
class _Field:
    name: str  # dotted path below the message, e.g. 'twist.linear.x'
    dtype: str
    count: int  # 1 for a scalar, N for a fixed array


@dataclass
class BatchFields:
    """Decoded fields of N messages.

    Attributes:
        stamp_ns: header.stamp as integer nanoseconds, shape (N,).
        frame_id: header.frame_id per message, shape (N,), numpy bytes.
        values: every other field by dotted name; shape (N,) for scalars, (N, K) for arrays.
    """

    stamp_ns: np.ndarray
    frame_id: np.ndarray
    values: dict[str, np.ndarray]


def _flatten(msgtype: str, prefix: str) -> list[_Field]:
    store = store_with(msgtype)
    if msgtype not in store.fielddefs:
        raise UnknownMessageTypeError(f'unknown message type {msgtype!r}')
    _, fields = store.fielddefs[msgtype]
    out: list[_Field] = []
    for name, desc in fields:
        kind, spec = desc
        path = f'{prefix}{name}'
        if not prefix and name == 'header' and desc[1] == _HEADER_TYPE:
            continue  # coded separately: its frame_id string makes the layout variable
        kind_name = getattr(kind, 'name', str(kind))
        if kind_name == 'BASE' and spec[0] in _PRIMITIVES:
            out.append(_Field(path, _PRIMITIVES[spec[0]], 1))
        elif kind_name == 'NAME':
            out.extend(_flatten(str(spec), f'{path}.'))
        elif kind_name == 'ARRAY' and getattr(spec[0][0], 'name', '') == 'BASE':
            base = spec[0][1][0]
            if base not in _PRIMITIVES:
                raise UnknownMessageTypeError(f'{msgtype}.{name}: {base} arrays are not fixed')
            out.append(_Field(path, _PRIMITIVES[base], int(spec[1])))
        else:
            raise UnknownMessageTypeError(f'{msgtype}.{name} has no fixed CDR layout')
    return out


@functools.cache
def flat_fields(msgtype: str) -> tuple[_Field, ...]:
    """The fixed-size fields following ``header`` of a header-stamped message type.

    Raises:
        UnknownMessageTypeError: the type is unknown, has no leading header, or holds
            strings/sequences (no fixed layout).
    """
    store = store_with(msgtype)
    if msgtype not in store.fielddefs:
        raise UnknownMessageTypeError(f'unknown message type {msgtype!r}')
    _, fields = store.fielddefs[msgtype]
    if not fields or fields[0][0] != 'header' or fields[0][1][1] != _HEADER_TYPE:
        raise UnknownMessageTypeError(f'{msgtype} does not start with a std_msgs/Header')
    return tuple(_flatten(msgtype, ''))


@functools.cache
def _layout(msgtype: str, frame_len: int, itemsize: int) -> np.dtype[Any]:
    """Structured dtype of one message whose frame_id takes ``frame_len`` bytes (incl. NUL)."""
    names = ['enc', 'sec', 'nanosec', 'frame_len']
    formats: list[Any] = ['S4', '<i4', '<u4', '<u4']
    offsets = [0, 4, 8, 12]
    if frame_len:
        names.append('frame_id')
        formats.append(f'S{frame_len}')
        offsets.append(16)
    offset = 16 + frame_len
    for field in flat_fields(msgtype):
        size = np.dtype(field.dtype).itemsize
        align = min(size, 8)
        offset = 4 + -(-(offset - 4) // align) * align
        names.append(field.name)
        formats.append((field.dtype, (field.count,)) if field.count > 1 else field.dtype)
        offsets.append(offset)
        offset += size * field.count
    if itemsize and itemsize < offset:
        raise BagFormatError(f'{msgtype}: message of {itemsize} bytes, layout needs {offset}')
    return np.dtype(
        {'names': names, 'formats': formats, 'offsets': offsets, 'itemsize': itemsize or offset}
    )


def decode_batch(msgtype: str, datas: Sequence[bytes]) -> BatchFields:
    """Decode N CDR messages of one header-stamped fixed-layout type at once.

    Args:
        msgtype: e.g. 'vd_msgs/msg/WheelAngles'.
        datas: CDR bytes of each message (little endian): a list, or a
            :class:`~vd_observer_node.bag.packed.PackedMessages` as the reader gives them
            (then without a Python object per message).

    Raises:
        BagFormatError: a message is too short, big endian, or inconsistent with the type.
        UnknownMessageTypeError: the type has no fixed layout.
    """
    fields = flat_fields(msgtype)
    n = len(datas)
    values = {f.name: np.zeros((n, f.count) if f.count > 1 else n, dtype=f.dtype) for f in fields}
    stamp = np.zeros(n, dtype=np.int64)
    frames = np.zeros(n, dtype='S1')
    if n == 0:
        return BatchFields(stamp, frames, values)
    packed = PackedMessages.from_list(datas).compact()
    lengths = packed.lengths
    if int(lengths.min()) < 16:
        raise BagFormatError(f'{msgtype}: message shorter than a CDR header')
    joined = packed.array
    starts = packed.starts
    if not (np.all(joined[starts] == 0) and np.all(joined[starts + 1] == 1)):
        raise BagFormatError(f'{msgtype}: only little-endian CDR is supported')
    frame_len = np.ascontiguousarray(joined[starts[:, None] + np.arange(12, 16)]).view('<u4')[:, 0]
    keys = (lengths << 32) | frame_len.astype(np.int64)
    unique = np.unique(keys)
    frame_width = int(frame_len.max())
    frames = np.zeros(n, dtype=f'S{max(frame_width, 1)}')
    for key in unique:
        length, flen = int(key) >> 32, int(key) & 0xFFFFFFFF
        dtype = _layout(msgtype, flen, length)
        if len(unique) == 1:
            rows = joined.view(dtype)
            sel: slice | np.ndarray = slice(None)
        else:
            sel = np.flatnonzero(keys == key)
            rows = np.ascontiguousarray(joined[starts[sel, None] + np.arange(length)]).view(dtype)
            rows = rows[:, 0]
        stamp[sel] = rows['sec'].astype(np.int64) * 1_000_000_000 + rows['nanosec']
        if flen:
            frames[sel] = rows['frame_id']
        for f in fields:
            values[f.name][sel] = rows[f.name]
    return BatchFields(stamp, frames, values)


def encode_batch(
    msgtype: str,
    stamp_ns: np.ndarray,
    frame_id: str,
    values: dict[str, np.ndarray],
) -> list[bytes]:
    """Encode N messages of one header-stamped fixed-layout type at once.

    Args:
        msgtype: e.g. 'vd_msgs/msg/TireForces'.
        stamp_ns: header.stamp [ns], shape (N,), int64.
        frame_id: header.frame_id shared by all messages.
        values: every field of :func:`flat_fields` by dotted name, shape (N,) or (N, K).

    Returns:
        N CDR byte strings, identical to rosbags' ``serialize_cdr`` output.

    Raises:
        BagUsageError: a field is missing or has the wrong shape, or a stamp does not fit
            builtin_interfaces/Time (int32 seconds).
    """
    return list(encode_packed(msgtype, stamp_ns, frame_id, values))


def encode_packed(
    msgtype: str,
    stamp_ns: np.ndarray,
    frame_id: str,
    values: dict[str, np.ndarray],
) -> PackedMessages:
    """:func:`encode_batch` without a bytes object per message: the N messages in one buffer
    (what `BagWriter.write_interleaved` copies into chunks with numpy).

    Raises:
        BagUsageError: as :func:`encode_batch`.
    """
    fields = flat_fields(msgtype)
    stamp = np.asarray(stamp_ns, dtype=np.int64)
    n = stamp.shape[0]
    frame = frame_id.encode() + b'\x00'
    dtype = _layout(msgtype, len(frame), 0)
    seconds = stamp // 1_000_000_000
    if n and (seconds.min() < -(2**31) or seconds.max() >= 2**31):
        # builtin_interfaces/Time.sec is int32: refuse rather than wrap around silently.
        raise BagUsageError(f'{msgtype}: header stamps beyond the int32 seconds range')
    rows = np.zeros(n, dtype=dtype)
    rows['enc'] = _ENCAPSULATION_LE
    rows['sec'] = seconds
    rows['nanosec'] = stamp % 1_000_000_000
    rows['frame_len'] = len(frame)
    rows['frame_id'] = frame
    for f in fields:
        if f.name not in values:
            raise BagUsageError(f'{msgtype}: field {f.name} missing')
        array = np.asarray(values[f.name])
        expected = (n, f.count) if f.count > 1 else (n,)
        if array.shape != expected:
            raise BagUsageError(f'{msgtype}.{f.name}: shape {array.shape}, expected {expected}')
        rows[f.name] = array
    return PackedMessages.fixed(rows.tobytes(), dtype.itemsize)


def upgrade_batch(msgtype: str, decode_as: str, datas: Sequence[bytes]) -> Sequence[bytes]:
    """Re-encode messages written with an older definition of ``msgtype`` in today's layout.

    Fields the old definition lacks (e.g. ``torque_source``, added to TireForces, Friction
    and Slope) are 0; stamps, frame ids and every other field are kept.

    Args:
        msgtype: the type's name, e.g. 'vd_msgs/msg/Slope' (today's fields).
        decode_as: the alias of the old definition (`typestore.decoding_type`).
        datas: CDR bytes in the old layout.

    Raises:
        BagFormatError: a message does not decode with the old layout.
        UnknownMessageTypeError: either layout is not fixed.
    """
    if decode_as == msgtype or not datas:
        return datas
    old = decode_batch(decode_as, datas)
    n = len(datas)
    values: dict[str, np.ndarray] = {}
    for f in flat_fields(msgtype):
        if f.name in old.values:
            values[f.name] = old.values[f.name]
        else:
            values[f.name] = np.zeros((n, f.count) if f.count > 1 else n, dtype=f.dtype)
    out: list[bytes] = [b''] * n
    for frame in np.unique(old.frame_id).tolist():
        members = np.flatnonzero(old.frame_id == frame)
        part = {k: v[members] for k, v in values.items()}
        encoded = encode_batch(msgtype, old.stamp_ns[members], frame.decode(), part)
        for k, data in zip(members.tolist(), encoded, strict=True):
            out[k] = data
    return out
