"""The wheel angles' L follows their resolution (`levant_step.followed_lipschitz`)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from vd_observer_node.estimation.differentiator import (
    DifferentiatorSettings,
    LevantDifferentiator,
)
from vd_observer_node.estimation.levant_step import (
    FOLLOW_MAX_RATIO,
    RESOLUTION_REFERENCE,
    followed_lipschitz,
)
from vd_observer_node.estimation.observer import ObserverConfig, WheelObserver

FLOOR = 300.0
T = np.arange(0.0, 4.0, 1e-3)  # 1 kHz
# a wheel at 20 rad/s with a 10 rad/s oscillation of 2 rad: |theta'''| = 2 * 10^3 = 2000
# rad/s^3, above the floor and below its cap
ANGLE = 20.0 * T + 2.0 * np.sin(10.0 * T)
OMEGA = 20.0 + 20.0 * np.cos(10.0 * T)


def _differentiator(follow: bool, n: int = 1) -> LevantDifferentiator:
    return LevantDifferentiator(
        FLOOR, n_channels=n, settings=DifferentiatorSettings(follow_resolution=follow)
    )


def _encoder(angle: np.ndarray, counts: int) -> np.ndarray:
    step = 2.0 * math.pi / counts
    return np.floor(angle / step) * step


def test_law_is_the_floor_times_the_square_root_of_the_resolution_ratio() -> None:
    # closed form: floor * sqrt(reference / resolution), between 1 and the cap times the floor
    assert pytest.approx(2.0 * math.pi / 96.0) == RESOLUTION_REFERENCE
    assert followed_lipschitz(FLOOR, RESOLUTION_REFERENCE) == FLOOR
    assert followed_lipschitz(FLOOR, 4.0 * RESOLUTION_REFERENCE) == FLOOR  # coarser: floor
    assert followed_lipschitz(FLOOR, RESOLUTION_REFERENCE / 4.0) == pytest.approx(2.0 * FLOOR)
    assert followed_lipschitz(FLOOR, 1e-12) == FOLLOW_MAX_RATIO * FLOOR
    for unknown in (0.0, -1.0, math.nan):
        assert followed_lipschitz(FLOOR, unknown) == FLOOR


@pytest.mark.parametrize('counts', [96, 1024, 8192])
def test_an_encoder_shows_its_step_as_the_resolution(counts: int) -> None:
    diff = _differentiator(True, n=4)
    samples = _encoder(ANGLE, counts)
    for t, angle in zip(T, samples, strict=True):
        diff.update(t, np.full(4, angle))
    step = 2.0 * math.pi / counts
    np.testing.assert_allclose(diff.resolution, step, rtol=1e-9)
    expected = FLOOR * min(math.sqrt(counts / 96.0), FOLLOW_MAX_RATIO)
    np.testing.assert_allclose(diff.lipschitz_in_use, expected, rtol=1e-9)


def test_exact_angles_take_the_cap_and_track_what_the_floor_cannot() -> None:
    # oracle: the closed-form derivative. L = 300 is below |theta'''| = 2000: the floor loses
    # the wheel (tens of rad/s); the cap, 3000, follows it within the discretization error
    errors = {}
    for follow in (False, True):
        diff = _differentiator(follow)
        omega = np.array([diff.update(t, a).first[0] for t, a in zip(T, ANGLE, strict=True)])
        errors[follow] = float(np.abs(omega - OMEGA)[T > 1.0].max())
        in_use = diff.lipschitz_in_use[0]
        assert in_use == (FOLLOW_MAX_RATIO * FLOOR if follow else FLOOR)
    assert errors[False] > 10.0  # measured 30.8 rad/s
    assert errors[True] < 2e-3  # measured 6.7e-4 rad/s


def test_without_following_nothing_is_noted_and_a_reset_keeps_the_resolution() -> None:
    fixed, following = _differentiator(False), _differentiator(True)
    samples = _encoder(ANGLE, 1024)
    for t, angle in zip(T[:500], samples[:500], strict=True):
        fixed.update(t, angle)
        following.update(t, angle)
    assert fixed.resolution[0] == 0.0 and fixed.lipschitz_in_use[0] == FLOOR
    learnt = following.lipschitz_in_use.copy()
    following.reset()  # a gap or a looped bag: the drive starts again, the sensor is the same
    np.testing.assert_array_equal(following.lipschitz_in_use, learnt)


def test_only_the_wheel_angles_follow() -> None:
    config = ObserverConfig()
    assert config.differentiator(wheels=True).follow_resolution
    assert not config.differentiator().follow_resolution  # the body speed
    speeds = ObserverConfig(wheel_input='speed')  # ABS speeds: not measured for this law
    assert not speeds.differentiator(wheels=True).follow_resolution
    off = ObserverConfig(follow_resolution=False)
    assert not off.differentiator(wheels=True).follow_resolution
    observer = WheelObserver(config)
    # exact angles: the first 0.1 s steps 40 mrad (L 384), the slow roll at 0.31 s much less
    for t, angle in zip(T[:400], ANGLE[:400], strict=True):
        observer.update(t, np.full(4, angle))
    np.testing.assert_array_equal(observer.differentiator.lipschitz_in_use, 3000.0)
