"""The ``vd`` command: bag info, bag repair, replay, and one-line errors with exit status 2."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from types import ModuleType

import pytest
from vd_common.topics import ESTIMATES_TIRE_FORCES, SENSORS_WHEEL_ANGLES
from vd_observer_node.bag import BagReader
from vd_observer_node.testing.synthetic_bags import write_synthetic_drive_bag
from vd_observer_node.tools.cli import main


@pytest.fixture
def drive_bag(tmp_path: Path) -> Path:
    write_synthetic_drive_bag(tmp_path / 'drive', duration_s=1.0, rate_hz=100.0)
    return tmp_path / 'drive'


def test_bag_info(drive_bag: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(['bag', 'info', str(drive_bag)]) == 0
    out = capsys.readouterr().out
    assert 'Messages:  500' in out
    assert SENSORS_WHEEL_ANGLES in out and 'vd_msgs/msg/WheelAngles' in out
    assert 'Duration:  0.990 s' in out


def test_corrupt_bag_one_line_error_then_repair(
    drive_bag: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    mcap = drive_bag / 'drive_0.mcap'
    mcap.write_bytes(mcap.read_bytes()[: mcap.stat().st_size // 2])
    assert main(['bag', 'info', str(drive_bag)]) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and err.startswith('vd: error: ')
    assert 'drive_0.mcap' in err and 'vd bag repair' in err
    assert main(['bag', 'info', '--recover', str(drive_bag)]) == 0
    assert capsys.readouterr().out.count('Damage:') == 1  # one truncation, reported once
    assert main(['bag', 'repair', str(drive_bag)]) == 0
    out = capsys.readouterr().out
    assert 'recovered' in out and 'original kept as' in out
    assert main(['bag', 'info', str(drive_bag)]) == 0


def test_replay(drive_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out_bag = tmp_path / 'est'
    assert main(['replay', '--no-progress', str(drive_bag), str(out_bag)]) == 0
    assert 'replayed 100 samples' in capsys.readouterr().out
    assert BagReader(out_bag).topics[ESTIMATES_TIRE_FORCES].message_count == 100


@pytest.mark.parametrize(
    'argv',
    [
        ['bag', 'info', '/nonexistent/bag'],
        ['bag', 'repair', '/nonexistent/bag'],
        ['replay', '/nonexistent/in', '/tmp/vd-never-written'],
    ],
)
def test_bad_paths_exit_2_without_traceback(
    argv: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith('vd: error: ') and 'Traceback' not in err
    assert err.count('\n') == 1


def test_existing_output_and_bad_vehicle(
    drive_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(['replay', '--no-progress', str(drive_bag), str(drive_bag)]) == 2
    assert 'already exists' in capsys.readouterr().err
    bad = tmp_path / 'vehicle.yaml'
    bad.write_text('chassis: {mass: -1}\n')
    argv = ['replay', '--no-progress', '--vehicle', str(bad), str(drive_bag), str(tmp_path / 'o')]
    assert main(argv) == 2
    assert capsys.readouterr().err.startswith('vd: error: ')


def test_usage_error_exits_2(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(['bag'])
    assert exc.value.code == 2


def test_replay_with_config_file(
    drive_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    good = tmp_path / 'good.yaml'
    good.write_text('observer:\n  speed_lipschitz: 40.0\n')
    # 3 s at 100 Hz: longer than the stamps after which the slope filter follows the rate
    longer = tmp_path / 'longer'
    write_synthetic_drive_bag(longer, duration_s=3.0, rate_hz=100.0)
    argv = ['replay', '--no-progress', '--config', str(good), str(longer), str(tmp_path / 'a')]
    assert main(argv) == 0
    # what the run used and where each setting came from: the file, and the 100 Hz bag's rate
    settings = [x for x in capsys.readouterr().out.splitlines() if x.startswith('settings: ')]
    assert settings == [
        'settings: observer.speed_lipschitz=40 (good.yaml); '
        'estimator.slope_filter_tau=0.178 (input rate 100 Hz); the rest defaults'
    ]
    fixed = tmp_path / 'fixed.yaml'
    fixed.write_text('estimator:\n  slope_filter_tau: 0.1\n')
    argv = ['replay', '--no-progress', '--config', str(fixed), str(drive_bag), str(tmp_path / 'c')]
    assert main(argv) == 0
    assert 'settings: estimator.slope_filter_tau=0.1 (fixed.yaml); the rest defaults\n' in (
        capsys.readouterr().out
    )
    bad = tmp_path / 'bad.yaml'
    bad.write_text('observer: [1, 2]\n')
    argv = ['replay', '--no-progress', '--config', str(bad), str(drive_bag), str(tmp_path / 'b')]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith('vd: error: ') and 'must be a mapping' in err


def test_the_command_parser_imports_no_report_fleet_or_numpy() -> None:
    """``vd --help`` and ``vd bag info`` build the whole parser: the report and fleet packages
    give their sub-commands' parsers without importing their modules (`tools.lazy`), so the
    help prints in a tenth of a second instead of 0.75 s."""
    heavy = (
        'numpy',
        'vd_observer_node.tools.report.evaluation',
        'vd_observer_node.tools.fleet.process',
        'vd_observer_node.tools.replay',
    )
    code = (
        'import sys\n'
        'from vd_observer_node.tools.cli import _parser\n'
        '_parser()\n'
        f'print(sorted(m for m in {heavy!r} if m in sys.modules))\n'
    )
    out = subprocess.run(
        [sys.executable, '-c', code], capture_output=True, text=True, check=True
    ).stdout
    assert out.strip() == '[]', out


def test_the_packages_export_their_names_on_first_use() -> None:
    """The lazy exports give the functions and classes, also where their module was imported
    first (a submodule's name would shadow an export: the report's `evaluate` lives in
    `evaluation`); an unknown name is an AttributeError."""
    import vd_observer_node.tools.report.evaluation as evaluation
    from vd_observer_node.tools import fleet, report
    from vd_observer_node.tools.fleet.run import run_fleet

    assert report.evaluate is evaluation.evaluate and callable(report.evaluate)
    assert report.AccuracyReport is evaluation.AccuracyReport
    assert fleet.run_fleet is run_fleet
    for package in (report, fleet):  # every exported name resolves, none to a module
        assert not [n for n in package.__all__ if isinstance(getattr(package, n), ModuleType)]
    with pytest.raises(AttributeError, match='no attribute'):
        _ = report.no_such_name  # type: ignore[attr-defined]
