"""Run a fleet: hash, skip what is done, calibrate the rest on an engine, store, consolidate.

Engines:

- :class:`LocalEngine` (default): a :class:`concurrent.futures.ProcessPoolExecutor` on the local
  cores, started by a ``forkserver`` that has mountcal imported (``spawn`` where there is none),
  with one BLAS/OpenMP thread per worker (so N workers use N cores, not N²). Chosen over a Dask
  ``LocalCluster`` because it needs no set-up, no ports and no optional dependency, starts in about
  a second, and its workers die with the parent. At most two jobs per worker are in flight, so
  when a worker process dies (out of memory, a crash in a native library) the suspects are known:
  they are retried one at a time, and a log that kills its worker twice is recorded as failed.
- :class:`DaskEngine` (``--scheduler tcp://HOST:PORT``): the same jobs on an existing Dask
  distributed cluster via ``distributed.Client(address)``. Workers need only the installed
  mountcal and the log files at the same paths (a shared file system). A task whose worker dies
  repeatedly comes back as ``KilledWorker`` and is recorded as failed.

Whatever the engine, each finished log is stored at once (:class:`~mountcal.fleet.store.PartStore`),
so a killed run loses at most the logs in flight.
"""

from __future__ import annotations

import contextlib
import importlib
import itertools
import multiprocessing
import os
import secrets
import threading
import time
from collections import deque
from collections.abc import Iterable, Iterator, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, CancelledError, Future, ProcessPoolExecutor, ThreadPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import pandas as pd

from mountcal.errors import InputError, MountcalError
from mountcal.fleet.inputs import FleetJob
from mountcal.fleet.progress import Progress
from mountcal.fleet.store import (
    LOG_COLUMNS,
    VEHICLE_COLUMNS,
    PartStore,
    check_overwritable,
    job_hash,
    schema,
    software_version,
    write_table,
)
from mountcal.fleet.vehicles import ALPHA, analyse_fleet
from mountcal.fleet.worker import run_job

