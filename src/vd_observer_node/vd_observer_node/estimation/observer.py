"""Online observers: wheel speed and acceleration from wheel angles, body acceleration.

Each observer is a `LevantDifferentiator` on the measured signal: the wheel angles theta_i
give (theta, omega, omega_dot), the body speed v gives (v, v_dot, v_ddot). Where only wheel
speeds are measured (``ObserverConfig.wheel_input = 'speed'``: ABS sensors) the wheel observer
is the first-order differentiator on omega_i and gives the same outputs, its angle being the
integral of omega from 0 at the start (see `differentiator`). Outputs at a
stamp are the estimates FOR that stamp (exactly so with the implicit discretization; the
explicit ones use the sample of the stamp only from the next step on).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any, ClassVar, Final, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.errors import ConfigurationError, InputShapeError
from vd_observer_node.estimation.differentiator import (
    DEFAULT_GAINS,
    DISCRETIZATIONS,
    INIT_POLICIES,
    DifferentiatorSettings,
    LevantDifferentiator,
    LevantGains,
)
from vd_observer_node.estimation.faults import FaultCounter

__all__ = [
    'WHEEL_INPUTS',
    'Observer',
    'ObserverConfig',
    'ObserverOutput',
    'SpeedObserver',
    'SpeedState',
    'WheelObserver',
    'WheelState',
]

FloatArray = NDArray[np.float64]

#: What the wheel sensors measure: unwrapped angles [rad] or speeds [rad/s].
WHEEL_INPUTS: Final = ('angle', 'speed')


@dataclass(frozen=True)
class ObserverConfig:
    """Settings of the wheel and speed observers.

    Attributes:
        gains: Levant gains (paper order l0, l1, l2), shared by both observers.
        wheel_lipschitz: L for the wheel angles, bound on |d^3 theta/dt^3| = |omega_ddot|
            [rad/s^3]. Larger tracks torque steps faster, smaller rejects encoder noise.
            With `follow_resolution` it is the floor, chosen for a 96 counts/rev encoder.
        speed_lipschitz: L for the body speed, bound on |d^3 v/dt^3| [m/s^4].
        discretization: one of `differentiator.DISCRETIZATIONS`.
        init: one of `differentiator.INIT_POLICIES`.
        max_gap: a gap between stamps longer than this [s] re-initialises the observer, and
            so does a stamp older than the last one by more than this (a looped bag); a
            smaller step back or a repeated stamp is dropped. See docs/faults.md.
        init_baseline: time [s] between the two samples of the 'finite_difference'
            initialisation (longer = less noise in the initial derivative).
        wheel_input: one of `WHEEL_INPUTS`: 'angle' runs the second-order differentiator on
            the wheel angles, 'speed' the first-order one on the wheel speeds (same
            wheel_lipschitz: it bounds |d^2 omega/dt^2| either way).
        follow_resolution: with wheel angles, each wheel's L rises above
            ``wheel_lipschitz`` as its angles show a finer resolution than a 96 counts/rev
            encoder: times sqrt(2 pi / 96 / resolution), at most times 10, the resolution
            being the smallest non-zero change between consecutive angles seen so far
            (`levant_step.followed_lipschitz`; exact angles take the cap). False: L is
            ``wheel_lipschitz`` throughout. Wheel speeds keep ``wheel_lipschitz``.
    """

    gains: LevantGains = field(default_factory=lambda: DEFAULT_GAINS)
    wheel_lipschitz: float = 300.0
    speed_lipschitz: float = 20.0
    discretization: str = 'implicit'
    init: str = 'finite_difference'
    max_gap: float = 0.5
    init_baseline: float = 0.05
    wheel_input: str = 'angle'
    follow_resolution: bool = True

    def __post_init__(self) -> None:
        if self.wheel_input not in WHEEL_INPUTS:
            raise ConfigurationError(
                f'unknown wheel_input {self.wheel_input!r}; use one of {WHEEL_INPUTS}'
            )
        if self.discretization not in DISCRETIZATIONS:
            raise ConfigurationError(
                f'unknown discretization {self.discretization!r}; use one of {DISCRETIZATIONS}'
            )
        if self.init not in INIT_POLICIES:
            raise ConfigurationError(f'unknown init {self.init!r}; use one of {INIT_POLICIES}')
        if not (math.isfinite(self.init_baseline) and self.init_baseline >= 0.0):
            raise ConfigurationError(f'init_baseline must be >= 0, got {self.init_baseline}')
        for name in ('wheel_lipschitz', 'speed_lipschitz', 'max_gap'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigurationError(f'{name} must be finite and > 0, got {value}')

    def differentiator(self, *, wheels: bool = False) -> DifferentiatorSettings:
        """The settings of an observer's differentiator (all but L and channels): the wheels'
        (`wheels`) follow their angles' resolution where `follow_resolution` says so."""
        return DifferentiatorSettings(
            gains=self.gains,
            discretization=self.discretization,
            init=self.init,
            max_gap=self.max_gap,
            init_baseline=self.init_baseline,
            follow_resolution=wheels and self.follow_resolution and self.wheel_input == 'angle',
        )

    @classmethod
    def from_mapping(cls, data: dict[str, Any]) -> ObserverConfig:
        """Build from a flat mapping (e.g. ROS parameters); gains as l0, l1, l2 keys.

        Raises:
            ConfigurationError: unknown key or invalid value.
        """
        known = {f.name for f in fields(cls)} - {'gains'}
        gain_keys = {'l0', 'l1', 'l2'}
        unknown = set(data) - known - gain_keys
        if unknown:
            raise ConfigurationError(f'unknown observer settings: {sorted(unknown)}')
        gains = LevantGains(**{k: float(v) for k, v in data.items() if k in gain_keys})
        kwargs = {k: v for k, v in data.items() if k in known}
        return cls(gains=gains, **kwargs)


