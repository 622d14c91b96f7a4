"""numba's njit with the project's settings, typed so mypy --strict keeps the signatures.

numba keys a function's on-disk cache on the file that defines it, not on the functions it
calls nor on the module constants it bakes in: a kernel of ``chain.py`` that calls a changed
function of ``estimation.py``, or reads a changed constant of ``estimation/drivetrain.py``,
would load stale machine code (the replay then silently runs the old estimator).
`clear_stale_cache` removes the package's numba cache when anything compiled into it may have
changed, once per import: it keys the cache on every source file of the package (the step
functions, their callees, the constants they read), and the numba, numpy and Python versions.
``python -m vd_observer_node.chain`` (run by ``make setup``) then builds the cache anew.
"""

from __future__ import annotations

import hashlib
import importlib.machinery
import importlib.util
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar, cast


def _load_blas_module_alone() -> None:
    """Load ``scipy.linalg.cython_blas`` without the ``scipy.linalg`` package around it.

    numba's ``numba.np.arraymath``, imported when the first kernel loads, imports that
    extension module only to learn that a BLAS is there. Imported the usual way it first runs
    ``scipy.linalg``'s package (0.1-0.15 s, a tenth of a short `vd replay`'s start; our
    kernels call no BLAS, nor does the replay need scipy.linalg). Loaded alone (3 ms) and
    registered under its name, numba finds it there and says BLAS is available (np.dot in a
    kernel works, tested); ``import scipy.linalg`` stays what it is. Anything unexpected (no
    scipy, another layout) leaves the import to numba.
    """
    name = 'scipy.linalg.cython_blas'
    if name in sys.modules or 'scipy.linalg' in sys.modules:
        return
    try:
        scipy = importlib.util.find_spec('scipy')
        if scipy is None or not scipy.submodule_search_locations:
            return
        folder = Path(next(iter(scipy.submodule_search_locations))) / 'linalg'
        for suffix in importlib.machinery.EXTENSION_SUFFIXES:
            path = folder / f'cython_blas{suffix}'
            if path.is_file():
                loader = importlib.machinery.ExtensionFileLoader(name, str(path))
                spec = importlib.util.spec_from_file_location(name, path, loader=loader)
                if spec is None:
                    return
                module = importlib.util.module_from_spec(spec)
                loader.exec_module(module)
                sys.modules[name] = module
                return
    except Exception:  # numba then imports it its own way
        sys.modules.pop(name, None)


_load_blas_module_alone()


def _import_numba_without_coverage() -> None:
    """Import numba without the ``coverage`` package where no coverage is being measured.

    numba imports ``coverage`` whenever it is installed (``numba.misc.coverage_support``), to
    report the lines of jitted code to a measurement running in the process: 38 ms of a short
    `vd replay`'s start on this project's venv, where pytest-cov installs it. A process that
    measures coverage imported it before numba (coverage starts before the code it measures),
    and numba then finds it as always; otherwise numba is told it is absent, as it is on a
    machine without it.
    """
    if 'coverage' in sys.modules or 'numba' in sys.modules:
        return
    sys.modules['coverage'] = None  # type: ignore[assignment]  # import coverage: ImportError
    try:
        import numba  # noqa: F401
    finally:
        del sys.modules['coverage']


_import_numba_without_coverage()

import numba  # noqa: E402 - after the BLAS module above
import numpy as np  # noqa: E402

__all__ = [
    'JIT_ENABLED',
    'PACKAGE',
    'FixedCall',
    'clear_stale_cache',
    'jit',
    'jit_inlined',
    'new_record',
    'new_records',
    'record_array',
    'sources_digest',
]

F = TypeVar('F', bound=Callable[..., Any])

#: Where `clear_stale_cache` records the digest of the sources the cache was built from.
STAMP_NAME = 'vd_kernel_sources.sha256'


