"""The kernels' disk cache is dropped when any kernel source changes (numba alone keys a
function's cache on its own file, so a caller would keep a changed callee's old code)."""

from __future__ import annotations

from pathlib import Path

from vd_observer_node.kernel._jit import STAMP_NAME, clear_stale_cache, sources_digest


def _folder(tmp_path: Path) -> Path:
    folder = tmp_path / 'kernel'
    (folder / '__pycache__').mkdir(parents=True)
    (folder / 'chain.py').write_text('def step(): return callee()\n', encoding='utf-8')
    (folder / 'estimation.py').write_text('def callee(): return 1\n', encoding='utf-8')
    return folder


def _cache_files(folder: Path) -> list[Path]:
    files = [folder / '__pycache__' / f'chain.step-1.py311.{ext}' for ext in ('nbi', '1.nbc')]
    for path in files:
        path.write_bytes(b'compiled')
    return files


def test_a_changed_callee_drops_the_cache_and_an_unchanged_one_keeps_it(tmp_path: Path) -> None:
    folder = _folder(tmp_path)
    assert clear_stale_cache(folder)  # no stamp yet: whatever is there is of unknown sources
    files = _cache_files(folder)
    assert not clear_stale_cache(folder)
    assert all(path.exists() for path in files)
    before = sources_digest(folder)
    (folder / 'estimation.py').write_text('def callee(): return 2\n', encoding='utf-8')
    assert sources_digest(folder) != before
    assert clear_stale_cache(folder)
    assert not any(path.exists() for path in files)
    stamp = folder / '__pycache__' / STAMP_NAME
    assert stamp.read_text(encoding='ascii') == sources_digest(folder)


def test_an_unwritable_cache_is_left_alone(tmp_path: Path) -> None:
    folder = _folder(tmp_path)
    (folder / '__pycache__').rmdir()
    (folder / '__pycache__').write_text('not a folder', encoding='utf-8')
    assert not clear_stale_cache(folder)


def test_a_changed_constant_outside_the_kernels_drops_the_cache(tmp_path: Path) -> None:
    # the compiled estimator bakes in constants of estimation/drivetrain.py: the cache is keyed
    # on the whole package, not only on the kernels' folder
    package = tmp_path / 'pkg'
    kernels = _folder(package)
    (package / 'estimation').mkdir()
    constants = package / 'estimation' / 'drivetrain.py'
    constants.write_text('EFFICIENCY = 0.9\n', encoding='utf-8')
    assert clear_stale_cache(kernels, package)
    files = _cache_files(kernels)
    assert not clear_stale_cache(kernels, package)
    constants.write_text('EFFICIENCY = 0.95\n', encoding='utf-8')
    assert clear_stale_cache(kernels, package)
    assert not any(path.exists() for path in files)


def test_the_installed_kernels_are_keyed_on_their_whole_package() -> None:
    from vd_observer_node.kernel import _jit

    assert _jit.KERNELS.parent == _jit.PACKAGE
    stamp = _jit.KERNELS / '__pycache__' / STAMP_NAME  # written at import: a writable tree
    assert stamp.read_text(encoding='ascii') == sources_digest(_jit.PACKAGE)
