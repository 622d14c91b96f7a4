"""A fleet of small synthetic bags for the fleet tests and ``scripts/bench_fleet.py``.

Good bags are synthetic drives (:func:`~.synthetic_bags.write_synthetic_drive_bag`, each with
its own seed); a damaged copy of one has bytes overwritten in the middle of its MCAP file (a
chunk CRC no longer matches), and a truncated one loses its last third (a recording cut off
by a crash, never repaired).
"""

from __future__ import annotations

import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path

from vd_observer_node.testing.synthetic_bags import write_synthetic_drive_bag

__all__ = ['TestFleet', 'corrupt_bag', 'truncate_bag', 'write_test_fleet']


def _mcap(bag: Path) -> Path:
    return next(bag.glob('*.mcap'))


def corrupt_bag(bag: str | os.PathLike[str]) -> None:
    """Overwrite 64 bytes in the middle of the bag's MCAP file (inside a chunk)."""
    path = _mcap(Path(bag))
    data = bytearray(path.read_bytes())
    middle = len(data) // 2
    data[middle : middle + 64] = bytes(b ^ 0xFF for b in data[middle : middle + 64])
    path.write_bytes(bytes(data))


def truncate_bag(bag: str | os.PathLike[str], keep: float = 2.0 / 3.0) -> None:
    """Cut the bag's MCAP file to ``keep`` of its size (no summary, no footer)."""
    path = _mcap(Path(bag))
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])


@dataclass
class TestFleet:
    """The bags written by :func:`write_test_fleet`.

    Attributes:
        folder: the folder holding every bag.
        good: bags that replay.
        corrupt: the bag with a damaged chunk (None if not asked for).
        truncated: the bag cut short (None if not asked for).
    """

    __test__ = False  # a helper, not a pytest test class

    folder: Path
    good: list[Path] = field(default_factory=list)
    corrupt: Path | None = None
    truncated: Path | None = None

    @property
    def bags(self) -> list[Path]:
        """Every bag, sorted by path (the order :func:`~vd_observer_node.tools.fleet.find_bags`
        lists a folder in)."""
        out = [*self.good, *(b for b in (self.corrupt, self.truncated) if b is not None)]
        return sorted(out)


def write_test_fleet(
    folder: str | os.PathLike[str],
    good: int = 4,
    *,
    duration_s: float = 2.0,
    rate_hz: float = 200.0,
    corrupt: bool = True,
    truncated: bool = True,
) -> TestFleet:
    """Write ``good`` synthetic drives (seeds 0, 1, ...) plus a corrupt and a truncated bag.

    Args:
        folder: folder to create the bags in (``drive_00``, ..., ``corrupt``, ``truncated``).
        good: number of good bags.
        duration_s: [s] of each drive.
        rate_hz: [Hz] sensor rate.
        corrupt: add a bag with a damaged chunk (a copy of drive 0).
        truncated: add a bag cut to two thirds (a copy of drive 1, or 0).
    """
    root = Path(folder)
    root.mkdir(parents=True, exist_ok=True)
    fleet = TestFleet(root)
    for k in range(good):
        bag = root / f'drive_{k:02d}'
        write_synthetic_drive_bag(bag, duration_s, rate_hz, seed=k)
        fleet.good.append(bag)
    if corrupt:
        fleet.corrupt = root / 'corrupt'
        _copy(fleet.good[0] if fleet.good else None, fleet.corrupt, duration_s, rate_hz)
        corrupt_bag(fleet.corrupt)
    if truncated:
        fleet.truncated = root / 'truncated'
        source = fleet.good[min(1, len(fleet.good) - 1)] if fleet.good else None
        _copy(source, fleet.truncated, duration_s, rate_hz)
        truncate_bag(fleet.truncated)
    return fleet


def _copy(source: Path | None, target: Path, duration_s: float, rate_hz: float) -> None:
    if source is None:
        write_synthetic_drive_bag(target, duration_s, rate_hz, seed=0)
    else:
        shutil.copytree(source, target)  # file names as metadata.yaml lists them
