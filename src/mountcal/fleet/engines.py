"""Engines: where the logs of a fleet are calibrated.

- :class:`LocalEngine` (default): a :class:`concurrent.futures.ProcessPoolExecutor` on the local
  cores, started by a ``forkserver`` that has mountcal imported (``spawn`` where there is none),
  with one BLAS/OpenMP thread per worker (so N workers use N cores, not N²; mountcal's readers
  then use no helper threads either, :func:`mountcal.core.threads.helpers_allowed`). Chosen over a Dask
  ``LocalCluster`` because it needs no set-up, no ports and no optional dependency, starts in about
  a second, and its workers die with the parent. At most two jobs per worker are in flight, so
  when a worker process dies (out of memory, a crash in a native library) the suspects are known:
  they are retried one at a time, and a log that kills its worker twice is recorded as failed.
  Workers ignore Ctrl-C (the command handles it and stops them) and die with the command however
  it ends, SIGKILL included: each watches the command's process (a pidfd, else a poll) and kills
  itself when it is gone, so no worker outlives its run holding the terminal or a pipe.
- :class:`DaskEngine` (``--scheduler tcp://HOST:PORT``): the same jobs on an existing Dask
  distributed cluster via ``distributed.Client(address)``. Workers need only the installed
  mountcal (the command's version, as the scheduler: :mod:`mountcal.fleet.dask_cluster` checks on
  connecting) and the log files at the same paths (a shared file system) or in object storage. Jobs
  go to the workers as paths, never bytes, in batches sized so that a batch holds about
  :data:`BATCH_TARGET_S` of work (estimated from the logs done so far; smaller at the end, so that
  the workers finish together): a task costs the scheduler a few milliseconds, a log ~0.1 s. A
  batch whose worker dies repeatedly comes back as ``KilledWorker`` and its logs are recorded as failed.

This module imports nothing heavy, so that the command line can start the worker server
(:func:`start_worker_server`) before it imports mountcal's numerical code itself: the two imports
then run at the same time, on two cores.
"""

from __future__ import annotations

import contextlib
import ctypes
import importlib
import itertools
import multiprocessing
import multiprocessing.forkserver
import multiprocessing.popen_forkserver  # imported here, not by the thread that starts the workers: a
import multiprocessing.popen_spawn_posix  # Ctrl-C in the main thread's import could leave it waiting for good
import os
import secrets
import select
import signal
import threading
import time
from collections import deque
from collections.abc import Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, CancelledError, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import TYPE_CHECKING, Any, Protocol

from mountcal.core.atomic import raise_if_interrupted
from mountcal.core.errors import InputError, MountcalError
from mountcal.core.option_names import option
from mountcal.fleet.dask_cluster import WORKER_MODULE, look_at_cluster
from mountcal.fleet.scheduler_address import check_scheduler_address

if TYPE_CHECKING:
    from mountcal.fleet.inputs import FleetJob

SERVER_MODULE = "mountcal.fleet.server"  # imported first by the worker server: it ignores Ctrl-C
PASSED_VARIABLES = ("AWS_",)  # the workers see these as the command has them now (object storage)
THREAD_VARIABLES = (
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS",
)
WAKE_S = 0.25  # the longest a wait for the workers goes without looking for a dropped Ctrl-C
QUEUED_PER_WORKER = 2  # jobs in flight per worker: one running, one waiting (no idle gap between logs)
MAX_WORKER_DEATHS = 2  # a log in flight when its worker died this often is recorded as failed
BATCH_TARGET_S = 0.5  # Dask: work per task (a task costs the scheduler and the network milliseconds)
MAX_BATCH = 64
CLEANUP_WAIT_S = 5.0  # the longest kill() and close() together wait for the workers (well inside atomic.GRACE_S)
TRANSIENT = "_transient"  # in a record: not to be stored (the run removes it)
WATCH_PERIOD_S = 1.0  # where there is no pidfd, a worker checks this often whether the command lives


class Engine(Protocol):
    """Runs :func:`~mountcal.fleet.worker.run_job` on jobs and yields (key, record) as each finishes.

    ``results`` takes (key, job) pairs lazily, so the caller can hash the logs while the first
    ones are being calibrated. ``start`` may begin setting up in the background; ``results`` starts
    it if needed; ``close`` releases the workers. Engines are context managers.
    """

    name: str
    notes: tuple[str, ...]  # what the engine found worth saying about itself (e.g. a cluster's settings)

    def start(self) -> None: ...

    def results(self, jobs: Iterable[tuple[str, FleetJob]]) -> Iterator[tuple[str, dict[str, Any]]]: ...

    def close(self) -> None: ...

    def __enter__(self) -> Engine: ...

    def __exit__(self, *exc: object) -> None: ...


