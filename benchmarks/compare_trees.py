"""mountcal's own paths of the throughput benchmarks, timed in two source trees side by side (before/after a change).

Each operation runs in a fresh process per run through *that tree's own* benchmark script (its child
mode), so each tree imports its own modules (the import paths differ between layouts):

- read 1 h MCAP: ``throughput_mcap.py --child mountcal --file F`` (ROS 2 Imu at 200 Hz);
- read 1 h BLF: ``throughput_can.py --child mountcal --log L --dbc D --out O`` (MM5.10 among 20 messages);
- rotate 1 h BLF / MCAP: ``rotate_throughput.py --child mountcal SRC OUT CAL DBC`` (read → rotate → Parquet);
- read → stops → calibrate, 1 h MCAP / BLF: ``throughput.py``'s ``mountcal_path(log, protocol, fmt)`` in a
  ``python -c`` process that puts the tree's benchmarks/ on sys.path, imports first, then times one call.

The inputs are generated once with the NEW tree's generators into ``--workdir`` (reused if present); the
runs alternate old, new, old, new …, each with ``PYTHONPATH=<tree>/src OMP_NUM_THREADS=1
OPENBLAS_NUM_THREADS=1``. Prints a markdown table (medians, min–max, after/before), the 1-min load average
before and after, and checks that both trees gave the same result (sample counts, checksums, angles to
4 decimals); exits 1 on a mismatch. Full size (the lead's command, on a quiet machine)::

    git -C /work/main worktree add /tmp/perf-old 98873b8
    .venv/bin/python benchmarks/compare_trees.py --old /tmp/perf-old --new . --runs 5 --workdir /tmp/ab

Quick check of the script itself: ``--hours 0.02 --runs 1 --workdir /tmp/ab-tiny`` (the parking session keeps
12 stops of ≥ 40 s, so it stays ≥ 12 min); ``--only BLF rotate`` picks operations by name. Both trees get the same
input files, DBCs and calibration (throughput_can's default DBC lies outside the tree, so it is passed).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

# throughput.py has no child mode: time its mountcal_path in a fresh interpreter (argv: benchdir log protocol fmt)
E2E_CHILD = """
import json, sys, time
sys.path.insert(0, sys.argv[1])
import encodings.cp1252, importlib, pkgutil, pyarrow.pandas_compat, pyarrow.vendored.version, throughput
import mountcal.estimate, mountcal.io  # every reader and estimator first: the call imports some lazily
for pkg in (mountcal.io, mountcal.estimate):
    for module in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + "."):
        importlib.import_module(module.name)
before = set(sys.modules)
t0 = time.perf_counter()
cal = throughput.mountcal_path(throughput.Path(sys.argv[2]), throughput.Path(sys.argv[3]), sys.argv[4])
seconds = time.perf_counter() - t0
late = len(set(sys.modules) - before)
print(json.dumps({"seconds": seconds, "angles": [cal.roll_deg, cal.pitch_deg, cal.yaw_deg], "late_imports": late}))
"""


def generate(new: Path, workdir: Path, hours: float, rate: float) -> dict[str, Path]:
    """The inputs, written once by the new tree's own generators (in this process, new tree first on sys.path)."""
    sys.path[:0] = [str(new / "src"), str(new / "benchmarks")]
    import rotate_throughput as rot
    import throughput as e2e
    import throughput_can as can
    import throughput_mcap as mcap

    files: dict[str, Path] = {}

    def made(key: str, path: Path, write: Callable[[], object]) -> None:
        if not path.exists():
            path.parent.mkdir(parents=True, exist_ok=True)
            t0 = time.perf_counter()
            write()
            print(f"wrote {path} ({path.stat().st_size / 2**20:.0f} MiB), {time.perf_counter() - t0:.0f} s", flush=True)
        files[key] = path

    n = round(hours * 3600 * rate)
    mcap_log = workdir / "read" / f"imu_{n}.mcap"
    made("read_mcap", mcap_log, lambda: mcap.write_log(mcap_log, n, rate))
    blf = workdir / "read" / f"imu_mm5_{hours * 60:g}min.blf"
    made("read_blf", blf, lambda: can.generate(blf, hours * 60))
    files["read_dbc"] = can.DEFAULT_DBC if can.DEFAULT_DBC.is_file() else can.FALLBACK_DBC  # one DBC for both trees
    logs, files["rotate_dbc"], files["rotate_cal"] = rot.prepare(workdir / "rotate", [hours], 0.0)
    files["rotate_blf"], files["rotate_mcap"] = logs[("blf", hours)], logs[("mcap", hours)]
    if hours != 1.0:  # 12 × (240 s stop + 60 s drive): shrink both, down to the simulator's defaults (40 s, 20 s)
        full, least = e2e.simulate_parking_log, {"stop_s": 40.0, "drive_s": 20.0}
        e2e.simulate_parking_log = lambda **kw: full(**kw | {k: max(kw[k] * hours, v) for k, v in least.items()})
    e2e_dir, t0 = workdir / f"e2e_{hours:g}h", time.perf_counter()
    fresh = not (e2e_dir / "hour.blf").exists()
    files.update({f"e2e_{k}": v for k, v in e2e.generate(e2e_dir).items()})
    if fresh:
        print(f"wrote {e2e_dir} (throughput.py's parking session), {time.perf_counter() - t0:.0f} s", flush=True)
    return files


