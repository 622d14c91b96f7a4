"""The online mass and rolling radius live (estimator_node, pipeline_node) equal offline replay,
and are recorded.

sim_node (short launch) -> the estimation node(s) with mass and radius adaptation on, recorded
by recorder_node; `vd replay` with the same estimator settings must compute, for every sensor
stamp, the same /vd/estimates/mass, /vd/estimates/rolling_radius and the same loads and slope
that used them (1e-9).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from rosproc import RosProcessGroup, wait_recording
from test_graph import (
    LAST_STAMP_NS,
    N_SAMPLES,
    RATE_HZ,
    SCENARIO,
    by_topic,
    wait_exit,
    wait_for_last_stamp,
)
from vd_common.topics import (
    ESTIMATES_MASS,
    ESTIMATES_ROLLING_RADIUS,
    ESTIMATES_SLOPE,
    ESTIMATES_TIRE_FORCES,
    SENSORS_WHEEL_ANGLES,
)
from vd_observer_node.estimation.estimator import EstimatorConfig
from vd_observer_node.situation.chain_settings import chain_settings
from vd_observer_node.tools.replay import replay_bag

#: every test here is a long end-to-end run (CI runs it; locally: make test-all)
pytestmark = pytest.mark.slow

#: excited (0.4 s) and converged (at 1.6 s) within the 4 s launch; the defaults need more
#: driving
MASS_PARAMS = {
    'mass_adaptation': True,
    'mass.min_speed': 1.0,
    'mass.min_excited_time': 0.3,
    'mass.converged_std_ratio': 0.2,
    'mass.grade_tau': 0.2,
    # the radius too, without holding the mass back (the launch has little free rolling)
    'radius_adaptation': True,
    'mass_waits_for_radius': False,
    'radius.min_speed': 1.0,
    'radius.min_free_time': 0.1,
    'radius.max_accel': 5.0,  # a launch: the rear wheels roll freely while it accelerates
    'radius.converged_std_ratio': 0.03,
}
CONFIG = EstimatorConfig.from_mapping(MASS_PARAMS)
FIELDS = {
    ESTIMATES_MASS: ('mass', 'mass_std', 'mass_used', 'converged', 'excited'),
    ESTIMATES_ROLLING_RADIUS: ('radius', 'radius_std', 'radius_used', 'converged', 'free_wheels'),
    ESTIMATES_TIRE_FORCES: ('fx', 'fz'),
    ESTIMATES_SLOPE: ('angle', 'valid'),
}


def _run(procs: RosProcessGroup, bag: Path, separate: bool) -> None:
    rec = procs.node('recorder', 'vd_observer_node', 'recorder_node', output=str(bag))
    if separate:
        nodes = [
            (procs.node('observer', 'vd_observer_node', 'observer_node'), 'observer ready'),
            (
                procs.node('estimator', 'vd_observer_node', 'estimator_node', **MASS_PARAMS),
                'estimator ready',
            ),
        ]
    else:
        pipe = procs.node('pipeline', 'vd_observer_node', 'pipeline_node', **MASS_PARAMS)
        nodes = [(pipe, 'pipeline ready')]
    for proc, text in [(rec, 'recording to'), *nodes]:
        proc.wait_for(text, timeout=60)
    wait_recording(rec, list(FIELDS))
    waiter = wait_for_last_stamp(
        procs, 'waiter', LAST_STAMP_NS, {ESTIMATES_MASS: 'vd_msgs.msg/MassEstimate'}
    )
    sim = procs.node(
        'sim',
        'vd_sim_node',
        'sim_node',
        scenario_file=str(SCENARIO),
        rate_hz=RATE_HZ,
        real_time_factor=1.0,
        min_sensor_subscribers=2,
    )
    assert wait_exit(sim, 60) == 0, sim.output()
    assert wait_exit(waiter, 180) == 0, waiter.output()
    for proc, _ in reversed(nodes):
        assert proc.stop() == 0, proc.output()[-3000:]
        assert 'Traceback' not in proc.output(), proc.output()[-3000:]
    assert rec.stop() == 0, rec.output()[-3000:]


@pytest.mark.ros
@pytest.mark.parametrize('separate', [False, True], ids=['pipeline_node', 'estimator_node'])
def test_the_live_mass_is_recorded_and_equals_the_replays(
    procs: RosProcessGroup, tmp_path: Path, separate: bool
) -> None:
    bag = tmp_path / 'live'
    _run(procs, bag, separate)
    live = by_topic(bag, [SENSORS_WHEEL_ANGLES, *FIELDS])
    stamps = sorted(live[SENSORS_WHEEL_ANGLES])
    assert len(stamps) == N_SAMPLES, 'the recorder lost sensor samples'
    assert sorted(live[ESTIMATES_MASS]) == stamps
    assert any(live[ESTIMATES_MASS][s].excited for s in stamps)
    assert live[ESTIMATES_MASS][stamps[-1]].converged  # so Fz and the slope used it
    assert sorted(live[ESTIMATES_ROLLING_RADIUS]) == stamps
    assert any(live[ESTIMATES_ROLLING_RADIUS][s].free_wheels for s in stamps)

    offline_bag = tmp_path / 'offline'
    replay_bag(bag, offline_bag, replace(chain_settings(), estimator=CONFIG), progress=False)
    offline = by_topic(offline_bag, list(FIELDS))
    for topic, names in FIELDS.items():
        for s in stamps:
            for name in names:
                a = np.asarray(getattr(live[topic][s], name), dtype=float)
                b = np.asarray(getattr(offline[topic][s], name), dtype=float)
                np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9, err_msg=f'{topic}.{name}')
