"""The nodes' raw message path: CDR bytes in, stamp matching, CDR bytes out (ROS-free).

What the estimator, alerts and pipeline nodes share around their subscriptions (taken with
``raw=True``) and publishers (given bytes): decoding each input with its
`bag.cdr_message.MessageCodec` into a `alignment.StampAligner`, and one encoder per output type
and ``frame_id`` (an output keeps the frame of the input it derives from).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from vd_observer_node.bag.cdr_message import AlertsCodec, MessageCodec
from vd_observer_node.bag.errors import BagFormatError
from vd_observer_node.estimation.alignment import StampAligner

__all__ = ['Encoders', 'aligned_input']


class Encoders:
    """One encoder per (message type, frame_id), made on first use."""

    def __init__(self) -> None:
        """Start with none."""
        self._codecs: dict[tuple[str, bytes], MessageCodec] = {}
        self._alerts: dict[bytes, AlertsCodec] = {}

    def __call__(self, msgtype: str, frame: bytes) -> MessageCodec:
        """The encoder of `msgtype` writing header.frame_id `frame`."""
        codec = self._codecs.get((msgtype, frame))
        if codec is None:
            codec = MessageCodec(msgtype, frame.decode(errors='replace'))
            self._codecs[(msgtype, frame)] = codec
        return codec

    def alerts(self, frame: bytes) -> AlertsCodec:
        """The vd_msgs/msg/Alerts encoder writing header.frame_id `frame`."""
        codec = self._alerts.get(frame)
        if codec is None:
            codec = AlertsCodec(frame.decode(errors='replace'))
            self._alerts[frame] = codec
        return codec


def aligned_input(
    msgtype: str,
    key: str,
    aligner: StampAligner,
    on_matched: Callable[[int, dict[str, Any]], None],
    counts: dict[str, int],
) -> Callable[[bytes], None]:
    """Subscription callback: decode, match by stamp, call ``on_matched`` once a set is full.

    Args:
        msgtype: the input's type, e.g. 'vd_msgs/msg/WheelStates'.
        key: its name in `aligner`.
        aligner: the node's stamp matcher; it receives ``(frame_id, field values)``.
        on_matched: called with (stamp [ns], {key: (frame_id, values)}) for every full set.
        counts: its 'undecodable' entry counts messages that are not valid CDR of `msgtype`
            (dropped, never a crash).
    """
    decoder = MessageCodec(msgtype)

    def callback(data: bytes) -> None:
        try:
            stamp_ns, frame, values = decoder.decode(data)
        except BagFormatError:
            counts['undecodable'] += 1
            return
        matched = aligner.push(key, stamp_ns, (frame, values))
        if matched is not None:
            on_matched(stamp_ns, matched)

    return callback
