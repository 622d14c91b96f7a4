"""CDR coding of ONE header-stamped fixed-layout message at a time (the live nodes' raw path).

The per-message counterpart of :mod:`.cdr_batch`, built from the same layout
(:func:`.cdr_batch.flat_fields` and its alignment rules), for nodes that subscribe with
``raw=True`` and publish bytes: rclpy's conversion of a message to and from a Python object
costs tens of microseconds per message, ``struct`` about a microsecond (measured by
``scripts/bench_message_path.py``).

A `MessageCodec` is built once per message type. `decode` accepts any ``frame_id`` length
(one ``struct.Struct`` per length, cached); `encode` writes the codec's own ``frame_id``. The
bytes are rosbags' CDR byte for byte (little endian, XCDR1) and rmw's up to the alignment
padding, which rmw leaves uninitialised and we zero; both are tested."""

from __future__ import annotations

import struct
from collections.abc import Sequence
from typing import Any, Final

from vd_observer_node.bag.alerts_cdr import ALERT_CHANNELS
from vd_observer_node.bag.cdr_batch import flat_fields
from vd_observer_node.bag.errors import BagFormatError, BagUsageError

__all__ = ['AlertsCodec', 'DecodedMessage', 'MessageCodec']

_STRUCT_CODES: Final = {
    '?': '?',
    'u1': 'B',
    'i1': 'b',
    '<i2': 'h',
    '<u2': 'H',
    '<i4': 'i',
    '<u4': 'I',
    '<i8': 'q',
    '<u8': 'Q',
    '<f4': 'f',
    '<f8': 'd',
}
_SIZES: Final = {'?': 1, 'u1': 1, 'i1': 1, '<i2': 2, '<u2': 2, '<i4': 4, '<u4': 4, '<i8': 8,
                 '<u8': 8, '<f4': 4, '<f8': 8}  # fmt: skip
_ENCAPSULATION_LE: Final = b'\x00\x01\x00\x00'
_NS: Final = 1_000_000_000

#: One decoded message: (stamp [ns], frame_id, field values in `MessageCodec.fields` order;
#: a scalar field is a number, an array field a tuple).
DecodedMessage = tuple[int, bytes, tuple[Any, ...]]