def _run_job(job: FleetJob) -> dict[str, Any]:
    """:func:`mountcal.fleet.worker.run_job`, submitted under this light module's name: the command sends
    the function by reference without importing all of mountcal first (≈ 1 s before the first log
    went out); the worker imports it once (the worker server, or a Dask preload, already has)."""
    from mountcal.fleet.worker import run_job

    return run_job(job)


def _run_batch(jobs: list[FleetJob]) -> list[dict[str, Any]]:
    """:func:`mountcal.fleet.worker.run_batch`, submitted by reference as :func:`_run_job` is."""
    from mountcal.fleet.worker import run_batch

    return run_batch(jobs)


def transient_failure(error: str, error_type: str) -> dict[str, Any]:
    """The record of a log that failed for a reason of the run, not of the log: the run does not
    store it (:data:`TRANSIENT`), so the next run tries the log again."""
    return {"status": "failed", "error": error, "error_type": error_type, TRANSIENT: True}


def engine_failure(err: BaseException, what: str) -> dict[str, Any]:
    """The record of a log the engine could not run (not stored: the next run retries it)."""
    kind = f"{type(err).__module__}.{type(err).__qualname__}"
    return transient_failure(f"{what} ({kind}: {err})", kind)


class LocalEngine:
    """Worker processes on this machine (see the module docstring)."""

    def __init__(self, workers: int | None = None) -> None:
        if workers is not None and workers < 1:
            raise InputError(
                option("workers", str(workers)), "a number of worker processes ≥ 1", str(workers), "Ask for 1 or more."
            )
        available = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
        self.workers = workers or available or 1
        self.name = f"local, {self.workers} worker process{'es' if self.workers > 1 else ''}"
        self.notes: tuple[str, ...] = ()
        self._pool: ProcessPoolExecutor | None = None
        self._starting: threading.Thread | None = None
        self._start_error: BaseException | None = None
        self._saved_env: dict[str, str | None] | None = None
        self._cleanup_until: float | None = None  # one budget for every wait of kill() and close()

    def __enter__(self) -> LocalEngine:
        return self

    def __exit__(self, *exc: object) -> None:
        if isinstance(exc[1], KeyboardInterrupt | SystemExit):
            self.kill()
        self.close()

    def kill(self) -> None:
        """Stop the workers now, logs in flight and all (an interrupted run: they are redone next time)."""
        if self._starting is not None:
            self._starting.join(self._cleanup_left())  # workers it has not started yet are not waited for
        processes = getattr(self._pool, "_processes", None) or {}
        for process in list(processes.values()):
            with contextlib.suppress(Exception):
                process.kill()

    def start(self) -> None:
        """Start the workers in a background thread (the forkserver imports mountcal meanwhile)."""
        if self._starting is not None:
            return
        self._saved_env = {k: os.environ.get(k) for k in THREAD_VARIABLES}
        start_worker_server()
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
            self._starting.join(self._cleanup_left())
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
            _forget_when_done(self._pool, self._cleanup_left())
            self._pool = None
        if self._saved_env is not None:
            for k, v in self._saved_env.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v
            self._saved_env = None
        self._starting = None
        self._cleanup_until = None

    def _cleanup_left(self) -> float:
        """Seconds left of the clean-up's one budget (started by the first wait of kill() or close())."""
        if self._cleanup_until is None:
            self._cleanup_until = time.monotonic() + CLEANUP_WAIT_S
        return max(0.0, self._cleanup_until - time.monotonic())

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
                    inflight[pool.submit(_run_job, by_key[key])] = key
            else:
                while not exhausted and len(inflight) < QUEUED_PER_WORKER * self.workers:
                    pair = next(source, None)  # pulls (and hashes) the next log only when a worker needs it
                    if pair is None:
                        exhausted = True
                    else:
                        by_key[pair[0]] = pair[1]
                        inflight[pool.submit(_run_job, pair[1])] = pair[0]
            if not inflight:
                continue
            done, _ = wait(inflight, timeout=WAKE_S, return_when=FIRST_COMPLETED)
            raise_if_interrupted()  # a Ctrl-C Python dropped in a callback ends the run all the same
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
        passed = {k: v for k, v in os.environ.items() if k.startswith(PASSED_VARIABLES) or k in THREAD_VARIABLES}
        return ProcessPoolExecutor(
            max_workers=self.workers,
            mp_context=worker_context(),
            initializer=worker_started,
            initargs=(os.getpid(), passed),
        )


