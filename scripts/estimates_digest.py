#!/usr/bin/env python3
"""Digests of every estimate `vd replay` writes, on the cases a refactor must keep bit for bit.

A refactor of the cascade (issue 40) must leave every published estimate unchanged to the bit.
This runs ``vd replay`` (its command line, so it holds across internal changes) on:

* ``paper``: the paper's scenario bag (``bags/paper_table1_100hz``), measured torques, with
  the situation monitor (friction potential and alerts);
* ``paper_adapt``: the same with the online mass and rolling radius on;
* ``rav4``: the RAV4 segment (``../shared/realdata``) on the engine path through the torque
  converter, the brake switch and the learnt torque offset;
* ``rav4_imu``: the same with its IMU fused;

and prints, per case and output topic, the message count and a SHA-256 of every message's
log time and serialized bytes (read with the ``mcap`` library, not vd's reader). ``--json
FILE`` stores them, ``--compare FILE`` compares with a stored run and exits 1 on any
difference. A case whose input is absent is skipped with a note.

Usage:
    python scripts/estimates_digest.py [--json FILE] [--compare FILE] [--cases a,b]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / 'src' / 'vd_observer_node' / 'config'
RAV4 = ROOT.parent / 'shared' / 'realdata' / 'comma2k19-rav4-seg40'
RAV4_VEHICLE = ROOT / 'src' / 'vd_common' / 'config' / 'toyota_rav4_2017_estimation.yaml'
ADAPT = 'estimator:\n  mass_adaptation: true\n  radius_adaptation: true\n'


def _cases(work: Path, wanted: set[str]) -> dict[str, list[str] | None]:
    paper = ROOT / 'bags' / 'paper_table1_100hz'
    adapt = work / 'adapt.yaml'
    adapt.write_text(ADAPT, encoding='utf-8')
    cases: dict[str, list[str] | None] = {
        'paper': [str(paper)] if paper.exists() else None,
        'paper_adapt': [str(paper), '--config', str(adapt)] if paper.exists() else None,
        'rav4': None,
        'rav4_imu': None,
    }
    if RAV4.exists() and wanted & {'rav4', 'rav4_imu'}:
        # scripts/ is on sys.path: this file runs as a script
        import import_comma2k19

        bag = work / 'rav4'
        import_comma2k19.main([str(RAV4), '--out', str(bag)])
        common = [
            '--vehicle',
            str(RAV4_VEHICLE),
            '--config',
            str(CONFIG / 'replay_100hz_example.yaml'),
        ]
        cases['rav4'] = [
            str(bag),
            '--mapping',
            str(CONFIG / 'input_mapping_comma2k19.yaml'),
            *common,
        ]
        cases['rav4_imu'] = [
            str(bag), '--mapping', str(CONFIG / 'input_mapping_comma2k19_imu.yaml'), *common
        ]  # fmt: skip
    return cases


def _digests(bag: Path) -> dict[str, list[Any]]:
    from mcap.reader import make_reader

    hashes: dict[str, Any] = {}
    counts: dict[str, int] = {}
    for file in sorted(bag.glob('*.mcap')):
        with file.open('rb') as stream:
            for _, channel, message in make_reader(stream).iter_messages(log_time_order=True):
                digest = hashes.setdefault(channel.topic, hashlib.sha256())
                digest.update(message.log_time.to_bytes(8, 'little'))
                digest.update(message.data)
                counts[channel.topic] = counts.get(channel.topic, 0) + 1
    return {topic: [counts[topic], hashes[topic].hexdigest()] for topic in sorted(hashes)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--json', type=Path, help='store the digests here')
    parser.add_argument('--compare', type=Path, help='compare with digests stored by --json')
    parser.add_argument('--cases', help='comma-separated case names (default: all)')
    args = parser.parse_args(argv)
    from vd_observer_node.tools.cli import main as vd

    result: dict[str, dict[str, list[Any]]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        names = ('paper', 'paper_adapt', 'rav4', 'rav4_imu')
        wanted = set(args.cases.split(',')) if args.cases else set(names)
        for name, replay in _cases(work, wanted).items():
            if name not in wanted:
                continue
            if replay is None:
                print(f'{name}: skipped (its input is not on this machine)')
                continue
            out = work / f'out_{name}'
            start = time.perf_counter()
            rc = vd(['replay', replay[0], str(out), *replay[1:], '--no-progress'])
            if rc != 0:
                print(f'{name}: vd replay exited {rc}')
                return 2
            result[name] = _digests(out)
            print(f'{name}: {len(result[name])} topics in {time.perf_counter() - start:.1f} s')
            for topic, (count, digest) in result[name].items():
                print(f'  {topic:40s} {count:7d} {digest[:16]}')
    if args.json is not None:
        args.json.write_text(json.dumps(result, indent=1), encoding='utf-8')
    if args.compare is not None:
        before = json.loads(args.compare.read_text(encoding='utf-8'))
        differ = [
            f'{name} {topic}'
            for name in result
            for topic in sorted(set(result[name]) | set(before.get(name, {})))
            if result[name].get(topic) != before.get(name, {}).get(topic)
        ]
        missing = sorted(set(before) - set(result))
        for line in differ:
            print(f'DIFFERS: {line}')
        if missing:
            print(f'not run now: {", ".join(missing)}')
        print('identical' if not differ else f'{len(differ)} topics differ')
        return 1 if differ else 0
    return 0


if __name__ == '__main__':
    sys.exit(main())