def _body_format(msgtype: str, frame_len: int) -> tuple[str, list[tuple[int, int]]]:
    """struct format after the header and each field's (start, count) in the unpacked tuple."""
    fmt = ''
    offset = 16 + frame_len
    spans: list[tuple[int, int]] = []
    index = 0
    for field in flat_fields(msgtype):
        size = _SIZES[field.dtype]
        align = min(size, 8)
        padded = 4 + -(-(offset - 4) // align) * align  # aligned from the encapsulation end
        fmt += 'x' * (padded - offset) + _STRUCT_CODES[field.dtype] * field.count
        offset = padded + size * field.count
        spans.append((index, field.count))
        index += field.count
    return fmt, spans


class MessageCodec:
    """Encode and decode one message type as CDR bytes, one message per call.

    Attributes:
        msgtype: e.g. 'vd_msgs/msg/WheelStates'.
        fields: dotted names of the fields after the header, in CDR order.
    """

    def __init__(self, msgtype: str, frame_id: str = '') -> None:
        """Prepare the codec.

        Args:
            msgtype: a header-stamped fixed-layout type (see :func:`.cdr_batch.flat_fields`).
            frame_id: header.frame_id written by `encode`.

        Raises:
            UnknownMessageTypeError: the type has no fixed layout.
        """
        self.msgtype = msgtype
        self.fields = tuple(f.name for f in flat_fields(msgtype))
        self._counts = tuple(f.count for f in flat_fields(msgtype))
        self._decoders: dict[int, tuple[struct.Struct, list[tuple[int, int]]]] = {}
        self.frame_id = frame_id
        frame = frame_id.encode() + b'\x00'
        body, _ = _body_format(msgtype, len(frame))
        self._frame = frame
        self._encoder = struct.Struct(f'<4siII{len(frame)}s{body}')

    def encode(self, stamp_ns: int, values: Sequence[float | int | bool]) -> bytes:
        """CDR bytes of one message.

        Args:
            stamp_ns: header.stamp [ns].
            values: every field's values flattened in `fields` order (an array field
                contributes its elements), e.g. for WheelStates 4 angles, 4 omegas, 4 omega_dots.

        Raises:
            BagUsageError: wrong number of values, or a stamp outside builtin_interfaces/Time.
        """
        sec, nanosec = divmod(int(stamp_ns), _NS)
        if not -(2**31) <= sec < 2**31:
            raise BagUsageError(f'{self.msgtype}: header stamp {stamp_ns} ns beyond int32 seconds')
        try:
            return self._encoder.pack(
                _ENCAPSULATION_LE, sec, nanosec, len(self._frame), self._frame, *values
            )
        except struct.error as exc:
            raise BagUsageError(
                f'{self.msgtype}: cannot encode {len(values)} values: {exc}'
            ) from None

    def decode(self, data: bytes) -> DecodedMessage:
        """Stamp, frame_id and field values of one message.

        Raises:
            BagFormatError: too short, big endian, or inconsistent with the type.
        """
        if len(data) < 16 or data[0] != 0 or data[1] != 1:
            raise BagFormatError(f'{self.msgtype}: not a little-endian CDR message')
        sec, nanosec, frame_len = struct.unpack_from('<iII', data, 4)
        decoder = self._decoders.get(frame_len)
        if decoder is None:
            body, spans = _body_format(self.msgtype, frame_len)
            decoder = (struct.Struct(f'<{body}'), spans)
            self._decoders[frame_len] = decoder
        unpacker, spans = decoder
        try:
            flat = unpacker.unpack_from(data, 16 + frame_len)
        except struct.error as exc:
            raise BagFormatError(f'{self.msgtype}: {exc}') from None
        values = tuple(
            flat[start] if count == 1 else flat[start : start + count] for start, count in spans
        )
        frame = bytes(data[16 : 16 + frame_len]).rstrip(b'\x00')
        return sec * _NS + nanosec, frame, values


class AlertsCodec:
    """Encode vd_msgs/msg/Alerts with all 12 channels, one message per call.

    The per-message counterpart of :func:`.alerts_cdr.encode_alerts` (same bytes, tested): the
    record sequence is not a fixed layout, but with the channel count fixed at 12 it is one
    ``struct`` format per ``frame_id``.
    """

    def __init__(self, frame_id: str = '') -> None:
        """Prepare the format for `frame_id` (header.frame_id of every message encoded)."""
        frame = frame_id.encode() + b'\x00'
        pad = -(12 + len(frame)) % 4  # the sequence length is aligned to 4 from offset 4
        self._frame = frame
        self._struct = struct.Struct(f'<4siII{len(frame)}s{pad}xI' + 'BBB?iIiI' * ALERT_CHANNELS)
        self.frame_id = frame_id

    def encode(
        self,
        stamp_ns: int,
        level: Sequence[int],
        onset_ns: Sequence[int],
        detected_ns: Sequence[int],
    ) -> bytes:
        """CDR bytes of one Alerts message.

        Args:
            stamp_ns: header.stamp [ns].
            level: 12 levels, kind-major (KIND_* code, then FL, FR, RL, RR).
            onset_ns: 12 onset stamps [ns] (0 while inactive).
            detected_ns: 12 detection stamps [ns] (0 while inactive).

        Raises:
            BagUsageError: not 12 channels, or a stamp outside builtin_interfaces/Time.
        """
        if not len(level) == len(onset_ns) == len(detected_ns) == ALERT_CHANNELS:
            raise BagUsageError(f'Alerts: need {ALERT_CHANNELS} channels per message')
        sec, nanosec = divmod(int(stamp_ns), _NS)
        fields: list[object] = [_ENCAPSULATION_LE, sec, nanosec, len(self._frame), self._frame]
        fields.append(ALERT_CHANNELS)
        for i in range(ALERT_CHANNELS):
            onset_s, onset_n = divmod(int(onset_ns[i]), _NS)
            det_s, det_n = divmod(int(detected_ns[i]), _NS)
            lv = int(level[i])
            fields += (i // 4, i % 4, lv, lv > 0, onset_s, onset_n, det_s, det_n)
        try:
            return self._struct.pack(*fields)
        except struct.error as exc:
            raise BagUsageError(f'Alerts: cannot encode: {exc}') from None
