"""`testing.devbag`: the estimate topics of a cascade result are those `vd replay` writes."""

from __future__ import annotations

import numpy as np
import pytest
from vd_common.topics import ESTIMATES_MASS, ESTIMATES_ROLLING_RADIUS, ESTIMATES_TORQUE_OFFSET
from vd_common.vehicle.params import default_vehicle_file
from vd_observer_node.estimation.cascade import (
    CascadeResult,
    CascadeSeries,
    CascadeSettings,
    run_cascade,
)
from vd_observer_node.estimation.estimator import EstimatorConfig
from vd_observer_node.estimation.vehicle import load_estimator_vehicle
from vd_observer_node.testing.devbag import cascade_topics
from vd_observer_node.tools.replay import ESTIMATE_TOPICS

ONLINE = (ESTIMATES_MASS, ESTIMATES_ROLLING_RADIUS)
#: written by vd replay where it changes, on the engine path only: never a cascade topic
ON_CHANGE = (ESTIMATES_TORQUE_OFFSET,)


@pytest.fixture(scope='module')
def result() -> CascadeResult:
    n = 50
    t = np.arange(n) * 1e-3
    return run_cascade(
        CascadeSeries(t, np.zeros((n, 4)), np.zeros(n), np.zeros((n, 4))),
        CascadeSettings(load_estimator_vehicle(default_vehicle_file())),
    )


@pytest.mark.parametrize(
    ('config', 'online'),
    [
        (None, ()),
        (EstimatorConfig(), ()),
        (EstimatorConfig(mass_adaptation=True), (ESTIMATES_MASS,)),
        (EstimatorConfig(radius_adaptation=True), (ESTIMATES_ROLLING_RADIUS,)),
        (EstimatorConfig(mass_adaptation=True, radius_adaptation=True), ONLINE),
    ],
)
def test_online_mass_and_radius_only_where_the_config_adapts_them(
    result: CascadeResult, config: EstimatorConfig | None, online: tuple[str, ...]
) -> None:
    topics = cascade_topics(result, np.zeros((result.t.shape[0], 4)), config)
    always = {t for t in ESTIMATE_TOPICS if t not in ONLINE + ON_CHANGE}
    assert set(topics) == always | set(online)
