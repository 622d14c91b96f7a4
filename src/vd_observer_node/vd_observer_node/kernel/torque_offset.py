"""Compiled twin of `estimation.torque_offset` (engine-torque offset learnt in neutral).

The state is a flat array with the slots of `TorqueOffsetState`, in its order; the settings
an array from `offset_params`. Every operation is the reference's, in the same order, so
the two agree bit for bit (tested).
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np
from numpy.typing import NDArray

from vd_observer_node.estimation.faults import stamp_dt as _stamp_dt
from vd_observer_node.estimation.torque_offset import (
    TorqueOffset,
    TorqueOffsetConfig,
    TorqueOffsetState,
)
from vd_observer_node.kernel._jit import jit

__all__ = [
    'OFFSET_CLAMPED_SLOT',
    'OFFSET_OUT_SIZE',
    'OFFSET_STATE_SIZE',
    'offset_from_packed',
    'offset_params',
    'offset_state',
    'offset_update',
]

FloatArray = NDArray[np.float64]

# settings (offset_params)
_MIN_EPISODE, _MIN_EPISODES, _MIN_TIME, _CONVERGED_STD, _MAX_OFFSET, _MAX_GAP = range(6)
# state slots: TorqueOffsetState's fields, in order
(_LAST_T, _T0, _W0, _T1, _W1, _TORQUE1, _INTEGRAL, _SUM_W, _SUM_WB, _SUM_WBB, _SUM_WW,
 _EPISODES, _CLAMPED) = range(13)  # fmt: skip
OFFSET_STATE_SIZE: Final = len(TorqueOffsetState._fields)
#: The state slot counting the stamps at which the estimate was clamped (a fault total).
OFFSET_CLAMPED_SLOT: Final = _CLAMPED
# output slots: TorqueOffset's fields, in order (flags as 0.0 / 1.0)
_O_OFFSET, _O_STD, _O_CONVERGED, _O_USED, _O_EPISODES, _O_CLAMPED = range(6)
OFFSET_OUT_SIZE: Final = len(TorqueOffset._fields)


def offset_params(config: TorqueOffsetConfig) -> FloatArray:
    """The settings as the kernel takes them."""
    return np.array(
        [
            config.min_episode_time,
            float(config.min_episodes),
            config.min_time,
            config.converged_std,
            config.max_offset,
            config.max_gap,
        ]
    )


def offset_state() -> FloatArray:
    """A fresh state (`TorqueOffsetState()`)."""
    return np.array(TorqueOffsetState(), dtype=np.float64)


def offset_from_packed(out: FloatArray) -> TorqueOffset:
    """The `TorqueOffset` an output row holds."""
    return TorqueOffset(
        float(out[_O_OFFSET]),
        float(out[_O_STD]),
        bool(out[_O_CONVERGED] != 0.0),
        float(out[_O_USED]),
        int(out[_O_EPISODES]),
        bool(out[_O_CLAMPED] != 0.0),
    )


@jit
def _estimate(prm: FloatArray, s: FloatArray, out: FloatArray) -> None:
    """`offset_estimate` into ``out``."""
    if s[_EPISODES] < 1.0:
        out[_O_OFFSET] = 0.0
        out[_O_STD] = prm[_MAX_OFFSET]
        out[_O_CONVERGED] = 0.0
        out[_O_USED] = 0.0
        out[_O_EPISODES] = 0.0
        out[_O_CLAMPED] = 0.0
        return
    mean = s[_SUM_WB] / s[_SUM_W]
    std = prm[_MAX_OFFSET]
    if s[_EPISODES] >= 2.0:
        variance = max(s[_SUM_WBB] / s[_SUM_W] - mean * mean, 0.0)
        n_eff = s[_SUM_W] * s[_SUM_W] / s[_SUM_WW]
        std = math.sqrt(variance / max(n_eff - 1.0, 1e-9))
    offset = min(max(mean, -prm[_MAX_OFFSET]), prm[_MAX_OFFSET])
    converged = (
        s[_EPISODES] >= prm[_MIN_EPISODES] and s[_SUM_W] >= prm[_MIN_TIME]
        and std <= prm[_CONVERGED_STD]
    )  # fmt: skip
    out[_O_OFFSET] = offset
    out[_O_STD] = std
    out[_O_CONVERGED] = 1.0 if converged else 0.0
    out[_O_USED] = offset if converged else 0.0
    out[_O_EPISODES] = s[_EPISODES]
    out[_O_CLAMPED] = 1.0 if offset != mean else 0.0


@jit
def offset_update(
    prm: FloatArray,
    inertia: float,
    s: FloatArray,
    t: float,
    engine_torque: float,
    gear: float,
    engine_speed: float,
    out: FloatArray,
) -> None:
    """`torque_offset_step`: advances ``s`` in place, writes the estimate into ``out``."""
    dt = _stamp_dt(s[_LAST_T], t, prm[_MAX_GAP]) if math.isfinite(t) else math.nan
    if math.isnan(dt):
        _estimate(prm, s, out)
        return
    if dt < 0.0:
        clamped = s[_CLAMPED]
        s[:] = 0.0
        s[_LAST_T] = math.nan
        s[_T0] = math.nan
        s[_CLAMPED] = clamped
    s[_LAST_T] = t
    neutral = gear == 0.0 and math.isfinite(engine_torque) and math.isfinite(engine_speed)
    if not math.isnan(s[_T0]):
        if neutral:
            s[_INTEGRAL] = s[_INTEGRAL] + 0.5 * (s[_TORQUE1] + engine_torque) * (t - s[_T1])
            s[_T1] = t
            s[_W1] = engine_speed
            s[_TORQUE1] = engine_torque
        else:
            duration = s[_T1] - s[_T0]
            s[_T0] = math.nan
            if duration >= prm[_MIN_EPISODE]:
                b = (s[_INTEGRAL] - inertia * (s[_W1] - s[_W0])) / duration
                s[_SUM_W] = s[_SUM_W] + duration
                s[_SUM_WB] = s[_SUM_WB] + duration * b
                s[_SUM_WBB] = s[_SUM_WBB] + duration * b * b
                s[_SUM_WW] = s[_SUM_WW] + duration * duration
                s[_EPISODES] = s[_EPISODES] + 1.0
    elif neutral:
        s[_T0] = t
        s[_W0] = engine_speed
        s[_T1] = t
        s[_W1] = engine_speed
        s[_TORQUE1] = engine_torque
        s[_INTEGRAL] = 0.0
    _estimate(prm, s, out)
    if out[_O_CLAMPED] != 0.0:
        s[_CLAMPED] = s[_CLAMPED] + 1.0
