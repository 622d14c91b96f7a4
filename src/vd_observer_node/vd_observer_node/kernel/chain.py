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
from vd_observer_node.estimation.drivetrain import (
    TORQUE_ENGINE,
    TORQUE_NONE,
    Drivetrain,
    engine_torques,
    engine_wheel_torques,
    gear_number,
)
from vd_observer_node.estimation.estimator import Estimator, EstimatorConfig, estimates_from_record
from vd_observer_node.estimation.estimator_step import ESTIMATES, estimator_update
from vd_observer_node.estimation.faults import ENGINE_FAULTS, FaultCounter, FaultReport
from vd_observer_node.estimation.observer import (
    WHEEL_INPUTS,
    ObserverConfig,
    SpeedState,
    WheelState,
)
from vd_observer_node.estimation.vehicle import EstimatorVehicle
from vd_observer_node.kernel._jit import jit
from vd_observer_node.kernel.levant import CompiledDifferentiator, diff_update
from vd_observer_node.kernel.situation import (
    P_CONFIDENCE,
    P_MU_MAX,
    P_ROAD,
    P_SLIP_PEAK,
    CompiledSituationMonitor,
    alerts_from_arrays,
    monitor_update,
    potential_from_arrays,
)
from vd_observer_node.kernel.torque_offset import (
    OFFSET_CLAMPED_SLOT,
    OFFSET_OUT_SIZE,
    offset_from_packed,
    offset_params,
    offset_state,
    offset_update,
)
from vd_observer_node.situation.friction_potential import TyreCurves
from vd_observer_node.situation.monitor import Situation, SituationSeries

__all__ = ['CompiledChain', 'run_cascade_compiled', 'run_situation_compiled', 'warm_up']

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


