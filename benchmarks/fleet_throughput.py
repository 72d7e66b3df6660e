"""Throughput of ``mountcal fleet``: 200 simulated logs in mixed formats, 1 → 2 workers on the local
engine and on a Dask LocalCluster side by side, and the cost model of docs/performance-fleet.md.

The fleet: 20 vehicles × 10 parking sessions of 5.5 minutes each (12 headings 30° apart, 20 s
stops, 200 Hz IMU, 65 600 samples), written by real writers in turn as a CSV sample table, a
Parquet sample table and a ROS 2 MCAP (``mcap_ros2.writer``, with its protocol sheet). Every
vehicle has its own mounting; vehicle ``v07`` is remounted by 2° after its fifth log.

Each configuration is timed end to end as a user runs it — a fresh ``mountcal fleet`` process
(``python -m mountcal``) writing a fresh output, so interpreter start, imports, hashing, worker
start-up, the calibrations and the consolidation are all inside:

1. ``--workers 1``;
2. ``--workers 2``;
3. ``--scheduler`` to a Dask ``LocalCluster(n_workers=1, threads_per_worker=1, processes=True)``
   with the settings docs/fleet.md gives for fleets (``FLEET_DASK_CONFIG``: the workers' profiler
   off, the monitors polled less often; mountcal preloaded in the workers) — ``--dask-defaults``
   runs it on Dask's defaults instead;
4. the same with ``n_workers=2``.

Each cluster is started just before its run and closed after it (its start-up is reported
separately: it is the cluster owner's cost); no cluster exists during the local runs (an idle one's
heartbeats would load them). The four runs of a repetition are back to back, so a slow moment of the
machine hits all alike; the speed-up 1 → 2 workers of each engine is given best over best, median
over median, and paired within repetitions. The four configurations must write identical tables
(``elapsed_s`` aside) and ``v07`` must be the only vehicle flagged as remounted.

Then the engines alone (workers started and warm, logs hashed: submitting the 200 jobs to the last
result), and the **cost model** ``T(W) = a + s·N + (Σ_i (c_log + c_byte·bytes_i) + n_tasks·c_task) / W``:
a fixed part ``a`` and a serial part per log ``s`` of the command (start, hashing, storing,
consolidation) from resumed runs (everything stored) on the whole fleet and on one vehicle; the
work per log and per byte from a least-squares fit of each log's calibration time (one worker) on
its size; the engines' overhead per task from no-op tasks. Its predictions of the four runs are
printed beside the measured medians, with its prediction for 10 000 vehicles × 100 sessions on a
32-worker cluster.

Run from the repository root::

    .venv/bin/python benchmarks/fleet_throughput.py --runs 5 --workdir /tmp/fleet-bench

``--workdir DIR`` keeps the generated fleet (it is reused when its parameters match).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd

T0_UNIX_S = 1_714_557_600  # 2024-05-01T10:00:00Z
UPHILL_AZIMUTH_DEG = 30.0  # simulate_parking_log's default
REMOUNTED = "v07"
KINDS = ("csv", "parquet", "mcap")
RATE_HZ = 200.0
RESUMED_RUNS = 5  # resumed runs of each size for the serial cost per log (interleaved)


def write_log(path: str, kind: str, angles: tuple[float, float, float], seed: int, day: int) -> None:
    """One 5.5-minute parking session as a sample table or an MCAP log (with its protocol sheet)."""
    from mountcal.simulate.stops import simulate_parking_log

    log = simulate_parking_log(
        *angles, beta_deg=tuple(range(0, 360, 30)), stop_s=20.0, drive_s=8.0, rate_hz=RATE_HZ, seed=seed
    )
    if kind in ("csv", "parquet"):
        frame = pd.DataFrame(
            {
                "t_s": log.t_s,
                "ax": log.acc_s[:, 0],
                "ay": log.acc_s[:, 1],
                "az": log.acc_s[:, 2],
                "gx": log.gyro_s[:, 0],
                "gy": log.gyro_s[:, 1],
                "gz": log.gyro_s[:, 2],
                "speed_mps": log.speed_mps,
                "heading_deg": log.heading_deg,
                "temperature_c": log.temperature_c,
            }
        )
        if kind == "csv":
            frame.to_csv(path, index=False, float_format="%.7g")
        else:
            frame.to_parquet(path)
        return
    from mountcal.io import writers as export

    start_s = T0_UNIX_S + day * 86_400
    export.write_mcap(path, log, with_temperature=False, with_odometry=False, start_time_s=start_s)
    export.write_protocol(Path(path).with_name(Path(path).stem + ".protocol.csv"), log, start_time_s=start_s)


def generate(folder: Path, n_logs: int, n_vehicles: int) -> None:
    """Write the fleet (in parallel: it is set-up, not the measurement)."""
    stamp = folder / "fleet.json"
    params = {"n_logs": n_logs, "n_vehicles": n_vehicles, "rate_hz": RATE_HZ, "version": 3}
    if stamp.exists() and json.loads(stamp.read_text()) == params:
        return
    shutil.rmtree(folder, ignore_errors=True)
    rng = np.random.default_rng(2011)
    tasks = []
    for v in range(n_vehicles):
        vehicle = f"v{v:02d}"
        (folder / "logs" / vehicle).mkdir(parents=True)
        angles = tuple(float(a) for a in rng.uniform(-8, 8, 3))
        per = n_logs // n_vehicles
        for i in range(per):
            mount = angles
            if vehicle == REMOUNTED and i >= per // 2:
                mount = (angles[0] + 2.0, angles[1], angles[2])
            kind = KINDS[(v + i) % 3]
            path = folder / "logs" / vehicle / f"session_{i:02d}.{kind}"
            tasks.append((str(path), kind, mount, 1000 * v + i, i))
    with ProcessPoolExecutor(os.cpu_count()) as pool:
        for future in [pool.submit(write_log, *t) for t in tasks]:
            future.result()
    stamp.write_text(json.dumps(params))


def run_cli(logs: Path, output: Path, extra: list[str]) -> float:
    """Wall time of one ``mountcal fleet`` process writing a fresh output."""
    for stale in (
        output,
        output.with_name(output.stem + "_vehicles.parquet"),
        output.with_name(output.name + ".parts"),
    ):
        shutil.rmtree(stale, ignore_errors=True) if stale.is_dir() else stale.unlink(missing_ok=True)
    command = [sys.executable, "-m", "mountcal", "fleet", str(logs), "-o", str(output), "-q"]
    command += ["--uphill-azimuth-deg", str(UPHILL_AZIMUTH_DEG), *extra]
    started = time.perf_counter()
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - started


def installed_bytecode() -> str:
    """Compile mountcal's modules as ``pip install`` does: an editable install run with
    PYTHONDONTWRITEBYTECODE set (this machine's shell) would otherwise compile every module from
    source in every process — the command, the worker server, each Dask worker — which no user's
    installed package does."""
    import compileall

    import mountcal

    folder = Path(mountcal.__file__).parent
    ok = compileall.compile_dir(folder, quiet=1, workers=0)
    return f"mountcal's bytecode: {'compiled' if ok else 'NOT all compiled'} in {folder} (as an install has it)"


ENGINE_RUNS = 3
TASK_PROBES = 200


def report(title: str, times: dict[str, list[float]], n_logs: int, busy: dict[str, list[float]] | None = None) -> None:
    """Per configuration: best and median wall time, and the speed-up over the same engine's one
    worker best over best, median over median, and paired (the median over repetitions of the
    one-worker time over this time in the same repetition)."""
    print(f"{title}:")
    head = f"  {'configuration':<30} {'best s':>7} {'logs/s':>7} {'speed-up':>8} {'median s':>9} {'speed-up':>8}"
    print(head + f" {'paired':>7}" + (f" {'busy s':>7}" if busy else ""), "  runs (s)")
    for name, values in times.items():
        one = times[name.replace("2 workers", "1 worker")]
        best0, median0 = min(one), statistics.median(one)
        best, median = min(values), statistics.median(values)
        paired = statistics.median(a / b for a, b in zip(one, values, strict=True))
        line = f"  {name:<30} {best:>7.1f} {n_logs / best:>7.2f} {best0 / best:>7.2f}×"
        line += f" {median:>9.1f} {median0 / median:>7.2f}× {paired:>6.2f}×"
        if busy:
            line += f" {statistics.median(busy[name]):>7.1f}"
        print(line, "  " + ", ".join(f"{v:.1f}" for v in values))


def cluster_cpu() -> tuple[float, float]:
    """CPU seconds so far of this process (a LocalCluster's scheduler and nannies run in it) and of
    its child processes (the cluster's workers; the timed command has ended when this is read)."""
    import psutil

    me = psutil.Process()
    workers = 0.0
    for child in me.children(recursive=True):
        with contextlib.suppress(psutil.Error):
            workers += sum(child.cpu_times()[:2])
    return sum(me.cpu_times()[:2]), workers


def cluster_monitoring(
    times: dict[str, list[float]], busy: dict[str, list[float]], cpu: dict[str, list[tuple[float, float]]]
) -> tuple[float, float]:
    """The Dask cluster's own CPU per second of a run, from the one-worker runs (whose worker has a core
    of its own, so its logs' wall time is their CPU time): (each worker beyond its logs, the
    scheduler and nannies)."""
    name = "Dask LocalCluster, 1 worker"
    worker = [(c[1] - b) / t for c, b, t in zip(cpu[name], busy[name], times[name], strict=True)]
    scheduler = [c[0] / t for c, t in zip(cpu[name], times[name], strict=True)]
    return max(0.0, statistics.median(worker)), statistics.median(scheduler)


def workers_of(name: str) -> int:
    return 2 if "2 workers" in name else 1


def engine_only(logs: Path, name: str, address: str | None) -> list[float]:
    """Seconds from submitting every job to the last result, on warm workers (no storing, no tables)."""
    from mountcal.fleet import DaskEngine, JobDefaults, LocalEngine, collect_jobs
    from mountcal.fleet.store import job_hash

    jobs = collect_jobs([logs], JobDefaults(uphill_azimuth_deg=UPHILL_AZIMUTH_DEG))
    todo = {job_hash(j): j for j in jobs}
    warm = dict(list(todo.items())[:4])
    engine = DaskEngine(address) if address else LocalEngine(workers_of(name))
    times = []
    with engine:
        for _ in engine.results(warm.items()):
            pass
        for _ in range(ENGINE_RUNS):
            started = time.perf_counter()
            records = [record for _, record in engine.results(todo.items())]
            times.append(time.perf_counter() - started)
            assert all(r["status"] == "ok" for r in records)
    return times


@contextlib.contextmanager
def dask_cluster(startup_s: list[float], workers: int) -> Iterator[str]:
    """A fresh LocalCluster (single-threaded worker processes) for one configuration's runs only;
    its start-up time is appended to ``startup_s``."""
    import dask
    from distributed import LocalCluster

    started = time.perf_counter()
    # the nannies hand this configuration to their worker processes
    from mountcal.fleet.dask_cluster import FLEET_DASK_CONFIG, WORKER_MODULE

    fleet = {**FLEET_DASK_CONFIG, "distributed.worker.preload": [WORKER_MODULE]}  # as docs/fleet.md starts one
    with (
        dask.config.set({} if DASK_DEFAULTS[0] else fleet),
        LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster,
    ):
        startup_s.append(time.perf_counter() - started)
        yield cluster.scheduler_address


DASK_DEFAULTS = [False]  # --dask-defaults: the clusters on Dask's default settings, not docs/fleet.md's


def cluster_for(name: str, startup_s: list[float]) -> contextlib.AbstractContextManager[str | None]:
    if name.startswith("Dask"):
        return dask_cluster(startup_s, workers_of(name))
    return contextlib.nullcontext()


def _noop(x: int) -> int:
    return x


def task_overhead() -> dict[str, float]:
    """Seconds per no-op task, all submitted at once: the local pool, and a one-worker Dask cluster."""
    from distributed import Client

    from mountcal.fleet.engines import worker_context

    out = {}
    with ProcessPoolExecutor(1, mp_context=worker_context()) as pool:
        pool.submit(_noop, 0).result()
        started = time.perf_counter()
        for f in [pool.submit(_noop, i) for i in range(TASK_PROBES)]:
            f.result()
        out["local"] = (time.perf_counter() - started) / TASK_PROBES
    with dask_cluster([], 1) as address, Client(address) as client:
        client.submit(_noop, -1).result()
        started = time.perf_counter()
        client.gather([client.submit(_noop, i, pure=False) for i in range(TASK_PROBES)])
        out["dask"] = (time.perf_counter() - started) / TASK_PROBES
    return out


def resumed_run(inputs: list[Path], output: Path, engine: tuple[str, ...] = ("--workers", "1")) -> float:
    """Wall time of a `mountcal fleet` run that finds every log already stored: the serial part."""
    command = [sys.executable, "-m", "mountcal", "fleet", *map(str, inputs), "-o", str(output), "-q", *engine]
    command += ["--uphill-azimuth-deg", str(UPHILL_AZIMUTH_DEG)]
    started = time.perf_counter()
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - started


def cost_model(
    logs: Path,
    output: Path,
    times: dict[str, list[float]],
    overhead: dict[str, float],
    monitoring: tuple[float, float],
) -> None:
    """Fit the model's constants, print its predictions beside the measured medians, and extrapolate."""
    from mountcal.fleet.engines import BATCH_TARGET_S

    table = pd.read_parquet(output)  # a one-worker run: every log stored, its calibration time measured alone
    vehicles = sorted(p for p in logs.iterdir() if p.is_dir())
    # s from the whole fleet against one vehicle (the same parts: nothing computed), interleaved so
    # that a slow spell hits both; half the fleet against all of it left ±0.2 s of noise on 100 logs,
    # ±2 ms per log, and moved the 10 000-vehicle prediction by a factor of 2.5 between runs
    few = vehicles[:1]
    n_all = len(table)
    n_few = int(table["vehicle_id"].isin([v.name for v in few]).sum())
    pairs = [(resumed_run([logs], output), resumed_run(few, output)) for _ in range(RESUMED_RUNS)]
    t_all, t_few = (statistics.median(t) for t in zip(*pairs, strict=True))
    s = max(0.0, statistics.median(ta - tf for ta, tf in pairs) / (n_all - n_few))  # < 0 only when noise dominates
    a = t_all - s * n_all
    with dask_cluster([], 1) as address:  # the Dask command's own fixed cost: importing distributed, connecting
        a_dask = statistics.median(resumed_run([logs], output, ("--scheduler", address)) for _ in range(3)) - s * n_all
    sizes = np.array([sum(Path(p).stat().st_size for p in str(log).split(" + ")) for log in table["log"]], dtype=float)
    from scipy.optimize import nnls

    scale = sizes.mean()  # fit in units of the mean log, then back to per byte (a well-conditioned problem)
    design = np.column_stack([np.ones_like(sizes), sizes / scale])
    (c_log, c_mean), _ = nnls(design, table["elapsed_s"].to_numpy(float))  # neither cost can be negative
    c_byte = c_mean / scale
    work = float(np.sum(c_log + c_byte * sizes))
    per_log = work / n_all
    batch = max(1.0, BATCH_TARGET_S / per_log)
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    m_worker, m_scheduler = monitoring
    print("cost model: T(W) = a + max(s·N + R/W, (s·N + R) / (C − m·W − m_s))")
    print("  R = Σ (c_log + c_byte·bytes) + n_tasks·c_task: the workers' work")
    print("  (the first term: each worker has a core; the second: W workers, the cluster's monitoring and the")
    print(f"  command share the machine's C = {cores} cores)")
    resumed = f"resumed, medians of {RESUMED_RUNS}: {t_all:.2f} s for {n_all}, {t_few:.2f} s for {n_few}"
    print(f"  a = {a:.2f} s local, {a_dask:.2f} s Dask; s = {1e3 * s:.2f} ms per log ({resumed})")
    print(
        f"  c_log = {1e3 * c_log:.1f} ms, c_byte = {1e9 * c_byte:.0f} ms/GB "
        f"(mean log {sizes.mean() / 1e6:.2f} MB: {1e3 * per_log:.0f} ms of work)"
    )
    local, dask = 1e3 * overhead["local"], 1e3 * overhead["dask"]
    print(f"  c_task = {local:.2f} ms local, {dask:.2f} ms Dask ({batch:.0f} logs a task)")
    print(
        f"  m = {m_worker:.3f} CPU s per s per Dask worker beyond its logs, m_s = {m_scheduler:.3f} for the "
        "scheduler and nannies (measured in the one-worker Dask runs; 0 for the local engine)"
    )
    print(f"  {'configuration':<30} {'predicted':>10} {'measured':>9} {'error':>7}")
    for name, values in times.items():
        dask = name.startswith("Dask")
        tasks, c_task = (n_all / batch, overhead["dask"]) if dask else (n_all, overhead["local"])
        w = workers_of(name)
        rest = (work + tasks * c_task, cores - (m_worker * w + m_scheduler if dask else 0.0))
        predicted = (a_dask if dask else a) + max(s * n_all + rest[0] / w, (s * n_all + rest[0]) / rest[1])
        measured = statistics.median(values)
        print(f"  {name:<30} {predicted:>9.1f}s {measured:>8.1f}s {100 * (predicted / measured - 1):>+6.0f}%")
    n, w = 10_000 * 100, 32
    tasks = n / batch
    parallel = (n * per_log + tasks * overhead["dask"]) / w
    scheduler = tasks * overhead["dask"]  # the scheduler and the command see every task one at a time
    serial = a_dask + s * n
    print(
        f"  10 000 vehicles × 100 sessions of these logs on {w} Dask workers: "
        f"{(serial + max(parallel, scheduler)) / 3600:.2f} h "
        f"= serial {serial / 3600:.2f} h + workers {parallel / 3600:.2f} h "
        f"(the scheduler's {scheduler / 3600:.2f} h for {tasks:.0f} tasks runs beside them)"
    )


def same(a: tuple[pd.DataFrame, pd.DataFrame], b: tuple[pd.DataFrame, pd.DataFrame]) -> bool:
    """Whether two runs wrote the same tables (bit for bit)."""
    try:
        for x, y in zip(a, b, strict=True):
            pd.testing.assert_frame_equal(x, y, check_exact=True)
    except AssertionError:
        return False
    return True


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--logs", type=int, default=200)
    parser.add_argument("--vehicles", type=int, default=20)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--workdir", type=Path, default=None, help="keep the generated fleet here")
    parser.add_argument(
        "--dask-defaults",
        action="store_true",
        help="run the Dask clusters on Dask's default settings, not those docs/fleet.md gives for fleets",
    )
    args = parser.parse_args(argv)
    DASK_DEFAULTS[0] = args.dask_defaults

    workdir = args.workdir or Path(tempfile.mkdtemp(prefix="mountcal-fleet-"))
    try:
        print(installed_bytecode())
        started = time.perf_counter()
        generate(workdir, args.logs, args.vehicles)
        logs = workdir / "logs"
        size = sum(p.stat().st_size for p in logs.rglob("*") if p.is_file())
        print(
            f"fleet: {args.logs} logs, {size / 1e6:.0f} MB in {logs} (ready in {time.perf_counter() - started:.0f} s)"
        )
        configs = {
            "local, 1 worker": ["--workers", "1"],
            "local, 2 workers": ["--workers", "2"],
            "Dask LocalCluster, 1 worker": ["--scheduler"],
            "Dask LocalCluster, 2 workers": ["--scheduler"],
        }
        times: dict[str, list[float]] = {name: [] for name in configs}
        busy: dict[str, list[float]] = {name: [] for name in configs}
        cluster_cpu_s: dict[str, list[tuple[float, float]]] = {name: [] for name in configs}
        loads: list[float] = []
        cluster_s: list[float] = []
        mismatches: list[str] = []
        tables: dict[str, tuple[pd.DataFrame, pd.DataFrame]] = {}
        for rep in range(args.runs):
            for k, (name, extra) in enumerate(configs.items()):
                output = workdir / f"out{k}" / "fleet.parquet"
                with cluster_for(name, cluster_s) as address:
                    loads.append(os.getloadavg()[0])
                    before = cluster_cpu()
                    times[name].append(run_cli(logs, output, extra + ([address] if address else [])))
                    after = cluster_cpu()
                cluster_cpu_s[name].append(tuple(b - a for a, b in zip(before, after, strict=True)))
                tables[name] = (
                    pd.read_parquet(output).drop(columns="elapsed_s"),
                    pd.read_parquet(output.with_name("fleet_vehicles.parquet")),
                )
                busy[name].append(float(pd.read_parquet(output, columns=["elapsed_s"])["elapsed_s"].sum()))
            mismatches += [
                f"run {rep + 1}: {name}" for name in configs if not same(tables[name], tables["local, 1 worker"])
            ]
        engine_s = {}
        for name in configs:
            with cluster_for(name, cluster_s) as address:
                engine_s[name] = engine_only(logs, name, address)
        reference_logs, reference_vehicles = tables["local, 1 worker"]
        ok = int((reference_logs["status"] == "ok").sum())
        remounted = sorted(reference_vehicles.loc[reference_vehicles["n_remounts"] > 0, "vehicle_id"])
        settings = "Dask's defaults (--dask-defaults)" if args.dask_defaults else "docs/fleet.md's for fleets"
        print(f"Dask clusters' settings: {settings}")
        print(f"Dask LocalCluster start-up (not in the runs, median): {statistics.median(cluster_s):.1f} s")
        print(f"{ok}/{len(reference_logs)} logs ok; remounts flagged: {remounted}")
        print(f"tables identical across the configurations of each run: {'yes' if not mismatches else mismatches}")
        shown = ", ".join(f"{x:.1f}" for x in loads)
        print(f"1-minute load average before each run: {shown} (on {os.cpu_count()} cores)")
        report("end to end (a fresh `mountcal fleet` process per run)", times, args.logs, busy)
        print("busy s: the logs' calibration times summed (median); it grows when the workers do not get a")
        print("core each (another load on the machine), and the speed-up falls with it.")
        report("engines alone (warm workers, hashed logs)", engine_s, args.logs)
        monitoring = cluster_monitoring(times, busy, cluster_cpu_s)
        cost_model(logs, workdir / "out0" / "fleet.parquet", times, task_overhead(), monitoring)
        return 0 if remounted == [REMOUNTED] and ok == args.logs and not mismatches else 1
    finally:
        if args.workdir is None:
            shutil.rmtree(workdir, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
