"""Topic names and message types the report reads: the vd topic contract, grouped."""

from __future__ import annotations

from vd_sim_node.topics import ESTIMATES, OBSERVER, SENSORS, TRUTH

__all__ = [
    'ESTIMATE_TOPICS',
    'GEAR_TOPIC',
    'SENSOR_TOPICS',
    'TRUTH_TOPICS',
    'WHEEL_NAMES',
]

#: Wheel order of every per-wheel array.
WHEEL_NAMES = ('FL', 'FR', 'RL', 'RR')

SENSOR_TOPICS = SENSORS
#: Gear changes (``gear`` field) mark the shift windows excluded from the metrics.
GEAR_TOPIC = '/vd/sensors/wheel_torques'
ESTIMATE_TOPICS = {**OBSERVER, **ESTIMATES}
TRUTH_TOPICS = TRUTH
