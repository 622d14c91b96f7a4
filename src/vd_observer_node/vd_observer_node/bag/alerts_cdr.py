"""Batch CDR encoding and decoding of vd_msgs/msg/Alerts (a sequence of records, which the
fixed-layout coder of :mod:`vd_observer_node.bag.cdr_batch` does not handle).

Encoding serves offline replay and the report's development bags; decoding serves the report.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from vd_observer_node.bag.cdr_batch import BatchFields
from vd_observer_node.bag.errors import BagFormatError
from vd_observer_node.bag.packed import PackedMessages

__all__ = [
    'ALERTS_TYPE',
    'ALERT_CHANNELS',
    'decode_alerts',
    'encode_alerts',
    'encode_alerts_packed',
]

ALERTS_TYPE = 'vd_msgs/msg/Alerts'
#: Records per message: 3 kinds x 4 wheels, kind-major (KIND_* code, then FL, FR, RL, RR).
ALERT_CHANNELS = 12
_RECORD_BYTES = 20  # kind, wheel, level, active (uint8 x 4) + onset, detected (Time x 2)


def _le(values: np.ndarray, dtype: str) -> np.ndarray:
    """shape (N, ...) -> (N, bytes) little-endian bytes of each row."""
    arr = np.ascontiguousarray(np.asarray(values).astype(dtype))
    return arr.view(np.uint8).reshape(arr.shape[0], -1)


def encode_alerts(
    stamp_ns: np.ndarray, frame_id: str, values: Mapping[str, np.ndarray]
) -> list[bytes]:
    """CDR bytes of vd_msgs/msg/Alerts messages with all 12 channels, kind-major.

    Args:
        stamp_ns: shape (N,), int64 [ns] header stamps.
        frame_id: header.frame_id.
        values: 'level' (N, 3, 4) (0 OK, 1 warning, 2 critical); optional 'onset_ns' and
            'detected_ns' (N, 3, 4) int64 [ns] (0 while inactive). ``active`` is level > 0.

    Returns:
        N serialized messages (CDR little endian, with the 4-byte encapsulation header).
    """
    return list(encode_alerts_packed(stamp_ns, frame_id, values))


def encode_alerts_packed(
    stamp_ns: np.ndarray, frame_id: str, values: Mapping[str, np.ndarray]
) -> PackedMessages:
    """:func:`encode_alerts` (same arguments) without a bytes object per message: the N
    messages in one buffer, which `BagWriter.write_interleaved` copies with numpy."""
    stamps = np.asarray(stamp_ns, dtype=np.int64)
    n = stamps.shape[0]
    level = np.asarray(values['level']).reshape(n, ALERT_CHANNELS)
    zeros = np.zeros((n, ALERT_CHANNELS), dtype=np.int64)
    onset = np.asarray(values.get('onset_ns', zeros), dtype=np.int64).reshape(n, ALERT_CHANNELS)
    detected = np.asarray(values.get('detected_ns', zeros), dtype=np.int64).reshape(
        n, ALERT_CHANNELS
    )
    frame = frame_id.encode() + b'\x00'
    count_at = 4 + ((12 + len(frame) + 3) & ~3)  # CDR alignment from the encapsulation end
    size = count_at + 4 + _RECORD_BYTES * ALERT_CHANNELS
    out = np.zeros((n, size), dtype=np.uint8)
    out[:, 1] = 1  # CDR little endian
    out[:, 4:8] = _le(stamps // 1_000_000_000, '<i4')
    out[:, 8:12] = _le(stamps % 1_000_000_000, '<u4')
    out[:, 12:16] = _le(np.full(n, len(frame)), '<u4')
    out[:, 16 : 16 + len(frame)] = np.frombuffer(frame, dtype=np.uint8)
    out[:, count_at : count_at + 4] = _le(np.full(n, ALERT_CHANNELS), '<u4')
    channel = np.arange(ALERT_CHANNELS)
    records = np.zeros((n, ALERT_CHANNELS, _RECORD_BYTES), dtype=np.uint8)
    records[:, :, 0] = channel // 4
    records[:, :, 1] = channel % 4
    records[:, :, 2] = level
    records[:, :, 3] = level > 0
    for k, stamp in ((4, onset), (12, detected)):
        records[:, :, k : k + 4] = _le(stamp // 1_000_000_000, '<i4').reshape(n, ALERT_CHANNELS, 4)
        records[:, :, k + 4 : k + 8] = _le(stamp % 1_000_000_000, '<u4').reshape(
            n, ALERT_CHANNELS, 4
        )
    out[:, count_at + 4 :] = records.reshape(n, -1)
    return PackedMessages.fixed(out.tobytes(), size)


def _u32(buf: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Little-endian uint32 at each byte offset of ``buf``, as int64."""
    raw = np.ascontiguousarray(buf[offsets[:, None] + np.arange(4)])
    out: np.ndarray = raw.view('<u4')[:, 0].astype(np.int64)
    return out


