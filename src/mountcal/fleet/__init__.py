"""Many logs of many vehicles: calibrate each, a consensus per vehicle, remounts; local or on Dask.

- :mod:`~mountcal.fleet.inputs`: folders, globs and manifest CSVs → :class:`FleetJob` per log.
- :mod:`~mountcal.fleet.worker`: one log → one plain record (never raises).
- :mod:`~mountcal.fleet.engines`: where logs are calibrated (local worker processes, Dask).
- :mod:`~mountcal.fleet.dask_cluster`: what is checked of a Dask cluster on connecting (one
  mountcal version everywhere, the settings for fleets).
- :mod:`~mountcal.fleet.run`: :func:`run_fleet`.
- :mod:`~mountcal.fleet.store`: content hashes, atomic part files, the tables' columns.
- :mod:`~mountcal.fleet.vehicles`: consensus on SO(3), disagreeing logs, remount detection.

Usage::

    from mountcal.fleet import FleetOptions, collect_jobs, run_fleet

    result = run_fleet(collect_jobs(["fleet/"]), "fleet.parquet", FleetOptions(workers=2))
    result.logs, result.vehicles  # DataFrames, also written as Parquet
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from mountcal.core import lazy

if TYPE_CHECKING:
    from mountcal.fleet.engines import DaskEngine, LocalEngine
    from mountcal.fleet.inputs import FleetJob, JobDefaults, collect_jobs, read_manifest
    from mountcal.fleet.run import FleetOptions, FleetResult, outputs_of, run_fleet
    from mountcal.fleet.summary import summary_lines
    from mountcal.fleet.vehicles import analyse_fleet

# imported on first use (PEP 562), so that mountcal.fleet.engines can start the worker server before
# anything heavy is imported
_HOMES = {
    "DaskEngine": "mountcal.fleet.engines",
    "FleetJob": "mountcal.fleet.inputs",
    "FleetOptions": "mountcal.fleet.run",
    "FleetResult": "mountcal.fleet.run",
    "JobDefaults": "mountcal.fleet.inputs",
    "LocalEngine": "mountcal.fleet.engines",
    "analyse_fleet": "mountcal.fleet.vehicles",
    "collect_jobs": "mountcal.fleet.inputs",
    "outputs_of": "mountcal.fleet.run",
    "read_manifest": "mountcal.fleet.inputs",
    "run_fleet": "mountcal.fleet.run",
    "summary_lines": "mountcal.fleet.summary",
}


lazy.install(__name__, _HOMES)

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
