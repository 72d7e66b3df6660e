"""What ``mountcal fleet --scheduler`` checks of a Dask cluster when it connects.

- **One software environment**: Dask's scheduler unpickles every task, and a fleet's tasks hold
  mountcal's jobs, so a scheduler that cannot import this mountcal would fail every log one by one;
  and a fleet's stored results are keyed by the command's mountcal version, so a worker of another
  version would store its answers under this version's keys. Both are refused here (a worker that
  joins later is caught per record by :mod:`mountcal.fleet.run`).
- **The settings for fleets** (:data:`FLEET_DASK_CONFIG`, docs/fleet.md "Dask settings for
  fleets") and mountcal preloaded in the workers: where they differ, a note says so.

This module imports nothing heavy: the functions that run on the scheduler and the workers are
pickled by reference to it.
"""

from __future__ import annotations

from typing import Any

from mountcal.core.errors import InputError
from mountcal.core.option_names import option
from mountcal.core.version import software_version

JOBS_MODULE = "mountcal.fleet.inputs"  # the types a fleet's tasks hold (FleetJob and its parts)
WORKER_MODULE = "mountcal.fleet.worker"  # what a fleet worker (local or Dask) imports before its first log
VERSION_KEY = "mountcal.version"  # in what a worker says of itself (_worker_settings)
# Dask settings for a cluster that runs fleets (docs/fleet.md, "Dask settings for fleets"). Dask's
# defaults sample every worker thread's stack each 10 ms (its profiler) and poll the event loop, the
# system and each worker's memory several times a second: on a busy single-threaded worker that costs
# ~10 % of its core, and the scheduler and nannies as much again, where workers and scheduler share
# cores (measured on a 200-log fleet: the workers' event loops 2.6 → 1.1 s CPU, the scheduler's
# 2.3 → 1.2 s). The dashboard loses the profile page and keeps coarser system plots.
FLEET_DASK_CONFIG: dict[str, object] = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "5s",
    "distributed.worker.memory.monitor-interval": "1s",
}


def look_at_cluster(client: Any, address: str) -> tuple[str, ...]:
    """Refuse a cluster that does not run this mountcal; else the notes on its settings (maybe none).

    Raises
    ------
    InputError
        The scheduler cannot import this mountcal version, or a worker runs another one.
    """
    _check_scheduler(client, address)
    seen = _workers(client)
    _check_workers(seen, address)
    return _settings_notes(seen)


def _check_scheduler(client: Any, address: str) -> None:
    ours = software_version()
    try:
        theirs = client.run_on_scheduler(_scheduler_version)
    except Exception as err:  # whatever the scheduler's unpickling raised
        text = str(err).strip()
        found = f"it cannot ({type(err).__name__}: {text.splitlines()[0] if text else ''})"
    else:
        if theirs == ours:
            return
        found = f"mountcal {theirs}"
    raise InputError(
        option("scheduler", address),
        f"a Dask scheduler that imports mountcal {ours}, this command's version (the scheduler unpickles every "
        "task, and a fleet's tasks hold mountcal's jobs)",
        found,
        f"Install mountcal {ours} where the scheduler runs, as on the workers (one software environment "
        "for the scheduler, the workers and this command).",
    )


def _workers(client: Any) -> dict[str, dict[str, object]]:
    """Each worker's fleet settings and mountcal version ({} when none answers: no workers yet)."""
    try:
        return dict(client.run(_worker_settings, list(FLEET_DASK_CONFIG)))
    except Exception:  # no workers yet, or a worker that cannot answer: each record is checked anyway
        return {}


def _check_workers(seen: dict[str, dict[str, object]], address: str) -> None:
    ours = software_version()
    by_version: dict[str, list[str]] = {}
    for worker, settings in seen.items():
        theirs = settings.get(VERSION_KEY)
        if theirs != ours:
            by_version.setdefault(str(theirs or "(a version that does not say)"), []).append(worker)
    if by_version:
        found = "; ".join(f"mountcal {v} on {', '.join(sorted(ws))}" for v, ws in sorted(by_version.items()))
        raise InputError(
            option("scheduler", address),
            f"mountcal {ours} on every Dask worker (this command's version, which the stored results are keyed by)",
            found,
            f"Install mountcal {ours} on those workers, or run this command with their version.",
        )


def _settings_notes(seen: dict[str, dict[str, object]]) -> tuple[str, ...]:
    """A note when the workers run with settings that slow a fleet down (FLEET_DASK_CONFIG)."""
    if not seen:
        return ()
    notes = []
    differ = sorted(
        {
            k
            for settings in seen.values()
            for k, v in settings.items()
            if k in FLEET_DASK_CONFIG and v != FLEET_DASK_CONFIG[k]
        }
    )
    if differ:
        values = {k: ", ".join(sorted({str(settings.get(k)) for settings in seen.values()})) for k in differ}
        shown = ", ".join(f"{k.removeprefix('distributed.')} ({v})" for k, v in values.items())
        notes.append(f"the Dask workers run with {shown}: Dask's monitoring costs a busy worker about 10 % of its core")
    cold = sum(not settings.get(WORKER_MODULE) for settings in seen.values())
    if cold:
        notes.append(
            f"{cold} of {len(seen)} Dask workers have not imported mountcal: each does at its first log (≈ 1 s of "
            f"CPU); start them with --preload {WORKER_MODULE}"
        )
    if notes:
        notes.append('for fleets start the cluster as docs/fleet.md shows ("Dask settings for fleets")')
    return ("; ".join(notes),) if notes else ()


def _worker_settings(keys: list[str]) -> dict[str, object]:
    """On a worker: its values of the Dask settings named, whether mountcal's worker module is
    imported, and its mountcal version."""
    import sys

    import dask

    return {
        **{k: dask.config.get(k, None) for k in keys},
        WORKER_MODULE: WORKER_MODULE in sys.modules,
        VERSION_KEY: software_version(),
    }


def _scheduler_version() -> str:
    """On the scheduler: the mountcal version it imports, once it has imported what unpickling a
    fleet's tasks needs (the jobs' types and what they import: a scheduler with mountcal but without
    one of its dependencies fails here, not on every log)."""
    import importlib

    importlib.import_module(JOBS_MODULE)
    return software_version()


__all__ = ["FLEET_DASK_CONFIG", "VERSION_KEY", "WORKER_MODULE", "look_at_cluster"]
