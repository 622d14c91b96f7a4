"""Early check of a node's ``--params-file`` arguments (ROS-free).

rcl refuses a missing or malformed parameter file inside ``rclpy.init`` with a traceback;
`vd_common.ros.lifecycle.run_node` calls `params_file_problem` first, so every node refuses it
with one line instead.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import yaml

__all__ = ['params_file_problem']


def params_file_problem(argv: Sequence[str]) -> str | None:
    """Check the ``--params-file`` arguments of a node's command line before rclpy sees them.

    rcl refuses a missing or malformed parameter file inside ``rclpy.init`` with a
    traceback; a node calls this first to refuse it with one line instead.

    Args:
        argv: the command line (``sys.argv`` or the args given to ``main``).

    Returns:
        One line naming the file and the problem, or None if every file is readable YAML
        holding a mapping.
    """
    args = list(argv)
    in_ros_args = False
    for i, arg in enumerate(args):
        if arg == '--ros-args':
            in_ros_args = True
        elif arg == '--':
            in_ros_args = False
        elif in_ros_args and arg == '--params-file' and i + 1 < len(args):
            path = args[i + 1]
            try:
                data = yaml.safe_load(Path(path).read_text(encoding='utf-8'))
            except OSError as exc:
                return f'--params-file {path}: cannot read it ({exc.strerror or exc})'
            except yaml.YAMLError as exc:
                reason = ' '.join(str(exc).split())
                return f'--params-file {path}: malformed YAML ({reason})'
            if not isinstance(data, dict):
                return (
                    f'--params-file {path}: must be a mapping '
                    '<node name>: {ros__parameters: {name: value, ...}}'
                )
    return None
