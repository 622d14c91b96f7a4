"""Mass, c0 and drag area against a synthetic drive obeying the force balance exactly."""

from __future__ import annotations

import numpy as np
import pytest
from vd_observer_node.tools.calibrate.errors import NotDeterminedError
from vd_observer_node.tools.calibrate.force_balance import fit_force_balance

MASS_KG = 1725.0
C0 = 0.011
DRAG_AREA_M2 = 0.78


def _drive(seed: int, top_speed_mps: float, samples: int = 4000) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    speed = 3.0 + (top_speed_mps - 3.0) * rng.random(samples)
    accel = rng.normal(0.0, 0.8, samples)
    slope = np.deg2rad(rng.normal(0.0, 3.0, samples))
    # Independent oracle: the force written out term by term (not the fit's design matrix).
    force = (
        MASS_KG * accel
        + MASS_KG * 9.81 * np.sin(slope)
        + MASS_KG * 9.81 * C0 * np.cos(slope)
        + 0.5 * 1.2 * DRAG_AREA_M2 * speed**2
    )
    # 50 N of torque-signal noise and 0.02 m/s^2 of acceleration noise.
    force += rng.normal(0.0, 50.0, samples)
    accel = accel + rng.normal(0.0, 0.02, samples)
    return force, speed, accel, slope


def test_force_balance_recovers_mass_c0_and_drag() -> None:
    fit = fit_force_balance(*_drive(seed=31, top_speed_mps=35.0))
    assert fit.drag_area_m2 is not None
    assert fit.not_determined == ()
    # Issue #37 targets: mass 3 %, drag 10 %, c0 20 %. Measured with this noise: mass 0.14 %
    # (std 0.06 %), c0 0.24 % (std 0.8 %), drag 0.14 % (std 0.56 %); bounds ~4 stds.
    assert abs(fit.mass_kg.value - MASS_KG) / MASS_KG < 0.005
    assert abs(fit.drag_area_m2.value - DRAG_AREA_M2) / DRAG_AREA_M2 < 0.025
    assert abs(fit.rolling_c0.value - C0) / C0 < 0.035
    assert abs(fit.mass_kg.value - MASS_KG) < 4.0 * fit.mass_kg.std
    assert abs(fit.rolling_c0.value - C0) < 4.0 * fit.rolling_c0.std
    assert abs(fit.drag_area_m2.value - DRAG_AREA_M2) < 4.0 * fit.drag_area_m2.std


def test_slow_drive_leaves_drag_not_determined() -> None:
    fit = fit_force_balance(*_drive(seed=32, top_speed_mps=14.0))
    assert fit.drag_area_m2 is None
    assert 'never above 60 km/h' in fit.not_determined[0]
    assert abs(fit.mass_kg.value - MASS_KG) / MASS_KG < 0.005
    # c0 then carries the drag at these speeds (0.0133 measured vs 0.011): more, never less.
    assert C0 < fit.rolling_c0.value < 1.5 * C0


def test_too_few_samples_is_not_determined() -> None:
    with pytest.raises(NotDeterminedError, match='usable samples'):
        fit_force_balance(*_drive(seed=33, top_speed_mps=30.0, samples=100))
