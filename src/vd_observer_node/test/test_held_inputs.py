"""Held inputs (the IMU): named in three places, carried everywhere else by name (issue 40).

A held input is sampled and held at each cascade stamp (the newest sample not later than it).
It is declared by its key in the input mapping (`mapping.HELD_KEYS`, `InputMapping.held_specs`),
its record and field in the cascade (`cascade_step.HELD_INPUTS`, `CascadeInputs`) and the part
that reads it; the node parameters, the replay (`ReplayRun.held`), `cascade.held_records`,
`Chain.update(held=...)` and pipeline_node take every one of them by name. These checks fail
when one of the places is missed.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from vd_observer_node.errors import InputShapeError
from vd_observer_node.estimation.cascade import held_records
from vd_observer_node.estimation.cascade_step import HELD_INPUTS, CascadeInputs
from vd_observer_node.inputs.mapping import HELD_KEYS, mapping_from_dict
from vd_observer_node.nodes.node_params import INPUT_PARAMS

VEHICLE_FILE = Path(__file__).resolve().parents[2] / 'vd_common' / 'config' / 'clio_rl_1_1.yaml'


def test_each_held_input_has_its_record_its_field_and_its_parameters() -> None:
    assert set(HELD_KEYS) == set(HELD_INPUTS)
    declared = {spec.name for spec in INPUT_PARAMS}
    for name, dtype in HELD_INPUTS.items():
        assert (dtype.names or ())[0] == 'stamp', name  # what the part judges the age by
        assert name in CascadeInputs._fields, name
        for key in HELD_KEYS[name]:
            assert f'inputs.{name}.{key}' in declared, (name, key)


def test_the_mapping_lists_its_held_inputs_by_their_cascade_names() -> None:
    mapping = mapping_from_dict({'imu': {'topic': '/imu', 'type': 'sensor_msgs/msg/Imu'}})
    assert [spec.name for spec in mapping.held_specs] == ['imu']
    assert mapping_from_dict({}).held_specs == ()


def test_held_columns_become_records_padded_with_nan() -> None:
    records = held_records(2, {'imu': [[1.0, 0.5], [math.nan, math.nan]]})['imu']
    assert records['stamp'][0] == 1.0 and records['f_x'][0] == 0.5
    assert math.isnan(records['pitch_rate'][0]) and math.isnan(records['stamp'][1])
    with pytest.raises(InputShapeError, match='no held input'):
        held_records(2, {'steering': np.zeros((2, 2))})
    with pytest.raises(InputShapeError, match='imu must have shape'):
        held_records(2, {'imu': np.zeros((2, 5))})
