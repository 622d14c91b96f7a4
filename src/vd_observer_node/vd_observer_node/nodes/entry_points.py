"""Console-script entry points of the nodes (see `vd_common.entry.guarded_main`)."""

from __future__ import annotations

from vd_common.entry import guarded_main

__all__ = [
    'alerts_node',
    'estimator_node',
    'observer_node',
    'pipeline_node',
    'player_node',
    'recorder_node',
]


def observer_node() -> int:
    """``ros2 run vd_observer_node observer_node``."""
    return guarded_main('vd_observer_node.nodes.observer_node')


def estimator_node() -> int:
    """``ros2 run vd_observer_node estimator_node``."""
    return guarded_main('vd_observer_node.nodes.estimator_node')


def alerts_node() -> int:
    """``ros2 run vd_observer_node alerts_node``."""
    return guarded_main('vd_observer_node.nodes.alerts_node')


def pipeline_node() -> int:
    """``ros2 run vd_observer_node pipeline_node``."""
    return guarded_main('vd_observer_node.nodes.pipeline_node')


def recorder_node() -> int:
    """``ros2 run vd_observer_node recorder_node``."""
    return guarded_main('vd_observer_node.nodes.recorder_node')


def player_node() -> int:
    """``ros2 run vd_observer_node player_node``."""
    return guarded_main('vd_observer_node.nodes.player_node')
