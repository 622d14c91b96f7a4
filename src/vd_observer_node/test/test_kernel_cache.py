"""The package's numba cache is dropped when any of its sources changes (numba alone keys a
function's cache on its own file, so a caller would keep a changed callee's old code)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from vd_observer_node.kernel._jit import STAMP_NAME, clear_stale_cache, sources_digest


def _package(tmp_path: Path) -> Path:
    package = tmp_path / 'pkg'
    for sub in ('kernel', 'estimation'):
        (package / sub / '__pycache__').mkdir(parents=True)
    (package / 'kernel' / 'chain.py').write_text('def step(): return callee()\n', 'utf-8')
    (package / 'estimation' / 'drivetrain.py').write_text('EFFICIENCY = 0.9\n', 'utf-8')
    return package


def _cache_files(package: Path) -> list[Path]:
    files = [
        package / sub / '__pycache__' / f'm.step-1.py311.{ext}'
        for sub in ('kernel', 'estimation')
        for ext in ('nbi', '1.nbc')
    ]
    for path in files:
        path.write_bytes(b'compiled')
    return files


def test_a_changed_source_anywhere_drops_every_cache_and_no_change_keeps_it(
    tmp_path: Path,
) -> None:
    package = _package(tmp_path)
    assert clear_stale_cache(package)  # no stamp yet: whatever is there is of unknown sources
    files = _cache_files(package)
    assert not clear_stale_cache(package)
    assert all(path.exists() for path in files)
    before = sources_digest(package)
    # a constant outside the file that compiles it: numba's own check would miss it
    (package / 'estimation' / 'drivetrain.py').write_text('EFFICIENCY = 0.95\n', 'utf-8')
    assert sources_digest(package) != before
    assert clear_stale_cache(package)
    assert not any(path.exists() for path in files)
    stamp = package / '__pycache__' / STAMP_NAME
    assert stamp.read_text(encoding='ascii') == sources_digest(package)


def test_an_unwritable_cache_is_left_alone(tmp_path: Path) -> None:
    package = _package(tmp_path)
    (package / '__pycache__').write_text('not a folder', encoding='utf-8')
    assert not clear_stale_cache(package)


def test_the_installed_package_is_keyed_on_all_its_sources() -> None:
    from vd_observer_node.kernel import _jit

    stamp = _jit.PACKAGE / '__pycache__' / STAMP_NAME  # written at import: a writable tree
    assert stamp.read_text(encoding='ascii') == sources_digest(_jit.PACKAGE)


def test_vd_jit_0_runs_the_same_source_uncompiled() -> None:
    code = (
        'from vd_observer_node.kernel import _jit\n'
        'f = _jit.jit(lambda x: x + 1)\n'
        'print(_jit.JIT_ENABLED, type(f).__name__, f(1))\n'
    )
    env = dict(os.environ, VD_JIT='0')
    out = subprocess.run(
        [sys.executable, '-c', code], env=env, capture_output=True, text=True, check=True
    )
    assert out.stdout.split() == ['False', 'function', '2']


def _compiled_python(code: str) -> str:
    """What ``code`` prints in a new process with the kernels compiled (``VD_JIT=1``)."""
    env = {**os.environ, 'VD_JIT': '1'}
    done = subprocess.run(
        [sys.executable, '-c', code], capture_output=True, text=True, env=env, timeout=300
    )
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_numba_finds_blas_without_scipy_linalg_and_scipy_linalg_still_works() -> None:
    """`_jit` loads scipy's BLAS module alone before numba looks for it (start-up of a short
    replay): a kernel loads without importing scipy.linalg, numba still says BLAS is there and
    np.dot compiles, and scipy.linalg imported afterwards is whole."""
    code = '\n'.join(
        [
            'import sys',
            'import numpy as np',
            'import vd_observer_node.kernel._jit',
            'import numba',
            'from numba.np import arraymath',
            "assert 'scipy.linalg' not in sys.modules, 'scipy.linalg imported'",
            'assert arraymath._HAVE_BLAS',
            '@numba.njit',
            'def dot(a, b):',
            '    return np.dot(a, b)',
            'assert dot(np.eye(2), np.ones(2)).tolist() == [1.0, 1.0]',
            'import scipy.linalg',
            'from scipy.linalg import cython_blas',
            "assert cython_blas is sys.modules['scipy.linalg.cython_blas']",
            'assert scipy.linalg.solve(2.0 * np.eye(2), np.ones(2)).tolist() == [0.5, 0.5]',
            "print('ok')",
        ]
    )
    assert _compiled_python(code).strip() == 'ok'


@pytest.mark.parametrize('measured', [False, True])
def test_numba_imports_coverage_only_where_coverage_is_measured(measured: bool) -> None:
    """`_jit` imports numba without ``coverage`` (38 ms of a short replay's start where it is
    installed), unless the process imported it first, as a coverage measurement does: numba
    then reports jitted lines to it as always; and ``import coverage`` works afterwards."""
    pytest.importorskip('coverage')
    code = '\n'.join(
        [
            'import sys',
            *(['import coverage'] if measured else []),
            'import vd_observer_node.kernel._jit',
            'from numba.misc import coverage_support',
            "print(coverage_support.coverage_available, 'coverage' in sys.modules)",
            'import coverage',
            'print(coverage.Coverage is not None)',
        ]
    )
    assert _compiled_python(code).split() == [str(measured), str(measured), 'True']