def run(tree: Path, cmd: list[str]) -> dict[str, Any]:
    """One fresh process with the tree's sources; its last stdout line is the JSON result."""
    env = {**os.environ, "PYTHONPATH": str(tree / "src"), "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, *cmd], env=env, cwd=tree, capture_output=True, text=True)
    if done.returncode != 0:
        shown_cmd = " ".join("<E2E_CHILD>" if c == E2E_CHILD else c for c in cmd)
        sys.exit(f"failed in {tree}: python {shown_cmd}\n{done.stderr[-3000:]}")
    result: dict[str, Any] = json.loads(done.stdout.strip().splitlines()[-1])
    return result


def parquet_sums(path: Path) -> dict[str, float]:
    import pyarrow.parquet as pq

    table = pq.read_table(path)
    sums = {name: float(np.sum(table.column(name).to_numpy())) for name in table.column_names}
    path.unlink()
    return sums


def operations(files: dict[str, Path], workdir: Path, h: str) -> dict[str, Callable[[Path, str], tuple[float, Any]]]:
    """Each operation: (tree, tag) → (seconds, the result to compare between the trees)."""

    def read_mcap(tree: Path, tag: str) -> tuple[float, Any]:
        cmd = [str(tree / "benchmarks/throughput_mcap.py"), "--child", "mountcal", "--file", str(files["read_mcap"])]
        r = run(tree, cmd)
        return r["seconds"], {"n": r["n"], "sum": r["sum"]}

    def read_blf(tree: Path, tag: str) -> tuple[float, Any]:
        out = workdir / f"read_blf_{tag}.npy"
        cmd = [str(tree / "benchmarks/throughput_can.py"), "--child", "mountcal", "--log", str(files["read_blf"])]
        r = run(tree, [*cmd, "--dbc", str(files["read_dbc"]), "--out", str(out)])
        acc = np.load(out)
        out.unlink()
        return r["seconds"], {"rows": r["rows"], "shape": list(acc.shape), "sum": acc.sum(axis=0).tolist()}

    def rotate(kind: str) -> Callable[[Path, str], tuple[float, Any]]:
        def op(tree: Path, tag: str) -> tuple[float, Any]:
            out = workdir / f"rotate_{kind}_{tag}.parquet"
            inputs = [files[f"rotate_{kind}"], out, files["rotate_cal"], files["rotate_dbc"]]
            r = run(tree, [str(tree / "benchmarks/rotate_throughput.py"), "--child", "mountcal", *map(str, inputs)])
            return r["seconds"], {"samples": r["samples"], "column sums": parquet_sums(out)}

        return op

    def e2e(fmt: str) -> Callable[[Path, str], tuple[float, Any]]:
        def op(tree: Path, tag: str) -> tuple[float, Any]:
            protocol = files["e2e_protocol" if fmt == "mcap" else "e2e_protocol_blf"]
            r = run(tree, ["-c", E2E_CHILD, str(tree / "benchmarks"), str(files[f"e2e_{fmt}"]), str(protocol), fmt])
            late = "modules imported in the timed call (not compared)"
            return r["seconds"], {"roll/pitch/yaw": r["angles"], late: r["late_imports"]}

        return op

    return {
        f"read {h} MCAP (throughput_mcap)": read_mcap,
        f"read {h} BLF (throughput_can)": read_blf,
        f"rotate {h} BLF (rotate_throughput)": rotate("blf"),
        f"rotate {h} MCAP (rotate_throughput)": rotate("mcap"),
        f"read → stops → calibrate {h} MCAP (throughput)": e2e("mcap"),
        f"read → stops → calibrate {h} BLF (throughput)": e2e("blf"),
    }


def same(a: Any, b: Any) -> bool:
    """Equal results: the same counts and keys, numbers equal to 4 decimals (or 1e-12 relative)."""
    if isinstance(a, dict) and isinstance(b, dict):
        keys = [k for k in a if not k.endswith("(not compared)")]
        return keys == [k for k in b if not k.endswith("(not compared)")] and all(same(a[k], b[k]) for k in keys)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float | int) and isinstance(b, float | int):
        return math.isclose(a, b, rel_tol=1e-12, abs_tol=5e-5)
    return bool(a == b)


