"""The tyre's friction peak table, road classes and axle means (what the estimator uses).

The simulator's truth built on this table is tested with vd_sim_node (test_friction_truth.py).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from vd_common.errors import ParameterError
from vd_common.vehicle.friction import (
    ROAD_CLASS_BOUNDS,
    ROAD_DRY,
    ROAD_ICE,
    ROAD_SNOW,
    ROAD_UNKNOWN,
    ROAD_WET,
    axle_mean,
    friction_table,
    road_class,
    road_class_of,
    unit_peak,
    vehicle_road_class,
)
from vd_common.vehicle.params import load_vehicle
from vd_common.vehicle.tire import magic_formula_fx

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'clio_rl_1_1.yaml'
TP = load_vehicle(CONFIG).tire
TABLE = friction_table(TP)
FINE = np.linspace(0.0, 1.0, 100_001)  # [-] slip grid of the brute-force search, step 1e-5


def test_unit_peak_matches_a_brute_force_search_of_the_curve() -> None:
    loads = np.array([1000.0, 2345.0, 3500.0, 4999.0])
    for driving in (True, False):
        mu, slip = unit_peak(TABLE, loads, np.full(loads.shape, driving))
        sign = 1.0 if driving else -1.0
        for k, fz in enumerate(loads):
            curve = sign * magic_formula_fx(sign * FINE, float(fz), 1.0, TP) / fz
            i = int(np.argmax(curve))
            assert mu[k] == pytest.approx(curve[i], abs=1e-6)
            assert slip[k] == pytest.approx(FINE[i], abs=1.5e-4)


def test_the_table_is_read_only_and_cached_per_tyre() -> None:
    assert friction_table(TP) is TABLE
    with pytest.raises(ValueError, match='read-only'):
        TABLE.mu_drive[0] = 0.0


def test_axles_are_wheel_means() -> None:
    means = axle_mean(np.arange(8.0).reshape(2, 4))
    np.testing.assert_array_equal(means, [[0.5, 2.5], [4.5, 6.5]])


def test_road_class_bounds() -> None:
    assert ROAD_CLASS_BOUNDS == (0.2, 0.45, 0.75)
    values = [0.0, 0.199, 0.2, 0.449, 0.45, 0.749, 0.75, 1.2, math.nan]
    expect = [ROAD_ICE, ROAD_ICE, ROAD_SNOW, ROAD_SNOW, ROAD_WET, ROAD_WET, ROAD_DRY, ROAD_DRY]
    np.testing.assert_array_equal(road_class(values), [*expect, ROAD_UNKNOWN])
    assert [road_class_of(v) for v in values] == [*expect, ROAD_UNKNOWN]
    np.testing.assert_array_equal(vehicle_road_class([[1.0, 0.3], [0.5, 0.9]]), [2, 3])


@given(st.lists(st.floats(0.0, 3.0), min_size=2, max_size=20))
def test_road_class_is_monotone_in_mu_max(values: list[float]) -> None:
    ordered = np.sort(np.asarray(values))
    codes = road_class(ordered)
    assert np.all(np.diff(codes) >= 0)
    assert codes.min() >= ROAD_ICE and codes.max() <= ROAD_DRY
    assert [road_class_of(v) for v in ordered.tolist()] == codes.tolist()


def test_invalid_grid_is_rejected() -> None:
    with pytest.raises(ParameterError, match='friction table grid'):
        friction_table(TP, load_min=0.0)
    with pytest.raises(ParameterError, match='friction table grid'):
        friction_table(TP, loads=1)
