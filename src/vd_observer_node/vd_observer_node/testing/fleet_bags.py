"""A fleet of small synthetic bags for the fleet tests and ``scripts/bench_fleet.py``.

Good bags are synthetic drives (:func:`~.synthetic_bags.write_synthetic_drive_bag`, each with
its own seed); a damaged copy of one has bytes overwritten in the middle of its MCAP file (a
chunk CRC no longer matches), and a truncated one loses its last third (a recording cut off
by a crash, never repaired).
"""

from __future__ import annotations

import os
import shutil
import signal
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from vd_common.topics import (
    ALERTS,
    ESTIMATES,
    ESTIMATES_ALERTS,
    OBSERVER,
    SENSORS,
    SENSORS_BODY_VELOCITY,
    SENSORS_WHEEL_ANGLES,
    SENSORS_WHEEL_TORQUES,
    TRUTH,
    TRUTH_BODY_ACCEL,
    TRUTH_BODY_VELOCITY,
    TRUTH_FRICTION,
    TRUTH_FRICTION_POTENTIAL,
    TRUTH_TIRE_FORCES,
    TRUTH_WHEEL_STATES,
)

from vd_observer_node.bag.alerts_cdr import encode_alerts
from vd_observer_node.bag.cdr_batch import encode_batch, flat_fields
from vd_observer_node.bag.writer import BagWriter
from vd_observer_node.testing.synthetic_bags import synthetic_drive, write_synthetic_drive_bag
from vd_observer_node.tools.fleet.process import FleetSettings, process_bag

#: A bag folder holding this file kills the worker process of :func:`process_or_die`.
DIE_MARKER = 'KILL_THE_WORKER'

__all__ = [
    'DIE_MARKER',
    'TestFleet',
    'corrupt_bag',
    'process_or_die',
    'truncate_bag',
    'write_recording_like_bag',
    'write_test_fleet',
]


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


def write_recording_like_bag(
    path: str | os.PathLike[str],
    duration_s: float,
    rate_hz: float = 1000.0,
    seed: int = 0,
    *,
    block_s: float = 10.0,
) -> int:
    """A bag laid out like a live recording of the demo: 20 topics at ``rate_hz``.

    The three sensor topics and the truth of wheel states, body acceleration and speed carry
    a synthetic drive, the true tyre forces, μ and friction potential plausible values; the
    other truth topics and the live observer, estimate and alert topics (which the replay
    does not read, but a recording holds) carry zeros. Written in
    blocks of ``block_s`` seconds, so a long bag needs little memory to make.

    Returns:
        Messages written.
    """
    drive = synthetic_drive(duration_s, rate_hz, seed)
    n = drive.stamp_ns.shape[0]
    fz = np.tile([3300.0, 3300.0, 2400.0, 2400.0], (n, 1))  # [N] a small car's static loads
    fx = drive.torque / 0.26
    given: dict[str, dict[str, np.ndarray]] = {
        SENSORS_WHEEL_ANGLES: {'angle': drive.angle},
        SENSORS_BODY_VELOCITY: {'twist.linear.x': drive.speed},
        SENSORS_WHEEL_TORQUES: {'torque': drive.torque},
        TRUTH_WHEEL_STATES: {
            'angle': drive.angle,
            'omega': drive.omega,
            'omega_dot': drive.omega_dot,
        },
        TRUTH_BODY_ACCEL: {'accel.linear.x': drive.accel},
        TRUTH_BODY_VELOCITY: {'twist.linear.x': drive.speed},
        TRUTH_TIRE_FORCES: {'fx': fx, 'fz': fz},
        TRUTH_FRICTION: {'mu': fx / fz, 'valid': np.ones((n, 4), dtype=bool)},
        TRUTH_FRICTION_POTENTIAL: {
            'mu_max': np.ones((n, 2)),
            'slip_peak': np.full((n, 2), 0.12),
            'confidence': np.ones((n, 2)),
        },
    }
    types = {**SENSORS, **TRUTH, **OBSERVER, **ESTIMATES, **ALERTS}
    names = list(types)
    block = max(1, round(block_s * rate_hz))
    written = 0
    with BagWriter(path) as writer:
        for name in names:
            writer.add_topic(name, types[name])
        for start in range(0, n, block):
            stop = min(start + block, n)
            stamps = drive.stamp_ns[start:stop]
            m = stop - start
            per_topic: list[list[bytes]] = []
            for name in names:
                if name == ESTIMATES_ALERTS:
                    zeros = np.zeros((m, 3, 4), dtype=np.int64)
                    values = {
                        'level': zeros.astype(np.uint8),
                        'onset_ns': zeros,
                        'detected_ns': zeros,
                    }
                    per_topic.append(encode_alerts(stamps, 'base_link', values))
                    continue
                fields = {}
                for spec in flat_fields(types[name]):
                    source = given.get(name, {}).get(spec.name)
                    shape = (m, spec.count) if spec.count > 1 else (m,)
                    fields[spec.name] = (
                        source[start:stop]
                        if source is not None
                        else np.zeros(shape, dtype=spec.dtype)
                    )
                per_topic.append(encode_batch(types[name], stamps, 'base_link', fields))
            # live order: every topic of one stamp, then the next stamp
            which = np.tile(np.arange(len(names), dtype=np.int64), m)
            datas = [per_topic[t][k] for k in range(m) for t in range(len(names))]
            writer.write_interleaved(names, which, datas, np.repeat(stamps, len(names)))
            written += len(datas)
    return written


def process_or_die(bag: str, settings: FleetSettings) -> dict[str, Any]:
    """:func:`~vd_observer_node.tools.fleet.process.process_bag`, except that a bag folder
    holding :data:`DIE_MARKER` kills the calling process with SIGKILL, as the kernel's
    out-of-memory killer would. For the fleet engines' tests (``run_fleet(function=...)``).
    """
    if (Path(bag) / DIE_MARKER).exists():
        os.kill(os.getpid(), signal.SIGKILL)
    return process_bag(bag, settings)
