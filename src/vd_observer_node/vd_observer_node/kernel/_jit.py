"""numba's njit with the project's settings, typed so mypy --strict keeps the signatures.

numba keys a function's on-disk cache on the file that defines it, not on the functions it
calls nor on the module constants it bakes in: a kernel of ``chain.py`` that calls a changed
function of ``estimation.py``, or reads a changed constant of ``estimation/drivetrain.py``,
would load stale machine code (the replay then silently runs the old estimator).
`clear_stale_cache` removes the kernels' cache when anything compiled into it may have
changed, once per import: it keys the cache on every source file of the package (kernels,
the reference modules whose constants they read), and the numba, numpy and Python versions.
``python -m vd_observer_node.kernel`` (run by ``make setup``) then builds the cache anew.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar, cast

import numba

__all__ = ['KERNELS', 'PACKAGE', 'clear_stale_cache', 'jit', 'sources_digest']

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


def clear_stale_cache(kernels: Path, sources: Path | None = None) -> bool:
    """Delete numba's cache files in ``kernels/__pycache__`` unless they were built from the
    sources below `sources` (default: `kernels`) as they are now; returns whether it did.

    Best effort: a folder that cannot be written (a read-only install) is left alone, as
    numba then caches elsewhere or not at all.
    """
    cache = kernels / '__pycache__'
    stamp = cache / STAMP_NAME
    digest = sources_digest(sources or kernels)
    try:
        if stamp.read_text(encoding='ascii') == digest:
            return False
    except OSError:
        pass
    try:
        for path in cache.glob('*.nb[ic]'):
            path.unlink(missing_ok=True)
        cache.mkdir(exist_ok=True)
        stamp.write_text(digest, encoding='ascii')
    except OSError:
        return False
    return True


#: the kernels' folder, and the package whose sources are compiled into them
KERNELS = Path(__file__).resolve().parent
PACKAGE = KERNELS.parent
clear_stale_cache(KERNELS, PACKAGE)


def jit(fn: F) -> F:
    """Compile `fn` in nopython mode, cached on disk (numba's cache=True), no fastmath.

    No fastmath: it would change NaN handling and the last bits the equality tests against
    the Python reference rely on. nogil: offline tools may run kernels in threads.
    """
    return cast(F, numba.njit(cache=True, nogil=True)(fn))
