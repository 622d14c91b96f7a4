"""Every public vd message type crosses the real middleware between two processes intact."""

from __future__ import annotations

from pathlib import Path

import pytest
from rosproc import RosProcessGroup

SCRIPT = Path(__file__).parent / 'ros_scripts' / 'msg_roundtrip.py'
TYPES = [
    'WheelAngles',
    'WheelTorques',
    'WheelStates',
    'TireForces',
    'Friction',
    'Resistances',
    'Slope',
    'TwistStamped',
    'AccelStamped',
    'Alerts',
    'FrictionPotential',
]


@pytest.mark.ros
def test_every_message_type_arrives_intact_in_another_process(procs: RosProcessGroup) -> None:
    sub = procs.python('sub', SCRIPT, 'sub')
    sub.wait_for('SUBSCRIBED')
    procs.python('pub', SCRIPT, 'pub')
    out = sub.wait_for('ALL RECEIVED', timeout=60)
    assert 'MISMATCH' not in out, out
    for name in TYPES:
        assert f'INTACT {name} ' in out
    # the content is not trivially zero: random values made it across
    assert '"angle": [0.0, 0.0, 0.0, 0.0]' not in out


def test_alert_kind_codes_of_the_core_match_the_message() -> None:
    """The nodes and replay publish `Alert.kind_code` (the index in ALERT_KINDS) as `kind`."""
    from vd_observer_node.situation.alerts import ALERT_KINDS

    from vd_msgs.msg import Alert

    codes = {
        'traction': Alert.KIND_TRACTION,
        'lock': Alert.KIND_LOCK,
        'low_friction': Alert.KIND_LOW_FRICTION,
    }
    assert {kind: ALERT_KINDS.index(kind) for kind in ALERT_KINDS} == codes