THREAD_VARIABLES = (
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS",
)
QUEUED_PER_WORKER = 2  # jobs in flight per worker: one running, one waiting (no idle gap between logs)
MAX_WORKER_DEATHS = 2  # a log in flight when its worker died this often is recorded as failed
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
    """

    workers: int | None = None
    scheduler: str | None = None
    retry_failed: bool = False
    progress: bool = True
    alpha: float = ALPHA
    floor_deg: float = 0.0


@dataclass(frozen=True)
class FleetResult:
    """What a fleet run produced.

    Attributes
    ----------
    logs, vehicles : DataFrame
        The tables written to ``output`` and ``vehicles_path``.
    computed : int
        Logs calibrated by this run.
    reused : int
        Logs whose results an earlier run had stored.
    engine : str
    elapsed_s : float
    discarded : dict of str to int
        What the run set aside, by reason (duplicate inputs, a killed run's temporary files,
        unreadable part files).
    """

    logs: pd.DataFrame
    vehicles: pd.DataFrame
    output: Path
    vehicles_path: Path
    parts: Path
    computed: int
    reused: int
    engine: str
    elapsed_s: float
    discarded: dict[str, int] = field(default_factory=dict)


def outputs_of(output: str | Path) -> tuple[Path, Path, Path]:
    """The per-log table, the per-vehicle table beside it, and the folder of part files."""
    output = Path(output)
    return output, output.with_name(f"{output.stem}_vehicles{output.suffix}"), output.with_name(output.name + ".parts")


class Engine(Protocol):
    """Runs :func:`~mountcal.fleet.worker.run_job` on jobs and yields (key, record) as each finishes.

    ``results`` takes (key, job) pairs lazily, so the caller can hash the logs while the first
    ones are being calibrated. ``start`` may begin setting up in the background; ``results`` starts
    it if needed; ``close`` releases the workers. Engines are context managers.
    """

    name: str

    def start(self) -> None: ...

    def results(self, jobs: Iterable[tuple[str, FleetJob]]) -> Iterator[tuple[str, dict[str, Any]]]: ...

    def close(self) -> None: ...

    def __enter__(self) -> Engine: ...

    def __exit__(self, *exc: object) -> None: ...


def engine_failure(err: BaseException, what: str) -> dict[str, Any]:
    """The record of a log the engine could not run (not stored: the next run retries it)."""
    kind = f"{type(err).__module__}.{type(err).__qualname__}"
    return {"status": "failed", "error": f"{what} ({kind}: {err})", "error_type": kind, "_transient": True}


class LocalEngine:
    """Worker processes on this machine (see the module docstring)."""

    def __init__(self, workers: int | None = None) -> None:
        if workers is not None and workers < 1:
            raise InputError("--workers", "a number of worker processes ≥ 1", str(workers), "Pass --workers 1 or more.")
        available = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
        self.workers = workers or available or 1
        self.name = f"local, {self.workers} worker process{'es' if self.workers > 1 else ''}"
        self._pool: ProcessPoolExecutor | None = None
        self._starting: threading.Thread | None = None
        self._start_error: BaseException | None = None
        self._saved_env: dict[str, str | None] | None = None

    def __enter__(self) -> LocalEngine:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def start(self) -> None:
        """Start the workers in a background thread (the forkserver imports mountcal meanwhile)."""
        if self._starting is not None:
            return
        # children started from now on inherit one BLAS/OpenMP thread each (no oversubscription)
        self._saved_env = {k: os.environ.get(k) for k in THREAD_VARIABLES}
        os.environ.update({k: "1" for k in THREAD_VARIABLES})
        self._starting = threading.Thread(target=self._warm_up, name="mountcal-fleet-start", daemon=True)
        self._starting.start()

    def _warm_up(self) -> None:
        try:
            self._pool = self._new_pool()
            for _ in range(self.workers):  # each submit to a pool without an idle worker forks one
                self._pool.submit(os.getpid)
        except BaseException as err:  # re-raised by results()
            self._start_error = err

    def close(self) -> None:
        """Stop the workers and restore the environment."""
        if self._starting is not None:
            self._starting.join()
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None
        if self._saved_env is not None:
            for k, v in self._saved_env.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v
            self._saved_env = None
        self._starting = None

    def results(self, jobs: Iterable[tuple[str, FleetJob]]) -> Iterator[tuple[str, dict[str, Any]]]:
        source = iter(jobs)
        first = next(source, None)
        if first is None:  # nothing to calibrate: no workers needed
            return
        source = itertools.chain([first], source)
        self.start()
        assert self._starting is not None
        self._starting.join()
        if self._start_error is not None:
            raise self._start_error
        by_key: dict[str, FleetJob] = {}
        suspects: deque[str] = deque()
        deaths: dict[str, int] = {}
        inflight: dict[Future[dict[str, Any]], str] = {}
        exhausted = False
        while not exhausted or suspects or inflight:
            pool = self._pool
            assert pool is not None
            if suspects:  # after a worker died, run each suspect alone to find the culprit
                if not inflight:
                    key = suspects.popleft()
                    inflight[pool.submit(run_job, by_key[key])] = key
            else:
                while not exhausted and len(inflight) < QUEUED_PER_WORKER * self.workers:
                    pair = next(source, None)  # pulls (and hashes) the next log only when a worker needs it
                    if pair is None:
                        exhausted = True
                    else:
                        by_key[pair[0]] = pair[1]
                        inflight[pool.submit(run_job, pair[1])] = pair[0]
            if not inflight:
                continue
            done, _ = wait(inflight, return_when=FIRST_COMPLETED)
            broken = any(isinstance(f.exception(), BrokenProcessPool) for f in done)
            if broken:  # a dead worker fails the whole pool: collect every job in flight
                done = wait(inflight).done
            for future in done:
                key = inflight.pop(future)
                error = future.exception()
                if error is None:
                    by_key.pop(key, None)
                    yield key, future.result()
                elif not isinstance(error, BrokenProcessPool):  # e.g. a job that does not pickle
                    yield key, engine_failure(error, "the worker pool could not run this log")
                else:
                    deaths[key] = deaths.get(key, 0) + 1
                    if deaths[key] < MAX_WORKER_DEATHS:
                        suspects.append(key)
                    else:
                        what = (
                            f"the worker process died {deaths[key]} times while calibrating this log "
                            "(out of memory, or a crash in a native library)"
                        )
                        yield key, engine_failure(error, what)
            if broken:
                pool.shutdown(wait=True, cancel_futures=True)
                self._pool = self._new_pool()

    def _new_pool(self) -> ProcessPoolExecutor:
        return ProcessPoolExecutor(max_workers=self.workers, mp_context=worker_context())


def worker_context() -> multiprocessing.context.BaseContext:
    """``forkserver`` with mountcal preloaded where there is one (workers start in milliseconds after
    the first), else ``spawn``; never a plain ``fork`` of a process that may hold threads."""
    if "forkserver" in multiprocessing.get_all_start_methods():
        context = multiprocessing.get_context("forkserver")
        context.set_forkserver_preload(["mountcal.fleet.worker"])
        return context
    return multiprocessing.get_context("spawn")


class DaskEngine:
    """An existing Dask distributed cluster (see the module docstring)."""

    def __init__(self, address: str, timeout_s: float = 20.0) -> None:
        self.address, self.timeout_s = address, timeout_s
        self.name = f"Dask scheduler {address}"
        self._client: Any = None
        self._distributed: Any = None

    def __enter__(self) -> DaskEngine:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def start(self) -> None:
        """Connect to the scheduler (before any log is hashed: an unreachable one fails at once)."""
        if self._client is not None:
            return
        try:
            self._distributed = importlib.import_module("distributed")  # optional: mountcal[fleet]
        except ImportError as err:
            raise InputError(
                "--scheduler",
                "the Dask distributed package",
                "it is not installed",
                "Install it: pip install 'mountcal[fleet]'; or run without --scheduler on the local cores.",
            ) from err
        try:
            self._client = self._distributed.Client(self.address, timeout=self.timeout_s, set_as_default=False)
        except (OSError, TimeoutError, ValueError) as err:
            raise InputError(
                f"--scheduler {self.address}",
                "a reachable Dask scheduler (tcp://HOST:PORT)",
                f"no connection ({type(err).__name__}: {err})",
                "Start one (`dask scheduler`, then `dask worker ADDRESS` on each machine) or check the address.",
            ) from err

    def close(self) -> None:
        if self._client is not None:
            with contextlib.suppress(Exception):
                self._client.close()
            self._client = None

    def results(self, jobs: Iterable[tuple[str, FleetJob]]) -> Iterator[tuple[str, dict[str, Any]]]:
        self.start()
        client = self._client
        token = secrets.token_hex(4)
        futures: dict[Any, str] = {}
        finished = self._distributed.as_completed([], loop=client.loop)
        try:
            for key, job in jobs:  # submit as the logs are hashed; collect what is already done meanwhile
                future = client.submit(run_job, job, key=f"mountcal-fleet-{token}-{key[:16]}", pure=False)
                futures[future] = key
                finished.add(future)
                while finished.has_ready():
                    yield from self._collect(finished.next_batch(block=False), futures)
            while not finished.is_empty():
                yield from self._collect(finished.next_batch(block=True), futures)
        except CancelledError as err:
            raise MountcalError(
                f"--scheduler {self.address}: lost the Dask scheduler ({err}); the logs finished so far are "
                "kept: run the same command again to resume."
            ) from err
        finally:
            with contextlib.suppress(Exception):
                client.cancel([f for f in futures if not f.done()])

    @staticmethod
    def _collect(batch: Iterable[Any], futures: dict[Any, str]) -> Iterator[tuple[str, dict[str, Any]]]:
        for future in batch:
            key = futures.pop(future)
            try:
                record = future.result()
            except (CancelledError, MountcalError):
                raise
            except Exception as err:  # KilledWorker and the like: this log, not the batch
                record = engine_failure(err, "the Dask cluster could not run this log")
            future.release()
            yield key, record


def make_engine(options: FleetOptions) -> Engine:
    """The engine the options ask for."""
    return DaskEngine(options.scheduler) if options.scheduler else LocalEngine(options.workers)


def run_fleet(jobs: Sequence[FleetJob], output: str | Path, options: FleetOptions | None = None) -> FleetResult:
    """Calibrate every job (skipping those an earlier run finished) and write the two tables.

    Parameters
    ----------
    jobs : sequence of FleetJob
        From :func:`mountcal.fleet.inputs.collect_jobs`.
    output : str or Path
        The per-log Parquet table; ``<stem>_vehicles.parquet`` and ``<output>.parts/`` go beside it.
    options : FleetOptions, optional

    Raises
    ------
    InputError
        The output is not ``.parquet`` or is one of the inputs; the scheduler is unreachable.
    """
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
    with make_engine(options) as engine:
        if len(stored) < len(jobs):  # likely work to do: start the workers while the first logs are hashed
            engine.start()
        try:
            for key, record in engine.results(todo()):
                if not record.pop("_transient", False):
                    store.save(key, record)
                results[key] = record
                progress.update(record.get("status") == "ok")
        finally:
            progress.finish()
    computed = len(pending)
    logs = _log_table(jobs, keys, setup_failures, results)
    logs, vehicles = analyse_fleet(logs, options.alpha, options.floor_deg)
    vehicles = _complete(vehicles, VEHICLE_COLUMNS)
    write_table(vehicles, schema(VEHICLE_COLUMNS, "vehicles"), vehicles_path)
    write_table(logs, schema(LOG_COLUMNS, "logs"), output)
    return FleetResult(
        logs=logs,
        vehicles=vehicles,
        output=output,
        vehicles_path=vehicles_path,
        parts=parts,
        computed=computed,
        reused=len({k for k in keys if k is not None}) - computed,
        engine=engine.name,
        elapsed_s=time.monotonic() - started,
        discarded={
            "inputs naming a log already listed": duplicates,
            "temporary files of a killed run": stale,
            "unreadable part files (their logs were recalculated)": unreadable,
        },
    )


def _check_output(output: Path, jobs: Sequence[FleetJob]) -> None:
    if output.suffix.lower() != ".parquet":
        raise InputError(
            str(output), "an output path ending in .parquet", output.suffix or "no suffix", "Name it fleet.parquet."
        )
    inputs = {Path(p) for job in jobs for p in job.job.paths}
    for table in outputs_of(output)[:2]:
        if table.resolve() in inputs:
            raise InputError(
                str(table),
                "an output path other than the inputs",
                "one of the logs",
                "Choose another -o path; mountcal never overwrites its input.",
            )
        check_overwritable(table)


def _hash_or_failure(job: FleetJob) -> tuple[str | None, dict[str, Any]]:
    """The job's content hash, or the record of why its files cannot be read (not stored)."""
    try:
        return job_hash(job), {}
    except MountcalError as err:
        return None, {"status": "failed", "error": str(err), "error_type": type(err).__name__}


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


def _complete(frame: pd.DataFrame, columns: Sequence[tuple[str, Any, str]]) -> pd.DataFrame:
    """The frame with every column of the table (missing ones null), in the table's order."""
    for name, _, _ in columns:
        if name not in frame.columns:
            frame[name] = None
    return frame[[name for name, _, _ in columns]]
