"""What a second busy core costs one fleet worker on this machine, without mountcal's command or engines.

A forkserver pool runs :func:`mountcal.fleet.worker.run_job` (the work of one log in a fleet) on a
slice of the fleet benchmark's logs: one process alone, then two processes at once, each on its own
slice, then the second slice alone. Each process reports its wall time and its CPU time (user + system)
after one warm-up log. When two at once take longer in wall time than in CPU time, the processes wait
for a core (the machine's own threads); when they take more CPU than alone, they slow each other
(caches, memory). Either bounds the 1 → 2 worker speed-up of any engine.

Run from the repository root, after ``benchmarks/fleet_throughput.py --workdir /tmp/fleet-bench``
has generated the logs::

    .venv/bin/python benchmarks/core_contention.py --logs /tmp/fleet-bench/logs --repeats 2
"""

from __future__ import annotations

import argparse
import os
import resource
import time
from multiprocessing import get_context
from pathlib import Path

THREADS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")  # one BLAS thread, as the workers


def _work(args: tuple[str, int, int]) -> tuple[float, float]:
    """Wall and CPU seconds of ``run_job`` on logs ``[first, first + n)`` of the folder, after one warm-up log."""
    import mountcal.fleet.worker as worker
    from mountcal.fleet.inputs import collect_jobs

    folder, first, n = args
    jobs = collect_jobs([folder])[first : first + n + 1]
    with worker.heap_for_logs():
        worker.run_job(jobs[0])
        before, t = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter()
        for job in jobs[1:]:
            worker.run_job(job)
        wall, after = time.perf_counter() - t, resource.getrusage(resource.RUSAGE_SELF)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def _line(name: str, results: list[tuple[float, float]]) -> str:
    return f"  {name:<10}" + "   ".join(f"wall {w:.2f} s, CPU {c:.2f} s" for w, c in results)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--logs", type=Path, required=True, help="the fleet benchmark's logs folder")
    parser.add_argument("--per-process", type=int, default=39, help="logs timed per process")
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()
    os.environ.update({k: "1" for k in THREADS})
    context = get_context("forkserver")
    a, b = (str(args.logs), 0, args.per_process), (str(args.logs), args.per_process + 1, args.per_process)
    for _ in range(args.repeats):
        with context.Pool(1) as pool:
            alone_a = pool.map(_work, [a])
        with context.Pool(2) as pool:
            together = pool.map(_work, [a, b])
        with context.Pool(1) as pool:
            alone_b = pool.map(_work, [b])
        print(_line("alone", alone_a + alone_b))
        print(_line("two", together), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
