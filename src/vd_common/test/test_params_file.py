"""--params-file check: one line per problem, before rclpy sees the file."""

from __future__ import annotations

from pathlib import Path

from vd_common.params_file import params_file_problem


def test_params_file_problems_are_one_line(tmp_path: Path) -> None:
    good = tmp_path / 'good.yaml'
    good.write_text('observer_node:\n  ros__parameters: {max_gap: 0.4}\n', encoding='utf-8')
    bad = tmp_path / 'bad.yaml'
    bad.write_text('observer_node:\n  ros__parameters: {max_gap: [1,\n', encoding='utf-8')
    scalar = tmp_path / 'scalar.yaml'
    scalar.write_text('42\n', encoding='utf-8')
    assert params_file_problem(['node', '--ros-args', '--params-file', str(good)]) is None
    assert params_file_problem(['node', '--params-file', str(bad)]) is None  # not a ROS arg
    for path, words in (
        (tmp_path / 'absent.yaml', 'cannot read'),
        (bad, 'malformed YAML'),
        (scalar, 'must be a mapping'),
    ):
        problem = params_file_problem(['node', '--ros-args', '--params-file', str(path)])
        assert problem is not None and words in problem and str(path) in problem
        assert '\n' not in problem
