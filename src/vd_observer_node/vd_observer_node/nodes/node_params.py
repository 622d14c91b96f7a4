"""Declared parameters of the estimation nodes, in one place (the pipeline node has them all).

Each list is built from the core's configuration dataclasses (`dataclass_param_specs`), so a
parameter's description and default cannot drift from the core. ``observer_node``,
``estimator_node`` and ``alerts_node`` declare their own list; ``pipeline_node`` declares the
union (one ``max_gap`` for observers and estimator, one ``vehicle_file`` and ``align_capacity``).

Every node that reads sensor topics also declares the input mapping (:data:`INPUT_PARAMS`):
``input_mapping``, the path of a mapping file, or the same settings as nested parameters
``inputs.<input>.<key>`` that a ROS params file can carry; :func:`take_input_mapping` builds
the :class:`~vd_observer_node.inputs.mapping.InputMapping` from either with the one parser of
:mod:`vd_observer_node.inputs.mapping`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Final

from vd_common.ros.parameters import ParamSpec, dataclass_param_specs
from vd_common.ros.publishing import ros_message_class
from vd_common.topics import (
    ESTIMATES_COMBINED,
    ESTIMATES_NAMESPACE,
    OBSERVER_BODY_VELOCITY,
    OBSERVER_NAMESPACE,
    SENSORS_BODY_VELOCITY,
    SENSORS_NAMESPACE,
)

from vd_observer_node.estimation.cascade import ESTIMATOR_SPEEDS
from vd_observer_node.estimation.differentiator import (
    DEFAULT_GAINS,
    DISCRETIZATIONS,
    INIT_POLICIES,
)
from vd_observer_node.estimation.estimator import (
    LOAD_TRANSFER_SOURCES,
    MASS_PREFIX,
    RADIUS_PREFIX,
    SLOPE_ACCEL_SOURCES,
    TORQUE_OFFSET_PREFIX,
    EstimatorConfig,
)
from vd_observer_node.estimation.imu_settings import VEHICLE_FIELDS, ImuGradeConfig
from vd_observer_node.estimation.mass_grade import MassGradeConfig
from vd_observer_node.estimation.observer import ObserverConfig
from vd_observer_node.estimation.rolling_radius import RollingRadiusConfig
from vd_observer_node.estimation.torque_offset import TorqueOffsetConfig
from vd_observer_node.inputs.errors import MappingError
from vd_observer_node.inputs.mapping import (
    ALIGNMENTS,
    FUSION_KEY,
    HELD_KEYS,
    IMU_INPUT,
    INPUT_KEYS,
    INPUTS,
    SUPPORTED_TYPES,
    UNITS,
    InputMapping,
    InputSpec,
    load_input_mapping,
    mapping_from_params,
)
from vd_observer_node.situation.alerts import ALERT_KINDS, AlertConfig
from vd_observer_node.situation.friction_potential import FrictionPotentialConfig
from vd_observer_node.situation.monitor import SituationConfig

__all__ = [
    'ALERTS_PARAMS',
    'ALIGN_CAPACITY',
    'ESTIMATE_TOPICS_PARAM',
    'ESTIMATE_TOPIC_LAYOUTS',
    'ESTIMATOR_PARAMS',
    'INPUT_MAPPING',
    'INPUT_PARAMS',
    'OBSERVER_PARAMS',
    'PIPELINE_PARAMS',
    'VEHICLE_FILE',
    'input_message_class',
    'take_input_mapping',
    'undeclared_inputs',
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

INPUT_MAPPING: Final = ParamSpec(
    'input_mapping',
    '',
    'input mapping YAML: the topics, types, joints, units and signs of the sensor inputs '
    f"(docs/input_mapping.md; '' = vd's own {SENSORS_NAMESPACE}* topics, "
    'or the inputs.* parameters)',
)
_KEY_DOCS: Final = {
    'topic': 'topic (absolute name)',
    'mount_rpy_deg': "sensor frame's roll, pitch, yaw in the body frame [deg]",
    'joints': 'JointState joint names, order FL, FR, RL, RR',
    'indices': 'Float64MultiArray element indices',
    'unit': 'unit',
    'scale': 'factor applied after the unit [-]',
    'sign': 'per-value sign, +1 or -1',
}
#: ``inputs.<input>.<key>``: the mapping file's settings as parameters (unset by default).
INPUT_PARAMS: Final = [
    INPUT_MAPPING,
    *(
        ParamSpec(
            f'inputs.{name}.{key}',
            None,
            f'{name}: {_KEY_DOCS.get(key, "message type" if key == "type" else key)}'
            + (f' ({" | ".join(UNITS[name])})' if key == 'unit' and name in UNITS else '')
            + (f' ({" | ".join(SUPPORTED_TYPES[name])})' if key == 'type' else '')
            + ("; unset with every other inputs.* = vd's own topic" if key == 'topic' else ''),
        )
        for name in INPUTS
        for key in INPUT_KEYS
    ),
    ParamSpec(
        'inputs.alignment',
        None,
        f'how the inputs are matched ({" | ".join(ALIGNMENTS)}): exact header stamps, or each '
        'wheel stamp with the newest not-later sample of the others (topics on their own clocks)',
    ),
    ParamSpec('inputs.max_age', None, "'latest' alignment: oldest held sample [s]"),
    # the held inputs (optional; the IMU, fused by pipeline_node, `imu_grade`): as the mapping
    # file's
    *(
        ParamSpec(
            f'inputs.{name}.{key}',
            None,
            f'{name}: {_KEY_DOCS.get(key, "message type" if key == "type" else key)}'
            + (f' ({" | ".join(UNITS[name])})' if key == 'unit' else '')
            + (f' ({" | ".join(SUPPORTED_TYPES[name])})' if key == 'type' else '')
            + (f'; unset: no {name} input' if key == 'topic' else ''),
        )
        for name, keys in HELD_KEYS.items()
        for key in keys
    ),
    *(
        ParamSpec(
            f'inputs.{IMU_INPUT}.{FUSION_KEY}.{spec.name}',
            None,
            f'{IMU_INPUT} fusion (unset: '
            + ('follows the input rate' if spec.default is None else f'{spec.default}')
            + f'): {spec.description}',
        )
        for spec in dataclass_param_specs(ImuGradeConfig, skip=VEHICLE_FIELDS)
    ),
]


def undeclared_inputs(node: Any) -> list[str]:
    """The ``inputs.*`` parameters given to `node` (params file, ``-p``) but not declared.

    ROS ignores a value given for an undeclared parameter, so a misspelt key
    (``inputs.body_speed.unti``) would silently keep its default; the nodes pass these names
    to :func:`take_input_mapping`, which refuses them naming the key.
    """
    # rclpy keeps the command line's and params files' values here (no public accessor)
    overrides = getattr(node, '_parameter_overrides', {})
    return [n for n in overrides if n.startswith('inputs.') and not node.has_parameter(n)]


def take_input_mapping(
    values: dict[str, Any],
    undeclared: Sequence[str] = (),
    *,
    estimates: bool = False,
    torque_paths: bool = False,
) -> InputMapping:
    """Remove the input-mapping parameters from `values` and build the mapping.

    Args:
        values: the declared parameters' values (:func:`declare_parameters`); ``input_mapping``
            and every ``inputs.*`` entry are popped.
        undeclared: ``inputs.*`` names given but not declared (:func:`undeclared_inputs`):
            refused as unknown inputs or keys.
        estimates: the node computes estimates from the wheel torques (estimator, alerts,
            pipeline): unless `torque_paths`, a mapping whose ``torque_source`` is not
            'measured' is refused (estimator_node and alerts_node read measured wheel torques
            only; the engine and no-torque paths run in pipeline_node, ``vd replay`` and
            ``vd report``).
        torque_paths: the node runs every torque source (pipeline_node).

    Raises:
        MappingError: unreadable file, a refused setting (one line naming the key), both a
            file and ``inputs.*`` parameters given, or a torque source the node cannot run.
    """
    path = values.pop(INPUT_MAPPING.name)
    params = {k: values.pop(k) for k in [k for k in values if k.startswith('inputs.')]}
    params.update(dict.fromkeys(undeclared, ''))  # any value: the name alone is refused
    given = sorted(k for k, v in params.items() if v is not None)
    if path and given:
        raise MappingError(
            f'parameters input_mapping and {given[0]} are both set: give the mapping either '
            'as a file or as inputs.* parameters'
        )
    mapping = load_input_mapping(path) if path else mapping_from_params(params)
    if estimates and not torque_paths and mapping.torque_source != 'measured':
        raise MappingError(
            f'{mapping.source}: torque_source {mapping.torque_source!r} runs in pipeline_node, '
            'vd replay and vd report; this node reads measured wheel_torques only (run '
            'pipeline_node instead)'
        )
    if estimates and not torque_paths and mapping.brake is not None:
        raise MappingError(
            f'{mapping.source}: brake runs in pipeline_node, vd replay and vd report; this '
            'node reads measured wheel_torques only (run pipeline_node instead)'
        )
    return mapping


def input_message_class(spec: InputSpec) -> Any:
    """The rclpy message class of a mapped input (what its subscription is created with).

    Raises:
        MappingError: the type's interface package is not installed (one line naming it).
    """
    try:
        return ros_message_class(spec.msgtype)
    except (ImportError, AttributeError) as exc:
        raise MappingError(
            f'{spec.name}.type: {spec.msgtype} is not installed here ({exc})'
        ) from None


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

_ESTIMATOR_CORE: Final = [
    *dataclass_param_specs(
        EstimatorConfig,
        skip=('mass', 'radius', 'torque_offset'),
        choices={
            'load_transfer_source': LOAD_TRANSFER_SOURCES,
            'slope_accel_source': SLOPE_ACCEL_SOURCES,
        },
    ),
    # the online mass estimator's settings, as EstimatorConfig.from_mapping takes them
    *(
        ParamSpec(f'{MASS_PREFIX}{p.name}', p.default, f'online mass: {p.description}')
        for p in dataclass_param_specs(MassGradeConfig)
    ),
    # ... and the online rolling radius's
    *(
        ParamSpec(f'{RADIUS_PREFIX}{p.name}', p.default, f'online rolling radius: {p.description}')
        for p in dataclass_param_specs(RollingRadiusConfig)
    ),
    # ... and the engine-torque offset's (engine path: pipeline_node, vd replay)
    *(
        ParamSpec(
            f'{TORQUE_OFFSET_PREFIX}{p.name}', p.default, f'engine-torque offset: {p.description}'
        )
        for p in dataclass_param_specs(TorqueOffsetConfig)
    ),
]

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

#: choices of pipeline_node's ``estimate_topics``
ESTIMATE_TOPIC_LAYOUTS: Final = ('separate', 'combined', 'both')
ESTIMATE_TOPICS_PARAM: Final = ParamSpec(
    'estimate_topics',
    'separate',
    f"'separate': one topic per quantity ({OBSERVER_NAMESPACE}*, {ESTIMATES_NAMESPACE}*, "
    "what vd replay writes and vd report reads); 'combined': the per-stamp estimates in one "
    f'vd_msgs/Estimates message on {ESTIMATES_COMBINED} instead (one message per stamp '
    "instead of seven); 'both'. Mass, radius, torque offset, friction potential and alerts "
    'keep their own topics.',
    choices=ESTIMATE_TOPIC_LAYOUTS,
)

PIPELINE_PARAMS: Final = [
    ESTIMATE_TOPICS_PARAM,
    *ESTIMATOR_PARAMS,
    *(p for p in OBSERVER_PARAMS if p.name != 'max_gap'),
    *_SITUATION_CORE,
]