def _time_ns(buf: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """builtin_interfaces/Time (int32 sec, uint32 nanosec) at each offset, as int64 ns."""
    sec = _u32(buf, offsets).astype(np.uint32).view(np.int32).astype(np.int64)
    out: np.ndarray = sec * 1_000_000_000 + _u32(buf, offsets + 4)
    return out


def decode_alerts(datas: Sequence[bytes]) -> BatchFields:
    """Batch-decode vd_msgs/msg/Alerts (a sequence of Alert records: no fixed layout).

    Each message is a header, a uint32 count and ``count`` 20-byte Alert records (their
    alignment is 4, so the records are packed). Absent channels (a publisher that sends only
    the active alerts) are OK with zero stamps.

    Args:
        datas: little-endian CDR bytes of N messages (a list or a PackedMessages).

    Returns:
        ``values``: 'level' (N, 3, 4) uint8, 'onset_ns' and 'detected_ns' (N, 3, 4) int64
        (0 while inactive), indexed [message, kind (KIND_*), wheel].

    Raises:
        BagFormatError: big-endian, truncated or inconsistent messages.
    """
    n = len(datas)
    level = np.zeros((n, 3, 4), dtype=np.uint8)
    onset = np.zeros((n, 3, 4), dtype=np.int64)
    detected = np.zeros((n, 3, 4), dtype=np.int64)
    stamp = np.zeros(n, dtype=np.int64)
    frames = np.zeros(n, dtype='S1')
    values: dict[str, np.ndarray] = {'level': level, 'onset_ns': onset, 'detected_ns': detected}
    if n == 0:
        return BatchFields(stamp, frames, values)
    packed = PackedMessages.from_list(datas).compact()
    lengths = packed.lengths
    if int(lengths.min()) < 24:
        raise BagFormatError(f'{ALERTS_TYPE}: message shorter than a header and a count')
    buf = packed.array
    starts = packed.starts
    if not (np.all(buf[starts] == 0) and np.all(buf[starts + 1] == 1)):
        raise BagFormatError(f'{ALERTS_TYPE}: only little-endian CDR is supported')
    stamp = _time_ns(buf, starts + 4)
    frame_len = _u32(buf, starts + 12)
    # CDR alignment counts from the end of the 4-byte encapsulation header
    count_at = starts + 4 + ((12 + frame_len + 3) & ~3)
    if np.any(count_at + 4 > starts + lengths):
        raise BagFormatError(f'{ALERTS_TYPE}: truncated message')
    count = _u32(buf, count_at)
    if np.any(count_at + 4 + _RECORD_BYTES * count > starts + lengths):
        raise BagFormatError(f'{ALERTS_TYPE}: alert count beyond the message')
    msg = np.repeat(np.arange(n), count)
    first = np.concatenate([[0], np.cumsum(count)[:-1]])
    at = count_at[msg] + 4 + _RECORD_BYTES * (np.arange(msg.size) - first[msg])
    kind, wheel = buf[at].astype(np.int64), buf[at + 1].astype(np.int64)
    ok = (kind < 3) & (wheel < 4)
    if not np.all(ok):
        raise BagFormatError(f'{ALERTS_TYPE}: alert kind or wheel out of range')
    level[msg, kind, wheel] = buf[at + 2]
    onset[msg, kind, wheel] = _time_ns(buf, at + 4)
    detected[msg, kind, wheel] = _time_ns(buf, at + 12)
    return BatchFields(stamp, frames, values)
