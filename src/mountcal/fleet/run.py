"""Run a fleet: hash, skip what is done, calibrate the rest on an engine, store, consolidate.

The engines (local worker processes, a Dask cluster) are in :mod:`mountcal.fleet.engines`. Whatever
the engine, each finished log is stored at once (:class:`~mountcal.fleet.store.PartStore`), so a
killed run loses at most the logs in flight.
"""

from __future__ import annotations

import json
import time
from collections import Counter
from collections.abc import Iterator, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from mountcal.core.errors import InputError, MountcalError, refuse_not_confident
from mountcal.core.paths import check_outputs, output_lock
from mountcal.core.version import software_version
from mountcal.fleet.agreement import ALPHA
from mountcal.fleet.engines import TRANSIENT, make_engine, transient_failure
from mountcal.fleet.inputs import COMPUTED_BY, FleetJob
from mountcal.fleet.overview import check_overview_overwritable, overview_path, write_overview
from mountcal.fleet.progress import Progress
from mountcal.fleet.storage import is_url, remove_orphans
from mountcal.fleet.store import (
    LOG_COLUMNS,
    MOUNTING_COLUMNS,
    VEHICLE_COLUMNS,
    PartStore,
    check_overwritable,
    job_hash,
    schema,
    write_table,
)
from mountcal.fleet.vehicles import analyse_fleet, vehicle_table

HASH_THREADS = 4


@dataclass(frozen=True)
class FleetOptions:
    """How to run a fleet.

    Attributes
    ----------
    workers : int or None
        Local worker processes; None uses every core available to this process.
    scheduler : str or None
        Address of a Dask scheduler (``tcp://host:8786``); None runs locally.
    retry_failed : bool
        Recalculate logs an earlier run recorded as failed (by default they are kept as they are).
    progress : bool
        Draw the progress line on stderr.
    alpha : float
        Significance of a disagreeing log and of a remount.
    floor_deg : float
        Mounting scatter between logs added in quadrature to each log's σ (0: trust the σ).
    require_confident : bool
        Refuse (write no table) when a log's calibration is not confident; else they are listed in
        ``FleetResult.not_confident`` and in both tables' metadata (``mountcal.not_confident_logs``).
    """

    workers: int | None = None
    scheduler: str | None = None
    retry_failed: bool = False
    progress: bool = True
    alpha: float = ALPHA
    floor_deg: float = 0.0
    require_confident: bool = False


@dataclass(frozen=True)
class FleetResult:
    """What a fleet run produced.

    Attributes
    ----------
    logs, vehicles : DataFrame
        The tables written to ``output`` (one row per log) and ``vehicles_path`` (one row per vehicle).
    mountings : DataFrame
        One row per vehicle and mounting period (the ``mountings`` of the vehicles table, flat).
    computed : int
        Logs calibrated by this run.
    reused : int
        Logs whose results an earlier run had stored.
    engine : str
    elapsed_s : float
    discarded : dict of str to int
        What the run set aside, by reason (duplicate inputs, a killed run's temporary files,
        unreadable part files).
    engine_notes : tuple of str
        What the engine found worth saying (a Dask cluster whose settings slow a fleet down).
    """

    logs: pd.DataFrame
    vehicles: pd.DataFrame
    mountings: pd.DataFrame
    output: Path
    vehicles_path: Path
    parts: Path
    computed: int
    reused: int
    engine: str
    elapsed_s: float
    discarded: dict[str, int] = field(default_factory=dict)
    engine_notes: tuple[str, ...] = ()
    not_confident: tuple[str, ...] = ()  # logs whose calibration is not confident (flag not_confident)
    layout: dict[str, int] = field(default_factory=dict)  # logs by layout: folders, canedge, manifest
    sessions: int = 0  # CANedge sessions
    splits: int = 0  # files read, a session's splits each


def outputs_of(output: str | Path) -> tuple[Path, Path, Path]:
    """The per-log table, the per-vehicle table beside it, and the folder of part files."""
    output = Path(output)
    return output, output.with_name(f"{output.stem}_vehicles{output.suffix}"), output.with_name(output.name + ".parts")


