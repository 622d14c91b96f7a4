"""Torque when it is not measured (issue 15): the engine input and ``torque_source`` of the
mapping, their refusals, the engine decoder, and ``vd replay`` on each torque path."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from vd_common.topics import (
    ESTIMATES_FRICTION,
    ESTIMATES_SLOPE,
    ESTIMATES_TIRE_FORCES,
    SENSORS_WHEEL_ANGLES,
    SENSORS_WHEEL_TORQUES,
)
from vd_common.vehicle.params import default_vehicle_file, load_vehicle
from vd_observer_node.bag import BagReader, BagWriter
from vd_observer_node.bag.cdr_batch import decode_batch
from vd_observer_node.bag.errors import ReplayInputError
from vd_observer_node.bag.reader import TopicArrays
from vd_observer_node.bag.typestore import message_class, serialize
from vd_observer_node.errors import ConfigurationError
from vd_observer_node.estimation import drivetrain
from vd_observer_node.inputs.decode import InputDecoder, decode_engine
from vd_observer_node.inputs.errors import MappingError
from vd_observer_node.inputs.mapping import InputMapping, default_mapping, mapping_from_dict
from vd_observer_node.situation.chain_settings import chain_settings
from vd_observer_node.testing.devbag import sim_topics, write_topic_arrays_bag
from vd_observer_node.tools.cli import main
from vd_observer_node.tools.replay import replay_bag
from vd_sim_node.vehicle.scenario import load_scenario
from vd_sim_node.vehicle.simulation import SimResult, simulate

#: the simulator's scenarios (the tests' oracle; vd_common holds only the vehicle file)
SCENARIOS = Path(__file__).resolve().parents[2] / 'vd_sim_node' / 'config' / 'scenarios'

ENGINE_TOPIC = '/can/engine'
#: the engine on CAN: gear, torque in kN m, engine speed in rpm
ENGINE_MAPPING = {
    'torque_source': 'engine',
    'engine_torque': {
        'topic': ENGINE_TOPIC,
        'type': 'std_msgs/msg/Float64MultiArray',
        'indices': [1, 0, 2],
        'unit': 'kN m',
        'speed_unit': 'rpm',
    },
}


def refused(data: Any, match: str) -> None:
    with pytest.raises(MappingError, match=match):
        mapping_from_dict(data, source='car.yaml')


def test_mapping_keys_of_the_torque_paths() -> None:
    default = default_mapping()
    assert default.torque_source == 'measured' and default.is_default
    assert [s.name for s in default.used_specs] == ['wheel_angles', 'body_speed', 'wheel_torques']
    none = mapping_from_dict({'torque_source': 'none'})
    assert [s.name for s in none.used_specs] == ['wheel_angles', 'body_speed']
    assert not none.is_default
    # the engine path reads vd's own WheelTorques (engine_torque, gear, engine_speed) unless
    # mapped, even on the topic the wheel torques would come from
    engine = mapping_from_dict({'torque_source': 'engine'})
    assert engine.used_specs[2].topic == SENSORS_WHEEL_TORQUES
    mapped = mapping_from_dict(ENGINE_MAPPING)
    spec = mapped.used_specs[2]
    assert (spec.topic, spec.indices, spec.factor) == (ENGINE_TOPIC, (1, 0, 2), 1000.0)
    assert spec.speed_factor == pytest.approx(math.pi / 30.0)
    two = mapping_from_dict(
        {**ENGINE_MAPPING, 'engine_torque': {**ENGINE_MAPPING['engine_torque'], 'indices': [1, 0]}}
    )
    assert two.used_specs[2].indices == (1, 0)


def test_mapping_refusals_name_the_key() -> None:
    engine = ENGINE_MAPPING['engine_torque']
    refused({'torque_source': 'guess'}, r"car.yaml: torque_source 'guess' is unknown")
    refused(
        {'engine_torque': {**engine, 'type': 'sensor_msgs/msg/JointState'}},
        r'engine_torque.type .* is not supported',
    )
    refused(
        {'engine_torque': {**engine, 'indices': [0]}},
        r'engine_torque.indices must list 2 or 3 or 4 element indices',
    )
    refused(
        {'engine_torque': {**engine, 'indices': [0, 1, 2, 3, 4]}},
        r'engine_torque.indices must list 2 or 3 or 4',
    )
    refused({'engine_torque': {**engine, 'speed_unit': 'Hz'}}, r"speed_unit 'Hz' is unknown")
    refused({'engine_torque': {**engine, 'unit': 'lbf ft'}}, r"engine_torque.unit 'lbf ft'")
    refused({'engine_torque': {**engine, 'gear': 3}}, r'engine_torque.gear: unknown key')
    refused({'engine_torque': {'topic': ENGINE_TOPIC}}, r'engine_torque.type is missing')
    refused(
        {'wheel_angles': {'topic': '/a', 'type': 'vd_msgs/msg/WheelAngles', 'speed_unit': 'rpm'}},
        r'wheel_angles.speed_unit is for engine_torque only',
    )
    refused(
        {
            'torque_source': 'engine',
            'engine_torque': {**engine, 'topic': SENSORS_WHEEL_ANGLES},
        },
        r'engine_torque.type: .* is also mapped as vd_msgs/msg/WheelAngles',
    )


def _float_array(values: list[float]) -> Any:
    layout = message_class('std_msgs/msg/MultiArrayLayout')(dim=[], data_offset=0)
    return message_class('std_msgs/msg/Float64MultiArray')(
        layout=layout, data=np.array(values, dtype=np.float64)
    )


def test_engine_decoder_units_and_missing_elements() -> None:
    spec = mapping_from_dict(ENGINE_MAPPING).used_specs[2]
    msgs = [_float_array([3.0, 0.08, 3000.0]), _float_array([0.0, -0.01, 900.0])]
    arrays = TopicArrays(
        spec.msgtype, np.array([5, 7], dtype=np.int64), [serialize(m) for m in msgs]
    )
    series = decode_engine(spec, arrays)
    np.testing.assert_array_equal(series.stamp_ns, [5, 7])  # log times: no header
    np.testing.assert_allclose(
        series.values[:, :3],
        [[80.0, 3.0, 100.0 * math.pi], [-10.0, 0.0, 30.0 * math.pi]],
        rtol=1e-12,
    )
    assert np.isnan(series.values[:, 3]).all()  # no turbine speed mapped
    two = dataclasses.replace(spec, indices=(1, 0))
    assert np.isnan(decode_engine(two, arrays).values[:, 2:]).all()
    # a turbine speed (rpm, as the engine speed) and a gear offset
    four = dataclasses.replace(spec, indices=(1, 0, 2, 2), gear_offset=1)
    np.testing.assert_allclose(
        decode_engine(four, arrays).values,
        [[80.0, 4.0, 100.0 * math.pi, 100.0 * math.pi], [-10.0, 1.0, 30.0 * math.pi,
                                                         30.0 * math.pi]],
        rtol=1e-12,
    )  # fmt: skip
    short = dataclasses.replace(spec, indices=(1, 0, 5))
    with pytest.raises(MappingError, match=r'engine_torque\.indices: element 5 is beyond'):
        decode_engine(short, arrays)


def test_live_engine_decoder_gives_the_replays_values(tmp_path: Path) -> None:
    """InputDecoder (pipeline_node, one message at a time) on the engine input: the values
    decode_engine gives for a bag, bit for bit, from vd's WheelTorques and a
    Float64MultiArray (kN m, rpm, another order; with and without the engine speed)."""
    write_bag(tmp_path / 'in', engine_topic=True)
    reader = BagReader(tmp_path / 'in_engine')
    own = default_mapping().engine
    mapped = mapping_from_dict(ENGINE_MAPPING).engine
    no_speed = dataclasses.replace(mapped, indices=(1, 0))
    inverted = dataclasses.replace(own, sign=(-1.0,), factor=1000.0)
    for spec in (own, mapped, no_speed, inverted):
        arrays = reader.topic_arrays([spec.topic])[spec.topic]
        series = decode_engine(spec, arrays)
        decoder = InputDecoder(spec)
        live = [
            decoder.decode(data, int(log))
            for data, log in zip(arrays.datas, arrays.log_time_ns, strict=True)
        ]
        np.testing.assert_array_equal([s for s, _, _ in live], series.stamp_ns)
        np.testing.assert_array_equal(np.array([v for _, _, v in live]), series.values)
    assert np.ptp(series.values[:, 1]) > 0  # the gear changes in the record
    with pytest.raises(MappingError, match='no decoder'):
        InputDecoder(dataclasses.replace(own, msgtype='sensor_msgs/msg/JointState'))


_SIM: list[SimResult] = []


def sim_run() -> SimResult:
    """12 s of the paper scenario at 100 Hz, ideal sensors: launch at 8 s, first gear."""
    if not _SIM:
        scenario = load_scenario(SCENARIOS / 'paper_table1.yaml')
        scenario = dataclasses.replace(
            scenario,
            duration=12.0,
            sensors=dataclasses.replace(scenario.sensors, rate_hz=100.0),
        )
        _SIM.append(simulate(load_vehicle(default_vehicle_file()), scenario))
    return _SIM[0]


def write_bag(path: Path, *, torques: bool = True, engine_topic: bool = False) -> np.ndarray:
    sim = sim_run()
    stamps = np.round(sim.t * 1e9).astype(np.int64) + 1_000_000_000
    topics = sim_topics(sim)
    if not torques:
        del topics[SENSORS_WHEEL_TORQUES]
    write_topic_arrays_bag(path, stamps, topics)
    if engine_topic:
        # the same drive with the engine on a CAN topic of its own, in a second bag file
        rows = zip(sim.gear, sim.engine_torque, sim.engine_speed, strict=True)
        datas = [
            serialize(_float_array([float(g), e / 1000.0, w * 30.0 / math.pi])) for g, e, w in rows
        ]
        merged = path.with_name(path.name + '_engine')
        reader = BagReader(path)
        with BagWriter(merged) as writer:
            for name, info in reader.topics.items():
                writer.add_topic(name, info.msgtype)
            writer.add_topic(ENGINE_TOPIC, 'std_msgs/msg/Float64MultiArray')
            for m in reader.raw_messages():
                writer.write(m.topic, m.data, m.log_time_ns)
            writer.write_batch(ENGINE_TOPIC, datas, stamps.tolist())
    return stamps


def estimate_values(bag: Path) -> dict[str, dict[str, np.ndarray]]:
    reader = BagReader(bag)
    arrays = reader.topic_arrays([ESTIMATES_TIRE_FORCES, ESTIMATES_FRICTION, ESTIMATES_SLOPE])
    return {t: decode_batch(a.msgtype, a.datas).values for t, a in arrays.items()}


def on_path(source: str) -> InputMapping:
    """vd's own topics with the torque source `source` (what ``vd replay --torque-source``
    makes of the mapping)."""
    return dataclasses.replace(default_mapping(), torque_source=source)


def test_replay_on_each_torque_path(tmp_path: Path) -> None:
    write_bag(tmp_path / 'in', engine_topic=True)
    sources = {}
    for source in ('measured', 'engine', 'none'):
        report = replay_bag(
            tmp_path / 'in', tmp_path / source, progress=False, mapping=on_path(source)
        )
        assert report.torque_source == source
        values = estimate_values(tmp_path / source)
        for topic in values:
            codes = values[topic]['torque_source']
            assert np.all(codes == drivetrain.TORQUE_SOURCES.index(source)), topic
        sources[source] = (report, values)
    measured, engine, none = (sources[s][1] for s in ('measured', 'engine', 'none'))
    assert sources['measured'][0].torque_valid_fraction == 1.0
    # idling with the clutch open, then the launch: the clutch settles closed for the last
    # fifth of the 12 s (measured 0.1998)
    assert sources['engine'][0].torque_valid_fraction == pytest.approx(0.20, abs=0.01)
    assert sources['none'][0].torque_valid_fraction == 0.0
    assert np.all(none[ESTIMATES_TIRE_FORCES]['fx'] == 0.0)
    assert not none[ESTIMATES_FRICTION]['valid'].any()
    assert not none[ESTIMATES_SLOPE]['valid'].any()
    # first gear with the clutch closed (9.5 s to the upshift at 11.5 s): the engine path's Fx
    # is the measured path's but for the observer's omega_dot error, which the engine-inertia
    # term multiplies by J_e * i^2 / 2 (14 kg m^2 in first gear, 18 times a front wheel's)
    window = slice(950, 1130)
    diff = (
        engine[ESTIMATES_TIRE_FORCES]['fx'][window, :2]
        - measured[ESTIMATES_TIRE_FORCES]['fx'][window, :2]
    )
    assert float(np.sqrt(np.mean(diff**2))) < 6.0  # N, on ~1550 N per front wheel
    # the same engine data on a Float64MultiArray (kN m, rpm, another order) replays alike
    mapped = replay_bag(
        tmp_path / 'in_engine',
        tmp_path / 'mapped',
        progress=False,
        mapping=mapping_from_dict(ENGINE_MAPPING),
    )
    assert mapped.torque_source == 'engine'
    again = estimate_values(tmp_path / 'mapped')
    for topic, fields in engine.items():
        for name, value in fields.items():
            np.testing.assert_allclose(again[topic][name], value, rtol=1e-9, atol=1e-9)


def test_replay_without_any_torque_topic(tmp_path: Path) -> None:
    write_bag(tmp_path / 'in', torques=False)
    with pytest.raises(ReplayInputError, match=SENSORS_WHEEL_TORQUES):
        replay_bag(tmp_path / 'in', tmp_path / 'measured', progress=False)
    with pytest.raises(ReplayInputError, match=SENSORS_WHEEL_TORQUES):
        replay_bag(tmp_path / 'in', tmp_path / 'engine', progress=False, mapping=on_path('engine'))
    report = replay_bag(
        tmp_path / 'in', tmp_path / 'none', progress=False, mapping=on_path('none')
    )
    assert report.unmatched == 0 and report.samples == sim_run().t.size
    assert SENSORS_WHEEL_TORQUES not in BagReader(tmp_path / 'none').topics
    with pytest.raises(ConfigurationError, match='torque source'):
        replay_bag(tmp_path / 'in', tmp_path / 'bad', progress=False, mapping=on_path('guess'))
    # settings made for the engine path do not run a mapping without torque
    with pytest.raises(ConfigurationError, match='torque_source'):
        replay_bag(
            tmp_path / 'in',
            tmp_path / 'bad2',
            chain_settings(on_path('engine')),
            progress=False,
            mapping=on_path('none'),
        )


def test_cli_replay_prints_the_torque_path(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    write_bag(tmp_path / 'in')
    args = ['replay', str(tmp_path / 'in'), str(tmp_path / 'out'), '--no-progress']
    assert main([*args, '--torque-source', 'engine']) == 0
    out = capsys.readouterr().out
    assert 'torque path: engine torque and gear' in out and '% of samples' in out
    assert main(['replay', str(tmp_path / 'in'), str(tmp_path / 'o2'), '--no-progress']) == 0
    assert 'torque path: measured wheel torques' in capsys.readouterr().out
