"""The topic contract: names unique and well formed, and written nowhere but in topics.py."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest
import vd_common.topics as topics
from vd_common.topics import (
    ALERTS,
    COMBINED,
    CONTRACT,
    ESTIMATES,
    NAMESPACE,
    OBSERVER,
    OPTIONAL_SENSORS,
    SENSORS,
    STATUS,
    TRUTH,
)

ROOT = Path(__file__).resolve().parents[3]
TOPICS_FILE = ROOT / 'src' / 'vd_common' / 'vd_common' / 'topics.py'
#: Folders whose Python files must name topics by the constants of topics.py.
SCANNED = ('src', 'tests', 'scripts')
GROUPS = {
    topics.SENSORS_NAMESPACE: [SENSORS, OPTIONAL_SENSORS],
    topics.OBSERVER_NAMESPACE: [OBSERVER],
    topics.ESTIMATES_NAMESPACE: [ESTIMATES, ALERTS],
    topics.TRUTH_NAMESPACE: [TRUTH],
    topics.STATUS_NAMESPACE: [STATUS],
}


def _topic_constants() -> dict[str, str]:
    """The public topic-name constants of topics.py (not the namespaces), by name."""
    return {
        n: value
        for n in topics.__all__
        if isinstance(value := getattr(topics, n), str) and not n.endswith('NAMESPACE')
    }


def literal_topic_names(source: str, filename: str = '<source>') -> list[tuple[int, str]]:
    """(line, text) of every string literal in code that contains ``NAMESPACE``.

    Docstrings and other bare string statements are text for a reader, not code, and comments
    are not in the syntax tree; f-string parts are literals like any other.
    """
    tree = ast.parse(source, filename)
    bare = {
        id(node.value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)
    }
    return sorted(
        (node.lineno, node.value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Constant)
        and isinstance(node.value, str)
        and id(node) not in bare
        and NAMESPACE in node.value
    )


def test_every_topic_is_in_one_group_only_and_in_the_group_namespace() -> None:
    groups = [SENSORS, OPTIONAL_SENSORS, OBSERVER, ESTIMATES, ALERTS, TRUTH, STATUS]
    assert sum(len(g) for g in groups) == len(CONTRACT), 'a topic name is in two groups'
    for namespace, members in GROUPS.items():
        assert namespace.startswith(NAMESPACE) and namespace.endswith('/')
        for name in (n for group in members for n in group):
            assert name.startswith(namespace), name
            assert re.fullmatch(r'[a-z_]+', name.removeprefix(namespace)), name


def test_message_types_are_ros2_type_names() -> None:
    for name, msgtype in CONTRACT.items():
        assert re.fullmatch(r'[a-z_]+/msg/[A-Z][A-Za-z0-9]*', msgtype), (name, msgtype)


def test_every_topic_has_one_constant_named_after_it() -> None:
    constants = _topic_constants()
    # COMBINED is optional and outside the recorder's contract (topics.py)
    grouped = {**CONTRACT, **COMBINED}
    assert sorted(constants.values()) == sorted(grouped), 'a topic without a constant'
    for constant, name in constants.items():
        assert name == NAMESPACE + constant.lower().replace('_', '/', 1), constant


@pytest.mark.parametrize(
    ('source', 'found'),
    [
        ("x = '<ns>truth/slope'\n", [(1, '<ns>truth/slope')]),
        ("x = f'{y} or <ns>sensors/*'\n", [(1, ' or <ns>sensors/*')]),
        ("x = '^<ns>'\n", [(1, '^<ns>')]),
        ('"""Reads <ns>truth/slope."""\nx = 1  # and <ns>estimates/slope\n', []),
        ("def f():\n    '''Writes '<ns>estimates/slope'.'''\n", []),
        ("x = '/clock'\n", []),
    ],
)
def test_the_scan_finds_literals_in_code_only(source: str, found: list[tuple[int, str]]) -> None:
    # <ns> stands for the namespace, so that this file passes its own scan
    expected = [(line, text.replace('<ns>', NAMESPACE)) for line, text in found]
    assert literal_topic_names(source.replace('<ns>', NAMESPACE)) == expected


def test_no_topic_name_is_written_outside_topics_py() -> None:
    """Code in src/, tests/ and scripts/ uses the constants of topics.py, never a literal."""
    if not all((ROOT / folder).is_dir() for folder in SCANNED):
        pytest.skip(f'{ROOT} is not the vd workspace')
    files = [
        path
        for folder in SCANNED
        for path in sorted((ROOT / folder).rglob('*.py'))
        if path != TOPICS_FILE
    ]
    assert len(files) > 50
    offenders = [
        f'{path.relative_to(ROOT)}:{line}: {text!r}'
        for path in files
        for line, text in literal_topic_names(path.read_text(encoding='utf-8'), str(path))
    ]
    assert not offenders, 'topic names written as literals (use vd_common.topics):\n' + (
        '\n'.join(offenders)
    )
