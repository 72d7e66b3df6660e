"""Throughput of reading an IMU from a BLF log: mountcal against python-can + cantools.

Generates (once, cached) a BLF log with a Bosch MM5.10 IMU at 100 Hz (three messages: AY1 in 0x70,
AX1 in 0x80, AZ in 0x576, the layout of the real DBC) among 20 other periodic messages, written by
python-can's BLFWriter, then times, each in a fresh subprocess so peak memory is its own:

(a) mountcal: ``read_can(log, dbc)`` → the (n, 3) accelerometer array;
(b) the conventional path: iterate ``can.BLFReader``, ``db.decode_message`` the IMU frames, collect
    to numpy and align the three messages the same way (nearest frame within one period).

Usage::

    .venv/bin/python benchmarks/throughput_can.py --minutes 60 --runs 3
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
DEFAULT_DBC = REPO / ".." / "shared" / "data" / "real" / "dbc" / "bosch_abs_m5_mm5.10_abs.dbc"
FALLBACK_DBC = REPO / "tests" / "data" / "mm5_imu.dbc"
IMU_IDS = {0x70: "AY1", 0x80: "AX1", 0x576: "AZ"}
LSB_G, OFFSET_G = 0.000127465, -4.1768
# other traffic: (id, period s); 990 frames/s with the IMU's 300 ≈ 1290 frames/s (≈ 30 % of 500 kbit/s)
OTHERS = (
    *[(ident, 0.01) for ident in (0x343, 0x24A, 0x140, 0x141, 0x100, 0x101)],
    *[(ident, 0.02) for ident in (0x142, 0x143, 0x200, 0x201, 0x202)],
    *[(ident, 0.05) for ident in (0x340, 0x341, 0x342, 0x300, 0x301)],
    *[(ident, 0.1) for ident in (0x541, 0x542, 0x560, 0x5C0)],
)


def _schedule(minutes: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Times and ids of every frame, time-ordered, with a little jitter."""
    duration = minutes * 60.0
    times, ids = [], []
    for offset, ident in enumerate(IMU_IDS):  # the IMU sends its three frames 0.2 ms apart
        t = np.arange(0.0, duration, 0.01) + 0.0002 * offset
        times.append(t + rng.normal(0, 2e-5, t.shape))
        ids.append(np.full(t.shape, ident))
    for ident, period in OTHERS:
        t = np.arange(rng.uniform(0, period), duration, period)
        times.append(t + rng.normal(0, 5e-5, t.shape))
        ids.append(np.full(t.shape, ident))
    t_all, id_all = np.concatenate(times), np.concatenate(ids)
    order = np.argsort(t_all, kind="stable")
    return np.abs(t_all[order]), id_all[order]


