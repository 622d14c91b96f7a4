"""Fleet-scale replay: many bags in parallel, on one machine or a Dask cluster, one report.

ROS-free. :func:`~.bags.find_bags` names the bags; :func:`~.run.run_fleet` runs the per-bag
function :func:`~.process.process_bag` over them (local process pool or Dask), storing one
result per bag so an interrupted run resumes; :func:`~.report.write_fleet_report` writes the
fleet report. The ``vd fleet`` sub-command is in :mod:`.cli`. See docs/fleet.md.
"""

from typing import TYPE_CHECKING

from vd_observer_node.tools.lazy import lazy_exports

if TYPE_CHECKING:  # the names as mypy and editors see them; imported on first use
    from vd_observer_node.tools.fleet.bags import find_bags, read_bag_list
    from vd_observer_node.tools.fleet.errors import FleetEngineError, FleetError, FleetInputError
    from vd_observer_node.tools.fleet.process import (
        ROW_COLUMNS,
        FleetSettings,
        bag_id,
        process_bag,
    )
    from vd_observer_node.tools.fleet.report import (
        FleetReport,
        Regression,
        compare_baseline,
        read_fleet_csv,
        write_fleet_report,
    )
    from vd_observer_node.tools.fleet.run import (
        ENGINES,
        FleetEngine,
        FleetRun,
        load_records,
        run_fleet,
    )

__all__ = [
    'ENGINES',
    'ROW_COLUMNS',
    'FleetEngine',
    'FleetEngineError',
    'FleetError',
    'FleetInputError',
    'FleetReport',
    'FleetRun',
    'FleetSettings',
    'Regression',
    'bag_id',
    'compare_baseline',
    'find_bags',
    'load_records',
    'process_bag',
    'read_bag_list',
    'read_fleet_csv',
    'run_fleet',
    'write_fleet_report',
]

__getattr__ = lazy_exports(
    __name__,
    {
        'ENGINES': 'run',
        'FleetEngine': 'run',
        'FleetEngineError': 'errors',
        'FleetError': 'errors',
        'FleetInputError': 'errors',
        'FleetReport': 'report',
        'FleetRun': 'run',
        'FleetSettings': 'process',
        'ROW_COLUMNS': 'process',
        'Regression': 'report',
        'bag_id': 'process',
        'compare_baseline': 'report',
        'find_bags': 'bags',
        'load_records': 'run',
        'process_bag': 'process',
        'read_bag_list': 'bags',
        'read_fleet_csv': 'report',
        'run_fleet': 'run',
        'write_fleet_report': 'report',
    },
)
