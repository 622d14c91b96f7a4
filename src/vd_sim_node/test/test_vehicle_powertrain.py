"""Engine map, idle governor, clutch, brakes, shift logic, and fast/slow law agreement."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from vd_common.vehicle.params import load_vehicle
from vd_sim_node.vehicle import laws
from vd_sim_node.vehicle.powertrain import (
    ClutchMode,
    DrivelineState,
    brake_torque,
    clutch_engagement,
    clutch_torque,
    combustion_torque,
    decide_shift,
    engine_drag_torque,
    full_load_torque,
)
from vd_sim_node.vehicle.resistances import aero_drag, rolling_resistance

CONFIG = Path(__file__).resolve().parents[2] / 'vd_common' / 'config' / 'clio_rl_1_1.yaml'
VP = load_vehicle(CONFIG)
EP, CP, GP = VP.engine, VP.clutch, VP.gearbox
RPM = math.pi / 30.0


def test_published_engine_figures() -> None:
    w = np.linspace(EP.full_load_speed[0], EP.max_speed, 20001)
    torque = full_load_torque(w, EP)
    power = torque * w
    assert torque.max() == pytest.approx(83.0, abs=0.01)  # published 83 N m
    assert power.max() == pytest.approx(36000.0, rel=0.01)  # published 36 kW
    assert w[np.argmax(power)] / RPM == pytest.approx(5250.0, rel=0.03)


def test_full_throttle_net_torque_is_the_full_load_curve() -> None:
    w = np.array([150.0, 262.0, 400.0, 550.0])
    net = combustion_torque(np.ones(4), w, EP) - engine_drag_torque(w, EP)
    np.testing.assert_allclose(net, full_load_torque(w, EP), rtol=1e-12)


def test_idle_governor_holds_engine_above_stall() -> None:
    # Closed throttle: torque only below idle speed, and it grows as the engine slows.
    assert combustion_torque(0.0, EP.idle_speed + 10.0, EP) == 0.0
    low = combustion_torque(0.0, EP.idle_speed - 5.0, EP)
    lower = combustion_torque(0.0, EP.idle_speed - 10.0, EP)
    assert 0.0 < low < lower


def test_rev_limiter_cuts_fuel() -> None:
    assert combustion_torque(1.0, EP.max_speed, EP) == 0.0
    assert combustion_torque(1.0, EP.max_speed + 50.0, EP) == 0.0


def test_clutch_modes() -> None:
    assert clutch_engagement(float(ClutchMode.OPEN), 400.0, CP) == 0.0
    assert clutch_engagement(float(ClutchMode.LOCKED), 50.0, CP) == 1.0
    launch = float(ClutchMode.LAUNCH)
    assert clutch_engagement(launch, CP.engage_start_speed, CP) == 0.0
    assert clutch_engagement(launch, CP.engage_full_speed, CP) == 1.0
    mid = 0.5 * (CP.engage_start_speed + CP.engage_full_speed)
    assert clutch_engagement(launch, mid, CP) == pytest.approx(0.5)
    # friction torque is dissipative: same sign as the slip
    assert clutch_torque(3.0, 2.0, 300.0, CP) > 0.0 > clutch_torque(-3.0, 2.0, 300.0, CP)
    assert abs(clutch_torque(1e3, 2.0, 300.0, CP)) <= CP.capacity


def test_clutch_engagement_ramp_after_a_shift() -> None:
    block = laws.make_clutch_ramp(CP)
    assert block(10.0, 10.0) == 0.0
    assert block(10.0 + 0.5 * CP.engage_time, 10.0) == pytest.approx(0.5)
    assert block(10.0 + 2.0 * CP.engage_time, 10.0) == 1.0
    assert block(0.0, -1e9) == 1.0
    t = np.array([9.0, 10.0 + 0.25 * CP.engage_time, 20.0])
    np.testing.assert_allclose(block(t, 10.0), [0.0, 0.25, 1.0])
    assert clutch_torque(5.0, 2.0, 300.0, CP, 0.5) == pytest.approx(
        0.5 * clutch_torque(5.0, 2.0, 300.0, CP)
    )


def test_brake_holds_like_stiff_damper_and_saturates() -> None:
    assert brake_torque(0.0, 1.0, 1000.0, 0.5) == 0.0
    assert brake_torque(100.0, 0.5, 1000.0, 0.5) == pytest.approx(500.0)
    assert brake_torque(-100.0, 0.5, 1000.0, 0.5) == pytest.approx(-500.0)


def test_resistances_match_paper_equation() -> None:
    v, fz = 30.0, 2500.0
    expected = 0.01 * (1.0 + 3.6 * v / 160.0) * fz
    assert rolling_resistance(v, fz, VP.rolling_resistance) == pytest.approx(expected, rel=1e-9)
    assert rolling_resistance(0.0, fz, VP.rolling_resistance) == 0.0
    assert aero_drag(30.0, VP.aero) == pytest.approx(0.5 * 1.225 * 0.33 * 1.85 * 900.0)
    assert aero_drag(-30.0, VP.aero) == pytest.approx(-aero_drag(30.0, VP.aero))


def _w_gb(w_gb_first: float) -> np.ndarray:
    ratios = np.array(GP.ratios)
    return w_gb_first * ratios / ratios[0]


def test_shift_logic_has_hysteresis() -> None:
    locked3 = DrivelineState(gear=3, clutch=ClutchMode.LOCKED)
    ratios = np.array(GP.ratios)
    # full throttle: upshift above the open-throttle speed, not below
    w3 = GP.upshift_speed_open + 1.0
    d = decide_shift(1.0, locked3, w3, w3 * ratios / ratios[2], 1.0, 30.0, True, GP, CP)
    assert d is not None and d.state.gear == 4 and d.state.clutch == ClutchMode.OPEN
    assert d.state.shift_end == pytest.approx(1.0 + GP.shift_time)
    w3 = GP.upshift_speed_open - 1.0
    assert decide_shift(1.0, locked3, w3, w3 * ratios / ratios[2], 1.0, 30.0, True, GP, CP) is None
    # between the thresholds nothing happens; below the downshift speed it shifts down
    w3 = 0.5 * (GP.downshift_speed + GP.upshift_speed_closed)
    assert decide_shift(1.0, locked3, w3, w3 * ratios / ratios[2], 0.0, 10.0, True, GP, CP) is None
    w3 = GP.downshift_speed - 1.0
    w_e = max(w3, CP.engage_start_speed + 1.0)
    d = decide_shift(1.0, locked3, w_e, w3 * ratios / ratios[2], 0.0, 10.0, True, GP, CP)
    assert d is not None and d.state.gear == 2


def test_shift_completes_and_clutch_events() -> None:
    shifting = DrivelineState(gear=2, clutch=ClutchMode.OPEN, shift_end=5.0)
    assert decide_shift(4.9, shifting, 300.0, _w_gb(300.0), 1.0, 10.0, True, GP, CP) is None
    d = decide_shift(5.0, shifting, 300.0, _w_gb(300.0), 1.0, 10.0, True, GP, CP)
    assert d is not None and d.state == DrivelineState(2, ClutchMode.LOCKED, ramp_start=5.0)
    launch = DrivelineState(gear=1, clutch=ClutchMode.LAUNCH)
    d = decide_shift(0.0, launch, CP.engage_full_speed, _w_gb(200.0), 1.0, 3.0, True, GP, CP)
    assert d is not None and d.state.clutch == ClutchMode.LOCKED
    locked = DrivelineState(gear=1, clutch=ClutchMode.LOCKED)
    d = decide_shift(0.0, locked, CP.engage_start_speed - 1, _w_gb(100.0), 0.0, 1.0, True, GP, CP)
    assert d is not None and d.state.clutch == ClutchMode.LAUNCH


def test_hold_brake_applies_at_standstill_and_releases_on_throttle() -> None:
    idle = DrivelineState(gear=1, clutch=ClutchMode.LAUNCH)
    d = decide_shift(0.0, idle, 80.0, _w_gb(0.0), 0.0, 0.0, True, GP, CP)
    assert d is not None and d.state.hold_brake
    assert decide_shift(0.0, idle, 80.0, _w_gb(0.0), 0.0, 0.0, False, GP, CP) is None
    held = DrivelineState(gear=1, clutch=ClutchMode.LAUNCH, hold_brake=True)
    d = decide_shift(0.0, held, 80.0, _w_gb(0.0), 0.5, 0.0, True, GP, CP)
    assert d is not None and not d.state.hold_brake


@settings(max_examples=150, deadline=None)
@given(
    thr=st.floats(0.0, 1.0),
    we=st.floats(-50.0, 800.0),
    slip=st.floats(-100.0, 100.0),
    mode=st.sampled_from([0.0, 1.0, 2.0]),
    ramp=st.floats(0.0, 1.0),
    v=st.floats(-60.0, 60.0),
    fz=st.floats(0.0, 5000.0),
    pedal=st.floats(0.0, 1.0),
)
def test_fast_laws_match_reference_functions(
    thr: float,
    we: float,
    slip: float,
    mode: float,
    ramp: float,
    v: float,
    fz: float,
    pedal: float,
) -> None:
    def both(law: laws.Law, *args: float) -> tuple[float, float]:
        fast = law(*[float(a) for a in args])
        slow = float(np.asarray(law(*[np.array([a]) for a in args])).ravel()[0])
        return fast, slow

    pairs = [
        (
            both(laws.make_combustion_law(EP), 0.0, thr, we, 3.0 * ramp * EP.idle_speed),
            combustion_torque(thr, we, EP, 3.0 * ramp * EP.idle_speed),
        ),
        (both(laws.make_engine_drag_law(EP), we), engine_drag_torque(we, EP)),
        (
            both(laws.make_clutch_law(CP), slip, mode, we, ramp),
            clutch_torque(slip, mode, we, CP, ramp),
        ),
        (both(laws.make_brake_law(1000.0, 0.5), slip, pedal), brake_torque(slip, pedal, 1e3, 0.5)),
        (
            both(laws.make_rolling_law(VP.rolling_resistance, 2.0), v + 0.01, v, fz),
            rolling_resistance(v, 2.0 * fz, VP.rolling_resistance),
        ),
        (both(laws.make_aero_law(VP.aero), v), aero_drag(v, VP.aero)),
    ]
    for (fast, slow), ref in pairs:
        assert fast == pytest.approx(slow, rel=1e-12, abs=1e-9)
        assert fast == pytest.approx(ref, rel=1e-12, abs=1e-9)