def _observers(config: ObserverConfig) -> tuple[CompiledDifferentiator, CompiledDifferentiator]:
    """Wheel (4 channels) and speed (1 channel) differentiators of `observer.Observer`."""

    def make(lipschitz: float, n: int, input_derivative: int) -> CompiledDifferentiator:
        return CompiledDifferentiator(
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


def _diff_args(d: CompiledDifferentiator) -> tuple[Any, ...]:
    return (d.prm, d.lip, d.z, d.f_last, d.active, d.pend_t, d.pend_f, d.scal, d.counts)


def _estimator_args(e: Estimator) -> tuple[Any, ...]:
    return (e.params, *e.state.args)


@jit
def _cascade_step(
    wprm: FloatArray, wlip: FloatArray, wz: FloatArray, wfl: FloatArray, wact: BoolArray,
    wpt: FloatArray, wpf: FloatArray, wsc: FloatArray, wcnt: NDArray[np.int64],
    sprm: FloatArray, slip_: FloatArray, sz: FloatArray, sfl: FloatArray, sact: BoolArray,
    spt: FloatArray, spf: FloatArray, ssc: FloatArray, scnt: NDArray[np.int64],
    ep: np.record, es: np.record, fst: FloatArray, sst: FloatArray, vst: FloatArray,
    measured: bool, dprm: FloatArray, escl: FloatArray, oprm: FloatArray, ost: FloatArray,
    oout: FloatArray, t: float, angle: FloatArray, speed: float, torque: FloatArray,
    engine: FloatArray, wheel: FloatArray, wheel_valid: BoolArray, body: FloatArray,
    body_valid: BoolArray, est: np.record,
) -> bool:  # fmt: skip
    """One stamp of `run_cascade`: wheel and speed observers, then the estimator.

    With the engine path (``dprm`` non-empty) the wheel torques come from ``engine``
    (engine torque, gear, engine speed) instead of ``torque``; returns whether the torque
    source held (`CascadeResult.torque_valid`). ``escl`` (2,) is the engine path's state:
    the stamp the clutch last slipped or the gear changed (-inf before), the last gear (nan).
    With ``oprm`` non-empty (`offset_params`) the engine path learns the engine-torque offset
    (state ``ost``, estimate written to ``oout``) and subtracts it once converged.
    """
    diff_update(wprm, wlip, wz, wfl, wact, wpt, wpf, wsc, wcnt, t, angle, wheel, wheel_valid)
    sample = np.empty(1)
    sample[0] = speed
    diff_update(sprm, slip_, sz, sfl, sact, spt, spf, ssc, scnt, t, sample, body, body_valid)
    v_est = speed if measured else body[0, 0]
    wheel_torque = torque
    torque_ok = True
    if dprm.shape[0] > 0:
        wheel_torque = np.empty(4)
        engine_torque = engine[0]
        if oprm.shape[0] > 0:
            offset_update(oprm, dprm[4], ost, t, engine[0], engine[1], engine[2], oout)
            engine_torque = engine_torque - oout[3]
        engaged = engine_torques(
            dprm, engine_torque, engine[1], engine[2], wheel[1], wheel[2], wheel_torque
        )
        if not engaged or engine[1] != escl[1]:
            escl[0] = t
        escl[1] = engine[1]
        torque_ok = engaged and t - escl[0] >= dprm[6]
    estimator_update(
        ep, es, fst, sst, vst, t, wheel[1], wheel[2], v_est, body[1, 0], wheel_torque,
        torque_ok, est,
    )  # fmt: skip
    return torque_ok


@jit
def _cascade_block(
    wprm: FloatArray, wlip: FloatArray, wz: FloatArray, wfl: FloatArray, wact: BoolArray,
    wpt: FloatArray, wpf: FloatArray, wsc: FloatArray, wcnt: NDArray[np.int64],
    sprm: FloatArray, slip_: FloatArray, sz: FloatArray, sfl: FloatArray, sact: BoolArray,
    spt: FloatArray, spf: FloatArray, ssc: FloatArray, scnt: NDArray[np.int64],
    ep: np.record, es: np.record, fst: FloatArray, sst: FloatArray, vst: FloatArray,
    measured: bool, dprm: FloatArray, escl: FloatArray, oprm: FloatArray, ost: FloatArray,
    t: FloatArray, angles: FloatArray, speeds: FloatArray, torques: FloatArray,
    engine: FloatArray, wheel: FloatArray, wheel_valid: BoolArray, body: FloatArray,
    est: NDArray[np.void], torque_valid: BoolArray, offsets: FloatArray,
) -> None:  # fmt: skip
    """`_cascade_step` over N stamps; wheel (N, 3, 4), body (N, 3), est (N,) `ESTIMATES`,
    offsets (N, OFFSET_OUT_SIZE) where the offset is learnt, else (0, OFFSET_OUT_SIZE).

    ``escl`` (2,) and ``ost`` are the engine path's state (`_cascade_step`), carried from
    block to block.
    """
    body1 = np.empty((3, 1))
    body_valid = np.empty(1, dtype=np.bool_)
    oout = np.zeros(OFFSET_OUT_SIZE)
    for k in range(t.shape[0]):
        torque_valid[k] = _cascade_step(
            wprm, wlip, wz, wfl, wact, wpt, wpf, wsc, wcnt, sprm, slip_, sz, sfl, sact, spt,
            spf, ssc, scnt, ep, es, fst, sst, vst, measured, dprm, escl, oprm, ost, oout, t[k],
            angles[k], speeds[k], torques[k], engine[k], wheel[k], wheel_valid[k], body1,
            body_valid, est[k],
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
    oprm = _offset_params(estimator_config, dprm)
    if state is not None and state.parts is not None:
        wheels, speed, estimator, escl, ost = state.parts
    else:
        wheels, speed = _observers(observer_config or ObserverConfig())
        estimator = Estimator(vehicle, estimator_config, source)
        # the engine path's state: the stamp the clutch last slipped or the gear changed
        # (-inf before), the last gear (nan)
        escl = np.array([-np.inf, np.nan])
        ost = offset_state()
        if state is not None:
            state.parts = (wheels, speed, estimator, escl, ost)
    wheel = np.zeros((n, 3, 4))
    wheel_valid = np.zeros((n, 4), dtype=np.bool_)
    body = np.zeros((n, 3))
    est = np.zeros(n, ESTIMATES)
    torque_valid = np.zeros(n, dtype=np.bool_)
    offsets = np.zeros((n if oprm.shape[0] > 0 else 0, OFFSET_OUT_SIZE))
    block: Any = _cascade_block  # its leading arguments come as tuples
    block(
        *_diff_args(wheels), *_diff_args(speed), *_estimator_args(estimator),
        estimator_speed == 'measured', dprm, escl, oprm, ost, stamps, angles, speeds, torques,
        engine_record, wheel, wheel_valid, body, est, torque_valid, offsets,
    )  # fmt: skip
    learnt = OffsetRecord(
        offsets[:, 0].copy(),
        offsets[:, 1].copy(),
        offsets[:, 2] != 0.0,
        offsets[:, 3].copy(),
        offsets[:, 4].astype(np.int64),
        offsets[:, 5] != 0.0,
    )
    if source == TORQUE_NONE:
        torque_valid[:] = False
    return CascadeResult(
        t=stamps.copy(),
        omega=wheel[:, 1, :].copy(),
        omega_dot=wheel[:, 2, :].copy(),
        speed=body[:, 0].copy(),
        accel=body[:, 1].copy(),
        fx=est['fx'].copy(),
        fz=est['fz'].copy(),
        mu=est['mu'].copy(),
        mu_valid=est['mu_valid'] != 0,
        slip=est['slip'].copy(),
        rolling=est['rolling'].copy(),
        aero=est['aero'].copy(),
        slope=est['slope'].copy(),
        slope_valid=est['slope_valid'].copy(),
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
        | (
            {'engine.torque_offset_clamped': int(ost[OFFSET_CLAMPED_SLOT])}
            if oprm.shape[0] > 0
            else {}
        ),
        mass=est['mass'].copy(),
        mass_std=est['mass_std'].copy(),
        mass_converged=est['mass_converged'].copy(),
        mass_used=est['mass_used'].copy(),
        mass_excited=est['mass_excited'].copy(),
        radius=est['radius'].copy(),
        radius_std=est['radius_std'].copy(),
        radius_converged=est['radius_converged'].copy(),
        radius_used=est['radius_used'].copy(),
        radius_free_wheels=est['radius_free_wheels'].copy(),
        **learnt.fields(),
    )


def _offset_params(config: EstimatorConfig | None, dprm: FloatArray) -> FloatArray:
    """The offset estimator's settings where the engine path (``dprm`` non-empty) learns it,
    else an empty array."""
    config = config or EstimatorConfig()  # the defaults, as run_cascade takes None
    if dprm.shape[0] == 0 or not config.torque_offset_adaptation:
        return np.zeros(0)
    return offset_params(config.torque_offset)


@jit
def _situation_block(
    fprm: FloatArray, flip: FloatArray, fz_: FloatArray, f_last: FloatArray,
    f_active: BoolArray, f_pend_t: FloatArray, f_pend_f: FloatArray, f_scal: FloatArray,
    f_counts: NDArray[np.int64], prm_f: FloatArray, tp: FloatArray, scales: FloatArray,
    table: FloatArray, static_load: FloatArray, cost: FloatArray, count: FloatArray,
    load: FloatArray, direction: FloatArray, fscal: FloatArray, last_sample: FloatArray,
    classes: NDArray[np.int64], pot: FloatArray, prm_a: FloatArray, thresholds: FloatArray,
    ch: FloatArray, detected: FloatArray, ascal: FloatArray, prm_s: FloatArray,
    mscal: FloatArray, t: FloatArray, angles: FloatArray, speeds: FloatArray,
    torques: FloatArray, omega: FloatArray, mu: FloatArray, mu_valid: BoolArray,
    fz: FloatArray, level: NDArray[np.int64], onset: FloatArray, det: FloatArray,
    mu_max: FloatArray, slip_peak: FloatArray, confidence: FloatArray,
    road: NDArray[np.int64], vehicle_road: NDArray[np.int64],
) -> None:  # fmt: skip
    """`monitor_update` over N stamps, writing `SituationSeries`' arrays."""
    slip = np.empty(4)
    for k in range(t.shape[0]):
        monitor_update(
            fprm, flip, fz_, f_last, f_active, f_pend_t, f_pend_f, f_scal, f_counts, prm_f, tp,
            scales, table, static_load, cost, count, load, direction, fscal, last_sample,
            classes, pot, prm_a, thresholds, ch, detected, ascal, prm_s, mscal, t[k],
            angles[k], speeds[k], torques[k], omega[k], mu[k], mu_valid[k], fz[k], slip,
        )  # fmt: skip
        for kind in range(3):
            for w in range(4):
                level[k, kind, w] = int(ch[kind, w, 0])
                onset[k, kind, w] = ch[kind, w, 1]
                det[k, kind, w] = detected[kind, w]
        best = -1
        best_conf = -2.0
        for a in range(2):
            mu_max[k, a] = pot[P_MU_MAX + a]
            slip_peak[k, a] = pot[P_SLIP_PEAK + a]
            confidence[k, a] = pot[P_CONFIDENCE + a]
            road[k, a] = int(pot[P_ROAD + a])
            # vehicle_road_class: the most confident axle with a known class
            if road[k, a] != 0 and pot[P_CONFIDENCE + a] > best_conf:
                best, best_conf = a, pot[P_CONFIDENCE + a]
        vehicle_road[k] = road[k, best] if best >= 0 else 0


def run_situation_compiled(
    monitor: CompiledSituationMonitor,
    wheel_angle: ArrayLike,
    speed: ArrayLike,
    wheel_torque: ArrayLike,
    cascade: CascadeResult,
) -> SituationSeries:
    """`situation.run_situation` (same arguments and result) in one compiled loop.

    Raises:
        InputShapeError: inconsistent shapes.
    """
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
    block: Any = _situation_block  # its leading arguments come as one tuple
    block(
        *monitor.args, f64(cascade.t, dtype=np.float64), angles, speeds, torques,
        f64(cascade.omega, dtype=np.float64), f64(cascade.mu, dtype=np.float64),
        f64(cascade.mu_valid, dtype=np.bool_), f64(cascade.fz, dtype=np.float64), level, onset,
        detected, mu_max, slip_peak, confidence, road, vehicle_road,
    )  # fmt: skip
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
        self.estimator = Estimator(vehicle, settings.estimator, source)
        self._drivetrain = settings.drivetrain if source == TORQUE_ENGINE else None
        self._none = source == TORQUE_NONE
        self.monitor = CompiledSituationMonitor(
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
        self._est = np.zeros(1, ESTIMATES).view(np.recarray)[0]
        # the engine path's parameters and state, as run_cascade_compiled gives them
        self._dprm = (
            self._drivetrain.params_array() if self._drivetrain is not None else np.zeros(0)
        )
        self._escl = np.array([-np.inf, np.nan])
        self._oprm = _offset_params(settings.estimator, self._dprm)
        self._ost = offset_state()
        self._oout = np.zeros(OFFSET_OUT_SIZE)
        self.engine_faults = FaultCounter(ENGINE_FAULTS) if self._oprm.shape[0] > 0 else None
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
            *self._args, self._measured, self._dprm, self._escl, self._oprm, self._ost,
            self._oout, float(t), angles, float(speed), torques, row, wheel, self._wheel_valid,
            body, self._body_valid, est,
        )  # fmt: skip
        offset = offset_from_packed(self._oout) if self._oprm.shape[0] > 0 else None
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
        mu_valid = est.mu_valid != 0
        monitor = self.monitor
        monitor.update_arrays(
            float(t),
            angles,
            float(speed),
            torques,
            wheel[1].copy(),
            np.array(est.mu),
            mu_valid,
            np.array(est.fz),
        )
        a = monitor.arrays
        return ChainOutput(
            WheelState(
                wheel[0].copy(), wheel[1].copy(), wheel[2].copy(), self._wheel_valid.copy()
            ),
            SpeedState(float(body[0, 0]), float(body[1, 0]), bool(self._body_valid[0])),
            estimates_from_record(est),
            Situation(
                float(t),
                potential_from_arrays(a.pot),
                alerts_from_arrays(a.ch, a.detected),
                monitor.slip.copy(),
            ),
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
    monitor = CompiledSituationMonitor(curves, np.array([3000.0, 2500.0]), 0.3)
    run_situation_compiled(monitor, angles, np.ones(2), np.zeros((2, 4)), cascade)
    monitor.update(0.02, np.zeros(4), 1.0, np.zeros(4), np.zeros(4), np.zeros(4), [0] * 4, [1] * 4)
    settings = ChainSettings(vehicle=vehicle, curves=curves)
    _warm = True
    CompiledChain(settings).update(0.0, np.zeros(4), 1.0, np.zeros(4))
