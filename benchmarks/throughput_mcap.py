"""Throughput of mountcal's vectorized MCAP reader against the conventional per-message path.

Writes one hour (by default) of ROS 2 ``sensor_msgs/msg/Imu`` at 200 Hz with the real ROS 2 MCAP
writer (zstd chunks of the default 1 MiB), then times, each in a fresh subprocess so peak memory is
per method:

(a) ``mountcal.io.mcap.read.read_mcap(path).acc_s`` → (n, 3) array;
(b) ``mcap`` + ``mcap_ros2`` ``iter_decoded_messages`` collecting ``linear_acceleration``
    into an (n, 3) array.

Run from the repository root::

    .venv/bin/python benchmarks/throughput_mcap.py --runs 3

The generated log is kept in ``--workdir`` (default: a temporary directory, removed afterwards).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from mountcal.io.mcap.write import IMU_DEFINITION

TOPIC = "/imu/data"


def simulate_drive(n: int, rate_hz: float, seed: int = 0) -> dict[str, np.ndarray]:
    """A plausible drive seen by a tilted IMU: gravity, manoeuvres, engine vibration and noise.

    Returns ``t_ns`` (n,) int64, ``acc`` and ``gyro`` (n, 3) in the sensor frame (m/s², rad/s) and
    ``quat`` (n, 4) (x, y, z, w), the vehicle's yaw as an orientation.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate_hz
    a_long = 1.2 * np.sin(2 * np.pi * t / 40.0) + 0.3 * np.sin(2 * np.pi * t / 7.0)
    yaw_rate = 0.15 * np.sin(2 * np.pi * t / 60.0)
    a_lat = 12.0 * yaw_rate
    f_v = np.stack([a_long, a_lat, np.full(n, 9.80665)], axis=1)
    f_v += 0.08 * np.sin(2 * np.pi * 31.0 * t)[:, None]  # engine vibration
    # mounting: roll 5°, pitch 6°, yaw 7° (docs/conventions.md §3), R_vs = Rz Ry Rx; a_s = R_vsᵀ f_v
    g, th, ph = np.radians([5.0, 6.0, 7.0])
    rx = np.array([[1, 0, 0], [0, np.cos(g), -np.sin(g)], [0, np.sin(g), np.cos(g)]])
    ry = np.array([[np.cos(th), 0, np.sin(th)], [0, 1, 0], [-np.sin(th), 0, np.cos(th)]])
    rz = np.array([[np.cos(ph), -np.sin(ph), 0], [np.sin(ph), np.cos(ph), 0], [0, 0, 1]])
    rot_vs = rz @ ry @ rx
    acc = f_v @ rot_vs + rng.normal(0.0, 0.02, (n, 3))
    gyro = np.stack([np.zeros(n), np.zeros(n), yaw_rate], axis=1) @ rot_vs + rng.normal(0.0, 0.002, (n, 3))
    yaw = np.cumsum(yaw_rate) / rate_hz
    quat = np.stack([np.zeros(n), np.zeros(n), np.sin(yaw / 2), np.cos(yaw / 2)], axis=1)
    t_ns = 1_700_000_000 * 10**9 + np.round(t * 1e9).astype(np.int64)
    return {"t_ns": t_ns, "acc": acc, "gyro": gyro, "quat": quat}


