"""Sensor models: quantised wheel encoders, noisy body speed and wheel torque.

The noise generators are seeded and consume one draw per sample in sample order, so the
measured series do not depend on how the simulator splits the run into integration chunks.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from vd_sim_node.vehicle.scenario import SensorSettings

__all__ = ['SensorModel', 'quantise_angle']

FloatArray = NDArray[np.float64]


def quantise_angle(angle: FloatArray, counts_per_rev: int) -> FloatArray:
    """Angle seen by an incremental encoder with ``counts_per_rev`` counts per revolution.

    Args:
        angle: true unwrapped angle, any shape, [rad].
        counts_per_rev: encoder resolution; 0 returns the angle unchanged (ideal sensor).

    Returns:
        ``floor(angle / step) * step`` with ``step = 2 pi / counts_per_rev``, [rad].
    """
    if counts_per_rev <= 0:
        return np.array(angle, dtype=float, copy=True)
    step = 2.0 * math.pi / counts_per_rev
    out: FloatArray = np.floor(np.asarray(angle) / step) * step
    return out


class SensorModel:
    """Turns true signals into measured ones, sample by sample in order."""

    def __init__(self, settings: SensorSettings, seed: int | None = None) -> None:
        """Create the generators.

        Args:
            settings: sensor settings of the scenario.
            seed: overrides ``settings.seed`` when given.
        """
        self.settings = settings
        seq = np.random.SeedSequence(settings.seed if seed is None else seed)
        speed_seq, torque_seq = seq.spawn(2)
        self._speed_rng = np.random.default_rng(speed_seq)
        self._torque_rng = np.random.default_rng(torque_seq)

    def measure(
        self, angle: FloatArray, speed: FloatArray, torque: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Measure a block of consecutive samples.

        Args:
            angle: true wheel angles, shape (M, 4), [rad].
            speed: true body speed, shape (M,), [m/s].
            torque: true wheel torques, shape (M, 4), [N m].

        Returns:
            (angle, speed, torque) as measured, same shapes.
        """
        s = self.settings
        a = quantise_angle(angle, s.encoder_counts_per_rev)
        v = np.array(speed, dtype=float, copy=True)
        if s.speed_noise_std > 0.0:
            v += s.speed_noise_std * self._speed_rng.standard_normal(v.shape)
        tq = np.array(torque, dtype=float, copy=True)
        if s.torque_noise_std > 0.0:
            tq += s.torque_noise_std * self._torque_rng.standard_normal(tq.shape)
        return a, v, tq
