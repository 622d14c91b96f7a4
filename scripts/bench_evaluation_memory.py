#!/usr/bin/env python3
"""Peak memory of evaluating one bag: whole-bag path vs streamed; prints figures, asserts nothing.

    python scripts/bench_evaluation_memory.py [--minutes 1,5,20] [--rate 1000]
                                              [--whole-up-to 5] [--block 200000]

For recording-like bags (20 topics at ``--rate`` Hz, the layout of a live demo recording:
sensors, truth, observer, estimates and alerts; :func:`write_recording_like_bag`) of
``--minutes`` each, one fresh process per (bag, path) evaluates the bag and prints its peak
RSS (``VmHWM``) and wall time:

* whole: ``evaluate(load_bag_series(bag))``, the reference (``vd report``), every topic decoded
  into arrays of the bag's length (only for bags up to ``--whole-up-to`` minutes: ~300 MiB
  per minute, 6 GiB for 20 min);
* streamed: :func:`vd_observer_node.tools.report.stream.evaluate_bag`, what ``vd fleet``'s
  worker runs, in blocks of ``--block`` messages.

The bag's file size is printed next to the peaks (``BagReader`` memory-maps the file and
hands read pages back, so the file is not part of the streamed peak). The load average is
printed: wall times on a shared machine are indicative only; memory figures are not
affected.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'src' / 'vd_observer_node'))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'src' / 'vd_sim_node'))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'src' / 'vd_common'))

from vd_observer_node.testing.fleet_bags import write_recording_like_bag

_PROBE = """
import json, sys, time
sys.path[:0] = json.loads(sys.argv[3])
path, bag, block = sys.argv[1], sys.argv[2], int(sys.argv[4])
started = time.perf_counter()
if path == 'whole':
    from vd_observer_node.tools.report.evaluation import evaluate
    from vd_observer_node.tools.report.load import load_bag_series
    report, _ = evaluate(load_bag_series(bag, progress=False))
else:
    from vd_observer_node.tools.report.stream import evaluate_bag
    report = evaluate_bag(bag, block_messages=block).report
wall = time.perf_counter() - started
# VmHWM, not ru_maxrss: Linux carries the bench parent's high-water mark (it made the bag)
# across fork + exec into ru_maxrss
peak = next(int(l.split()[1]) for l in open('/proc/self/status') if l.startswith('VmHWM'))
print(json.dumps({'peak_kib': peak, 'wall_s': wall, 'quantities': len(report.quantities)}))
"""


def _load() -> str:
    return ' '.join(f'{x:.2f}' for x in os.getloadavg())


def _probe(path: str, bag: Path, block: int) -> dict[str, float]:
    paths = json.dumps([p for p in sys.path if p])
    done = subprocess.run(
        [sys.executable, '-c', _PROBE, path, str(bag), paths, str(block)],
        capture_output=True,
        text=True,
        check=True,
    )
    result: dict[str, float] = json.loads(done.stdout.strip().splitlines()[-1])
    return result


def _size_mib(bag: Path) -> float:
    return sum(p.stat().st_size for p in bag.rglob('*') if p.is_file()) / 2**20


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--minutes', default='1,5,20', help='bag lengths [min], comma-separated')
    parser.add_argument('--rate', type=float, default=1000.0, help='[Hz] message rate')
    parser.add_argument(
        '--whole-up-to', type=float, default=5.0, help='[min] longest bag for the whole path'
    )
    parser.add_argument('--block', type=int, default=200_000, help='messages per block')
    args = parser.parse_args()
    minutes = [float(m) for m in args.minutes.split(',')]
    print(f'evaluation memory: recording-like bags, 20 topics at {args.rate:g} Hz')
    print(f'{"bag":>8} {"file":>9} {"whole":>10} {"streamed":>10}   wall (load)')
    with tempfile.TemporaryDirectory(prefix='vd-bench-eval-') as tmp:
        for m in minutes:
            bag = Path(tmp) / f'bag_{m:g}min'
            write_recording_like_bag(bag, m * 60.0, args.rate, seed=0)
            size = _size_mib(bag)
            whole = _probe('whole', bag, args.block) if m <= args.whole_up_to else None
            streamed = _probe('streamed', bag, args.block)
            w = f'{whole["peak_kib"] / 1024:8.0f} M' if whole else f'{"-":>10}'
            s = streamed['peak_kib'] / 1024
            walls = f'streamed {streamed["wall_s"]:.1f} s'
            if whole:
                walls = f'whole {whole["wall_s"]:.1f} s, ' + walls
            print(f'{m:6g} m {size:7.0f} M {w} {s:8.0f} M   {walls} (load {_load()})')
            for p in bag.rglob('*'):
                if p.is_file():
                    p.unlink()
    print('peak RSS [MiB] (VmHWM) of one process evaluating one bag')


if __name__ == '__main__':
    main()
