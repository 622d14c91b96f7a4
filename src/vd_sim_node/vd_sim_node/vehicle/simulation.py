"""ROS-free simulator: :func:`simulate` for a whole run and :class:`Simulator` to step it.

Integration: LSODA (``scipy.integrate.odeint``, stiff/non-stiff switching) on the compiled
bond-graph right-hand side, in chunks that end at every input discontinuity (scenario
breakpoints, gear-shift and clutch events) so the solver never steps across a jump. The
sample outputs come from LSODA's own interpolant at the sample instants, and every truth
signal is then evaluated *exactly* on the sampled states with the vectorised model
(``omega_dot`` is the right-hand side at the sample state, not a finite difference).

The driver/transmission logic (:func:`~vd_sim_node.vehicle.powertrain.decide_shift`) runs at
the sample instants, like a controller at the sensor rate: after each chunk the first sample
at which the logic wants to act is found, the chunk is cut there and integration restarts
from that sample's state with the new discrete state.

:class:`Simulator` and :func:`simulate` share this machinery: ``step()`` hands out the
samples of the current chunk one by one and integrates the next chunk when needed.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.integrate import odeint
from vd_common.errors import ParameterError
from vd_common.vehicle.friction import friction_table
from vd_common.vehicle.params import VehicleParams

from vd_sim_node.errors import SimulationError
from vd_sim_node.vehicle.friction_truth import true_friction_potential
from vd_sim_node.vehicle.model import WHEELS, VehicleModel
from vd_sim_node.vehicle.powertrain import (
    ClutchMode,
    DrivelineState,
    ShiftDecision,
    decide_shift,
    upshift_speed,
)
from vd_sim_node.vehicle.scenario import Scenario
from vd_sim_node.vehicle.sensors import SensorModel, imu_specific_force
from vd_sim_node.vehicle.variants import apply_variant, driven_wheel_torque_offset

__all__ = [
    'HOLD_BRAKE_PEDAL',
    'SampleFrame',
    'SimResult',
    'Simulator',
    'simulate',
    'with_torque_offset',
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Brake pedal applied by the automatic standstill hold, [0..1].
HOLD_BRAKE_PEDAL = 0.3
_STANDSTILL_SPEED = 0.1  # [m/s], as in decide_shift


@dataclass(frozen=True)
class SimResult:
    """Sampled sensors and ground truth of one run. N samples, wheel order FL, FR, RL, RR.

    Attributes:
        t: shape (N,), [s], sample times (uniform 1/rate_hz, from 0).
        wheel_angle: shape (N, 4), [rad], measured (unwrapped; quantised if an encoder).
        body_speed: shape (N,), [m/s], measured longitudinal speed.
        wheel_torque: shape (N, 4), [N m], measured drive minus brake torque per wheel.
        engine_torque: shape (N,), [N m], net engine torque (combustion minus drag).
        engine_speed: shape (N,), [rad/s].
        gear: shape (N,), int, 0 neutral (during a shift), 1..n.
        omega: shape (N, 4), [rad/s], true wheel speeds.
        omega_dot: shape (N, 4), [rad/s^2], exact model derivative at the sample.
        angle_true: shape (N, 4), [rad], exact wheel angle.
        speed_true: shape (N,), [m/s], true body speed v.
        accel_true: shape (N,), [m/s^2], dv/dt along the road.
        fx: shape (N, 4), [N], tyre longitudinal force (road on tyre, positive forward).
        fz: shape (N, 4), [N], dynamic tyre normal load.
        mu: shape (N, 4), [-], fx / fz.
        slip: shape (N, 4), [-], (omega R - v) / max(|omega R|, |v|, v_min).
        rolling: shape (N, 4), [N], rolling-resistance magnitude per wheel.
        aero: shape (N,), [N], drag magnitude.
        slope: shape (N,), [rad], road slope.
        road_mu: shape (N,), [-], road friction scale.
        peak_mu: shape (N, 4), [-], true friction potential: the MF peak mu at the wheel's
            load and road_mu, on the side of the sign of fx (see :mod:`.friction_truth`).
        peak_slip: shape (N, 4), [-], slip magnitude at that peak.
        throttle: shape (N,), [0..1], throttle applied to the engine (0 during a shift).
        brake_torque: shape (N, 4), [N m], brake torque magnitude per wheel.
        power_sources: shape (N,), [W], power of all bond-graph sources (engine, gravity).
        power_dissipated: shape (N,), [W], power into all R elements (tyres, brakes, ...).
        energy_stored: shape (N,), [J], kinetic + spring energy of the bond graph.
        pitch: shape (N,), [rad], body pitch relative to the road, nose down positive, from
            the suspension and tyre deflections (0 at the level-road static equilibrium).
        imu_true: shape (N, 2), [m/s^2], true specific force (f_x, f_z) in the IMU's axes
            (its mounting pitch applied; the body's motion normal to the road neglected).
        imu: shape (N, 2), [m/s^2], the IMU's reading: ``imu_true`` with the bias and noise
            of the scenario's sensors (whether or not ``sensors.imu`` publishes it).
        gyro_true: shape (N,), [rad/s], the IMU's true rate about its y axis (REP 103: nose
            down positive): the body's pitch rate on the road plus the road's grade changes,
            each sample the mean over the sample period before it (the change of the
            sensor's pitch over the period; 0 at the first), as an integrating gyro gives it.
        gyro: shape (N,), [rad/s], its reading with the scenario's gyro bias and noise.
        events: (time [s], description) of scenario steps, gear shifts, clutch events.
    """

    t: FloatArray
    wheel_angle: FloatArray
    body_speed: FloatArray
    wheel_torque: FloatArray
    engine_torque: FloatArray
    engine_speed: FloatArray
    gear: IntArray
    omega: FloatArray
    omega_dot: FloatArray
    angle_true: FloatArray
    speed_true: FloatArray
    accel_true: FloatArray
    fx: FloatArray
    fz: FloatArray
    mu: FloatArray
    slip: FloatArray
    rolling: FloatArray
    aero: FloatArray
    slope: FloatArray
    road_mu: FloatArray
    peak_mu: FloatArray
    peak_slip: FloatArray
    throttle: FloatArray
    brake_torque: FloatArray
    power_sources: FloatArray
    power_dissipated: FloatArray
    energy_stored: FloatArray
    pitch: FloatArray
    imu_true: FloatArray
    imu: FloatArray
    gyro_true: FloatArray
    gyro: FloatArray
    events: tuple[tuple[float, str], ...]


@dataclass(frozen=True)
class SampleFrame:
    """One sample of :class:`SimResult` (same field meanings, one time step).

    Per-wheel fields have shape (4,), ``imu_true`` and ``imu`` (2,), the others are scalars.
    """

    t: float
    wheel_angle: FloatArray
    body_speed: float
    wheel_torque: FloatArray
    engine_torque: float
    engine_speed: float
    gear: int
    omega: FloatArray
    omega_dot: FloatArray
    angle_true: FloatArray
    speed_true: float
    accel_true: float
    fx: FloatArray
    fz: FloatArray
    mu: FloatArray
    slip: FloatArray
    rolling: FloatArray
    aero: float
    slope: float
    road_mu: float
    peak_mu: FloatArray
    peak_slip: FloatArray
    throttle: float
    brake_torque: FloatArray
    power_sources: float
    power_dissipated: float
    energy_stored: float
    pitch: float
    imu_true: FloatArray
    imu: FloatArray
    gyro_true: float
    gyro: float


_SERIES = tuple(f.name for f in fields(SampleFrame))


class Simulator:
    """Incremental simulator of one scenario.

    Example::

        sim = Simulator(load_vehicle(p), load_scenario(s))
        while not sim.done:
            frame = sim.step()      # the next 1 kHz sample, sensors and truth

    Attributes:
        model: the compiled vehicle model.
        scenario: the scenario being run.
        rate_hz: sample rate, [Hz].
        n_samples: total number of samples (t = 0 .. duration inclusive).
        events: (time, description) so far.
        nfev: right-hand-side evaluations so far (integration cost).
    """

    def __init__(
        self,
        vehicle: VehicleParams | VehicleModel,
        scenario: Scenario,
        *,
        rate_hz: float | None = None,
        seed: int | None = None,
        rtol: float = 1e-7,
        atol_scale: float = 1.0,
        max_chunk: float = 8.0,
    ) -> None:
        """Prepare a run.

        Args:
            vehicle: parameters (compiled here, after the scenario's ``true_vehicle``
                variant is applied) or an already compiled model (reuse it to avoid
                recompiling the bond graph for every run; refused with a variant that
                changes the physics).
            scenario: the scenario.
            rate_hz: sample rate, [Hz]; default the scenario's ``sensors.rate_hz``.
            seed: noise seed; default the scenario's ``sensors.seed``.
            rtol: LSODA relative tolerance.
            atol_scale: multiplies the per-state absolute tolerances (see docs).
            max_chunk: longest integration chunk without a logic check, [s].
        """
        truth = scenario.true_vehicle
        if isinstance(vehicle, VehicleModel):
            if truth.changes_physics:
                raise SimulationError(
                    f'scenario {scenario.name} drives a variant of the vehicle '
                    '(true_vehicle): pass the VehicleParams, not a compiled VehicleModel'
                )
            self.model = vehicle
        else:
            # The scenario's true car; the estimators keep reading the vehicle file.
            self.model = VehicleModel(apply_variant(vehicle, truth))
        self._torque_offset = truth.engine_torque_offset_nm
        self.scenario = scenario
        self.rate_hz = float(scenario.sensors.rate_hz if rate_hz is None else rate_hz)
        if not (self.rate_hz > 0.0 and math.isfinite(self.rate_hz)):
            raise SimulationError(f'rate_hz must be > 0, got {rate_hz}')
        if not max_chunk > 0.0:
            raise SimulationError(f'max_chunk must be > 0 s, got {max_chunk}')
        self.n_samples = math.floor(scenario.duration * self.rate_hz + 1e-9) + 1
        # Wheel angles grow without bound (10^4 rad in the paper run): a relative tolerance
        # would let their absolute error grow with them, so they get an absolute one only.
        self._rtol = np.where(self._angle_mask(), 0.0, rtol)
        self._atol = self._absolute_tolerances() * atol_scale
        self._max_chunk = max_chunk
        self._sensors = SensorModel(scenario.sensors, seed)
        vp = self.model.params
        self._total_ratios = np.array(vp.gearbox.ratios) * vp.gearbox.final_drive
        self._friction_table = friction_table(vp.tire)  # truth of the friction potential
        self._pitch_reference = self._deflection_pitch(
            self.model.static_state(0.0, vp.engine.idle_speed)[:, None]
        )[0]
        self._last_tilt = math.nan  # [rad] the sensor's pitch at the last sample (the gyro)
        self._k = 0  # next sample index to compute
        self._t = 0.0  # time of the state self._x
        self._drv, self._x = self._initial_conditions()
        self.events: list[tuple[float, str]] = self._scenario_events()
        self.nfev = 0
        # Samples integrated but not yet handed out by step(): one block and a cursor; the
        # frames are built lazily so a step costs ~10 us, not a whole block's worth.
        self._block: dict[str, Any] | None = None
        self._cursor = 0
        self._emitted = 0

    # -- public ----------------------------------------------------------------------

    @property
    def done(self) -> bool:
        """True when every sample has been handed out by :meth:`step`."""
        return self._emitted >= self.n_samples

    @property
    def t(self) -> float:
        """Time of the next sample :meth:`step` will return, [s]."""
        return self._emitted / self.rate_hz

    def step(self) -> SampleFrame:
        """Advance to the next sample time and return sensors + truth there.

        Raises:
            SimulationError: the run is finished, or the integration failed.
        """
        if self.done:
            raise SimulationError('the scenario is finished; check Simulator.done')
        while self._block is None or self._cursor >= len(self._block['t']):
            self._block = self._next_block()
            self._cursor = 0
        frame = _frame(self._block, self._cursor)
        self._cursor += 1
        self._emitted += 1
        return frame

    def run(self, progress: Callable[[float, float], None] | None = None) -> SimResult:
        """Simulate the remaining samples and return the whole series.

        Only valid before any :meth:`step` (the result always starts at t = 0).

        Args:
            progress: called after each chunk with (simulated time [s], duration [s]).
        """
        if self._emitted or self._k:
            raise SimulationError('run() must be called on a fresh Simulator')
        blocks: list[dict[str, Any]] = []
        while self._k < self.n_samples:
            blocks.append(self._next_block())
            if progress is not None:
                progress(self._k / self.rate_hz, self.scenario.duration)
        self._emitted = self.n_samples
        data = {name: np.concatenate([b[name] for b in blocks]) for name in _SERIES}
        data['gear'] = data['gear'].astype(np.int64)
        return SimResult(**data, events=tuple(self.events))

    # -- set-up helpers ----------------------------------------------------------------

    def _initial_conditions(self) -> tuple[DrivelineState, FloatArray]:
        """Discrete state and static-equilibrium state vector at t = 0."""
        s = self.scenario
        m = self.model
        vp = m.params
        gear = min(s.initial_gear, len(vp.gearbox.ratios))
        v0 = s.initial_speed
        w_gb = v0 / vp.wheel.effective_radius * float(self._total_ratios[gear - 1])
        clutch = ClutchMode.LAUNCH
        w_e = self._idle_speed()
        if s.neutral:
            clutch = ClutchMode.OPEN
        elif w_gb >= vp.clutch.engage_full_speed:
            clutch, w_e = ClutchMode.LOCKED, w_gb
        hold = s.hold_brake and s.throttle.at(0.0) <= 0.0 and v0 < _STANDSTILL_SPEED
        x = m.static_state(s.slope.at(0.0), w_e)
        x[m.idx_p_x] = m.geometry.m * v0
        x[m.idx_p_spin] = m.inertia * v0 / vp.wheel.effective_radius
        return DrivelineState(gear=gear, clutch=clutch, hold_brake=hold), x

    def _idle_speed(self) -> float:
        ep = self.model.params.engine
        # Idle governor torque balances the drag torque (tanh ~ 1 at idle speed).
        return (ep.idle_gain * ep.idle_speed - ep.drag_torque_c0) / (
            ep.idle_gain + ep.drag_torque_c1
        )

    def _angle_mask(self) -> NDArray[np.bool_]:
        names = self.model.compiled.state_names
        return np.array([n.startswith('angle_') for n in names])

    def _absolute_tolerances(self) -> FloatArray:
        """Absolute tolerances per state, scaled to each state's physical size."""
        names = self.model.compiled.state_names
        atol = np.empty(len(names))
        for k, name in enumerate(names):
            # Chosen with scripts/check_integration_accuracy.py: tighter values cost RHS calls
            # (the lightly damped body modes cross zero) without changing the wheel speeds.
            if name.endswith('.q') and name.startswith('angle_'):
                atol[k] = 1e-6  # [rad], the only control of the angle error (rtol 0)
            elif name.endswith('.q'):
                atol[k] = 1e-7  # [m] spring / tyre deflections
            elif name.startswith('mass_x'):
                atol[k] = 1e-3  # [kg m/s]
            elif name.startswith(('spin_', 'engine_')):
                # [kg m^2/s]: ~1e-6 rad/s, so a locked wheel (omega ~ 0) stays accurate too
                atol[k] = 1e-6
            else:
                atol[k] = 1e-5  # [kg m/s], [kg m^2/s]: vertical and pitch momenta
        return atol

    def _deflection_pitch(self, X: FloatArray) -> FloatArray:
        """Body pitch, nose down positive, [rad], of states X (n, M), from the axles'
        suspension + tyre extensions (absolute: subtract the level static value)."""
        si = self.model.compiled.state_index
        geo = self.model.geometry

        def height(axle: str) -> FloatArray:
            h: FloatArray = X[si[f'spring_c_{axle}.q']] + X[si[f'tyre_c_{axle}.q']]
            return h

        out: FloatArray = (height('rear') - height('front')) / (geo.a_s + geo.b_s)
        return out

    def _scenario_events(self) -> list[tuple[float, str]]:
        s = self.scenario
        events = []
        for label, sig, unit, scale in (
            ('throttle', s.throttle, '', 1.0),
            ('brake', s.brake, '', 1.0),
            ('slope', s.slope, ' deg', 180.0 / math.pi),
            ('road_mu', s.road_mu, '', 1.0),
        ):
            for i in range(1, len(sig.times)):
                if sig.times[i] < s.duration:
                    a, b = sig.values[i - 1] * scale, sig.values[i] * scale
                    events.append((sig.times[i], f'{label} {a:g} -> {b:g}{unit}'))
        events.sort(key=lambda e: e[0])
        return events

    # -- the chunk machinery --------------------------------------------------------------

    def _inputs(self, t: float, drv: DrivelineState) -> FloatArray:
        s = self.scenario
        throttle = 0.0 if drv.clutch == ClutchMode.OPEN else s.throttle.at(t)
        brake = s.brake.at(t)
        if drv.hold_brake:
            brake = max(brake, HOLD_BRAKE_PEDAL)
        return self.model.input_vector(
            throttle,
            brake,
            s.slope.at(t),
            s.road_mu.at(t),
            float(self._total_ratios[drv.gear - 1]),
            float(drv.clutch),
            drv.ramp_start,
            drv.rev_match if drv.clutch == ClutchMode.OPEN else 0.0,
        )

    def _decide(self, k: int, x: FloatArray) -> ShiftDecision | None:
        m = self.model
        t = k / self.rate_hz
        omega = x[m.idx_p_spin] / m.inertia
        w_gb = 0.5 * (omega[0] + omega[1]) * self._total_ratios
        return decide_shift(
            t,
            self._drv,
            float(x[m.idx_p_engine] / m.params.engine.inertia),
            w_gb,
            self.scenario.throttle.at(t),
            float(x[m.idx_p_x] / m.geometry.m),
            self.scenario.hold_brake,
            m.params.gearbox,
            m.params.clutch,
        )

    def _apply_logic(self, k: int) -> None:
        for _ in range(8):  # a few rules may fire in a row (e.g. shift end, then hold)
            decision = self._decide(k, self._x)
            if decision is None:
                return
            self._drv = decision.state
            self.events.append((k / self.rate_hz, decision.description))

    def _may_act(self, X: FloatArray, t: FloatArray) -> NDArray[np.bool_]:
        """Vectorised pre-screen of :func:`decide_shift` on samples X (n, M) at times t."""
        m = self.model
        drv = self._drv
        vp = m.params
        w_e = X[m.idx_p_engine] / vp.engine.inertia
        omega_front = 0.5 * (X[m.idx_p_spin[0]] + X[m.idx_p_spin[1]]) / m.inertia[0]
        w_gb = omega_front * self._total_ratios[drv.gear - 1]
        thr = self.scenario.throttle.sample(t)
        n = len(vp.gearbox.ratios)
        act = np.zeros(t.shape, dtype=bool)
        if drv.shift_end is not None:
            return t >= drv.shift_end - 1e-12
        if drv.clutch == ClutchMode.LOCKED:
            act |= w_e < vp.clutch.engage_start_speed
        if drv.clutch == ClutchMode.LAUNCH:
            act |= (w_e >= vp.clutch.engage_full_speed) & (thr > 0.0)
        if drv.clutch == ClutchMode.OPEN:
            pass  # neutral: no shifting (see decide_shift)
        elif drv.gear < n:
            up = np.array([upshift_speed(float(v), vp.gearbox) for v in np.unique(thr)])
            act |= w_gb > up[np.searchsorted(np.unique(thr), thr)]
        if drv.gear > 1 and drv.clutch != ClutchMode.OPEN:
            act |= w_gb < vp.gearbox.downshift_speed
        if self.scenario.hold_brake:
            v = X[m.idx_p_x] / m.geometry.m
            if drv.hold_brake:
                act |= thr > 0.0
            else:
                act |= (thr <= 0.0) & (np.abs(v) < _STANDSTILL_SPEED)
        return act

    def _chunk_end(self) -> float:
        t = self._t
        ends = [self.scenario.duration, t + self._max_chunk]
        ends += [b for b in self.scenario.breakpoints() if b > t + 1e-12]
        if self._drv.shift_end is not None and self._drv.shift_end > t + 1e-12:
            ends.append(self._drv.shift_end)
        # the end of the clutch engagement ramp is a kink in the inputs: end a chunk there
        ramp_end = self._drv.ramp_start + self.model.params.clutch.engage_time
        if ramp_end > t + 1e-12:
            ends.append(ramp_end)
        return min(ends)

    def _next_block(self) -> dict[str, Any]:
        """Integrate one chunk and return the samples it completes (at least one)."""
        rate = self.rate_hz
        k0 = self._k
        if abs(self._t - k0 / rate) < 1e-9:
            self._apply_logic(k0)
        u = self._inputs(self._t, self._drv)
        t_end = self._chunk_end()
        last = self.n_samples - 1
        k_hi = min(math.floor(t_end * rate + 1e-9), last)
        ks = np.arange(k0, k_hi + 1)
        ts = ks / rate
        tout = ts if abs(ts[0] - self._t) < 1e-9 else np.concatenate([[self._t], ts])
        tail = abs(tout[-1] - t_end) > 1e-9
        if tail:
            tout = np.concatenate([tout, [t_end]])
        if len(tout) < 2:  # final sample exactly at the current time
            tout = np.array([self._t, self._t + 1e-9])
        Y, info = odeint(  # type: ignore[call-overload]  # scipy-stubs reject Callable[..., X]
            self.model.rhs,
            self._x,
            tout,
            args=(u,),
            tfirst=True,
            rtol=self._rtol,
            atol=self._atol,
            mxstep=200000,
            full_output=True,
        )
        if info['message'] != 'Integration successful.':
            raise SimulationError(
                f'integration failed near t = {self._t:.6f} s: {info["message"]}'
            )
        self.nfev += int(info['nfe'][-1])
        first = 0 if abs(tout[0] - ts[0]) < 1e-9 else 1
        X = Y[first : first + len(ts)].T  # (n, M) at the sample times
        if not np.all(np.isfinite(Y)):
            raise SimulationError(f'non-finite state in the chunk starting at t = {self._t:.6f} s')
        final_chunk = k_hi == last and t_end >= self.scenario.duration - 1e-12
        # The sample at the chunk start was already checked by _apply_logic.
        act = self._may_act(X[:, 1:], ts[1:])
        cut = None
        for j in np.flatnonzero(act) + 1:
            if self._decide(int(ks[j]), X[:, j]) is not None:
                cut = int(j)
                break
        if cut is not None:
            keep = cut
            self._x = X[:, cut].copy()
            self._t = float(ts[cut])
            self._k = int(ks[cut])
        else:
            # The sample at t_end (a breakpoint) belongs to the next chunk, with new inputs.
            keep = len(ks) if (final_chunk or tail) else len(ks) - 1
            self._x = Y[-1].copy()
            self._t = t_end
            self._k = int(ks[keep - 1]) + 1 if keep else k0
        if keep == 0:
            return _empty_block()
        return self._evaluate(ts[:keep], X[:, :keep], u)

    def _evaluate(self, ts: FloatArray, X: FloatArray, u: FloatArray) -> dict[str, Any]:
        """Sensors and truth on sampled states X (n, M) with constant inputs u."""
        m = self.model
        vp = m.params
        c = m.compiled
        out = c.output_vector(ts, X, u)
        M = len(ts)
        mass = m.geometry.m
        r_eff = vp.wheel.effective_radius
        omega = (X[m.idx_p_spin] / m.inertia[:, None]).T
        omega_dot = (out[m.out_spin_rate] / m.inertia[:, None]).T
        angle = X[m.idx_angle].T.copy()
        v = X[m.idx_p_x] / mass
        accel = out[m.out_momentum_rate_x] / mass
        fx = out[m.out_fx].T
        fz_f = out[m.out['fz_front']]
        fz_r = out[m.out['fz_rear']]
        fz = np.stack([fz_f, fz_f, fz_r, fz_r], axis=1)
        brake_signed = out[m.out_brake].T
        drive = np.zeros((M, 4))
        drive[:, :2] = -out[m.out_drive].T
        torque = drive - brake_signed
        wr = omega * r_eff
        den = np.maximum(np.maximum(np.abs(wr), np.abs(v)[:, None]), vp.tire.low_speed_velocity)
        slip = (wr - v[:, None]) / den
        with np.errstate(divide='ignore', invalid='ignore'):
            mu = np.where(fz > 0.0, fx / np.where(fz > 0.0, fz, 1.0), 0.0)
        roll_f = 0.5 * np.abs(out[m.out['rolling_front']])
        roll_r = 0.5 * np.abs(out[m.out['rolling_rear']])
        w_e = X[m.idx_p_engine] / vp.engine.inertia
        engine_torque = out[m.out['combustion']] - out[m.out['engine_drag']]
        gear = 0 if self._drv.clutch == ClutchMode.OPEN else self._drv.gear
        meas_angle, meas_speed, meas_torque = self._sensors.measure(angle, v, torque)
        if self._torque_offset:
            # A map-based torque signal that is off: the sensors lie, the physics does not.
            gears = np.full(M, gear, dtype=np.int64)
            meas_torque[:, :2] += driven_wheel_torque_offset(vp, gears, self._torque_offset)[
                :, None
            ]
            engine_torque = engine_torque + self._torque_offset
        full = np.full
        pitch = self._deflection_pitch(X) - self._pitch_reference
        imu_true = imu_specific_force(
            accel, full(M, u[2]), pitch, self.scenario.sensors.imu_mount_pitch,
            vp.environment.gravity,
        )  # fmt: skip
        gyro_true = self._gyro_rate(ts, pitch - full(M, u[2]))
        potential = true_friction_potential(self._friction_table, fz, fx, full(M, u[3]))
        return {
            't': ts.copy(),
            'wheel_angle': meas_angle,
            'body_speed': meas_speed,
            'wheel_torque': meas_torque,
            'engine_torque': engine_torque,
            'engine_speed': w_e,
            'gear': full(M, gear, dtype=np.int64),
            'omega': omega,
            'omega_dot': omega_dot,
            'angle_true': angle,
            'speed_true': v,
            'accel_true': accel,
            'fx': fx,
            'fz': fz,
            'mu': mu,
            'slip': slip,
            'rolling': np.stack([roll_f, roll_f, roll_r, roll_r], axis=1),
            'aero': np.abs(out[m.out['aero']]),
            'slope': full(M, u[2]),
            'road_mu': full(M, u[3]),
            'peak_mu': potential.mu_max,
            'peak_slip': potential.slip_peak,
            'throttle': full(M, u[0]),
            'brake_torque': np.abs(brake_signed),
            'power_sources': out[c.n_outputs - 3],
            'power_dissipated': out[c.n_outputs - 2],
            'energy_stored': np.asarray(c.stored_energy(X), dtype=float),
            'pitch': pitch,
            'imu_true': imu_true,
            'imu': self._sensors.measure_imu(imu_true),
            'gyro_true': gyro_true,
            'gyro': self._sensors.measure_gyro(gyro_true),
        }

    def _gyro_rate(self, ts: FloatArray, tilt: FloatArray) -> FloatArray:
        """[rad/s] the mean rate of the sensor's pitch ``tilt`` (nose down, against the
        level; shape (M,), [rad]) over each sample period ``ts`` [s] ends (0 at the first
        sample of the run); the last tilt is kept for the next block."""
        before = np.concatenate([[tilt[0] if math.isnan(self._last_tilt) else self._last_tilt],
                                 tilt[:-1]])  # fmt: skip
        rate: FloatArray = (tilt - before) * self.rate_hz
        self._last_tilt = float(tilt[-1])
        return rate


def _empty_block() -> dict[str, Any]:
    four = np.empty((0, 4))
    one = np.empty(0)
    return {name: (four.copy() if name in _WHEEL_SERIES else one.copy()) for name in _SERIES} | {
        'gear': np.empty(0, dtype=np.int64),
        'imu_true': np.empty((0, 2)),
        'imu': np.empty((0, 2)),
    }


_WHEEL_SERIES = frozenset(
    {
        'wheel_angle',
        'wheel_torque',
        'omega',
        'omega_dot',
        'angle_true',
        'fx',
        'fz',
        'mu',
        'slip',
        'rolling',
        'peak_mu',
        'peak_slip',
        'brake_torque',
    }
)


_VECTOR_SERIES = frozenset({'imu_true', 'imu'})


def _frame(block: dict[str, Any], i: int) -> SampleFrame:
    """Sample ``i`` of a block as a :class:`SampleFrame` (per-wheel rows copied)."""
    kw: dict[str, Any] = {}
    for name in _SERIES:
        val = block[name][i]
        if name in _WHEEL_SERIES or name in _VECTOR_SERIES:
            kw[name] = val.copy()
        elif name == 'gear':
            kw[name] = int(val)
        else:
            kw[name] = float(val)
    return SampleFrame(**kw)


def simulate(
    vehicle: VehicleParams | VehicleModel,
    scenario: Scenario,
    *,
    rate_hz: float | None = None,
    seed: int | None = None,
    progress: Callable[[float, float], None] | None = None,
    rtol: float = 1e-7,
    atol_scale: float = 1.0,
    max_chunk: float = 8.0,
) -> SimResult:
    """Simulate a whole scenario.

    Args:
        vehicle: parameters or an already compiled :class:`VehicleModel`.
        scenario: the scenario.
        rate_hz: sample rate, [Hz]; default the scenario's ``sensors.rate_hz`` (1000).
        seed: noise seed; default the scenario's ``sensors.seed``.
        progress: called after each chunk with (simulated time [s], duration [s]).
        rtol: LSODA relative tolerance.
        atol_scale: multiplies the per-state absolute tolerances.
        max_chunk: longest integration chunk without a logic check, [s].

    Returns:
        Sensors and truth at every sample, see :class:`SimResult`.
    """
    sim = Simulator(
        vehicle,
        scenario,
        rate_hz=rate_hz,
        seed=seed,
        rtol=rtol,
        atol_scale=atol_scale,
        max_chunk=max_chunk,
    )
    return sim.run(progress)


# Keep the wheel order documented next to the data it orders.
assert WHEELS == ('FL', 'FR', 'RL', 'RR')


def with_torque_offset(
    result: SimResult, params: VehicleParams, engine_offset_nm: float
) -> SimResult:
    """The run with an offset on its torque SIGNALS (the physics is unchanged).

    Models a torque signal computed from an engine map whose torque is off by a constant:
    the engine torque signal gets ``engine_offset_nm`` and each driven (front) wheel's
    torque signal gets ``engine_offset_nm * ratio(gear) * final_drive / 2`` (open
    differential) while a gear is engaged (``gear >= 1``); during a shift (gear 0) the wheel
    signals are left as they are.

    Args:
        result: a finished run of :func:`~vd_sim_node.vehicle.simulation.simulate`.
        params: the vehicle it ran (its gear ratios).
        engine_offset_nm: offset on the engine torque, [N m].

    Returns:
        A copy of ``result`` with ``engine_torque`` and ``wheel_torque`` offset.

    Raises:
        ParameterError: ``engine_offset_nm`` is not finite.
    """
    if not math.isfinite(engine_offset_nm):
        raise ParameterError(f'engine torque offset must be finite, got {engine_offset_nm}')
    per_wheel = driven_wheel_torque_offset(params, result.gear, engine_offset_nm)
    wheel_torque = np.array(result.wheel_torque, dtype=float, copy=True)
    wheel_torque[:, 0] += per_wheel
    wheel_torque[:, 1] += per_wheel
    return dataclasses.replace(
        result,
        engine_torque=np.asarray(result.engine_torque, dtype=float) + engine_offset_nm,
        wheel_torque=wheel_torque,
    )
