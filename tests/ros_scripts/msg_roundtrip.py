"""Publish (``pub``) or receive and check (``sub``) one message of every public vd type.

Both sides fill the messages from the same seeded generator, so the subscriber can check
that what crossed the middleware is intact, field by field. Used by test_msgs_middleware.py.
"""

from __future__ import annotations

import importlib
import json
import random
import sys
from typing import Any

import rclpy
from geometry_msgs.msg import AccelStamped, TwistStamped
from rclpy.node import Node

from vd_msgs.msg import (
    Alerts,
    Friction,
    FrictionPotential,
    Resistances,
    Slope,
    TireForces,
    WheelAngles,
    WheelStates,
    WheelTorques,
)

TYPES = [
    WheelAngles,
    WheelTorques,
    WheelStates,
    TireForces,
    Friction,
    Resistances,
    Slope,
    TwistStamped,
    AccelStamped,
    Alerts,
    FrictionPotential,
]


def fill(msg: Any, rng: random.Random) -> Any:
    """Set every field of `msg` (recursively) to a random value of its type."""
    for name, kind in msg.get_fields_and_field_types().items():
        value = getattr(msg, name)
        if kind.startswith('double[') or kind.startswith('float['):
            value[:] = [rng.uniform(-1e3, 1e3) for _ in range(len(value))]
        elif kind.startswith('boolean['):
            setattr(msg, name, [rng.random() < 0.5 for _ in range(len(value))])
        elif kind.startswith('uint8['):
            setattr(msg, name, [rng.randint(0, 255) for _ in range(len(value))])
        elif kind.startswith('sequence<'):
            package, _, type_name = kind[len('sequence<') : -1].partition('/')
            item_class = getattr(importlib.import_module(f'{package}.msg'), type_name)
            setattr(msg, name, [fill(item_class(), rng) for _ in range(3)])
        elif kind in ('double', 'float'):
            setattr(msg, name, rng.uniform(-1e3, 1e3))
        elif kind == 'int8':
            setattr(msg, name, rng.randint(-128, 127))
        elif kind == 'uint8':
            setattr(msg, name, rng.randint(0, 255))
        elif kind in ('int32', 'uint32'):
            setattr(msg, name, rng.randint(0, 2**31 - 1))
        elif kind == 'boolean':
            setattr(msg, name, rng.random() < 0.5)
        elif kind == 'string':
            setattr(msg, name, f'base_link_{rng.randint(0, 999)}')
        else:
            fill(value, rng)
    return msg


def as_dict(msg: Any) -> Any:
    """A message as plain JSON-able data (fields recursively, arrays as lists)."""
    if hasattr(msg, 'get_fields_and_field_types'):
        return {n: as_dict(getattr(msg, n)) for n in msg.get_fields_and_field_types()}
    if isinstance(msg, str | bool | int | float):
        return msg
    if hasattr(msg, '__len__'):
        return [as_dict(v) if hasattr(v, 'get_fields_and_field_types') else _plain(v) for v in msg]
    return msg


def _plain(value: Any) -> Any:
    return value if isinstance(value, bool) else float(value)


def expected(kind: type) -> Any:
    return fill(kind(), random.Random(kind.__name__))


def topic(kind: type) -> str:
    return '/roundtrip/' + kind.__name__.lower()


def main() -> int:
    mode = sys.argv[1]
    rclpy.init()
    node = Node('roundtrip_' + mode)
    if mode == 'pub':
        pubs = [(node.create_publisher(k, topic(k), 10), expected(k)) for k in TYPES]

        def publish() -> None:
            for pub, msg in pubs:
                pub.publish(msg)

        node.create_timer(0.05, publish)
        print('PUBLISHING', flush=True)
    else:
        seen: set[str] = set()

        def make_cb(kind: type) -> Any:
            want = json.dumps(as_dict(expected(kind)), sort_keys=True)

            def cb(msg: Any) -> None:
                got = json.dumps(as_dict(msg), sort_keys=True)
                if kind.__name__ in seen:
                    return
                seen.add(kind.__name__)
                status = 'INTACT' if got == want else 'MISMATCH'
                print(f'{status} {kind.__name__} {got}', flush=True)
                if len(seen) == len(TYPES):
                    print('ALL RECEIVED', flush=True)

            return cb

        for k in TYPES:
            node.create_subscription(k, topic(k), make_cb(k), 10)
        print('SUBSCRIBED', flush=True)
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
