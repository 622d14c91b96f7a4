"""Topic names and message types the report reads: the vd topic contract, grouped."""

from __future__ import annotations

from vd_common.topics import (
    ALERTS,
    ESTIMATES,
    ESTIMATES_ALERTS,
    ESTIMATES_FRICTION_POTENTIAL,
    OBSERVER,
    SENSORS,
    SENSORS_WHEEL_TORQUES,
    TRUTH,
    TRUTH_FRICTION_POTENTIAL,
)

__all__ = [
    'ALERT_TOPIC',
    'ALERT_TOPICS',
    'ESTIMATED_POTENTIAL_TOPIC',
    'ESTIMATE_TOPICS',
    'GEAR_TOPIC',
    'SENSOR_TOPICS',
    'TRUE_POTENTIAL_TOPIC',
    'TRUTH_TOPICS',
    'WHEEL_NAMES',
]

#: Wheel order of every per-wheel array.
WHEEL_NAMES = ('FL', 'FR', 'RL', 'RR')

SENSOR_TOPICS = SENSORS
#: Gear changes (``gear`` field) mark the shift windows excluded from the metrics.
GEAR_TOPIC = SENSORS_WHEEL_TORQUES
ESTIMATE_TOPICS = {**OBSERVER, **ESTIMATES}
TRUTH_TOPICS = TRUTH
#: Alerts and the friction-potential estimate (the alerts section of the report).
ALERT_TOPICS = ALERTS
ALERT_TOPIC = ESTIMATES_ALERTS
ESTIMATED_POTENTIAL_TOPIC = ESTIMATES_FRICTION_POTENTIAL
#: The simulator's true friction potential (MF peak at the true load and road mu).
TRUE_POTENTIAL_TOPIC = TRUTH_FRICTION_POTENTIAL
