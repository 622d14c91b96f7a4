"""The estimator stands alone: vd_observer_node runs where vd_sim_node is not installed.

A user running the estimator on a real car installs vd_msgs, vd_common and vd_observer_node,
not the simulator. Each check here runs in a fresh Python whose import system refuses
vd_sim_node (a `sys.meta_path` finder installed before anything else is imported, so the
simulator's copy in install/ cannot be found either), imports every module of
vd_observer_node, the nodes included, and runs ``vd replay`` on the reference bag. Any
attempt to import the simulator is recorded, also one that the code caught and survived.
The simulator remains the tests' oracle: vd_observer_node's package.xml declares it as a
test dependency only, which is checked here too.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BAG = ROOT / 'bags' / 'paper_table1_100hz'
PACKAGE = 'vd_observer_node'

#: Installed as sitecustomize, so it is in place before the script's first import.
REFUSE_SIMULATOR = """
import importlib.abc
import sys


class RefuseSimulator(importlib.abc.MetaPathFinder):
    # refuses vd_sim_node, wherever it is installed, and notes every attempt

    attempts = []

    def find_spec(self, name, path=None, target=None):
        if name == 'vd_sim_node' or name.startswith('vd_sim_node.'):
            RefuseSimulator.attempts.append(name)
            message = f'No module named {name!r} (refused: no simulator)'
            raise ModuleNotFoundError(message, name=name)
        return None


sys.meta_path.insert(0, RefuseSimulator())
"""

#: Imports every module of vd_observer_node found on disk, then runs `vd` with argv[2:].
IMPORT_ALL_AND_RUN = """
import importlib
import json
import pkgutil
import sys
from pathlib import Path

import sitecustomize

import vd_observer_node

root = Path(vd_observer_node.__file__).parent
on_disk = sorted(
    '.'.join(('vd_observer_node', *p.relative_to(root).with_suffix('').parts)).removesuffix(
        '.__init__'
    )
    for p in root.rglob('*.py')
    if '__pycache__' not in p.parts
)
walk_errors = []
walked = sorted(
    info.name
    for info in pkgutil.walk_packages(
        vd_observer_node.__path__, 'vd_observer_node.', onerror=walk_errors.append
    )
)
imported = {}
failed = {}
for name in ['vd_observer_node', *walked]:
    try:
        imported[name] = importlib.import_module(name).__file__
    except Exception as exc:  # noqa: BLE001 (reported, not skipped)
        failed[name] = f'{type(exc).__name__}: {exc}'
status = None
if len(sys.argv) > 2:
    from vd_observer_node.tools.cli import main

    status = main(sys.argv[2:])