def _payloads(ids: np.ndarray, t: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """8-byte payloads: IMU messages carry a tilted, vibrating gravity vector in the MM5.10 layout."""
    data = rng.integers(0, 256, (ids.shape[0], 8), dtype=np.uint8)
    g = {0x80: 0.05, 0x70: -0.02, 0x576: 0.998}
    for ident, mean in g.items():
        rows = ids == ident
        value_g = mean + 0.01 * np.sin(2 * np.pi * 0.1 * t[rows]) + rng.normal(0, 0.002, rows.sum())
        raw = np.round((value_g - OFFSET_G) / LSB_G).astype(np.uint16)
        data[rows, 4] = raw & 0xFF
        data[rows, 5] = raw >> 8
    return data


def generate(path: Path, minutes: float) -> None:
    """Write the benchmark log with python-can's BLFWriter."""
    import can

    rng = np.random.default_rng(7)
    t, ids = _schedule(minutes, rng)
    data = _payloads(ids, t, rng)
    t0 = 1_700_000_000.0
    with can.BLFWriter(path) as writer:
        for k in range(t.shape[0]):
            writer.on_message_received(
                can.Message(
                    timestamp=t0 + t[k],
                    arbitration_id=int(ids[k]),
                    is_extended_id=False,
                    data=data[k].tobytes(),
                    channel=0,
                )
            )


def run_mountcal(log: Path, dbc: Path) -> np.ndarray:
    from mountcal.io.can.read import read_can

    return read_can(log, dbc).acc_s


def run_conventional(log: Path, dbc: Path) -> np.ndarray:
    """python-can BLFReader + cantools decode_message, then the same nearest-in-time alignment."""
    import can
    import cantools

    db = cantools.database.load_file(dbc, strict=False)
    t = {ident: [] for ident in IMU_IDS}
    v = {ident: [] for ident in IMU_IDS}
    with can.BLFReader(log) as reader:
        for msg in reader:
            if msg.arbitration_id in IMU_IDS:
                signals = db.decode_message(msg.arbitration_id, msg.data)
                t[msg.arbitration_id].append(msg.timestamp)
                v[msg.arbitration_id].append(signals[IMU_IDS[msg.arbitration_id]])
    arrays = {i: (np.asarray(t[i]), np.asarray(v[i]) * 9.80665) for i in IMU_IDS}
    t_ref, ax = arrays[0x80]
    columns, keep = {0x80: ax}, np.ones(t_ref.shape, bool)
    for ident in (0x70, 0x576):
        t_k, v_k = arrays[ident]
        period = float(np.median(np.diff(t_k[:1000])))
        after = np.clip(np.searchsorted(t_k, t_ref), 0, t_k.shape[0] - 1)
        before = np.clip(after - 1, 0, None)
        index = np.where(np.abs(t_ref - t_k[before]) <= np.abs(t_k[after] - t_ref), before, after)
        keep &= np.abs(t_k[index] - t_ref) <= period
        columns[ident] = v_k[index]
    return np.stack([columns[0x80], columns[0x70], columns[0x576]], axis=1)[keep]


def _peak_mib() -> float:
    """Peak resident memory of this process: VmHWM (reset by exec, unlike ru_maxrss, which a child
    inherits from a parent that grew before forking), else ru_maxrss."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return float(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _child(which: str, log: Path, dbc: Path, out: Path | None) -> None:
    import can  # noqa: F401  # imports (≈ 0.3 s, the same libraries for both paths) are not timed
    import cantools  # noqa: F401

    import mountcal.io.can.read  # noqa: F401

    baseline_mib = _peak_mib()
    start = time.perf_counter()
    acc = (run_mountcal if which == "mountcal" else run_conventional)(log, dbc)
    seconds = time.perf_counter() - start
    if out is not None:
        np.save(out, acc)
    peak_mib = _peak_mib()
    result = {"seconds": seconds, "peak_mib": peak_mib, "baseline_mib": baseline_mib, "rows": int(acc.shape[0])}
    print(json.dumps(result))


def _measure(which: str, log: Path, dbc: Path, out: Path | None = None) -> dict[str, float]:
    cmd = [sys.executable, __file__, "--child", which, "--log", str(log), "--dbc", str(dbc)]
    if out is not None:
        cmd += ["--out", str(out)]
    done = subprocess.run(cmd, check=True, capture_output=True, text=True)
    return dict(json.loads(done.stdout.strip().splitlines()[-1]))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--minutes", type=float, default=60.0, help="length of the generated log")
    parser.add_argument("--runs", type=int, default=3, help="timed runs of each path (median reported)")
    parser.add_argument("--dir", type=Path, default=Path("/tmp/mountcal-bench"), help="where the log is cached")
    parser.add_argument("--dbc", type=Path, default=DEFAULT_DBC if DEFAULT_DBC.is_file() else FALLBACK_DBC)
    parser.add_argument("--child", choices=["mountcal", "conventional"], help=argparse.SUPPRESS)
    parser.add_argument("--log", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--out", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        _child(args.child, args.log, args.dbc, args.out)
        return 0
    args.dir.mkdir(parents=True, exist_ok=True)
    log = args.dir / f"imu_mm5_{args.minutes:g}min.blf"
    if not log.is_file():
        print(f"generating {log} ...", flush=True)
        generate(log, args.minutes)
    print(f"log: {log} ({log.stat().st_size / 2**20:.1f} MiB), DBC: {args.dbc.name}")
    check = {"mountcal": args.dir / "mountcal.npy", "conventional": args.dir / "conventional.npy"}
    runs: dict[str, list[dict[str, float]]] = {"mountcal": [], "conventional": []}
    for k in range(args.runs):  # interleaved, so a busy machine slows both paths alike
        for which in runs:
            runs[which].append(_measure(which, log, args.dbc, check[which] if k == 0 else None))
    results = {}
    for which, measured in runs.items():
        results[which] = {
            "seconds": statistics.median(r["seconds"] for r in measured),
            "peak_mib": max(r["peak_mib"] for r in measured),
            "baseline_mib": max(r["baseline_mib"] for r in measured),
            "rows": measured[0]["rows"],
            "all": [round(r["seconds"], 3) for r in measured],
        }
        print(which, json.dumps(results[which]), flush=True)
    ours, theirs = (np.load(p) for p in check.values())
    same = ours.shape == theirs.shape and np.allclose(ours, theirs, rtol=1e-12, atol=0)
    speedup = results["conventional"]["seconds"] / results["mountcal"]["seconds"]
    print(f"same result: {same}; speed-up: {speedup:.1f}x")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
