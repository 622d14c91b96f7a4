"""Accuracy report of a bag: estimates vs simulator truth, metrics (JSON/Markdown) and PNGs.

ROS-free. Pipeline: :func:`load_bag_series` (batch-decoded topics) -> :func:`evaluate`
(metrics, comparisons, the alerts section of :mod:`.alerts`) -> :func:`report_json` /
:func:`report_markdown` / :func:`report_text` and :func:`~.figures.write_figures`. The
``vd report`` sub-command is in :mod:`.cli`. See docs/report.md.
"""

from vd_observer_node.tools.report.alerts import AlertSettings, AlertsSection
from vd_observer_node.tools.report.errors import ReportError, ReportInputError
from vd_observer_node.tools.report.evaluate import (
    AccuracyReport,
    Comparison,
    EvaluationSettings,
    QuantityMetrics,
    SlopeConvergence,
    evaluate,
)
from vd_observer_node.tools.report.format import report_json, report_markdown, report_text
from vd_observer_node.tools.report.load import BagSeries, TopicSeries, load_bag_series
from vd_observer_node.tools.report.metrics import ErrorStats

__all__ = [
    'AccuracyReport',
    'AlertSettings',
    'AlertsSection',
    'BagSeries',
    'Comparison',
    'ErrorStats',
    'EvaluationSettings',
    'QuantityMetrics',
    'ReportError',
    'ReportInputError',
    'SlopeConvergence',
    'TopicSeries',
    'evaluate',
    'load_bag_series',
    'report_json',
    'report_markdown',
    'report_text',
]
