"""Accuracy report of a bag: estimates vs simulator truth, metrics (JSON/Markdown) and PNGs.

ROS-free. Pipeline: :func:`load_bag_series` (batch-decoded topics) -> :func:`evaluate`
(metrics, comparisons, the alerts section of :mod:`.alerts`) -> :func:`report_json` /
:func:`report_markdown` / :func:`report_text` and :func:`~.figures.write_figures`. The
``vd report`` sub-command is in :mod:`.cli`. See docs/report.md.
"""

from typing import TYPE_CHECKING

from vd_observer_node.tools.lazy import lazy_exports

if TYPE_CHECKING:  # the names as mypy and editors see them; imported on first use
    from vd_observer_node.tools.report.alerts import AlertSettings, AlertsSection
    from vd_observer_node.tools.report.errors import ReportError, ReportInputError
    from vd_observer_node.tools.report.evaluation import evaluate
    from vd_observer_node.tools.report.format import report_json, report_markdown, report_text
    from vd_observer_node.tools.report.load import BagSeries, TopicSeries, load_bag_series
    from vd_observer_node.tools.report.metrics import ErrorStats
    from vd_observer_node.tools.report.results import (
        AccuracyReport,
        Comparison,
        EvaluationSettings,
        QuantityMetrics,
        SlopeConvergence,
    )

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

__getattr__ = lazy_exports(
    __name__,
    {
        'AccuracyReport': 'results',
        'AlertSettings': 'alerts',
        'AlertsSection': 'alerts',
        'BagSeries': 'load',
        'Comparison': 'results',
        'ErrorStats': 'metrics',
        'EvaluationSettings': 'results',
        'QuantityMetrics': 'results',
        'ReportError': 'errors',
        'ReportInputError': 'errors',
        'SlopeConvergence': 'results',
        'TopicSeries': 'load',
        'evaluate': 'evaluation',
        'load_bag_series': 'load',
        'report_json': 'format',
        'report_markdown': 'format',
        'report_text': 'format',
    },
)
