"""A node's health on ``/diagnostics``: one DiagnosticStatus per node, stamped with its clock,
with the publishes the middleware refused added (`publishing.PublishRefusals`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node

from vd_common.ros.publishing import PublishRefusals

__all__ = [
    'diagnostic_array',
    'node_status',
]


def diagnostic_array(
    stamp: Time,
    name: str,
    hardware_id: str,
    level: bytes | int,
    message: str,
    values: Mapping[str, object],
) -> DiagnosticArray:
    """One-status DiagnosticArray; `level` is DiagnosticStatus.OK/WARN/ERROR/STALE (bytes)."""
    status = DiagnosticStatus(
        level=level if isinstance(level, bytes) else bytes([level]),
        name=name,
        message=message,
        hardware_id=hardware_id,
        values=[KeyValue(key=str(k), value=str(v)) for k, v in values.items()],
    )
    return DiagnosticArray(header=_header(stamp), status=[status])


def node_status(
    node: Node,
    name: str,
    hardware_id: str,
    level: int,
    message: str,
    values: Mapping[str, object],
    refusals: PublishRefusals | None = None,
) -> DiagnosticArray:
    """`diagnostic_array` stamped with the node's clock now (the nodes' periodic status).

    With `refusals`, the publishes refused since the previous status are added to the level,
    message and values (`PublishRefusals.status`).
    """
    if refusals is not None:
        level, message, refused = refusals.status(level, message)
        values = {**values, **refused}
    return diagnostic_array(
        node.get_clock().now().to_msg(), name, hardware_id, level, message, values
    )


def _header(stamp: Time) -> Any:
    from std_msgs.msg import Header

    return Header(stamp=stamp)