class WheelState(NamedTuple):
    """Wheel observer output for one stamp (shapes (4,), order FL, FR, RL, RR).

    Attributes:
        angle: [rad], filtered unwrapped angle.
        omega: [rad/s].
        omega_dot: [rad/s^2].
        valid: bool, False while initialising or when the wheel's sample was invalid.
    """

    angle: FloatArray
    omega: FloatArray
    omega_dot: FloatArray
    valid: NDArray[np.bool_]


class SpeedState(NamedTuple):
    """Speed observer output for one stamp.

    Attributes:
        speed: [m/s], filtered body speed.
        accel: [m/s^2], dv/dt along the road.
        valid: False while initialising or when the sample was invalid.
    """

    speed: float
    accel: float
    valid: bool


class _DifferentiatorObserver:
    """What both observers share: one differentiator and its fault bookkeeping."""

    #: signals differentiated together (4 wheels, or the 1 body speed)
    _channels: ClassVar[int]
    #: the wheel observer (its L may follow the resolution, `ObserverConfig.differentiator`)
    _wheels: ClassVar[bool] = False

    @staticmethod
    def _lipschitz(config: ObserverConfig) -> float:
        """L of this signal kind [unit/s^3]."""
        raise NotImplementedError

    @staticmethod
    def _input_derivative(config: ObserverConfig) -> int:
        """Which derivative of the estimated signal the samples are (0: itself)."""
        return 0

    def __init__(self, config: ObserverConfig) -> None:
        """Create the observer from its settings."""
        #: the differentiator (its records are what `cascade_step.cascade_block` steps)
        self.differentiator = LevantDifferentiator(
            self._lipschitz(config),
            n_channels=self._channels,
            settings=config.differentiator(wheels=self._wheels),
            input_derivative=self._input_derivative(config),
        )

    @property
    def rejected_count(self) -> int:
        """Samples rejected for a duplicate, slightly older or non-finite stamp."""
        return self.differentiator.rejected_count

    @property
    def faults(self) -> FaultCounter:
        """Input faults per kind (see `differentiator.LevantDifferentiator`)."""
        return self.differentiator.faults


class WheelObserver(_DifferentiatorObserver):
    """Four-wheel Levant differentiator on the wheel angles (or speeds, `wheel_input`)."""

    _channels = 4
    _wheels = True
    last: WheelState | None = None

    @staticmethod
    def _lipschitz(config: ObserverConfig) -> float:
        return config.wheel_lipschitz

    @staticmethod
    def _input_derivative(config: ObserverConfig) -> int:
        return WHEEL_INPUTS.index(config.wheel_input)

    def update(self, t: float, angles: ArrayLike) -> WheelState:
        """Feed the wheel sensors at stamp t.

        Args:
            t: stamp [s].
            angles: shape (4,), FL, FR, RL, RR: unwrapped angles [rad], or speeds [rad/s]
                when the observer was configured with ``wheel_input='speed'``.

        Raises:
            InputShapeError: angles is not of shape (4,).
        """
        a = np.asarray(angles, dtype=np.float64)
        if a.shape != (4,):
            raise InputShapeError(f'wheel sensors must have shape (4,), got {a.shape}')
        est = self.differentiator.update(t, a)
        self.last = WheelState(est.value, est.first, est.second, est.valid)
        return self.last


class SpeedObserver(_DifferentiatorObserver):
    """Levant differentiator on the measured body speed."""

    _channels = 1
    last: SpeedState | None = None

    @staticmethod
    def _lipschitz(config: ObserverConfig) -> float:
        return config.speed_lipschitz

    def update(self, t: float, speed: float) -> SpeedState:
        """Feed the measured body speed [m/s] at stamp t [s]."""
        est = self.differentiator.update(t, speed)
        self.last = SpeedState(float(est.value[0]), float(est.first[0]), bool(est.valid[0]))
        return self.last


class ObserverOutput(NamedTuple):
    """Combined observer output for one stamp.

    Attributes:
        omega: shape (4,), [rad/s].
        omega_dot: shape (4,), [rad/s^2].
        accel: [m/s^2], body longitudinal acceleration.
    """

    omega: FloatArray
    omega_dot: FloatArray
    accel: float


class Observer:
    """Wheel and speed observers driven by common stamps (offline use, tests).

    The ROS node receives the two topics separately and can use `wheels` and `speed`
    directly.
    """

    def __init__(self, config: ObserverConfig) -> None:
        """Create both observers from one settings object."""
        self.wheels = WheelObserver(config)
        self.speed = SpeedObserver(config)

    def update(self, t: float, angles: ArrayLike, speed: float) -> ObserverOutput:
        """Feed wheel angles, shape (4,) [rad], and body speed [m/s] sampled at stamp t [s]."""
        wheel = self.wheels.update(t, angles)
        body = self.speed.update(t, speed)
        return ObserverOutput(wheel.omega, wheel.omega_dot, body.accel)
