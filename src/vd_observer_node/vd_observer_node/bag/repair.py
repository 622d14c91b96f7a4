"""Repair of a bag whose writer died (SIGKILL, power loss, disk full).

A killed :class:`~.writer.BagWriter` leaves an MCAP file that ends inside or after its last
chunk, without summary, footer or ``metadata.yaml``. Repair reads everything readable with a
lenient scan, writes it to a fresh MCAP (new chunks, summary, footer), puts that in place of
the damaged file (kept as ``<file>.bak`` unless asked otherwise) and writes ``metadata.yaml``.
"""

from __future__ import annotations

import os
import shutil
from dataclasses import dataclass, field, replace
from pathlib import Path

from vd_observer_node.bag.errors import BagNotFoundError, BagUsageError
from vd_observer_node.bag.metadata import write_metadata
from vd_observer_node.bag.reader import BagReader, find_mcap_files
from vd_observer_node.bag.writer import BagWriter

__all__ = ['RepairReport', 'repair_bag']


@dataclass(frozen=True)
class RepairReport:
    """Outcome of :func:`repair_bag`.

    Attributes:
        bag: the repaired bag folder.
        mcap_file: the rebuilt MCAP file.
        messages_recovered: messages in the rebuilt file.
        topic_counts: messages recovered per topic.
        problems: the damage found (one line each); empty if the bag was intact.
        backup: where the original MCAP file was kept, None if deleted.
    """

    bag: Path
    mcap_file: Path
    messages_recovered: int
    topic_counts: dict[str, int] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)
    backup: Path | None = None


def repair_bag(path: str | os.PathLike[str], *, keep_backup: bool = True) -> RepairReport:
    """Rebuild a readable bag (summary, footer, ``metadata.yaml``) from a damaged one.

    Args:
        path: the bag folder (a bare ``.mcap`` file is repaired in its folder).
        keep_backup: keep the original MCAP file as ``<name>.bak``.

    Returns:
        What was recovered.

    Raises:
        BagNotFoundError: no MCAP file at ``path``.
        BagFormatError: the file is not MCAP at all (bad magic).
        BagUsageError: the bag is split into several MCAP files (not produced by vd).
    """
    source = Path(path)
    files = find_mcap_files(source)
    if len(files) != 1:
        raise BagUsageError(f'{source}: repair handles single-file bags, found {len(files)}')
    damaged = files[0]
    folder = damaged.parent
    reader = BagReader(damaged, recover=True)
    topics = reader.topics
    work = folder.parent / f'.{folder.name}.repair'
    if work.exists():
        shutil.rmtree(work)
    counts: dict[str, int] = {}
    with BagWriter(work, file_name=damaged.name) as writer:
        for info in topics.values():
            if not info.msgtype:
                continue
            try:
                writer.add_topic(
                    info.name, info.msgtype, info.qos_profiles_yaml, definition=info.definition
                )
            except BagUsageError:  # unreadable QoS text: keep the data, lose the QoS
                writer.add_topic(info.name, info.msgtype, '', definition=info.definition)
        for msg in reader.raw_messages():
            if msg.topic not in writer.topics:  # schema-less channel: nothing to decode it by
                continue
            writer.write(msg.topic, msg.data, msg.log_time_ns, msg.publish_time_ns)
            counts[msg.topic] = counts.get(msg.topic, 0) + 1
        problems = [str(p) for p in reader.problems]
    summary = writer.summary()
    rebuilt = work / damaged.name
    if not rebuilt.is_file():
        raise BagNotFoundError(f'{rebuilt}: repair output missing')
    backup: Path | None = None
    if keep_backup:
        backup = damaged.with_name(damaged.name + '.bak')
        damaged.replace(backup)
    rebuilt.replace(damaged)
    write_metadata(folder, replace(summary, file_name=damaged.name))
    shutil.rmtree(work)
    return RepairReport(
        bag=folder,
        mcap_file=damaged,
        messages_recovered=sum(counts.values()),
        topic_counts=counts,
        problems=problems,
        backup=backup,
    )
