"""Levant's robust exact differentiator on irregular time stamps: settings and the stateful
n-channel wrapper.

The math (the recursive and non-recursive forms, the explicit, Taylor and implicit
discretizations, the first-order differentiator on samples of f') and the per-stamp update
with its fault rules are `levant_step`'s, compiled with numba; `LevantDifferentiator` owns its
records and calls `levant_step.levant_update`.

The default gains (l0, l1, l2) = (2.0, 1.5, 1.1) are Levant's published sequence
{1.1, 1.5, 2, 3, 5, 8} for n = 2 (Levant, Int. J. Control 76(9/10), 2003, where it is indexed
the other way round: lambda_2 = 2 on the first equation, lambda_0 = 1.1 on the last). Their
non-recursive form k0 = l0, k1 = l1 * sqrt(l0) (= 2.12), k2 = l2 is the set (2, 2.12, 1.1)
tabulated by Levant and Livne for n = 2. The first-order differentiator on f' samples uses
the last two, (l1, l2) = (1.5, 1.1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.errors import ConfigurationError, InputShapeError
from vd_observer_node.estimation.faults import OBSERVER_FAULTS, FaultCounter
from vd_observer_node.estimation.levant_step import (
    DISCRETIZATIONS,
    INIT_POLICIES,
    INPUT_DERIVATIVES,
    PARAMS_DTYPE,
    STATE_DTYPE,
    LevantParts,
    followed_lipschitz,
    levant_reset,
    levant_update,
    levant_update_arrays,
    new_channels,
)
from vd_observer_node.kernel._jit import new_record, record_array

__all__ = [
    'DEFAULT_GAINS',
    'DISCRETIZATIONS',
    'INIT_POLICIES',
    'INPUT_DERIVATIVES',
    'DerivativeEstimate',
    'DifferentiatorSettings',
    'LevantDifferentiator',
    'LevantGains',
    'checked_settings',
    'levant_params',
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class LevantGains:
    """Gains of the recursive form, in the paper's order (l0 on the first equation).

    Attributes:
        l0: gain of the |z0 - f|^(2/3) term [-].
        l1: gain of the |z1 - v0|^(1/2) term [-].
        l2: gain of the sign term driving z2 [-], must exceed 1.
    """

    l0: float = 2.0
    l1: float = 1.5
    l2: float = 1.1

    def __post_init__(self) -> None:
        for name in ('l0', 'l1', 'l2'):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0.0):
                raise ConfigurationError(f'Levant gain {name} must be finite and > 0: {value!r}')
        if self.l2 <= 1.0:
            # The last gain must dominate the unknown f''' (|f'''| <= L) to converge at all.
            raise ConfigurationError(f'Levant gain l2 must be > 1, got {self.l2}')

    def nonrecursive(self) -> tuple[float, float, float]:
        """Gains (k0, k1, k2) of the equivalent non-recursive form [-]."""
        return self.l0, self.l1 * math.sqrt(self.l0), self.l2


#: Levant's published gains for the second-order differentiator.
DEFAULT_GAINS: Final = LevantGains()


@dataclass(frozen=True)
class DifferentiatorSettings:
    """A `LevantDifferentiator`'s settings but its L and channels (which the observers set
    per signal); `ObserverConfig.differentiator` gives the observers'.

    Attributes:
        gains: recursive-form gains.
        discretization: one of `DISCRETIZATIONS`.
        init: one of `INIT_POLICIES`.
        max_gap: time gap [s] beyond which the state is re-initialised.
        init_baseline: minimum time [s] between the two samples of the
            'finite_difference' initialisation.
        max_jump_back: a stamp older than the last accepted one by more than this [s]
            resets the state instead of being rejected; None = `max_gap`.
        follow_resolution: each channel's L rises above the given one (its floor) as the
            samples show a finer resolution (`levant_step.followed_lipschitz`).
    """

    gains: LevantGains = DEFAULT_GAINS
    discretization: str = 'implicit'
    init: str = 'finite_difference'
    max_gap: float = math.inf
    init_baseline: float = 0.0
    max_jump_back: float | None = None
    follow_resolution: bool = False


class DerivativeEstimate(NamedTuple):
    """Output of `LevantDifferentiator.update` for one stamp.

    Attributes:
        value: shape (n,), estimate of f.
        first: shape (n,), estimate of f' [unit/s].
        second: shape (n,), estimate of f'' [unit/s^2].
        valid: shape (n,), bool, False while a channel is not initialised or its current
            sample was rejected (then the outputs are an open-loop prediction).
    """

    value: FloatArray
    first: FloatArray
    second: FloatArray
    valid: NDArray[np.bool_]


def checked_settings(
    lipschitz: ArrayLike,
    n_channels: int,
    discretization: str,
    init: str,
    max_gap: float,
    init_baseline: float,
    max_jump_back: float | None,
    input_derivative: int = 0,
) -> tuple[FloatArray, float]:
    """Check a differentiator's settings (see `LevantDifferentiator`).

    Returns:
        (L per channel, shape (n,); the jump back [s] that resets, `max_gap` if None).

    Raises:
        ConfigurationError: invalid L, name or gap.
    """
    if discretization not in DISCRETIZATIONS:
        raise ConfigurationError(
            f'unknown discretization {discretization!r}; use one of {DISCRETIZATIONS}'
        )
    if init not in INIT_POLICIES:
        raise ConfigurationError(f'unknown init policy {init!r}; use one of {INIT_POLICIES}')
    if n_channels < 1:
        raise ConfigurationError(f'n_channels must be >= 1, got {n_channels}')
    if input_derivative not in INPUT_DERIVATIVES:
        raise ConfigurationError(
            f'input_derivative must be one of {INPUT_DERIVATIVES}, got {input_derivative!r}'
        )
    lip = np.broadcast_to(np.asarray(lipschitz, dtype=np.float64), (n_channels,)).copy()
    if not np.all(np.isfinite(lip) & (lip > 0.0)):
        raise ConfigurationError(f'Lipschitz bounds L must be finite and > 0: {lip}')
    if not (math.isfinite(init_baseline) and init_baseline >= 0.0):
        raise ConfigurationError(f'init_baseline must be finite and >= 0: {init_baseline}')
    if not max_gap > 0.0:
        raise ConfigurationError(f'max_gap must be > 0, got {max_gap}')
    jump = float(max_gap) if max_jump_back is None else float(max_jump_back)
    if not jump > 0.0:
        raise ConfigurationError(f'max_jump_back must be > 0, got {max_jump_back}')
    return lip, jump


def levant_params(
    settings: DifferentiatorSettings, max_jump_back: float, input_derivative: int = 0
) -> np.record:
    """The `levant_step.PARAMS_DTYPE` record of these (checked) settings (`max_jump_back` [s]
    resolved from the settings' None)."""
    p = new_record(PARAMS_DTYPE)
    gains = settings.gains
    p.l0, p.l1, p.l2 = gains.l0, gains.l1, gains.l2
    p.k0, p.k1, p.k2 = gains.nonrecursive()
    p.discretization = DISCRETIZATIONS.index(settings.discretization)
    p.init = INIT_POLICIES.index(settings.init)
    p.max_gap = float(settings.max_gap)
    p.init_baseline = settings.init_baseline
    p.max_jump_back = max_jump_back
    p.input_derivative = input_derivative
    p.follow_resolution = settings.follow_resolution
    return p


class LevantDifferentiator:
    """Stateful n-channel Levant differentiator on irregular time stamps.

    Second order on samples of f, or first order on samples of f' (``input_derivative=1``,
    see the module docstring); the outputs are (f, f', f'') estimates either way.

    Invalid input never poisons the state (every case counted in `faults`, see
    `vd_observer_node.estimation.faults`):

    * a non-finite stamp, a duplicate stamp or a stamp slightly older than the last one is
      rejected (state unchanged, also counted in `rejected_count`);
    * a stamp older than the last one by more than `max_jump_back` (a looped bag, a restarted
      source) resets the state and starts again from that sample ('time_jump_back');
    * a gap longer than `max_gap` re-initialises every channel from the new sample ('gap');
    * a non-finite sample of one channel makes that channel coast open loop for the step (its
      `valid` flag is False; 'non_finite_value');
    * a step whose state overflows (absurdly large finite input) resets the state
      ('non_finite_output'), so the outputs stay finite always.

    Initialisation policies (per channel, on its first finite samples):
        'first_sample': z = (f0, 0, 0) at the first sample.
        'finite_difference': waits for a sample at least `init_baseline` after the first
            and starts from z = (f1, (f1 - f0) / (t1 - t0), 0), which removes most of the
            convergence transient when the signal starts with a large slope (a car already
            moving); a baseline of a few tens of ms keeps noise from producing a huge
            initial slope.
        'zero': z = (0, 0, 0) before the first sample, then normal steps (shows finite-time
            convergence from a wrong state; mostly for tests).
    """

    def __init__(
        self,
        lipschitz: ArrayLike,
        *,
        n_channels: int,
        settings: DifferentiatorSettings = DifferentiatorSettings(),
        input_derivative: int = 0,
    ) -> None:
        """Create the differentiator.

        Args:
            lipschitz: shape (n,) or scalar, L, bound on |f'''| [unit/s^3], > 0.
            n_channels: number n of independent signals differentiated together.
            settings: gains, discretization, initialisation, gap and jump-back settings.
            input_derivative: one of `INPUT_DERIVATIVES`: 0 when the samples are f, 1 when
                they are f' (L then bounds the second derivative of the samples).

        Raises:
            ConfigurationError: invalid L, name or gap.
        """
        s = settings
        lip, jump = checked_settings(
            lipschitz,
            n_channels,
            s.discretization,
            s.init,
            s.max_gap,
            s.init_baseline,
            s.max_jump_back,
            input_derivative,
        )
        self._n = n_channels
        self._discretization = s.discretization
        self._row = int(input_derivative)
        #: `levant_step.PARAMS_DTYPE` record
        self.params = levant_params(s, jump, input_derivative)
        #: shape (n,), L per channel [unit/s^3] (the floor where it follows the resolution)
        self.lipschitz = lip
        #: `levant_step.STATE_DTYPE` record: last stamp, fault counters
        self.record = new_record(STATE_DTYPE)
        #: (n,) `levant_step.CHANNEL_DTYPE` records: estimates and initialisation per channel
        self.channels = new_channels(n_channels)
        #: the two records as the arrays they live in (`update`'s fast numba call)
        self._params_array = record_array(self.params)
        self._record_array = record_array(self.record)
        self._faults = FaultCounter(OBSERVER_FAULTS)
        self._synced = dict.fromkeys(OBSERVER_FAULTS, 0)
        self._out = np.zeros((3, n_channels))
        self._valid = np.zeros(n_channels, dtype=np.bool_)
        self.reset()
        self._warm_up()

    def _warm_up(self) -> None:
        """Compile `levant_update` (or load it from numba's cache) before the first sample."""
        levant_update(
            self.params, self.lipschitz, self.record.copy(), self.channels.copy(), 0.0,
            np.zeros(self._n), self._out, self._valid,
        )  # fmt: skip

    def parts(self) -> LevantParts:
        """The records as the compiled loops take them (`levant_step.LevantParts`; views of
        the live records, which are never replaced)."""
        return LevantParts(
            record_array(self.params), self.lipschitz, record_array(self.record),
            self.channels.view(np.ndarray),
        )  # fmt: skip

    @property
    def lipschitz_in_use(self) -> FloatArray:
        """Shape (n,), the L each channel steps with now [unit/s^3]: `lipschitz`, or where it
        follows the resolution, what the resolution seen so far gives."""
        if not self.params.follow_resolution:
            return self.lipschitz.copy()
        # the law the step used, on what it learnt (the step keeps it per channel only so as
        # not to take a square root per sample)
        return np.array([
            followed_lipschitz(floor, resolution)
            for floor, resolution in zip(self.lipschitz, self.resolution, strict=True)
        ])  # fmt: skip

    @property
    def resolution(self) -> FloatArray:
        """Shape (n,), the smallest non-zero change between consecutive samples seen so far
        [unit] (0: none yet; noted only where L follows the resolution)."""
        return np.asarray(self.channels.resolution, dtype=np.float64).copy()

    @property
    def discretization(self) -> str:
        """Discretization name."""
        return self._discretization

    @property
    def input_derivative(self) -> int:
        """Which derivative of f the samples are (0: f, 1: f')."""
        return self._row

    @property
    def state(self) -> FloatArray:
        """shape (3, n), copy of (f, f', f'') estimates at `time`."""
        z: FloatArray = self.channels.z.T.copy()
        return z

    @property
    def time(self) -> float | None:
        """Stamp [s] of the last accepted sample, None before the first."""
        t = float(self.record.t)
        return None if math.isnan(t) else t

    @property
    def rejected_count(self) -> int:
        """Samples rejected for a non-finite, repeated or slightly older stamp."""
        return int(self.record.rejected)

    @property
    def faults(self) -> FaultCounter:
        """Input faults per kind (`faults.OBSERVER_FAULTS`), from the record's counters."""
        for kind in OBSERVER_FAULTS:
            total = int(self.record[kind])
            if total > self._synced[kind]:
                self._faults.count(kind, total - self._synced[kind])
                self._synced[kind] = total
        return self._faults

    def reset(self) -> None:
        """Forget all history (back to the state before the first sample; faults stay)."""
        levant_reset(self.params, self.record, self.channels)

    def update(self, t: float, f: ArrayLike) -> DerivativeEstimate:
        """Feed the sample f taken at stamp t and return the estimates for stamp t.

        Args:
            t: sample stamp [s]; must increase strictly.
            f: shape (n,) or scalar, the sample.

        Returns:
            The estimates for stamp t (unchanged previous ones if t was rejected).

        Raises:
            InputShapeError: f does not broadcast to shape (n,).
        """
        try:
            sample = np.broadcast_to(np.asarray(f, dtype=np.float64), (self._n,))
        except ValueError as exc:
            raise InputShapeError(f'expected {self._n} samples, got shape {np.shape(f)}') from exc
        out, valid = self._out, self._valid
        levant_update_arrays(
            self._params_array, self.lipschitz, self._record_array, self.channels, float(t),
            np.ascontiguousarray(sample), out, valid,
        )  # fmt: skip
        return DerivativeEstimate(out[0].copy(), out[1].copy(), out[2].copy(), valid.copy())