def worker_started(parent: int, environment: dict[str, str]) -> None:
    """A worker's first act: ignore Ctrl-C, take the command's environment as it is now (the worker
    server may be older than a change to it), and watch the command to die with it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    with contextlib.suppress(OSError, AttributeError):  # glibc: recycle a log's arrays (see worker.heap_for_logs)
        libc = ctypes.CDLL(None)
        libc.mallopt(-3, 32 << 20)  # M_MMAP_THRESHOLD
        libc.mallopt(-1, 64 << 20)  # M_TRIM_THRESHOLD
    for key in [k for k in os.environ if k.startswith(PASSED_VARIABLES)]:
        os.environ.pop(key)
    os.environ.update(environment)
    threading.Thread(target=_die_with, args=(parent,), name="mountcal-parent-watch", daemon=True).start()


def _die_with(parent: int) -> None:
    """Return never: kill this process as soon as ``parent`` has ended (SIGKILL to it included)."""
    try:
        fd = os.pidfd_open(parent)
    except ProcessLookupError:
        fd = -1  # already gone
    except (AttributeError, OSError):  # no pidfd (not Linux ≥ 5.3): poll
        fd = None
    if fd is None:
        while True:
            time.sleep(WATCH_PERIOD_S)
            try:
                os.kill(parent, 0)
            except ProcessLookupError:
                break
            except PermissionError:  # alive, another user's: cannot be ours
                pass
    elif fd >= 0:
        select.select([fd], [], [])
    os.kill(os.getpid(), signal.SIGKILL)


def worker_context() -> multiprocessing.context.BaseContext:
    """``forkserver`` with mountcal preloaded where there is one (workers start in milliseconds after
    the first), else ``spawn``; never a plain ``fork`` of a process that may hold threads."""
    if "forkserver" in multiprocessing.get_all_start_methods():
        context = multiprocessing.get_context("forkserver")
        context.set_forkserver_preload([SERVER_MODULE, WORKER_MODULE])
        return context
    return multiprocessing.get_context("spawn")


def start_worker_server() -> None:
    """Set one BLAS/OpenMP thread for the worker processes to come and start the forkserver, which
    imports mountcal in the background; returns at once. Calling it again does nothing more.

    The variables are set in this process's environment, which the server and its workers inherit
    (:meth:`LocalEngine.close` restores them).
    """
    os.environ.update({k: "1" for k in THREAD_VARIABLES})
    if worker_context().get_start_method() == "forkserver":
        # started with Ctrl-C ignored, which Python then keeps: a Ctrl-C while the server (or a
        # worker forked from it) starts is the command's to handle, not a traceback of theirs
        with _sigint_ignored():
            multiprocessing.forkserver.ensure_running()


def _forget_when_done(pool: ProcessPoolExecutor, timeout_s: float) -> None:
    """Wait a little for the pool's manager thread and, once it has ended, drop it from the exit hook's
    list: CPython 3.11's hook writes to the thread's wake-up pipe even after the thread closed it
    (an "Exception ignored … Bad file descriptor" traceback after a Ctrl-C)."""
    import concurrent.futures.process as process

    thread = getattr(pool, "_executor_manager_thread", None)
    if thread is None:
        return
    thread.join(timeout_s)
    if not thread.is_alive():
        getattr(process, "_threads_wakeups", {}).pop(thread, None)


@contextlib.contextmanager
def _sigint_ignored() -> Iterator[None]:
    """SIGINT ignored in this process for the block (where signals can be set: the main thread)."""
    try:
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:  # not the main thread: the server's first import ignores it instead
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


class DaskEngine:
    """An existing Dask distributed cluster (see the module docstring)."""

    def __init__(self, address: str, timeout_s: float = 20.0) -> None:
        self.address, self.timeout_s = address, timeout_s
        self.name = f"Dask scheduler {address}"
        self.live_workers = 0  # the cluster's workers when last looked (the progress bar shows them)
        self.notes: tuple[str, ...] = ()
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
                option("scheduler", self.address),
                "the Dask distributed package",
                "it is not installed",
                "Install it: pip install 'mountcal[fleet]'; or run on the local cores (no scheduler).",
            ) from err
        check_scheduler_address(self.address)
        try:
            self._client = self._distributed.Client(self.address, timeout=self.timeout_s, set_as_default=False)
        except (OSError, TimeoutError, ValueError) as err:
            raise InputError(
                option("scheduler", self.address),
                "a reachable Dask scheduler (tcp://HOST:PORT)",
                f"no connection ({type(err).__name__}: {err})",
                "Start one (`dask scheduler`, then `dask worker ADDRESS` on each machine) or check the address.",
            ) from err
        try:
            self.notes = look_at_cluster(self._client, self.address)
        except InputError:
            self.close()
            raise

    def close(self) -> None:
        if self._client is not None:
            with contextlib.suppress(Exception):
                self._client.close()
            self._client = None

    def workers(self) -> int:
        """The cluster's workers now (at least 1: a cluster still starting is given time)."""
        try:
            return max(1, len(self._client.scheduler_info(n_workers=-1).get("workers", {})))
        except Exception:  # a scheduler too old for n_workers, or busy: the batching only needs a guess
            return max(1, len(self._client.scheduler_info().get("workers", {})))

    def results(self, jobs: Iterable[tuple[str, FleetJob]]) -> Iterator[tuple[str, dict[str, Any]]]:
        self.start()
        client = self._client
        token = secrets.token_hex(4)
        source = iter(jobs)
        waiting: deque[tuple[str, FleetJob]] = deque()  # hashed, not yet submitted
        alone: deque[tuple[str, FleetJob]] = deque()  # the logs of a failed batch, to be run one per task
        serial = itertools.count()  # task keys are unique, also for a log submitted again alone
        batches: dict[Any, list[tuple[str, FleetJob]]] = {}
        sizing = _BatchSizing()
        finished = self._distributed.as_completed([], loop=client.loop)
        exhausted = False
        workers, looked = self.workers(), time.monotonic()
        self.live_workers = workers
        try:
            while True:
                # keep two batches per worker queued; look ahead so that the last batches can be shrunk
                ahead = 2 * workers * sizing.size(MAX_BATCH * workers, False, workers) + 1
                while not exhausted and len(waiting) < ahead:
                    pair = next(source, None)
                    if pair is None:
                        exhausted = True
                    else:
                        waiting.append(pair)
                while (alone or waiting) and len(batches) < 2 * workers:
                    if alone:
                        batch = [alone.popleft()]
                    else:
                        size = sizing.size(len(waiting), exhausted, workers)
                        batch = [waiting.popleft() for _ in range(min(size, len(waiting)))]
                    name = f"mountcal-fleet-{token}-{next(serial)}-{batch[0][0][:16]}"
                    future = client.submit(_run_batch, [job for _, job in batch], key=name, pure=False)
                    batches[future] = batch
                    finished.add(future)
                if not batches:
                    break
                for future in finished.next_batch(block=True):
                    batch = batches.pop(future)
                    records = self._records(future, len(batch))
                    if records is None and len(batch) > 1:  # a batch whose worker died: find which log, alone
                        future.release()
                        alone.extend(batch)
                        continue
                    for (key, _), record in zip(batch, records or self._failures(future, len(batch)), strict=True):
                        sizing.done(record)
                        yield key, record
                if time.monotonic() - looked > WATCH_PERIOD_S:  # the cluster may grow or shrink
                    workers, looked = self.workers(), time.monotonic()
                    self.live_workers = workers
        except CancelledError as err:
            raise MountcalError(
                f"{self.address}: lost the Dask scheduler ({err}); the logs finished so far are "
                "kept: run the same command again to resume."
            ) from err
        finally:
            with contextlib.suppress(Exception):
                client.cancel([f for f in batches if not f.done()])

    @staticmethod
    def _records(future: Any, n: int) -> list[dict[str, Any]] | None:
        """The batch's records; None when the cluster could not run it (KilledWorker and the like)."""
        try:
            records = future.result()
        except (CancelledError, MountcalError):
            raise
        except Exception:  # these logs, not the run
            return None
        future.release()
        return list(records)

    @staticmethod
    def _failures(future: Any, n: int) -> list[dict[str, Any]]:
        error = future.exception()
        future.release()
        return [engine_failure(error, "the Dask cluster could not run this log")] * n


