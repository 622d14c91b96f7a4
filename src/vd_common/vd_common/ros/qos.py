"""The QoS profiles of vd's topics, chosen on purpose (see the README's topic contract).

* Sensor, observer, estimate and truth streams: RELIABLE, KEEP_LAST, depth 1000. Reliable
  publishers also serve best-effort subscribers (``qos_profile_sensor_data``), so users may
  pick either; our own subscribers ask for reliable delivery with room for a 1 s stall at
  1 kHz, because a lost wheel-angle sample is a corrupted derivative.
* ``/clock``: RELIABLE, depth 1, like ``ros2 bag play``.
* ``/diagnostics``: RELIABLE, depth 10 (the diagnostic_aggregator default).
* Estimates published only where they change: transient local, depth 10.
"""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

__all__ = [
    'CLOCK_QOS',
    'DIAGNOSTICS_QOS',
    'STATE_QOS',
    'STREAM_QOS',
]


STREAM_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1000,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
CLOCK_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE
)
DIAGNOSTICS_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE
)
#: Estimates published only where they change (the engine-torque offset): the last ones are
#: kept for subscribers that join later (transient local; volatile subscribers match too).
STATE_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
