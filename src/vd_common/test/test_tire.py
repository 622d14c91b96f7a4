"""Magic Formula tyre: shape, load dependence, road friction scale, low-speed floor."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from vd_common.vehicle.params import load_vehicle
from vd_common.vehicle.tire import magic_formula_fx, slip_ratio, tire_force_from_slip_velocity

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'clio_rl_1_1.yaml'
TP = load_vehicle(CONFIG).tire


def test_free_rolling_tyre_carries_no_force() -> None:
    assert magic_formula_fx(0.0, 2500.0, 1.0, TP) == 0.0
    assert tire_force_from_slip_velocity(0.0, 0.0, 2500.0, 1.0, TP) == 0.0


@pytest.mark.parametrize('fz', [1500.0, 2500.0, 3500.0])
def test_peak_is_road_mu_times_load_dependent_friction(fz: float) -> None:
    kappa = np.linspace(0.0, 1.0, 20001)
    dfz = (fz - TP.nominal_load) / TP.nominal_load
    for mu in (1.0, 0.3):
        peak = magic_formula_fx(kappa, fz, mu, TP).max()
        # sin(.) reaches 1 at the peak of the curve: Dx = mu (pDx1 + pDx2 dfz) Fz.
        assert peak == pytest.approx(mu * (TP.pDx1 + TP.pDx2 * dfz) * fz, rel=1e-6)


def test_slip_stiffness_at_origin_is_kx() -> None:
    fz = 3000.0
    dfz = (fz - TP.nominal_load) / TP.nominal_load
    kx = fz * (TP.pKx1 + TP.pKx2 * dfz) * np.exp(TP.pKx3 * dfz)
    h = 1e-7
    slope = (magic_formula_fx(h, fz, 1.0, TP) - magic_formula_fx(-h, fz, 1.0, TP)) / (2 * h)
    assert slope == pytest.approx(kx, rel=1e-5)


def test_heavier_load_more_force_but_lower_friction_coefficient() -> None:
    kappa = np.array(0.12)
    f_light = float(magic_formula_fx(kappa, 2000.0, 1.0, TP))
    f_heavy = float(magic_formula_fx(kappa, 4000.0, 1.0, TP))
    assert f_heavy > f_light
    assert f_heavy / 4000.0 < f_light / 2000.0


def test_no_load_no_force() -> None:
    assert magic_formula_fx(0.2, 0.0, 1.0, TP) == 0.0
    assert float(magic_formula_fx(np.array([0.2]), np.array([-10.0]), 1.0, TP)[0]) == 0.0


def test_slip_ratio_definition_and_floor() -> None:
    # driving: (wR - v) / wR ; braking: (wR - v) / v ; standstill: floored denominator
    assert slip_ratio(2.0, 10.0, 1.0) == pytest.approx(2.0 / 12.0)
    assert slip_ratio(-2.0, 10.0, 1.0) == pytest.approx(-0.2)
    assert slip_ratio(0.1, 0.0, 1.0) == pytest.approx(0.1)
    assert slip_ratio(-10.0, 10.0, 1.0) == pytest.approx(-1.0)  # locked wheel


@settings(max_examples=200, deadline=None)
@given(vs=st.floats(-40.0, 40.0), vg=st.floats(-50.0, 50.0), fz=st.floats(1.0, 6000.0))
def test_tyre_is_passive(vs: float, vg: float, fz: float) -> None:
    # The tyre R must never deliver power: Fx * slip velocity >= 0.
    tp = dataclasses.replace(TP, pHx1=0.0, pHx2=0.0, pVx1=0.0, pVx2=0.0)
    assert tire_force_from_slip_velocity(float(vs), float(vg), float(fz), 1.0, tp) * vs >= 0.0


def test_force_bounded_by_peak() -> None:
    kappa = np.linspace(-1.0, 1.0, 4001)
    fx = magic_formula_fx(kappa, 2500.0, 1.0, TP)
    assert np.max(np.abs(fx)) <= 1.0001 * TP.pDx1 * 2500.0
