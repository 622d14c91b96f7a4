"""The ament layout is right, so `ros2 run` / `ros2 launch` find our nodes on a ROS install."""

from __future__ import annotations

import ast
import importlib.util
import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PYTHON_PACKAGES = ['vd_common', 'vd_sim_node', 'vd_observer_node']
ALL_PACKAGES = ['vd_msgs', *PYTHON_PACKAGES]


def setup_py_kwargs(pkg: str) -> dict[str, object]:
    """The literal keyword arguments of setup() in src/<pkg>/setup.py (without running it)."""
    tree = ast.parse((ROOT / 'src' / pkg / 'setup.py').read_text())
    consts = {
        t.id: ast.literal_eval(n.value)
        for n in tree.body
        if isinstance(n, ast.Assign)
        for t in n.targets
        if isinstance(t, ast.Name) and isinstance(n.value, ast.Constant)
    }
    call = next(
        n
        for n in ast.walk(tree)
        if isinstance(n, ast.Call) and getattr(n.func, 'id', '') == 'setup'
    )
    out: dict[str, object] = {}
    for kw in call.keywords:
        if isinstance(kw.value, ast.Name) and kw.value.id in consts:
            out[str(kw.arg)] = consts[kw.value.id]
        else:
            try:
                out[str(kw.arg)] = ast.literal_eval(kw.value)
            except ValueError:
                continue
    return out


def console_scripts(pkg: str) -> dict[str, str]:
    entry_points = setup_py_kwargs(pkg).get('entry_points', {})  # vd_common has none
    assert isinstance(entry_points, dict)
    scripts = {}
    for line in entry_points.get('console_scripts', []):
        name, target = (s.strip() for s in line.split('='))
        scripts[name] = target
    return scripts


@pytest.mark.parametrize('pkg', ALL_PACKAGES)
def test_package_xml_is_format_3_with_a_valid_maintainer(pkg: str) -> None:
    root = ET.parse(ROOT / 'src' / pkg / 'package.xml').getroot()
    assert root.get('format') == '3'
    assert root.findtext('name') == pkg
    maintainer = root.find('maintainer')
    assert maintainer is not None and '@' in maintainer.get('email', '')


@pytest.mark.parametrize('pkg', PYTHON_PACKAGES)
def test_package_xml_and_setup_py_agree_on_name_and_version(pkg: str) -> None:
    root = ET.parse(ROOT / 'src' / pkg / 'package.xml').getroot()
    kwargs = setup_py_kwargs(pkg)
    assert kwargs['name'] == root.findtext('name') == pkg
    assert kwargs['version'] == root.findtext('version')
    assert root.findtext('export/build_type') == 'ament_python'


def run_dependencies(pkg: str) -> set[str]:
    """What `pkg` needs installed to run (and to build): package.xml's non-test dependencies."""
    root = ET.parse(ROOT / 'src' / pkg / 'package.xml').getroot()
    tags = ('depend', 'exec_depend', 'build_depend', 'build_export_depend', 'buildtool_depend')
    return {str(e.text).strip() for tag in tags for e in root.findall(tag)}


@pytest.mark.parametrize('pkg', ['vd_sim_node', 'vd_observer_node'])
def test_the_simulator_and_the_estimator_depend_on_vd_common(pkg: str) -> None:
    """Declared in package.xml (colcon builds vd_common first) and in setup.py."""
    assert 'vd_common' in run_dependencies(pkg)
    install_requires = setup_py_kwargs(pkg)['install_requires']
    assert isinstance(install_requires, list) and 'vd_common' in install_requires


def test_vd_common_depends_on_no_other_vd_package() -> None:
    assert not {d for d in run_dependencies('vd_common') if d.startswith('vd_')}
    assert 'vd_common' not in run_dependencies('vd_msgs')


@pytest.mark.parametrize('pkg', PYTHON_PACKAGES)
def test_setup_cfg_installs_scripts_where_ros2_run_looks(pkg: str) -> None:
    text = (ROOT / 'src' / pkg / 'setup.cfg').read_text()
    assert f'script_dir=$base/lib/{pkg}' in text
    assert f'install_scripts=$base/lib/{pkg}' in text
    assert (ROOT / 'src' / pkg / 'resource' / pkg).is_file()


@pytest.mark.parametrize('pkg', ALL_PACKAGES)
def test_package_is_registered_in_the_ament_index(pkg: str, install_dir: Path) -> None:
    marker = install_dir / pkg / 'share' / 'ament_index' / 'resource_index' / 'packages' / pkg
    assert marker.is_file()
    assert (install_dir / pkg / 'share' / pkg / 'package.xml').is_file()