def shown(value: Any) -> str:
    """A result for the report, numbers to 4 decimals."""
    if isinstance(value, float):
        return f"{value:.4f}"
    if isinstance(value, list):
        return "[" + ", ".join(shown(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {shown(v)}" for k, v in value.items()) + "}"
    return str(value)


def spread(seconds: list[float]) -> str:
    return f"{statistics.median(seconds):.3f} s ({min(seconds):.3f}–{max(seconds):.3f})"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", type=Path, required=True, help="the tree before the change (e.g. /tmp/perf-old)")
    parser.add_argument("--new", type=Path, required=True, help="the tree after the change (e.g. .)")
    parser.add_argument("--runs", type=int, default=5, help="runs per tree and operation (alternating)")
    parser.add_argument("--workdir", type=Path, default=Path("/tmp/ab"), help="inputs, generated once and reused")
    parser.add_argument("--hours", type=float, default=1.0, help="length of every log (shrink to test: 0.02)")
    parser.add_argument("--rate", type=float, default=200.0, help="IMU rate of the read-MCAP log (Hz)")
    parser.add_argument("--only", nargs="+", metavar="WORD", help="only the operations whose name holds one of these")
    args = parser.parse_args(argv)
    old, new, workdir = args.old.resolve(), args.new.resolve(), args.workdir.resolve()
    for tree in (old, new):
        if not (tree / "src" / "mountcal").is_dir() or not (tree / "benchmarks").is_dir():
            parser.error(f"{tree} is not a mountcal tree (src/mountcal and benchmarks/)")
    workdir.mkdir(parents=True, exist_ok=True)
    files = generate(new, workdir, args.hours, args.rate)
    ops = {
        name: op
        for name, op in operations(files, workdir, f"{args.hours:g} h").items()
        if not args.only or any(w.lower() in name.lower() for w in args.only)
    }

    def rev(tree: Path) -> str:
        def git(*words: str) -> str:
            return subprocess.run(["git", "-C", str(tree), *words], capture_output=True, text=True).stdout.strip()

        return git("rev-parse", "--short", "HEAD") + (" + uncommitted" if git("status", "--porcelain", "src") else "")

    print(f"before: {old} ({rev(old)}); after: {new} ({rev(new)}); logs of {args.hours:g} h; {args.runs} runs each")
    load_before, t_start = os.getloadavg()[0], time.perf_counter()
    rows, mismatches = [], []
    for name, op in ops.items():
        seconds: dict[str, list[float]] = {"old": [], "new": []}
        results: dict[str, list[Any]] = {"old": [], "new": []}
        for _ in range(args.runs):  # alternating, so a busy spell of the machine hits both trees
            for tag, tree in (("old", old), ("new", new)):
                s, result = op(tree, tag)
                seconds[tag].append(s)
                results[tag].append(result)
        ratio = statistics.median(seconds["new"]) / statistics.median(seconds["old"])
        rows.append(f"| {name} | {spread(seconds['old'])} | {spread(seconds['new'])} | {ratio:.2f} |")
        ref = results["old"][0]
        agree = all(same(ref, r) for r in results["old"] + results["new"])
        print(f"{name}: {'same' if agree else 'MISMATCH'}; before {shown(ref)}", flush=True)
        if shown(results["new"][0]) != shown(ref):
            print(f"  after {shown(results['new'][0])}")
        if not agree:
            mismatches.append(name)
    load_after = os.getloadavg()[0]
    took = time.perf_counter() - t_start
    print(f"\n1-min load average: {load_before:.2f} before, {load_after:.2f} after ({took:.0f} s of runs)\n")
    print(f"| operation | before ({rev(old)}) median (min–max) | after ({rev(new)}) median (min–max) | after/before |")
    print("|---|---|---|---|")
    print("\n".join(rows))
    if mismatches:
        print(f"\nMISMATCH between the trees' results: {', '.join(mismatches)}")
        return 1
    print("\nBoth trees gave the same results (counts, checksums, angles to 4 decimals).")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
