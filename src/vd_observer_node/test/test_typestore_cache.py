"""vd_msgs' parsed definitions kept between starts (`bag.typestore.parsed_vd_msgs`): what
is read back is what rosbags' parser gives, and any change parses anew."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from rosbags.typesys import get_types_from_msg
from vd_observer_node.bag import typestore
from vd_observer_node.bag.typestore import find_vd_msgs_dir, parsed_vd_msgs


def _parsed(folder: Path) -> dict[str, object]:
    """The oracle: rosbags' parser on every file."""
    types: dict[str, object] = {}
    for path in sorted(folder.glob('*.msg')):
        types.update(get_types_from_msg(path.read_text(), f'vd_msgs/msg/{path.stem}'))
    return types


@pytest.fixture
def msgs(tmp_path: Path) -> Path:
    folder = tmp_path / 'msg'
    shutil.copytree(find_vd_msgs_dir(), folder)
    return folder


def test_kept_definitions_are_the_parser_s_and_are_read_back(
    msgs: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    cache = tmp_path / 'cache'
    first = parsed_vd_msgs(msgs, cache)
    assert first == _parsed(msgs)
    assert len(list(cache.glob('vd_msgs_types.*.pickle'))) == 1

    def refuse(*_: object) -> None:
        raise AssertionError('parsed again')

    monkeypatch.setattr(typestore, 'get_types_from_msg', refuse)
    assert parsed_vd_msgs(msgs, cache) == first  # read back, not parsed


def test_a_changed_file_or_a_damaged_cache_is_parsed_anew(msgs: Path, tmp_path: Path) -> None:
    cache = tmp_path / 'cache'
    parsed_vd_msgs(msgs, cache)
    (kept,) = cache.glob('vd_msgs_types.*.pickle')
    slope = msgs / 'Slope.msg'
    slope.write_text(slope.read_text() + '\nfloat64 added_field\n')
    changed = parsed_vd_msgs(msgs, cache)
    assert changed == _parsed(msgs)
    assert 'added_field' in str(changed['vd_msgs/msg/Slope'])
    (now,) = cache.glob('vd_msgs_types.*.pickle')  # the stale one removed
    assert now != kept
    now.write_bytes(b'not a pickle')
    assert parsed_vd_msgs(msgs, cache) == changed


def test_a_cache_that_cannot_be_written_parses_each_time(msgs: Path, tmp_path: Path) -> None:
    blocked = tmp_path / 'file'
    blocked.write_text('')  # a file where the cache folder would be
    assert parsed_vd_msgs(msgs, blocked / 'cache') == _parsed(msgs)