def write_log(path: Path, n: int, rate_hz: float) -> None:
    """Write n Imu messages with the real ROS 2 MCAP writer (zstd, default chunk size)."""
    from mcap_ros2.writer import Writer

    sim = simulate_drive(n, rate_hz)
    cov = [0.0004, 0, 0, 0, 0.0004, 0, 0, 0, 0.0004]
    with open(path, "wb") as f, Writer(f) as writer:
        schema = writer.register_msgdef("sensor_msgs/msg/Imu", IMU_DEFINITION)
        for i in range(n):
            t_ns = int(sim["t_ns"][i])
            ax, ay, az = sim["acc"][i].tolist()
            gx, gy, gz = sim["gyro"][i].tolist()
            qx, qy, qz, qw = sim["quat"][i].tolist()
            msg = {
                "header": {"stamp": {"sec": t_ns // 10**9, "nanosec": t_ns % 10**9}, "frame_id": "imu_link"},
                "orientation": {"x": qx, "y": qy, "z": qz, "w": qw},
                "orientation_covariance": cov,
                "angular_velocity": {"x": gx, "y": gy, "z": gz},
                "angular_velocity_covariance": cov,
                "linear_acceleration": {"x": ax, "y": ay, "z": az},
                "linear_acceleration_covariance": cov,
            }
            writer.write_message(TOPIC, schema, msg, log_time=t_ns + 1_500_000, publish_time=t_ns)


def read_mountcal(path: Path) -> np.ndarray:
    """(a) mountcal's vectorized reader."""
    from mountcal.io.mcap.read import read_mcap

    return read_mcap(path).acc_s


def read_conventional(path: Path) -> np.ndarray:
    """(b) the usual way: decode every message with mcap_ros2, collect the fields."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    rows = []
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _schema, _channel, _message, msg in reader.iter_decoded_messages(topics=[TOPIC]):
            a = msg.linear_acceleration
            rows.append((a.x, a.y, a.z))
    return np.array(rows, dtype=np.float64)


METHODS = {"mountcal": read_mountcal, "conventional": read_conventional}


def run_one(method: str, path: Path) -> None:
    """Child process: time one read and print seconds, peak RSS and a checksum as JSON."""
    import mcap.reader  # noqa: F401  (import cost is not part of the measured read)
    import mcap_ros2.decoder  # noqa: F401

    import mountcal.io.mcap.read  # noqa: F401

    rss_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0 = time.perf_counter()
    acc = METHODS[method](path)
    seconds = time.perf_counter() - t0
    rss_peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    out = {
        "seconds": seconds,
        "rss_before_mib": rss_before / 1024,
        "rss_peak_mib": rss_peak / 1024,
        "n": int(acc.shape[0]),
        "sum": acc.sum(axis=0).tolist(),
    }
    print(json.dumps(out))


def measure(method: str, path: Path) -> dict[str, float]:
    cmd = [sys.executable, __file__, "--child", method, "--file", str(path)]
    done = subprocess.run(cmd, check=True, capture_output=True, text=True)
    result: dict[str, float] = json.loads(done.stdout.strip().splitlines()[-1])
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=1.0, help="length of the log (default 1 h)")
    parser.add_argument("--rate", type=float, default=200.0, help="IMU rate in Hz (default 200)")
    parser.add_argument("--runs", type=int, default=3, help="runs per method; the median is reported")
    parser.add_argument("--workdir", type=Path, help="where to keep the generated log (reused if present)")
    parser.add_argument("--child", choices=sorted(METHODS), help=argparse.SUPPRESS)
    parser.add_argument("--file", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        run_one(args.child, args.file)
        return 0

    n = round(args.hours * 3600 * args.rate)
    with tempfile.TemporaryDirectory() as tmp:
        workdir = args.workdir or Path(tmp)
        workdir.mkdir(parents=True, exist_ok=True)
        path = workdir / f"imu_{n}.mcap"
        if not path.exists():
            t0 = time.perf_counter()
            write_log(path, n, args.rate)
            print(f"wrote {path} ({path.stat().st_size / 2**20:.1f} MiB) in {time.perf_counter() - t0:.1f} s")
        print(f"log: {n} Imu messages at {args.rate:g} Hz, {path.stat().st_size / 2**20:.1f} MiB, zstd chunks")
        load_before = os.getloadavg()[0]
        results: dict[str, list[dict[str, float]]] = {m: [] for m in METHODS}
        for _ in range(args.runs):  # interleaved, so a busy spell on the machine hits both methods
            for m in METHODS:
                results[m].append(measure(m, path))
        load_after = os.getloadavg()[0]

    ref, ours = results["conventional"][0], results["mountcal"][0]
    if ref["n"] != ours["n"] or not np.allclose(ref["sum"], ours["sum"], rtol=1e-12):
        print(f"MISMATCH: conventional {ref['n']} {ref['sum']}, mountcal {ours['n']} {ours['sum']}")
        return 1
    median = {m: statistics.median(r["seconds"] for r in rs) for m, rs in results.items()}
    print(f"1-min load average: {load_before:.2f} before, {load_after:.2f} after (2 idle cores: < 0.3)")
    print(f"{'method':<14}{'median s':>10}  {'peak RSS MiB':>12}  {'read MiB':>8}  runs s")
    for m, rs in results.items():
        runs = ", ".join(f"{r['seconds']:.3f}" for r in rs)
        peak = statistics.median(r["rss_peak_mib"] for r in rs)
        growth = statistics.median(r["rss_peak_mib"] - r["rss_before_mib"] for r in rs)
        print(f"{m:<14}{median[m]:>10.3f}  {peak:>12.0f}  {growth:>8.0f}  {runs}")
    print(f"speed-up: {median['conventional'] / median['mountcal']:.1f}x  (samples: {ours['n']}, identical sums)")
    print("(peak RSS: whole process; read MiB: peak minus the RSS after imports; medians over runs)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
