"""`vd replay` / `vd report` with ``--mapping`` and no ``--vehicle`` say that the Clio is used."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from vd_common.topics import SENSORS_BODY_VELOCITY, SENSORS_WHEEL_ANGLES, SENSORS_WHEEL_TORQUES
from vd_common.vehicle.params import default_vehicle_file
from vd_observer_node.testing.synthetic_bags import write_synthetic_drive_bag
from vd_observer_node.tools.cli import main

WARNING = (
    f'warning: no --vehicle: the shipped Renault Clio file ({default_vehicle_file()}) is used '
    "for this mapped bag; give your car's file with --vehicle (docs/vehicle_file.md)"
)


@pytest.fixture(scope='module')
def mapped_bag(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A 2 s drive without estimates and a mapping of its topics (vd's own types)."""
    folder = tmp_path_factory.mktemp('mapped')
    bag = folder / 'drive'
    write_synthetic_drive_bag(bag, 2.0, with_truth=False)
    mapping = folder / 'mapping.yaml'
    inputs = {
        'wheel_angles': (SENSORS_WHEEL_ANGLES, 'vd_msgs/msg/WheelAngles'),
        'body_speed': (SENSORS_BODY_VELOCITY, 'geometry_msgs/msg/TwistStamped'),
        'wheel_torques': (SENSORS_WHEEL_TORQUES, 'vd_msgs/msg/WheelTorques'),
    }
    data = {name: {'topic': topic, 'type': kind} for name, (topic, kind) in inputs.items()}
    mapping.write_text(yaml.safe_dump(data), encoding='utf-8')
    return bag, mapping


def test_replay_with_a_mapping_and_no_vehicle_warns_once(
    mapped_bag: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag, mapping = mapped_bag
    assert main(['replay', str(bag), str(tmp_path / 'a'), '--mapping', str(mapping)]) == 0
    assert capsys.readouterr().err.splitlines().count(WARNING) == 1
    vehicle = str(default_vehicle_file())
    args = ['replay', str(bag), str(tmp_path / 'b'), '--mapping', str(mapping)]
    assert main([*args, '--vehicle', vehicle]) == 0
    assert 'warning: no --vehicle' not in capsys.readouterr().err
    assert main(['replay', str(bag), str(tmp_path / 'c')]) == 0  # vd's own bag: the Clio's
    assert 'warning: no --vehicle' not in capsys.readouterr().err


def test_report_with_a_mapping_and_no_vehicle_warns_once(
    mapped_bag: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag, mapping = mapped_bag
    out = tmp_path / 'report'
    assert main(['report', str(bag), '--out', str(out), '--mapping', str(mapping)]) == 0
    captured = capsys.readouterr()
    assert captured.err.splitlines().count(WARNING) == 1
    args = ['report', str(bag), '--out', str(out), '--mapping', str(mapping)]
    assert main([*args, '--vehicle', str(default_vehicle_file())]) == 0
    assert 'warning: no --vehicle' not in capsys.readouterr().err