def run_fleet(
    jobs: Sequence[FleetJob],
    output: str | Path,
    options: FleetOptions | None = None,
    set_aside: Mapping[str, int] | None = None,
) -> FleetResult:
    """Calibrate every job (skipping those an earlier run finished) and write the two tables.

    Parameters
    ----------
    jobs : sequence of FleetJob
        From :func:`mountcal.fleet.inputs.collect_jobs`.
    output : str or Path
        The per-log Parquet table; ``<stem>_vehicles.parquet`` and ``<output>.parts/`` go beside it.
    options : FleetOptions, optional
    set_aside : mapping of str to int, optional
        Files the inputs' layout set aside, by reason (``collect_jobs(discarded=…)``): reported
        with the run's own.

    Raises
    ------
    InputError
        The output is not ``.parquet`` or is one of the inputs; the scheduler is unreachable;
        another run is writing the same output (it holds the lock).
    """
    with output_lock(outputs_of(output)[0]):  # two runs on one output would redo each other's work
        return _run_locked(jobs, output, options, dict(set_aside or {}))


def _run_locked(
    jobs: Sequence[FleetJob], output: str | Path, options: FleetOptions | None, set_aside: dict[str, int]
) -> FleetResult:
    options = options or FleetOptions()
    started = time.monotonic()
    output, vehicles_path, parts = outputs_of(output)
    seen: set[tuple[str, tuple[str, ...]]] = set()
    unique_jobs = []
    for job in jobs:  # a log reached by two inputs (a folder and a glob over it) is calibrated once
        if (job.vehicle_id, job.job.paths) not in seen:
            seen.add((job.vehicle_id, job.job.paths))
            unique_jobs.append(job)
    duplicates, jobs = len(jobs) - len(unique_jobs), unique_jobs
    _check_output(output, jobs)
    store = PartStore(parts)
    stale = store.remove_temporaries()
    stored, unreadable = store.load()
    keys: list[str | None] = [None] * len(jobs)
    setup_failures: dict[int, dict[str, Any]] = {}
    results: dict[str, dict[str, Any]] = {}
    progress = Progress(len(jobs), enabled=options.progress)

    def todo() -> Iterator[tuple[str, FleetJob]]:
        """Jobs to calibrate, as their hashes come in (threads hash ahead, in input order)."""
        with ThreadPoolExecutor(HASH_THREADS) as hasher:
            for i, (key, failure) in enumerate(hasher.map(_hash_or_failure, jobs)):
                keys[i] = key
                if key is None:
                    setup_failures[i] = failure
                    progress.update(False)
                elif key in results or key in pending:
                    progress.reuse()  # the same files and options under another name
                elif key in stored and (stored[key].get("status") == "ok" or not options.retry_failed):
                    results[key] = stored[key]
                    progress.reuse()
                else:
                    pending.add(key)
                    yield key, jobs[i]

    pending: set[str] = set()
    version = software_version()
    with make_engine(options.workers, options.scheduler) as engine:
        if len(stored) < len(jobs):  # likely work to do: start the workers while the first logs are hashed
            engine.start()
        try:
            for key, record in engine.results(todo()):
                record = _computed_here(record, version)
                if not record.pop(TRANSIENT, False):
                    store.save(key, record)
                results[key] = record
                progress.workers(getattr(engine, "live_workers", 0))
                progress.update(record.get("status") == "ok")
        finally:
            progress.finish()
    if any(is_url(path) for job in jobs for path in job.job.paths):
        remove_orphans()  # this machine's copies of killed workers' fetches: the workers are done now
    computed = len(pending)
    logs = _log_table(jobs, keys, setup_failures, results)
    logs, mountings = analyse_fleet(logs, options.alpha, options.floor_deg)
    mountings = _complete(mountings, MOUNTING_COLUMNS)
    vehicles = _complete(vehicle_table(mountings, logs), VEHICLE_COLUMNS)
    doubtful = tuple(str(log) for log, sure in zip(logs["log"], logs["confident"], strict=True) if _not_confident(sure))
    if doubtful and options.require_confident:
        refuse_not_confident(
            str(output),
            f"{len(doubtful)} log(s) not confident: {', '.join(doubtful[:5])}" + (" …" if len(doubtful) > 5 else ""),
            "Check those logs (their results are kept for the next run)",
        )
    said = {"mountcal.confident": json.dumps(not doubtful), "mountcal.not_confident_logs": json.dumps(doubtful)}
    write_table(vehicles, schema(VEHICLE_COLUMNS, "vehicles"), vehicles_path, said)
    write_table(logs, schema(LOG_COLUMNS, "logs"), output, said)
    write_overview(overview_path(output), vehicles, logs, f"mountcal fleet: {output.name}")
    return FleetResult(
        logs=logs,
        vehicles=vehicles,
        mountings=mountings,
        output=output,
        vehicles_path=vehicles_path,
        parts=parts,
        computed=computed,
        reused=len({k for k in keys if k is not None}) - computed,
        engine=engine.name,
        engine_notes=engine.notes,
        elapsed_s=time.monotonic() - started,
        discarded={
            **set_aside,
            "inputs naming a log already listed": duplicates,
            "temporary files of a killed run": stale,
            "unreadable part files (their logs were recalculated)": unreadable,
        },
        not_confident=doubtful,
        layout=dict(Counter(job.layout for job in jobs)),
        sessions=sum(job.session is not None for job in jobs),
        splits=sum(len(job.job.paths) for job in jobs),
    )


