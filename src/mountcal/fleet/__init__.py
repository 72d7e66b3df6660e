"""Many logs of many vehicles: calibrate each, a consensus per vehicle, remounts; local or on Dask.

- :mod:`~mountcal.fleet.inputs`: folders, globs and manifest CSVs → :class:`FleetJob` per log.
- :mod:`~mountcal.fleet.worker`: one log → one plain record (never raises).
- :mod:`~mountcal.fleet.run`: engines (local processes, Dask) and :func:`run_fleet`.
- :mod:`~mountcal.fleet.store`: content hashes, atomic part files, the tables' columns.
- :mod:`~mountcal.fleet.vehicles`: consensus on SO(3), disagreeing logs, remount detection.

Usage::

    from mountcal.fleet import FleetOptions, collect_jobs, run_fleet

    result = run_fleet(collect_jobs(["fleet/"]), "fleet.parquet", FleetOptions(workers=2))
    result.logs, result.vehicles  # DataFrames, also written as Parquet
"""

from mountcal.fleet.inputs import FleetJob, JobDefaults, collect_jobs, read_manifest
from mountcal.fleet.run import DaskEngine, FleetOptions, FleetResult, LocalEngine, outputs_of, run_fleet
from mountcal.fleet.summary import summary_lines
from mountcal.fleet.vehicles import analyse_fleet

__all__ = [
    "DaskEngine",
    "FleetJob",
    "FleetOptions",
    "FleetResult",
    "JobDefaults",
    "LocalEngine",
    "analyse_fleet",
    "collect_jobs",
    "outputs_of",
    "read_manifest",
    "run_fleet",
    "summary_lines",
]
