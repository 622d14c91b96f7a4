"""The import graph reads top-down: each folder of a package imports only the folders below it.

Read from the source with `ast` (every import statement, also those inside functions), so a
lazy import cannot hide an upward dependency.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / 'src'

#: vd_observer_node's rooms and what each may import (besides itself and vd_common).
OBSERVER_LAYERS: dict[str, set[str]] = {
    'errors': set(),
    # numba's decorator with the project's settings (kernel/_jit.py): what every concept's
    # step functions are compiled with, so the rooms that compute may use it
    'jit': set(),
    # the offline writer's compiled byte copy (bag/copy_kernel.py)
    'bag': {'errors', 'jit'},
    'estimation': {'errors', 'jit'},
    'situation': {'errors', 'jit', 'estimation'},
    'inputs': {'errors', 'bag', 'estimation'},
    # the per-stamp chain picks its compiled twin, which implements the chain's interface
    'chain': {'errors', 'jit', 'estimation', 'situation', 'kernel'},
    'kernel': {'errors', 'jit', 'estimation', 'situation', 'chain'},
    'tools': {'errors', 'bag', 'inputs', 'jit', 'estimation', 'situation', 'chain', 'kernel'},
    'testing': {
        'errors',
        'bag',
        'inputs',
        'jit',
        'estimation',
        'situation',
        'chain',
        'kernel',
        'tools',
    },
    # thin nodes: the core and the node plumbing, never the offline tools or test helpers
    'nodes': {'errors', 'bag', 'inputs', 'jit', 'estimation', 'situation', 'chain', 'kernel'},
}
#: vd_sim_node's rooms (besides vd_common): the bond-graph core is a leaf, the vehicle model
#: sits on it, the node (sim_node and its entry point) on top.
SIM_LAYERS: dict[str, set[str]] = {
    'errors': set(),
    'lockstep': set(),
    'bondgraph': set(),
    'vehicle': {'errors', 'bondgraph'},
    'nodes': {'errors', 'lockstep', 'bondgraph', 'vehicle'},
}
#: vd_common's rooms: the base of the other two, it imports neither of them.
COMMON_LAYERS: dict[str, set[str]] = {
    'errors': set(),
    'topics': set(),
    'params_file': set(),
    'entry': set(),
    'yaml_reader': set(),
    'settings_log': set(),
    'vehicle': {'errors', 'yaml_reader'},
    'ros': {'errors', 'params_file', 'entry', 'settings_log'},
}
#: modules at a package's top level that belong to its nodes
_NODE_PLUMBING = {'entry'}
#: which packages each package may import
PACKAGES = {
    'vd_common': set(),
    'vd_sim_node': {'vd_common'},
    'vd_observer_node': {'vd_common'},
}


def _room(module: str, package: str) -> str | None:
    parts = module.split('.')
    if parts[-1] == '__init__':
        parts = parts[:-1]
    if parts[0] != package:
        return None
    if len(parts) == 1:
        return 'package'
    name = parts[1]
    if package == 'vd_observer_node' and parts[1:3] == ['kernel', '_jit']:
        return 'jit'
    if package == 'vd_common':
        return name
    if parts[1:3] == ['kernel', '_jit']:
        return 'jit'
    return 'nodes' if name.endswith('_node') or name in _NODE_PLUMBING else name


def _imports(path: Path) -> Iterator[str]:
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            if '.' in node.module:
                yield node.module
            else:  # `from package import module`: the room is the module's
                yield from (f'{node.module}.{alias.name}' for alias in node.names)
        elif isinstance(node, ast.Import):
            yield from (alias.name for alias in node.names)


def _modules(package: str, src: Path = SRC) -> list[Path]:
    return sorted((src / package / package).rglob('*.py'))


def _violations(package: str, layers: dict[str, set[str]], src: Path = SRC) -> list[str]:
    found = []
    for path in _modules(package, src):
        module = '.'.join(path.relative_to(src / package).with_suffix('').parts)
        room = _room(module, package)
        if room in (None, 'package'):
            continue
        assert room in layers, f'{module}: room {room!r} has no place in the layer table'
        for imported in _imports(path):
            target = _room(imported, package)
            if target is None or target == room:
                continue
            if target not in layers[room]:
                found.append(f'{module} imports {imported} ({room} -> {target})')
    return found


def test_vd_observer_node_imports_top_down() -> None:
    assert _violations('vd_observer_node', OBSERVER_LAYERS) == []


def test_vd_sim_node_imports_top_down() -> None:
    assert _violations('vd_sim_node', SIM_LAYERS) == []


def test_vd_common_imports_top_down() -> None:
    assert _violations('vd_common', COMMON_LAYERS) == []


@pytest.mark.parametrize(
    ('package', 'path'),
    [(package, path) for package in PACKAGES for path in _modules(package)],
    ids=lambda x: x if isinstance(x, str) else f'{x.parent.name}/{x.name}',
)
def test_packages_import_only_the_packages_below_them(package: str, path: Path) -> None:
    """vd_common imports no vd package; the simulator and the estimator only vd_common.

    Lazy imports inside functions count too: vd_observer_node must run without vd_sim_node
    installed (tests/test_standalone_estimator.py runs it so).
    """
    found = _foreign_imports(package, path)
    assert found == [], f'{path.name} imports {found}: allowed {sorted(PACKAGES[package])}'


def _foreign_imports(package: str, path: Path) -> list[str]:
    others = set(PACKAGES) - {package} - PACKAGES[package]
    return [m for m in _imports(path) if m.split('.')[0] in others]


def test_the_package_check_sees_a_lazy_import(tmp_path: Path) -> None:
    module = tmp_path / 'devbag.py'
    module.write_text(
        'def truth():\n'
        '    from vd_sim_node.vehicle.friction_truth import FrictionTruth\n'
        '    import vd_sim_node\n'
        '    from vd_common.vehicle import friction\n'
    )
    assert _foreign_imports('vd_observer_node', module) == [
        'vd_sim_node.vehicle.friction_truth',
        'vd_sim_node',
    ]
    assert _foreign_imports('vd_sim_node', module) == []


def test_the_layer_check_sees_a_violation(tmp_path: Path) -> None:
    """The checker itself: a bag module importing the estimation room is reported."""
    package = tmp_path / 'vd_observer_node' / 'vd_observer_node'
    (package / 'bag').mkdir(parents=True)
    (package / 'bag' / 'reader.py').write_text(
        'def f():\n    from vd_observer_node.estimation.cascade import run_cascade\n'
    )
    found = _violations('vd_observer_node', OBSERVER_LAYERS, tmp_path)
    assert found == [
        'vd_observer_node.bag.reader imports vd_observer_node.estimation.cascade '
        '(bag -> estimation)'
    ]
