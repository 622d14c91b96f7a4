"""numba's njit with the project's settings, typed so mypy --strict keeps the signatures.

numba keys a function's on-disk cache on the file that defines it, not on the functions it
calls: a kernel of ``chain.py`` that calls a changed function of ``estimation.py`` would load
stale machine code (the replay then silently runs the old estimator). `clear_stale_cache`
removes this folder's cache when any kernel source changed, once per import.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar, cast

import numba

__all__ = ['clear_stale_cache', 'jit', 'sources_digest']

F = TypeVar('F', bound=Callable[..., Any])

#: Where `clear_stale_cache` records the digest of the sources the cache was built from.
STAMP_NAME = 'vd_kernel_sources.sha256'


def sources_digest(folder: Path) -> str:
    """SHA-256 of the names and contents of the ``*.py`` files of `folder`."""
    digest = hashlib.sha256()
    for path in sorted(folder.glob('*.py')):
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def clear_stale_cache(folder: Path) -> bool:
    """Delete numba's cache files in ``folder/__pycache__`` unless they were built from the
    sources `folder` holds now; returns whether it deleted them.

    Best effort: a folder that cannot be written (a read-only install) is left alone, as
    numba then caches elsewhere or not at all.
    """
    cache = folder / '__pycache__'
    stamp = cache / STAMP_NAME
    digest = sources_digest(folder)
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


clear_stale_cache(Path(__file__).resolve().parent)


def jit(fn: F) -> F:
    """Compile `fn` in nopython mode, cached on disk (numba's cache=True), no fastmath.

    No fastmath: it would change NaN handling and the last bits the equality tests against
    the Python reference rely on. nogil: offline tools may run kernels in threads.
    """
    return cast(F, numba.njit(cache=True, nogil=True)(fn))