print(json.dumps({
    'root': str(root),
    'on_disk': on_disk,
    'walked': ['vd_observer_node', *walked],
    'walk_errors': walk_errors,
    'imported': imported,
    'failed': failed,
    'status': status,
    'attempts': sitecustomize.RefuseSimulator.attempts,
    'loaded': sorted(m for m in sys.modules if m.split('.')[0] == 'vd_sim_node'),
}))
"""


def run_without_simulator(tmp_path: Path, source_tree: bool, *vd_args: str) -> dict[str, object]:
    """Run IMPORT_ALL_AND_RUN in a Python that refuses vd_sim_node; return its report.

    Args:
        tmp_path: scratch folder (holds the sitecustomize).
        source_tree: import vd_observer_node and vd_common from src/ (else the install).
        vd_args: arguments of ``vd`` to run after the imports (none: only import).
    """
    hook = tmp_path / 'refuse_simulator'
    hook.mkdir(exist_ok=True)
    (hook / 'sitecustomize.py').write_text(REFUSE_SIMULATOR, encoding='utf-8')
    paths = [str(hook)]
    if source_tree:
        paths += [str(ROOT / 'src' / 'vd_observer_node'), str(ROOT / 'src' / 'vd_common')]
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join([*paths, env.get('PYTHONPATH', '')])
    script = tmp_path / 'import_all_and_run.py'
    script.write_text(IMPORT_ALL_AND_RUN, encoding='utf-8')
    result = subprocess.run(
        [sys.executable, str(script), 'vd', *vd_args],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        timeout=600,
    )
    assert result.returncode == 0, result.stderr[-4000:]
    report: dict[str, object] = json.loads(result.stdout.strip().splitlines()[-1])
    return report


def check_report(report: dict[str, object], where: Path) -> None:
    """Every module on disk was walked and imported from `where`, none touched the simulator."""
    assert Path(str(report['root'])) == where / PACKAGE
    on_disk, walked = report['on_disk'], report['walked']
    assert isinstance(on_disk, list) and isinstance(walked, list)
    assert len(on_disk) > 80
    assert walked == on_disk, 'pkgutil did not walk every module on disk'
    assert report['walk_errors'] == []
    assert report['failed'] == {}
    imported = report['imported']
    assert isinstance(imported, dict) and sorted(imported) == on_disk
    assert all(Path(f).is_relative_to(where) for f in imported.values())
    for node in ('observer_node', 'estimator_node', 'alerts_node', 'pipeline_node'):
        assert f'{PACKAGE}.nodes.{node}' in imported
    assert report['attempts'] == [], 'vd_observer_node tried to import the simulator'
    assert report['loaded'] == []


def test_the_estimator_imports_and_replays_without_the_simulator(tmp_path: Path) -> None:
    """The source tree: every module imports, `vd replay` of the reference bag runs."""
    out = tmp_path / 'replayed'
    report = run_without_simulator(tmp_path, True, 'replay', str(BAG), str(out), '--no-progress')
    check_report(report, ROOT / 'src' / PACKAGE)
    assert report['status'] == 0
    from vd_common.topics import ESTIMATES_SLOPE, SENSORS_WHEEL_ANGLES
    from vd_observer_node.bag import BagReader

    replayed = BagReader(out)
    sensors = replayed.topics[SENSORS_WHEEL_ANGLES].message_count
    assert sensors == 15_001
    assert replayed.topics[ESTIMATES_SLOPE].message_count == sensors


def test_the_installed_estimator_imports_without_the_simulator(
    tmp_path: Path, install_dir: Path
) -> None:
    """What colcon installed: the same modules, found in install/ (vd_sim_node is there too)."""
    assert (install_dir / 'vd_sim_node').is_dir()  # refused although installed
    site = next((install_dir / PACKAGE / 'lib').glob('python3*/site-packages'))
    report = run_without_simulator(tmp_path, False)
    check_report(report, site)
    assert report['status'] is None


def test_the_refusal_works(tmp_path: Path) -> None:
    """The finder itself: the simulator is installed, yet cannot be imported."""
    hook = tmp_path / 'refuse_simulator'
    hook.mkdir()
    (hook / 'sitecustomize.py').write_text(REFUSE_SIMULATOR, encoding='utf-8')
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join([str(hook), env.get('PYTHONPATH', '')])
    code = 'import vd_sim_node.vehicle.simulation'
    result = subprocess.run(
        [sys.executable, '-c', code], capture_output=True, text=True, env=env, cwd=tmp_path
    )
    assert result.returncode != 0
    assert 'refused: no simulator' in result.stderr


def _dependencies(pkg: str) -> dict[str, set[str]]:
    root = ET.parse(ROOT / 'src' / pkg / 'package.xml').getroot()
    out: dict[str, set[str]] = {}
    for element in root:
        if element.tag.endswith('depend') and element.text:
            out.setdefault(element.tag, set()).add(element.text.strip())
    return out


@pytest.mark.parametrize(
    'tag', ['depend', 'build_depend', 'exec_depend', 'build_export_depend', 'buildtool_depend']
)
def test_the_estimator_package_needs_the_simulator_only_for_its_tests(tag: str) -> None:
    dependencies = _dependencies(PACKAGE)
    assert 'vd_sim_node' not in dependencies.get(tag, set())
    assert 'vd_sim_node' in dependencies['test_depend']
    assert 'vd_common' in dependencies['exec_depend']
