"""Declared parameters of the estimation nodes, in one place (the pipeline node has them all).

Each list is built from the core's configuration dataclasses (`dataclass_param_specs`), so a
parameter's description and default cannot drift from the core. ``observer_node``,
``estimator_node`` and ``alerts_node`` declare their own list; ``pipeline_node`` declares the
union (one ``max_gap`` for observers and estimator, one ``vehicle_file`` and ``align_capacity``)
plus ``kernel``.
"""

from __future__ import annotations

from typing import Final

from vd_sim_node.ros_common import ParamSpec, dataclass_param_specs
from vd_sim_node.topics import OBSERVER_BODY_VELOCITY, SENSORS_BODY_VELOCITY

from vd_observer_node.chain import ESTIMATOR_SPEEDS, KERNELS
from vd_observer_node.estimation.differentiator import (
    DEFAULT_GAINS,
    DISCRETIZATIONS,
    INIT_POLICIES,
)
from vd_observer_node.estimation.estimator import (
    LOAD_TRANSFER_SOURCES,
    SLOPE_ACCEL_SOURCES,
    EstimatorConfig,
)
from vd_observer_node.estimation.observer import ObserverConfig
from vd_observer_node.situation.alerts import ALERT_KINDS, AlertConfig
from vd_observer_node.situation.friction_potential import FrictionPotentialConfig
from vd_observer_node.situation.monitor import SituationConfig

__all__ = [
    'ALERTS_PARAMS',
    'ALIGN_CAPACITY',
    'ESTIMATOR_PARAMS',
    'KERNEL',
    'OBSERVER_PARAMS',
    'PIPELINE_PARAMS',
    'VEHICLE_FILE',
]

VEHICLE_FILE: Final = ParamSpec(
    'vehicle_file',
    '',
    "vehicle parameter YAML shared with the simulator ('' = the installed Clio RL 1.1 file)",
)
ALIGN_CAPACITY: Final = ParamSpec(
    'align_capacity',
    1000,
    'messages buffered per topic while matching stamps (1000: a 1 s lag between inputs at 1 kHz)',
    low=1,
    high=100000,
)
KERNEL: Final = ParamSpec(
    'kernel',
    'compiled',
    "per-sample math: 'compiled' (numba kernel) or 'python' (the reference; same results, "
    'about 30x the CPU per sample)',
    choices=KERNELS,
)

OBSERVER_PARAMS: Final = [
    *dataclass_param_specs(
        ObserverConfig,
        # what the wheel sensors are follows from the input mapping, not a parameter of its own
        skip=('gains', 'wheel_input'),
        choices={'discretization': DISCRETIZATIONS, 'init': INIT_POLICIES},
    ),
    ParamSpec('l0', DEFAULT_GAINS.l0, 'Levant gain lambda0 [-]'),
    ParamSpec('l1', DEFAULT_GAINS.l1, 'Levant gain lambda1 [-]'),
    ParamSpec('l2', DEFAULT_GAINS.l2, 'Levant gain lambda2 [-], > 1'),
]

_ESTIMATOR_CORE: Final = dataclass_param_specs(
    EstimatorConfig,
    choices={
        'load_transfer_source': LOAD_TRANSFER_SOURCES,
        'slope_accel_source': SLOPE_ACCEL_SOURCES,
    },
)

ESTIMATOR_PARAMS: Final = [
    VEHICLE_FILE,
    ParamSpec(
        'speed_source',
        'measured',
        f"body speed fed to the estimator: 'measured' ({SENSORS_BODY_VELOCITY}; the slope "
        f"low-pass smooths it) or 'observer' ({OBSERVER_BODY_VELOCITY}, filtered); must "
        'match the offline cascade (run_cascade estimator_speed) for identical results',
        choices=ESTIMATOR_SPEEDS,
    ),
    ALIGN_CAPACITY,
    *_ESTIMATOR_CORE,
]

_THRESHOLD_DEFAULTS: Final = AlertConfig()

_SITUATION_CORE: Final = [
    *dataclass_param_specs(SituationConfig),
    *dataclass_param_specs(AlertConfig, skip=ALERT_KINDS),
    *(
        ParamSpec(
            f'{kind}.{name}',
            float(getattr(getattr(_THRESHOLD_DEFAULTS, kind), name)),
            f'{kind} alert hysteresis threshold {name} '
            f'[{"-" if kind != "low_friction" else "utilisation |mu|/mu_max"}] '
            '(see docs/alerts.md)',
        )
        for kind in ALERT_KINDS
        for name in ('warning_on', 'warning_off', 'critical_on', 'critical_off')
    ),
    *dataclass_param_specs(FrictionPotentialConfig, skip=('road_scales', 'class_bounds')),
]

ALERTS_PARAMS: Final = [VEHICLE_FILE, ALIGN_CAPACITY, *_SITUATION_CORE]

PIPELINE_PARAMS: Final = [
    KERNEL,
    *ESTIMATOR_PARAMS,
    *(p for p in OBSERVER_PARAMS if p.name != 'max_gap'),
    *_SITUATION_CORE,
]
