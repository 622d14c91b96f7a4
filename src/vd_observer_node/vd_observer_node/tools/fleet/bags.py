"""Which bags a fleet run processes: folders, glob patterns and list files of paths.

A folder that holds a ``metadata.yaml`` is one bag (rosbag2's layout, split files
included); any other folder is searched (recursively, in sorted order, following symbolic
links to folders, each real folder once) for bag folders and loose ``.mcap`` files, each of
which is a bag of its own. A pattern with ``*``, ``?`` or
``[`` that names no existing path is expanded with :func:`glob.glob` (``**`` recursive).
List files hold one path, folder or pattern per line (``#`` starts a comment; relative
paths are relative to the list file).

A path that does not exist is kept: the run reports it as a failed bag ("no such bag")
rather than losing it silently among hundreds.
"""

from __future__ import annotations

import glob
import os
from collections.abc import Iterable, Sequence
from pathlib import Path

from vd_observer_node.tools.fleet.errors import FleetInputError

__all__ = ['find_bags', 'is_bag', 'read_bag_list']

_GLOB_CHARS = frozenset('*?[')


def is_bag(path: Path) -> bool:
    """True for a ``.mcap`` file or a folder with a ``metadata.yaml``."""
    if path.is_file():
        return path.suffix == '.mcap'
    return (path / 'metadata.yaml').is_file()


def _bags_under(folder: Path) -> list[Path]:
    found: list[Path] = []
    seen: set[str] = set()
    # symlinked folders are followed (a fleet is often a folder of links to the drives);
    # each real folder is walked once, so a link back up the tree ends there
    for root, dirs, _ in os.walk(folder, followlinks=True):
        here = Path(root)
        real = os.path.realpath(here)
        if real in seen:
            dirs[:] = []
            continue
        seen.add(real)
        if is_bag(here):
            found.append(here)
            dirs[:] = []  # a bag folder's insides are its files, not more bags
            continue
        dirs.sort()
        found.extend(sorted(p for p in here.glob('*.mcap') if p.is_file()))
    return found


def _expand(spec: str, base: Path | None) -> list[Path]:
    path = Path(spec).expanduser()
    if base is not None and not path.is_absolute():
        path = base / path
    if path.exists():
        return [path] if is_bag(path) else _bags_under(path)
    if _GLOB_CHARS & set(spec):
        matches = sorted(Path(m) for m in glob.glob(str(path), recursive=True))
        out: list[Path] = []
        for match in matches:
            out.extend([match] if is_bag(match) else _bags_under(match) if match.is_dir() else [])
        return out
    return [path]  # missing: reported as a failed bag, not dropped


def read_bag_list(path: str | os.PathLike[str]) -> list[str]:
    """Entries of a list file (one path, folder or pattern per line; ``#`` comments).

    Raises:
        FleetInputError: the file cannot be read.
    """
    try:
        text = Path(path).read_text(encoding='utf-8')
    except (OSError, UnicodeDecodeError) as exc:
        raise FleetInputError(f'{path}: cannot read the bag list: {exc}') from exc
    entries = []
    for line in text.splitlines():
        entry = line.split('#', 1)[0].strip()
        if entry:
            entries.append(entry)
    return entries


def find_bags(
    specs: Sequence[str | os.PathLike[str]] = (),
    list_files: Iterable[str | os.PathLike[str]] = (),
) -> list[Path]:
    """Bags named by folders, patterns, paths and list files, each once, in the order given.

    Args:
        specs: bag folders, ``.mcap`` files, folders of bags, or glob patterns.
        list_files: text files listing such entries, one a line.

    Returns:
        Bag paths (absolute, normalised), duplicates removed (first occurrence kept).

    Raises:
        FleetInputError: a list file cannot be read, or nothing at all was named.
    """
    named: list[tuple[str, Path | None]] = [(os.fspath(s), None) for s in specs]
    for list_file in list_files:
        folder = Path(list_file).resolve().parent
        named.extend((entry, folder) for entry in read_bag_list(list_file))
    if not named:
        raise FleetInputError('no bags named (give folders, .mcap files, patterns or --list)')
    out: list[Path] = []
    seen: set[Path] = set()
    for spec, base in named:
        for bag in _expand(spec, base):
            key = Path(os.path.normpath(bag.absolute()))  # 'lists/../a' is 'a'
            if key not in seen:
                seen.add(key)
                out.append(key)
    return out
