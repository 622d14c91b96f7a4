"""The chain without a tyre (an estimation-only vehicle file): every estimate, no situation."""

from __future__ import annotations

import dataclasses

import numpy as np
from vd_common.vehicle.params import default_vehicle_file
from vd_observer_node.chain import Chain, ChainOutput
from vd_observer_node.estimation.vehicle import (
    EstimatorVehicle,
    load_vehicle_params,
    no_tire_note,
)
from vd_observer_node.situation.chain_settings import ChainSettings
from vd_observer_node.situation.friction_potential import TyreCurves
from vd_observer_node.testing.synthetic import synthetic_trajectory


def _run(settings: ChainSettings, seconds: float = 6.0) -> list[ChainOutput]:
    traj = synthetic_trajectory(np.arange(0.0, seconds, 0.002), settings.vehicle)
    chain = Chain(settings)
    return [
        chain.update(float(t), traj.angle[i], float(traj.speed[i]), traj.torque[i])
        for i, t in enumerate(traj.t)
    ]


def test_without_curves_every_estimate_is_the_same_and_no_situation() -> None:
    params = load_vehicle_params()
    assert params.tire is not None and no_tire_note(params) is None
    vehicle = EstimatorVehicle.from_params(params)
    with_tire = _run(ChainSettings(vehicle=vehicle, curves=TyreCurves.from_tire(params.tire)))
    without = _run(ChainSettings(vehicle=vehicle, curves=None))
    assert all(out.situation is not None for out in with_tire)
    assert all(out.situation is None for out in without)
    # the monitor reads the cascade and feeds nothing back: the estimates are bit for bit
    for a, b in zip(with_tire, without, strict=True):
        np.testing.assert_array_equal(a.wheel.omega, b.wheel.omega)
        assert (a.speed.speed, a.speed.accel) == (b.speed.speed, b.speed.accel)
        np.testing.assert_array_equal(a.estimates.fx, b.estimates.fx)
        np.testing.assert_array_equal(a.estimates.mu, b.estimates.mu)
        assert (a.estimates.slope, a.estimates.slope_valid) == (
            b.estimates.slope,
            b.estimates.slope_valid,
        )
    slopes = [o.estimates.slope for o in without if o.estimates.slope_valid]
    assert len(slopes) > len(without) // 2  # the slope does run without a tyre


def test_the_note_names_the_file_without_tire() -> None:
    params = dataclasses.replace(load_vehicle_params(default_vehicle_file()), tire=None)
    note = no_tire_note(params)
    assert note == (
        f'off (no tire in vehicle file {default_vehicle_file()}: the friction potential and '
        'the alerts need its Magic Formula coefficients)'
    )
