"""The compiled chain: observers -> estimator -> situation monitor, per stamp and per block.

* `CompiledChain`: the compiled implementation of `vd_observer_node.chain.Chain` (what
  ``pipeline_node`` runs per stamp), tested equal to `chain.PythonChain`;
* `run_cascade_compiled` and `run_situation_compiled`: the compiled `cascade.run_cascade` and
  `situation.run_situation` over a whole record in one call each (offline replay), tested
  equal to them.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vd_observer_node.chain import ChainOutput, ChainSettings, chain_faults, engine_row
from vd_observer_node.errors import InputShapeError
from vd_observer_node.estimation.cascade import (
    CascadeResult,
    CascadeState,
    OffsetRecord,
    checked_engine,
    checked_record,
)
from vd_observer_node.estimation.differentiator import LevantDifferentiator
from vd_observer_node.estimation.drivetrain import (
    TORQUE_ENGINE,
    TORQUE_NONE,
    Drivetrain,
    engine_wheel_torques,
    gear_number,
)
from vd_observer_node.estimation.estimator import EstimatorConfig
from vd_observer_node.estimation.faults import ENGINE_FAULTS, FaultCounter, FaultReport
from vd_observer_node.estimation.levant_step import levant_reset, levant_update
from vd_observer_node.estimation.observer import (
    WHEEL_INPUTS,
    ObserverConfig,
    SpeedState,
    WheelState,
)
from vd_observer_node.estimation.torque_offset import (
    OFFSET_ESTIMATE_DTYPE,
    new_offset_estimate,
    new_offset_state,
    offset_from_record,
    offset_params,
    torque_offset_step,
)
from vd_observer_node.estimation.vehicle import EstimatorVehicle
from vd_observer_node.kernel._jit import jit
from vd_observer_node.kernel.estimation import (
    E_AERO,
    E_FX,
    E_FZ,
    E_MASS,
    E_MASS_CONVERGED,
    E_MASS_EXCITED,
    E_MASS_STD,
    E_MASS_USED,
    E_MU,
    E_MU_VALID,
    E_RADIUS,
    E_RADIUS_CONVERGED,
    E_RADIUS_FREE,
    E_RADIUS_STD,
    E_RADIUS_USED,
    E_ROLL,
    E_SLIP,
    E_SLOPE,
    E_SLOPE_VALID,
    EST_SIZE,
    CompiledEstimator,
    engine_torques,
    estimates_from_packed,
    estimator_update,
)
from vd_observer_node.situation.alerts import alerts_reset
from vd_observer_node.situation.friction_fit import fit_reset, vehicle_road_class
from vd_observer_node.situation.friction_potential import TyreCurves
from vd_observer_node.situation.monitor import (
    SituationMonitor,
    SituationSeries,
    monitor_restarts,
    monitor_step,
)

__all__ = [
    'CompiledChain',
    'compiled_monitor',
    'run_cascade_compiled',
    'run_situation_compiled',
    'warm_up',
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


def _observers(config: ObserverConfig) -> tuple[LevantDifferentiator, LevantDifferentiator]:
    """Wheel (4 channels) and speed (1 channel) differentiators of `observer.Observer`."""

    def make(lipschitz: float, n: int, input_derivative: int) -> LevantDifferentiator:
        return LevantDifferentiator(
            lipschitz,
            n_channels=n,
            gains=config.gains,
            discretization=config.discretization,
            init=config.init,
            max_gap=config.max_gap,
            init_baseline=config.init_baseline,
            input_derivative=input_derivative,
        )

    wheel_input = WHEEL_INPUTS.index(config.wheel_input)
    return make(config.wheel_lipschitz, 4, wheel_input), make(config.speed_lipschitz, 1, 0)


def _diff_args(d: LevantDifferentiator) -> tuple[Any, ...]:
    return d.kernel_args


def _estimator_args(e: CompiledEstimator) -> tuple[Any, ...]:
    s = e.s
    return (
        e.prm, s.scal, s.held, s.f_stages, s.f_prev, s.f_meta, s.s_stages, s.s_prev, s.s_meta,
        s.v_stages, s.v_prev, s.v_meta, s.last, e.counts,
    )  # fmt: skip


@jit
def _cascade_step(
    wprm: np.record, wlip: FloatArray, wst: np.record, wch: np.recarray,
    sprm: np.record, slip_: FloatArray, sst_: np.record, sch: np.recarray,
    eprm: FloatArray, escal: FloatArray, held: FloatArray, fst: FloatArray, fpr: FloatArray,
    fme: FloatArray, sst: FloatArray, spr: FloatArray, sme: FloatArray, vst: FloatArray,
    vpr: FloatArray, vme: FloatArray, last: FloatArray, ecnt: NDArray[np.int64],
    measured: bool, dprm: FloatArray, escl: FloatArray, offset_on: bool, oprm: np.record,
    ost: np.record, oout: np.record, t: float, angle: FloatArray, speed: float, torque: FloatArray,
    engine: FloatArray, wheel: FloatArray, wheel_valid: BoolArray, body: FloatArray,
    body_valid: BoolArray, est: FloatArray,
) -> bool:  # fmt: skip
    """One stamp of `run_cascade`: wheel and speed observers, then the estimator.

    With the engine path (``dprm`` non-empty) the wheel torques come from ``engine``
    (engine torque, gear, engine speed) instead of ``torque``; returns whether the torque
    source held (`CascadeResult.torque_valid`). ``escl`` (2,) is the engine path's state:
    the stamp the clutch last slipped or the gear changed (-inf before), the last gear (nan).
    With ``offset_on`` the engine path learns the engine-torque offset (settings ``oprm``,
    state ``ost``, estimate written to ``oout``) and subtracts it once converged.
    """
    levant_update(wprm, wlip, wst, wch, t, angle, wheel, wheel_valid)
    sample = np.empty(1)
    sample[0] = speed
    levant_update(sprm, slip_, sst_, sch, t, sample, body, body_valid)
    v_est = speed if measured else body[0, 0]
    wheel_torque = torque
    torque_ok = True
    if dprm.shape[0] > 0:
        wheel_torque = np.empty(4)
        engine_torque = engine[0]
        if offset_on:
            torque_offset_step(oprm, dprm[4], ost, t, engine[0], engine[1], engine[2], oout)
            engine_torque = engine_torque - oout.used
        engaged = engine_torques(
            dprm, engine_torque, engine[1], engine[2], wheel[1], wheel[2], wheel_torque
        )
        if not engaged or engine[1] != escl[1]:
            escl[0] = t
        escl[1] = engine[1]
        torque_ok = engaged and t - escl[0] >= dprm[6]
    estimator_update(
        eprm, escal, held, fst, fpr, fme, sst, spr, sme, vst, vpr, vme, last, ecnt, t,
        wheel[1], wheel[2], v_est, body[1, 0], wheel_torque, torque_ok, est,
    )  # fmt: skip
    return torque_ok


@jit
def _cascade_block(
    wprm: np.record, wlip: FloatArray, wst: np.record, wch: np.recarray,
    sprm: np.record, slip_: FloatArray, sst_: np.record, sch: np.recarray,
    eprm: FloatArray, escal: FloatArray, held: FloatArray, fst: FloatArray, fpr: FloatArray,
    fme: FloatArray, sst: FloatArray, spr: FloatArray, sme: FloatArray, vst: FloatArray,
    vpr: FloatArray, vme: FloatArray, last: FloatArray, ecnt: NDArray[np.int64],
    measured: bool, dprm: FloatArray, escl: FloatArray, offset_on: bool, oprm: np.record,
    ost: np.record, oout: np.record, t: FloatArray, angles: FloatArray, speeds: FloatArray,
    torques: FloatArray, engine: FloatArray, wheel: FloatArray, wheel_valid: BoolArray,
    body: FloatArray, est: FloatArray, torque_valid: BoolArray, offsets: np.ndarray,
) -> None:  # fmt: skip
    """`_cascade_step` over N stamps; wheel (N, 3, 4), body (N, 3), est (N, EST_SIZE),
    offsets (N,) `OFFSET_ESTIMATE_DTYPE` records where the offset is learnt, else (0,).

    ``escl`` (2,) and ``ost`` are the engine path's state (`_cascade_step`), carried from
    block to block; ``oout`` the estimate record it writes into.
    """
    body1 = np.empty((3, 1))
    body_valid = np.empty(1, dtype=np.bool_)
    for k in range(t.shape[0]):
        torque_valid[k] = _cascade_step(
            wprm, wlip, wst, wch, sprm, slip_, sst_, sch, eprm, escal, held, fst, fpr, fme,
            sst, spr, sme, vst, vpr, vme, last, ecnt, measured, dprm, escl, offset_on, oprm,
            ost, oout, t[k], angles[k], speeds[k], torques[k], engine[k], wheel[k],
            wheel_valid[k], body1, body_valid, est[k],
        )  # fmt: skip
        if offsets.shape[0] > 0:
            offsets[k] = oout
        body[k, 0] = body1[0, 0]
        body[k, 1] = body1[1, 0]
        body[k, 2] = body1[2, 0]


def run_cascade_compiled(
    t: ArrayLike,
    wheel_angle: ArrayLike,
    body_speed: ArrayLike,
    wheel_torque: ArrayLike,
    vehicle: EstimatorVehicle,
    observer_config: ObserverConfig | None = None,
    estimator_config: EstimatorConfig | None = None,
    estimator_speed: str = 'measured',
    *,
    torque_source: str = 'measured',
    engine: ArrayLike | None = None,
    drivetrain: Drivetrain | None = None,
    state: CascadeState | None = None,
) -> CascadeResult:
    """`cascade.run_cascade` (same arguments and result) in one compiled loop.

    With `state` (a `CascadeState` of this function), a record is run block by block as
    `run_cascade` does it.

    Raises:
        InputShapeError: inconsistent shapes.
        ConfigurationError: unknown estimator_speed or torque_source, or the engine path
            without engine or drivetrain.
    """
    stamps, angles, speeds, torques = checked_record(
        t, wheel_angle, body_speed, wheel_torque, estimator_speed
    )
    n = stamps.shape[0]
    source, engine_record = checked_engine(n, torque_source, engine, drivetrain)
    dprm = (
        drivetrain.params_array()
        if drivetrain is not None and source == TORQUE_ENGINE
        else np.zeros(0)
    )
    offset_on, oprm = _offset_params(estimator_config, dprm)
    if state is not None and state.parts is not None:
        wheels, speed, estimator, escl, ost = state.parts
    else:
        wheels, speed = _observers(observer_config or ObserverConfig())
        estimator = CompiledEstimator(vehicle, estimator_config, source)
        # the engine path's state: the stamp the clutch last slipped or the gear changed
        # (-inf before), the last gear (nan)
        escl = np.array([-np.inf, np.nan])
        ost = new_offset_state()
        if state is not None:
            state.parts = (wheels, speed, estimator, escl, ost)
    wheel = np.zeros((n, 3, 4))
    wheel_valid = np.zeros((n, 4), dtype=np.bool_)
    body = np.zeros((n, 3))
    est = np.zeros((n, EST_SIZE))
    torque_valid = np.zeros(n, dtype=np.bool_)
    offsets = np.zeros(n if offset_on else 0, OFFSET_ESTIMATE_DTYPE)
    block: Any = _cascade_block  # its leading arguments come as tuples
    block(
        *_diff_args(wheels), *_diff_args(speed), *_estimator_args(estimator),
        estimator_speed == 'measured', dprm, escl, offset_on, oprm, ost, new_offset_estimate(),
        stamps, angles, speeds, torques, engine_record, wheel, wheel_valid, body, est,
        torque_valid, offsets,
    )  # fmt: skip
    learnt = OffsetRecord(
        offsets['offset'].copy(),
        offsets['offset_std'].copy(),
        offsets['converged'].copy(),
        offsets['used'].copy(),
        offsets['episodes'].copy(),
        offsets['clamped'].copy(),
    )
    if source == TORQUE_NONE:
        torque_valid[:] = False
    return CascadeResult(
        t=stamps.copy(),
        omega=wheel[:, 1, :].copy(),
        omega_dot=wheel[:, 2, :].copy(),
        speed=body[:, 0].copy(),
        accel=body[:, 1].copy(),
        fx=est[:, E_FX : E_FX + 4].copy(),
        fz=est[:, E_FZ : E_FZ + 4].copy(),
        mu=est[:, E_MU : E_MU + 4].copy(),
        mu_valid=est[:, E_MU_VALID : E_MU_VALID + 4] != 0.0,
        slip=est[:, E_SLIP : E_SLIP + 4].copy(),
        rolling=est[:, E_ROLL : E_ROLL + 4].copy(),
        aero=est[:, E_AERO].copy(),
        slope=est[:, E_SLOPE].copy(),
        slope_valid=est[:, E_SLOPE_VALID] != 0.0,
        wheel_valid=wheel_valid,
        torque_valid=torque_valid,
        torque_source=source,
        angle=wheel[:, 0, :].copy(),
        faults={
            f'{part}.{kind}': count
            for part, counter in (
                ('wheel', wheels.faults),
                ('speed', speed.faults),
                ('estimator', estimator.faults),
            )
            for kind, count in counter.counts.items()
        }
        | ({'engine.torque_offset_clamped': int(ost.clamped)} if offset_on else {}),
        mass=est[:, E_MASS].copy(),
        mass_std=est[:, E_MASS_STD].copy(),
        mass_converged=est[:, E_MASS_CONVERGED] != 0.0,
        mass_used=est[:, E_MASS_USED].copy(),
        mass_excited=est[:, E_MASS_EXCITED] != 0.0,
        radius=est[:, E_RADIUS].copy(),
        radius_std=est[:, E_RADIUS_STD].copy(),
        radius_converged=est[:, E_RADIUS_CONVERGED] != 0.0,
        radius_used=est[:, E_RADIUS_USED].copy(),
        radius_free_wheels=est[:, E_RADIUS_FREE].astype(np.int64),
        **learnt.fields(),
    )


def _offset_params(config: EstimatorConfig | None, dprm: FloatArray) -> tuple[bool, np.record]:
    """Whether the engine path (``dprm`` non-empty) learns the offset, and the offset
    estimator's settings record (the defaults' when it does not)."""
    config = config or EstimatorConfig()  # the defaults, as run_cascade takes None
    on = dprm.shape[0] > 0 and config.torque_offset_adaptation
    return on, offset_params(config.torque_offset)


@jit
def _situation_block(
    fprm: np.record, flip: FloatArray, fst_: np.record, fch: np.recarray, mp: Any, ms: Any,
    fp: Any, tyre: Any, scales: FloatArray,
    table: FloatArray, static_load: FloatArray, fs: Any, cost: FloatArray, pot: Any, ap: Any,
    al: Any, t: FloatArray, angles: FloatArray, speeds: FloatArray, torques: FloatArray,
    omega: FloatArray, mu: FloatArray, mu_valid: BoolArray, fz: FloatArray,
    level: NDArray[np.int64], onset: FloatArray, det: FloatArray, mu_max: FloatArray,
    slip_peak: FloatArray, confidence: FloatArray, road: NDArray[np.int64],
    vehicle_road: NDArray[np.int64], slip: FloatArray,
) -> None:  # fmt: skip
    """`SituationMonitor.advance` over N stamps (the fast differentiator's arrays first, then
    the monitor's records), writing `SituationSeries`' arrays."""
    fast = np.empty((3, 4))
    fast_valid = np.empty(4, dtype=np.bool_)
    for k in range(t.shape[0]):
        if monitor_restarts(mp, ms, t[k]):
            # SituationMonitor.reset
            levant_reset(fprm, fst_, fch)
            fit_reset(fp, scales, table, static_load, fs, cost, pot)
            alerts_reset(al)
            ms.t = math.nan
        levant_update(
            fprm, flip, fst_, fch, t[k], angles[k], fast, fast_valid,
        )  # fmt: skip
        monitor_step(
            mp, ms, fp, tyre, scales, table, fs, cost, pot, ap, al, t[k], fast[1], fast_valid,
            speeds[k], torques[k], omega[k], mu[k], mu_valid[k], fz[k], slip,
        )  # fmt: skip
        level[k] = al.level
        onset[k] = al.onset
        det[k] = al.detected
        mu_max[k] = pot.mu_max
        slip_peak[k] = pot.slip_peak
        confidence[k] = pot.confidence
        road[k] = pot.road_class
        vehicle_road[k] = vehicle_road_class(pot.road_class, pot.confidence)


def compiled_monitor(
    curves: TyreCurves, static_load: ArrayLike, radius: float, **settings: Any
) -> SituationMonitor:
    """A `SituationMonitor` (kept for the callers until the chain is one runner)."""
    return SituationMonitor(curves, static_load, radius, **settings)


def run_situation_compiled(
    monitor: SituationMonitor,
    wheel_angle: ArrayLike,
    speed: ArrayLike,
    wheel_torque: ArrayLike,
    cascade: CascadeResult,
) -> SituationSeries:
    """`situation.run_situation` (same arguments and result) in one compiled loop.

    Args:
        monitor: the monitor whose records the block advances.

    Raises:
        InputShapeError: inconsistent shapes.
        TypeError: the monitor's fast observer is not compiled.
    """
    fast = monitor.fast
    angles = np.ascontiguousarray(wheel_angle, dtype=np.float64)
    speeds = np.ascontiguousarray(speed, dtype=np.float64)
    torques = np.ascontiguousarray(wheel_torque, dtype=np.float64)
    n = cascade.t.shape[0]
    if angles.shape != (n, 4) or speeds.shape != (n,) or torques.shape != (n, 4):
        raise InputShapeError(
            f'expected wheel_angle ({n}, 4), speed ({n},), wheel_torque ({n}, 4); got '
            f'{angles.shape}, {speeds.shape}, {torques.shape}'
        )
    level = np.zeros((n, 3, 4), dtype=np.int64)
    onset = np.full((n, 3, 4), math.nan)
    detected = np.full((n, 3, 4), math.nan)
    mu_max, slip_peak, confidence = np.zeros((n, 2)), np.zeros((n, 2)), np.zeros((n, 2))
    road = np.zeros((n, 2), dtype=np.int64)
    vehicle_road = np.zeros(n, dtype=np.int64)
    f64 = np.ascontiguousarray
    fr, al = monitor.friction, monitor.monitor
    block: Any = _situation_block  # its leading arguments come as one tuple
    block(
        *_diff_args(fast), monitor.params, monitor.state, fr.params, fr.tyre, fr.scales,
        fr.table, fr.static_load, fr.state, fr.cost, fr.potential, al.params, al.state,
        f64(cascade.t, dtype=np.float64), angles, speeds, torques,
        f64(cascade.omega, dtype=np.float64), f64(cascade.mu, dtype=np.float64),
        f64(cascade.mu_valid, dtype=np.bool_), f64(cascade.fz, dtype=np.float64), level, onset,
        detected, mu_max, slip_peak, confidence, road, vehicle_road, monitor.slip,
    )  # fmt: skip
    monitor.refresh()
    return SituationSeries(
        t=cascade.t.copy(),
        level=level,
        onset=onset,
        detected=detected,
        mu_max=mu_max,
        slip_peak=slip_peak,
        confidence=confidence,
        road_class=road,
        vehicle_road_class=vehicle_road,
    )


class CompiledChain:
    """The compiled `vd_observer_node.chain.Chain`: one compiled call per stamp and part."""

    def __init__(self, settings: ChainSettings) -> None:
        """Create the kernels' state from `settings` (compiled, or loaded from the cache)."""
        warm_up(settings.curves)
        self.settings = settings
        vehicle = settings.vehicle
        self.wheels, self.speed = _observers(settings.observer)
        source = settings.source
        self.estimator = CompiledEstimator(vehicle, settings.estimator, source)
        self._drivetrain = settings.drivetrain if source == TORQUE_ENGINE else None
        self._none = source == TORQUE_NONE
        self.monitor = compiled_monitor(
            settings.curves,
            vehicle.static_wheel_loads[[0, 2]],
            vehicle.effective_radius,
            observer=settings.observer,
            alerts=settings.alerts,
            friction=settings.friction,
            situation=settings.situation,
        )
        self._args = (
            *_diff_args(self.wheels),
            *_diff_args(self.speed),
            *_estimator_args(self.estimator),
        )
        self._measured = settings.estimator_speed == 'measured'
        self._wheel = np.zeros((3, 4))
        self._wheel_valid = np.zeros(4, dtype=np.bool_)
        self._body = np.zeros((3, 1))
        self._body_valid = np.zeros(1, dtype=np.bool_)
        self._est = np.zeros(EST_SIZE)
        # the engine path's parameters and state, as run_cascade_compiled gives them
        self._dprm = (
            self._drivetrain.params_array() if self._drivetrain is not None else np.zeros(0)
        )
        self._escl = np.array([-np.inf, np.nan])
        self._offset_on, self._oprm = _offset_params(settings.estimator, self._dprm)
        self._ost = new_offset_state()
        self._oout = new_offset_estimate()
        self.engine_faults = FaultCounter(ENGINE_FAULTS) if self._offset_on else None
        self._no_engine = np.zeros(3)

    def update(
        self,
        t: float,
        wheel_angle: ArrayLike,
        speed: float,
        wheel_torque: ArrayLike,
        engine: ArrayLike | None = None,
    ) -> ChainOutput:
        """Advance to stamp t (`chain.PythonChain.update`).

        Raises:
            InputShapeError: an array input has the wrong shape, or no engine on the engine
                path.
        """
        angles = np.ascontiguousarray(wheel_angle, dtype=np.float64)
        torques = np.ascontiguousarray(wheel_torque, dtype=np.float64)
        if angles.shape != (4,) or torques.shape != (4,):
            raise InputShapeError(
                f'wheel_angle and wheel_torque must have shape (4,), got {angles.shape}, '
                f'{torques.shape}'
            )
        row = engine_row(engine) if self._drivetrain is not None else self._no_engine
        if self._none:
            torques = np.zeros(4)  # the replay's: no torque topic, zeros everywhere
        step: Any = _cascade_step  # its leading arguments come as one tuple
        wheel, body, est = self._wheel, self._body, self._est
        step(
            *self._args, self._measured, self._dprm, self._escl, self._offset_on, self._oprm,
            self._ost, self._oout, float(t), angles, float(speed), torques, row, wheel,
            self._wheel_valid, body, self._body_valid, est,
        )  # fmt: skip
        offset = offset_from_record(self._oout) if self._offset_on else None
        if offset is not None and offset.clamped and self.engine_faults is not None:
            self.engine_faults.count('torque_offset_clamped')
        if self._drivetrain is not None:
            # the monitor gets the torques the engine path gave the estimator, from the
            # reference function as the replay computes them (0 where it had none)
            used = offset.used if offset is not None else 0.0
            derived = engine_wheel_torques(
                float(row[0]) - used, gear_number(float(row[1])), self._drivetrain, wheel[2]
            )
            torques = np.where(np.isfinite(derived), derived, 0.0)
        mu_valid = est[E_MU_VALID : E_MU_VALID + 4] != 0.0
        situation = self.monitor.update(
            float(t),
            angles,
            float(speed),
            torques,
            wheel[1].copy(),
            est[E_MU : E_MU + 4].copy(),
            mu_valid,
            est[E_FZ : E_FZ + 4].copy(),
        )
        return ChainOutput(
            WheelState(
                wheel[0].copy(), wheel[1].copy(), wheel[2].copy(), self._wheel_valid.copy()
            ),
            SpeedState(float(body[0, 0]), float(body[1, 0]), bool(self._body_valid[0])),
            estimates_from_packed(est),
            situation,
            offset,
        )

    def fault_report(self) -> FaultReport:
        """Faults since the previous call (`chain.PythonChain.fault_report`)."""
        return chain_faults(
            self.wheels.faults, self.speed.faults, self.estimator.faults, self.engine_faults
        )


_warm = False


def warm_up(curves: TyreCurves) -> None:
    """Compile (or load from numba's disk cache) every kernel now, once per process.

    Nodes call it at start so that the first sample does not pay for compilation; `curves`
    only gives the tyre arrays their types (any tyre will do).
    """
    global _warm
    if _warm:
        return
    vehicle = EstimatorVehicle(
        mass=1000.0, wheelbase=2.5, cg_to_front_axle=1.0, cg_height=0.5, inertia_front=1.0,
        inertia_rear=1.0, effective_radius=0.3, drag_coefficient=0.3, frontal_area=2.0,
        air_density=1.2, rolling_c0=0.01, rolling_c1=0.0, gravity=9.81,
    )  # fmt: skip
    t = np.array([0.0, 0.01])
    angles = np.zeros((2, 4))
    cascade = run_cascade_compiled(t, angles, np.ones(2), np.zeros((2, 4)), vehicle)
    monitor = compiled_monitor(curves, np.array([3000.0, 2500.0]), 0.3)
    run_situation_compiled(monitor, angles, np.ones(2), np.zeros((2, 4)), cascade)
    monitor.update(0.02, np.zeros(4), 1.0, np.zeros(4), np.zeros(4), np.zeros(4), [0] * 4, [1] * 4)
    settings = ChainSettings(vehicle=vehicle, curves=curves)
    _warm = True
    CompiledChain(settings).update(0.0, np.zeros(4), 1.0, np.zeros(4))
