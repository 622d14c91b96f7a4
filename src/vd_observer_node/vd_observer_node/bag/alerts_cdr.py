"""Batch CDR encoding of vd_msgs/msg/Alerts (a sequence of records, which the fixed-layout
encoder of :mod:`.cdr_batch` does not handle).

Shared by offline replay (:mod:`.replay`) and the report's development bags
(``report.devbag``).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

__all__ = ['ALERTS_TYPE', 'ALERT_CHANNELS', 'encode_alerts']

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
    buf = out.tobytes()  # one copy, then slices: cheaper than a tobytes() per row
    return [buf[i : i + size] for i in range(0, n * size, size)]