def _check_output(output: Path, jobs: Sequence[FleetJob]) -> None:
    if output.suffix.lower() != ".parquet":
        raise InputError(
            str(output), "an output path ending in .parquet", output.suffix or "no suffix", "Name it fleet.parquet."
        )
    table, vehicles, _ = outputs_of(output)
    check_outputs(
        {"fleet table": table, "vehicles table": vehicles, "overview page": overview_path(output)},
        {
            "log": [p for job in jobs for p in job.job.paths if _local(p)],
            "DBC, mapping or protocol sheet": [p for job in jobs for p in _settings_files(job) if _local(p)],
        },
    )
    for path in (table, vehicles):
        check_overwritable(path)
    check_overview_overwritable(overview_path(output))


def _local(path: str) -> bool:
    """A local file that could be the output: not an object in storage, nor a symlink loop (which
    resolves to nothing, and fails its own row)."""
    if is_url(path):
        return False
    try:
        Path(path).resolve()
    except (OSError, RuntimeError):
        return False
    return True


def _settings_files(job: FleetJob) -> list[str]:
    dbc = job.job.log.dbc
    given = [dbc] if isinstance(dbc, str) else list(dbc or ())
    return [p for p in (*given, job.job.log.mapping, job.job.protocol) if p]


def _hash_or_failure(job: FleetJob) -> tuple[str | None, dict[str, Any]]:
    """The job's content hash, or the record of why its files cannot be read (not stored)."""
    try:
        return job_hash(job), {}
    except MountcalError as err:
        return None, {"status": "failed", "error": str(err), "error_type": type(err).__name__}


def _computed_here(record: dict[str, Any], version: str) -> dict[str, Any]:
    """The record, or a failure not to be stored when another mountcal version computed it.

    A log's key names this command's mountcal version; a worker installed apart (a Dask worker
    from another image, one that joined the cluster later) would store its own version's answer
    under it, and every later run would take that answer as this version's.
    """
    by = record.pop(COMPUTED_BY, None)
    if by == version or record.get(TRANSIENT):  # the engine's own failures are not stored anyway
        return record
    return transient_failure(
        f"expected this log calibrated by mountcal {version} (this command's version, which its stored "
        f"result is keyed by), found it calibrated by mountcal {by or '(a version that does not say)'} on a "
        "worker; install the same mountcal on every worker: the log is not stored and the next run retries it",
        "VersionMismatch",
    )


def _log_table(
    jobs: Sequence[FleetJob],
    keys: Sequence[str | None],
    setup_failures: Mapping[int, dict[str, Any]],
    results: Mapping[str, dict[str, Any]],
) -> pd.DataFrame:
    rows = []
    version = software_version()
    for i, job in enumerate(jobs):
        key = keys[i]
        record = setup_failures.get(i) or (results.get(key, {}) if key else {})
        if not record:
            continue  # interrupted before this log finished
        start, source = job.start_time, "manifest" if job.start_time else None
        if start is None and record.get("log_start_time"):
            start, source = record["log_start_time"], "log clock"
        rows.append(
            {
                **{k: v for k, v in record.items() if k != "log_start_time"},
                "vehicle_id": job.vehicle_id,
                "log": job.log,
                "start_time": start,
                "start_time_source": source,
                "content_hash": key,
                "mountcal_version": version,
                "flags": list(record.get("flags") or []),
            }
        )
    frame = _complete(pd.DataFrame(rows), LOG_COLUMNS)
    frame["start_time"] = pd.to_datetime(frame["start_time"], utc=True, format="ISO8601")
    return frame


def _not_confident(confident: Any) -> bool:
    """A log whose ``confident`` column is false (null — a failed log — is neither)."""
    return not pd.isna(confident) and not bool(confident)


def _complete(frame: pd.DataFrame, columns: Sequence[tuple[str, Any, str]]) -> pd.DataFrame:
    """The frame with every column of the table (missing ones null), in the table's order."""
    for name, _, _ in columns:
        if name not in frame.columns:
            frame[name] = None
    return frame[[name for name, _, _ in columns]]