@pytest.mark.parametrize(
    ('pkg', 'exe'),
    [(pkg, exe) for pkg in PYTHON_PACKAGES for exe in console_scripts(pkg)],
)
def test_console_script_is_installed_and_its_module_exists(
    pkg: str, exe: str, install_dir: Path
) -> None:
    path = install_dir / pkg / 'lib' / pkg / exe
    assert path.is_file(), f'{path} missing: `ros2 run {pkg} {exe}` would not find it'
    assert os.access(path, os.X_OK)
    module, _, func = console_scripts(pkg)[exe].partition(':')
    spec = importlib.util.find_spec(module)
    assert spec is not None and spec.origin is not None, f'{module} does not exist'
    tree = ast.parse(Path(spec.origin).read_text())
    assert any(isinstance(n, ast.FunctionDef) and n.name == func for n in tree.body)


@pytest.mark.parametrize('pkg', PYTHON_PACKAGES)
def test_config_and_launch_files_are_installed(pkg: str, install_dir: Path) -> None:
    for sub in ('config', 'launch'):
        src_files = sorted(
            p.relative_to(ROOT / 'src' / pkg)
            for p in (ROOT / 'src' / pkg / sub).rglob('*')
            if p.is_file() and (p.suffix == '.yaml' or p.name.endswith('.launch.py'))
        )
        for rel in src_files:
            assert (install_dir / pkg / 'share' / pkg / rel).is_file(), f'{rel} not installed'


def test_vd_msgs_python_bindings_are_importable() -> None:
    from vd_msgs.msg import WheelAngles

    msg = WheelAngles()
    assert (msg.FL, msg.FR, msg.RL, msg.RR) == (0, 1, 2, 3)
    assert len(msg.angle) == 4


def test_parameter_files_match_the_declared_parameters() -> None:
    """config/<node>.yaml are generated from the nodes' declarations and must be current."""
    result = subprocess.run(
        [sys.executable, str(ROOT / 'scripts' / 'gen_param_files.py'), '--check'],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stdout + result.stderr


#: third-party modules the ROS-free bag core imports: pip name (requirements/python.in) and
#: rosdep key (package.xml; None: no rosdep key exists, pip only)
BAG_CORE_IMPORTS = {
    'numpy': ('numpy', 'python3-numpy'),
    'yaml': ('pyyaml', 'python3-yaml'),
    'zstandard': ('zstandard', 'python3-zstandard'),
    'lz4': ('lz4', 'python3-lz4'),
    'rosbags': ('rosbags', None),
}


def test_bag_core_imports_are_declared_dependencies() -> None:
    """Every third-party module vd_observer_node.bag imports is declared, not inherited.

    zstandard and lz4 once arrived only through `mcap`; the bag core's codec imports them
    itself, so they are listed in requirements/python.in and package.xml in their own right.
    """
    bag = ROOT / 'src' / 'vd_observer_node' / 'vd_observer_node' / 'bag'
    imported: set[str] = set()
    for path in bag.glob('*.py'):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                imported.update(alias.name.split('.')[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                imported.add(node.module.split('.')[0])
    third_party = {
        name
        for name in imported
        if name not in sys.stdlib_module_names
        and name not in ('vd_observer_node', 'vd_common', 'vd_sim_node')
    }
    # ament_index_python: optional (a ROS install brings it; the core works without it)
    third_party.discard('ament_index_python')
    assert third_party == set(BAG_CORE_IMPORTS), 'update BAG_CORE_IMPORTS and the declarations'
    requirements = {
        line.split('#')[0].strip().lower()
        for line in (ROOT / 'requirements' / 'python.in').read_text().splitlines()
    }
    lock = {
        line.split('==')[0].strip().lower()
        for line in (ROOT / 'requirements' / 'lock-kilted-py311.txt').read_text().splitlines()
        if '==' in line
    }
    root = ET.parse(ROOT / 'src' / 'vd_observer_node' / 'package.xml').getroot()
    exec_depends = {e.text for e in root.findall('exec_depend')}
    for module, (pip_name, rosdep_key) in BAG_CORE_IMPORTS.items():
        assert pip_name in requirements, f'{module}: {pip_name} not in requirements/python.in'
        assert pip_name in lock, f'{module}: {pip_name} not pinned in the lock'
        if rosdep_key is not None:
            assert rosdep_key in exec_depends, f'{module}: {rosdep_key} not in package.xml'


def test_test_modules_have_unique_names() -> None:
    """pytest imports test files by their basename (no __init__.py in the test folders): two
    files of one name in different folders stop the whole collection ('import file mismatch')."""
    folders = [ROOT / 'tests', *(ROOT / 'src' / pkg / 'test' for pkg in PYTHON_PACKAGES)]
    seen: dict[str, Path] = {}
    clashes = []
    for folder in folders:
        for path in sorted(folder.glob('test_*.py')):
            if path.name in seen:
                clashes.append(f'{path.relative_to(ROOT)} and {seen[path.name].relative_to(ROOT)}')
            seen[path.name] = path
    assert clashes == []