class _BatchSizing:
    """How many logs a Dask task takes: about BATCH_TARGET_S of work at the rate seen so far (one log
    until a log has been timed), and at the end no more than an even share of what is left, so that
    the workers finish together."""

    def __init__(self) -> None:
        self.seconds = 0.0
        self.logs = 0

    def done(self, record: dict[str, Any]) -> None:
        elapsed = record.get("elapsed_s")
        if isinstance(elapsed, float | int):
            self.seconds += float(elapsed)
            self.logs += 1

    def size(self, waiting: int, exhausted: bool, workers: int) -> int:
        if not self.logs:
            return 1
        per_log = max(self.seconds / self.logs, 1e-3)
        size = int(min(MAX_BATCH, max(1, BATCH_TARGET_S / per_log)))
        if exhausted:  # the tail: at most a share of what is left for each of two batches per worker
            size = min(size, max(1, waiting // (2 * workers)))
        return size


def make_engine(workers: int | None = None, scheduler: str | None = None) -> Engine:
    """A Dask engine for a scheduler address, else local worker processes."""
    return DaskEngine(scheduler) if scheduler else LocalEngine(workers)


__all__ = [
    "DaskEngine",
    "Engine",
    "LocalEngine",
    "engine_failure",
    "make_engine",
    "start_worker_server",
    "transient_failure",
]
