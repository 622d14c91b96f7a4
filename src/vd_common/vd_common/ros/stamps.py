"""Time on the wire: builtin_interfaces/Time <-> integer nanoseconds, and a serialized
message's ``header.stamp`` read without decoding it (the cores keep time as int ns).
"""

from __future__ import annotations

import struct

from builtin_interfaces.msg import Time

__all__ = [
    'header_stamp_ns',
    'ns_to_time',
    'time_to_ns',
]


_NS = 1_000_000_000


def ns_to_time(ns: int) -> Time:
    """Convert integer nanoseconds to a builtin_interfaces/Time (floor division, sec >= 0)."""
    sec, nanosec = divmod(int(ns), _NS)
    return Time(sec=sec, nanosec=nanosec)


def time_to_ns(stamp: Time) -> int:
    """Convert a builtin_interfaces/Time to integer nanoseconds."""
    return int(stamp.sec) * _NS + int(stamp.nanosec)


def header_stamp_ns(cdr: bytes) -> int | None:
    """``header.stamp`` [ns] of a serialized message that begins with a std_msgs/Header.

    Reads the 4-byte encapsulation (CDR little or big endian) and the stamp's sec and nanosec
    after it, without decoding the message; None where `cdr` is too short or not plain CDR.
    """
    if len(cdr) < 12 or cdr[0] != 0 or cdr[1] not in (0, 1):
        return None
    sec, nanosec = struct.unpack_from('<iI' if cdr[1] == 1 else '>iI', cdr, 4)
    return int(sec) * _NS + int(nanosec)