def sources_digest(folder: Path) -> str:
    """SHA-256 of the relative paths and contents of the ``*.py`` files below `folder`
    (recursively), and of the numba, numpy and Python versions that compile them."""
    import platform

    import numpy

    digest = hashlib.sha256()
    for version in (numba.__version__, numpy.__version__, platform.python_version()):
        digest.update(version.encode())
    for path in sorted(folder.rglob('*.py')):
        digest.update(path.relative_to(folder).as_posix().encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def clear_stale_cache(package: Path) -> bool:
    """Delete numba's cache files in every ``__pycache__`` below `package` unless they were
    built from the sources below `package` as they are now; returns whether it did.

    The compiled functions live in several modules of the package (each concept's module holds
    its own step functions), and a caller bakes in its callees and their module constants: the
    cache is one, keyed on every source. Best effort: a tree that cannot be written (a
    read-only install) is left alone, as numba then caches elsewhere or not at all.
    """
    cache = package / '__pycache__'
    stamp = cache / STAMP_NAME
    digest = sources_digest(package)
    try:
        if stamp.read_text(encoding='ascii') == digest:
            return False
    except OSError:
        pass
    try:
        for path in package.rglob('__pycache__/*.nb[ic]'):
            path.unlink(missing_ok=True)
        cache.mkdir(exist_ok=True)
        stamp.write_text(digest, encoding='ascii')
    except OSError:
        return False
    return True


#: the package whose sources are compiled (its compiled functions, their callees, constants)
PACKAGE = Path(__file__).resolve().parent.parent
#: ``VD_JIT=0`` runs every compiled function as the plain Python it is written in (debugging,
#: coverage, a traceback with line numbers); anything else, or unset, compiles.
JIT_ENABLED = os.environ.get('VD_JIT', '1') != '0'
if JIT_ENABLED:
    clear_stale_cache(PACKAGE)


_RECORD_TYPES: dict[tuple[Any, bool], Any] = {}


def _register_record_typeof() -> None:
    """Type a record argument once per dtype, not on every call.

    numba types a numpy record argument (`np.record`, `np.void`) at every call by building
    its Record type from the dtype afresh: 250-1200 us for the estimator's records, so a
    wrapper's compiled step cost 50 us per call in dispatch alone (arrays take numba's fast
    path). The type depends on the dtype only (and its alignment), so it is cached here.
    """
    import numpy as np
    from numba.core.typing.typeof import typeof_impl
    from numba.np import numpy_support

    @typeof_impl.register(np.void)
    def _typeof_record(val: Any, c: Any) -> Any:
        dtype = val.dtype
        key = (dtype, bool(dtype.isalignedstruct))
        found = _RECORD_TYPES.get(key)
        if found is None:
            found = _RECORD_TYPES[key] = numpy_support.from_dtype(dtype)
        return found


if JIT_ENABLED:
    _register_record_typeof()


def jit(fn: F) -> F:
    """Compile `fn` in nopython mode, cached on disk (numba's cache=True), no fastmath.

    No fastmath: it would change NaN handling and the last bits the equality tests against
    the Python reference rely on. nogil: offline tools may run kernels in threads.
    """
    if not JIT_ENABLED:
        return fn
    return cast(F, numba.njit(cache=True, nogil=True)(fn))


def jit_inlined(fn: F) -> F:
    """`jit`, inlined into its compiled callers (numba's ``inline='always'``).

    For a step called once a stamp by its block's loop with the parts as NamedTuples of
    arrays: a call passes every array of them by value and counts a reference to each;
    inlined, the loop reads them in place (cascade + monitor offline: 16.7-19.8 us a sample
    called, 16.0-16.3 inlined, bench_kernel.py, paper_table1 / launch_low_mu, load 1.0).
    """
    if not JIT_ENABLED:
        return fn
    return cast(F, numba.njit(cache=True, nogil=True, inline='always')(fn))


def new_record(dtype: np.dtype[Any]) -> np.record:
    """A zeroed record of `dtype` (an ``np.record``: fields read and written as attributes,
    compiled or not), living in a 1-element array (`record_array` gives it back)."""
    record: np.record = new_records(dtype, 1)[0]
    return record


def new_records(dtype: np.dtype[Any], n: int) -> Any:
    """N zeroed records of `dtype` as a plain ndarray whose elements are ``np.record``s:
    fields read as attributes by the plain Python source (``VD_JIT=0``) as by numba."""
    return np.zeros(n, dtype).view(np.recarray).view(np.ndarray)


def record_array(record: Any) -> Any:
    """The 1-element structured array a record (`np.zeros(1, dtype).view(np.recarray)[0]`)
    lives in, as a plain ndarray sharing its memory.

    The compiled functions called from Python once per stamp take their records this way and
    index ``[0]``: numba types an array argument on its fast path (two records as arguments
    cost 53 us a call, two such arrays 1.4 us, measured).

    Raises:
        TypeError: `record` is not a view into a 1-element array (a copy, say).
    """
    base = record.base
    if getattr(base, 'shape', None) != (1,):
        raise TypeError('record_array needs a record made as np.zeros(1, dtype)...[0]')
    return base.view(type=np.ndarray)


class FixedCall:
    """A compiled function called with the same leading arguments (its parts, built once) and
    trailing arrays of one layout, without numba's typing of every argument at every call.

    numba types each argument of each call: arrays take a fast path, but a NamedTuple of
    parts does not (26 us a call for the situation monitor's parts, inputs and outputs, 11 us
    here, measured). The machine code for the arguments' types is looked up once; each call
    compares numba's own fingerprint of the trailing arguments (dtype, dimensions, layout,
    writeability: what numba's dispatcher keys its types on) with the first call's, and one
    that differs goes through numba's dispatcher as usual: a call never runs on code compiled
    for other types. With ``VD_JIT=0`` it calls the plain Python function.
    """

    def __init__(self, fn: Callable[..., Any], fixed: tuple[Any, ...], example: tuple[Any, ...]):
        """Compile (or load) `fn` for ``fn(*fixed, *example)`` and keep its machine code.

        Args:
            fn: a `jit` function.
            fixed: the leading arguments every call passes (the same objects).
            example: trailing arguments of the layout the calls will pass (copies are used).
        """
        self.fn = fn
        self.fixed = fixed
        self._entry: Callable[..., Any] | None = None
        if not JIT_ENABLED:
            return
        from numba._dispatcher import compute_fingerprint
        from numba.core.typing.typeof import Purpose, typeof

        self._fingerprint = compute_fingerprint
        self._expected = compute_fingerprint(example)

        copies = tuple(_copied(item) for item in (*fixed, *example))
        fn(*copies)
        signature = tuple(
            typeof(item, Purpose.argument)  # type: ignore[no-untyped-call]
            for item in (*fixed, *example)
        )
        overloads = getattr(fn, 'overloads', {})
        found = overloads.get(signature)
        self._entry = found.entry_point if found is not None else None

    def __call__(self, *trailing: Any) -> Any:
        """``fn(*fixed, *trailing)``."""
        if self._entry is not None and self._fingerprint(trailing) == self._expected:
            return self._entry(*self.fixed, *trailing)
        return self.fn(*self.fixed, *trailing)


def _copied(value: Any) -> Any:
    """A deep copy of an array or a (Named)tuple of them."""
    if isinstance(value, tuple):
        items = [_copied(item) for item in value]
        return type(value)(*items) if hasattr(value, '_fields') else tuple(items)
    return value.copy()
