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


def test_the_start_s_store_defines_its_types_as_jazzy_and_takes_the_rest_when_asked(
    tmp_path: Path,
) -> None:
    """The store of a start (vd_msgs, `COMMON_TYPES` and what they are made of, kept beside
    the bytecode) gives each of its types the definition and hash of Jazzy's store with
    vd_msgs (the oracle); a type outside it brings in the rest of Jazzy's, in the same store.
    Every type the input mapping supports is among those of a start."""
    from rosbags.typesys import get_typestore
    from vd_observer_node.inputs.mapping import SUPPORTED_TYPES

    kept = typestore.kept_types(find_vd_msgs_dir(), tmp_path)
    oracle = get_typestore(typestore.BASE_STORE)
    oracle.register(_parsed(find_vd_msgs_dir()))
    assert set(typestore.VD_MSG_TYPES) | set(typestore.COMMON_TYPES) <= set(kept)
    assert all(kept[name] == oracle.fielddefs[name] for name in kept)
    supported = {t for types in SUPPORTED_TYPES.values() for t in types}
    assert supported <= set(kept), supported - set(kept)
    store = typestore.vd_typestore()
    for name in [*typestore.VD_MSG_TYPES, *typestore.COMMON_TYPES]:
        assert typestore.message_definition(name) == oracle.generate_msgdef(name, 2)[0]
        assert typestore.type_hash(name) == oracle.hash_rihs01(name)
    assert typestore.message_class('sensor_msgs/msg/LaserScan').__msgtype__ == (
        'sensor_msgs/msg/LaserScan'
    )
    assert typestore.vd_typestore() is store
    assert set(oracle.fielddefs) <= set(store.fielddefs)
