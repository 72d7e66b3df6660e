"""Throughput of mountcal's ROS bag reader against rosbags' own per-message deserialisation.

Writes one hour (by default) of a drive with rosbags' own writers — ``sensor_msgs/msg/Imu`` at
200 Hz, ``nav_msgs/msg/Odometry`` at 50 Hz and ``sensor_msgs/msg/NavSatFix`` at 5 Hz — as a ROS 1
bag (uncompressed, lz4 or bz2 chunks) or a ROS 2 bag folder (SQLite ``.db3`` or ``.mcap``), then
times, each in a fresh subprocess so peak memory is per method:

(a) ``mountcal.read_log(bag).acc_s`` → (n, 3) array (mountcal also reads the odometry and fix:
    speed, heading and position channels);
(b) ``rosbags.highlevel.AnyReader``: every Imu message deserialised by rosbags (its generated
    per-type deserialiser), ``linear_acceleration`` collected into an (n, 3) array.

Run from the repository root::

    .venv/bin/python benchmarks/throughput_bags.py --runs 3 --format ros1
    .venv/bin/python benchmarks/throughput_bags.py --runs 3 --format ros1-lz4 --format db3 --format mcap-bag

The generated bags are kept in ``--workdir`` (default: a temporary directory, removed afterwards).
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
from typing import Any

import numpy as np
from throughput_mcap import simulate_drive

TOPIC = "/imu/data"
FORMATS = ("ros1", "ros1-lz4", "ros1-bz2", "db3", "mcap-bag")


def _messages(store: Any, n: int, rate_hz: float, ros1: bool) -> Any:
    """(topic, type, t_ns, message) in time order: Imu at ``rate_hz``, odometry at rate/4, fix at rate/40."""
    t = store.types
    sim = simulate_drive(n, rate_hz)
    vec, quat = t["geometry_msgs/msg/Vector3"], t["geometry_msgs/msg/Quaternion"]
    cov9, cov36 = np.diag([4e-4] * 3).ravel(), np.zeros(36)

    def header(t_ns: int, frame: str) -> Any:
        args: dict[str, Any] = {"stamp": t["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9)}
        args["frame_id"] = frame
        if ros1:
            args["seq"] = 0
        return t["std_msgs/msg/Header"](**args)

    for i in range(n):
        t_ns = int(sim["t_ns"][i])
        a, g, q = sim["acc"][i], sim["gyro"][i], sim["quat"][i]
        orientation = quat(x=q[0], y=q[1], z=q[2], w=q[3])
        yield (
            TOPIC,
            "sensor_msgs/msg/Imu",
            t_ns,
            t["sensor_msgs/msg/Imu"](
                header=header(t_ns, "imu_link"),
                orientation=orientation,
                orientation_covariance=cov9,
                angular_velocity=vec(x=g[0], y=g[1], z=g[2]),
                angular_velocity_covariance=cov9,
                linear_acceleration=vec(x=a[0], y=a[1], z=a[2]),
                linear_acceleration_covariance=cov9,
            ),
        )
        if i % 4 == 0:
            pose = t["geometry_msgs/msg/Pose"](
                position=t["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0), orientation=orientation
            )
            twist = t["geometry_msgs/msg/Twist"](linear=vec(x=15.0, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.0))
            yield (
                "/odom",
                "nav_msgs/msg/Odometry",
                t_ns,
                t["nav_msgs/msg/Odometry"](
                    header=header(t_ns, "odom"),
                    child_frame_id="base_link",
                    pose=t["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov36),
                    twist=t["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=cov36),
                ),
            )
        if i % 40 == 0:
            yield (
                "/fix",
                "sensor_msgs/msg/NavSatFix",
                t_ns,
                t["sensor_msgs/msg/NavSatFix"](
                    header=header(t_ns, "gps"),
                    status=t["sensor_msgs/msg/NavSatStatus"](status=0, service=1),
                    latitude=48.7758,
                    longitude=9.1829,
                    altitude=250.0,
                    position_covariance=cov9,
                    position_covariance_type=2,
                ),
            )


def write_bag(path: Path, fmt: str, n: int, rate_hz: float) -> None:
    """Write the drive with rosbags' writer of ``fmt``."""
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2
    from rosbags.typesys import Stores, get_typestore

    ros1 = fmt.startswith("ros1")
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    writer: Any
    if ros1:
        writer = Writer1(path)
        if fmt != "ros1":
            writer.set_compression(Writer1.CompressionFormat[fmt.split("-")[1].upper()])
    else:
        plugin = StoragePlugin.SQLITE3 if fmt == "db3" else StoragePlugin.MCAP
        writer = Writer2(path, version=9, storage_plugin=plugin)
    serialize = store.serialize_ros1 if ros1 else store.serialize_cdr
    with writer:
        conns: dict[str, Any] = {}
        for topic, type_name, t_ns, msg in _messages(store, n, rate_hz, ros1):
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, type_name, typestore=store)
            writer.write(conns[topic], t_ns + 1_500_000, serialize(msg, type_name))


def read_mountcal(path: Path) -> np.ndarray:
    """(a) mountcal's reader (whole chunks, whole arrays)."""
    from mountcal import read_log

    return read_log(path).acc_s


def read_rosbags(path: Path) -> np.ndarray:
    """(b) rosbags' documented way: AnyReader, one deserialised message at a time."""
    from rosbags.highlevel import AnyReader

    rows = []
    with AnyReader([path]) as reader:
        connections = [c for c in reader.connections if c.topic == TOPIC]
        for connection, _, raw in reader.messages(connections=connections):
            a = reader.deserialize(raw, connection.msgtype).linear_acceleration  # type: ignore[attr-defined]
            rows.append((a.x, a.y, a.z))
    return np.array(rows, dtype=np.float64)


METHODS = {"mountcal": read_mountcal, "rosbags": read_rosbags}


def run_one(method: str, path: Path) -> None:
    """Child process: time one read and print seconds, peak RSS and a checksum as JSON."""
    import rosbags.highlevel  # noqa: F401  (import cost is not part of the measured read)

    import mountcal.io.bag.read  # noqa: F401

    rss_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0 = time.perf_counter()
    acc = METHODS[method](path)
    seconds = time.perf_counter() - t0
    rss_peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    print(
        json.dumps(
            {
                "seconds": seconds,
                "rss_before_mib": rss_before / 1024,
                "rss_peak_mib": rss_peak / 1024,
                "n": int(acc.shape[0]),
                "sum": np.sort(acc, axis=0).sum(axis=0).tolist(),
            }
        )
    )


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
    parser.add_argument("--format", action="append", choices=FORMATS, help="bag format(s) (default ros1)")
    parser.add_argument("--workdir", type=Path, help="where to keep the generated bags (reused if present)")
    parser.add_argument("--child", choices=sorted(METHODS), help=argparse.SUPPRESS)
    parser.add_argument("--file", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        run_one(args.child, args.file)
        return 0

    n = round(args.hours * 3600 * args.rate)
    failed = 0
    with tempfile.TemporaryDirectory() as tmp:
        workdir = args.workdir or Path(tmp)
        workdir.mkdir(parents=True, exist_ok=True)
        for fmt in args.format or ["ros1"]:
            path = workdir / (f"drive_{n}_{fmt}" + (".bag" if fmt.startswith("ros1") else ""))
            if not path.exists():
                t0 = time.perf_counter()
                write_bag(path, fmt, n, args.rate)
                print(f"wrote {path} in {time.perf_counter() - t0:.1f} s")
            size = sum(f.stat().st_size for f in ([path] if path.is_file() else path.iterdir()))
            print(f"\n{fmt}: {n} Imu messages at {args.rate:g} Hz (+ odometry, fix), {size / 2**20:.1f} MiB")
            load_before = os.getloadavg()[0]
            results: dict[str, list[dict[str, float]]] = {m: [] for m in METHODS}
            for _ in range(args.runs):  # interleaved, so a busy spell on the machine hits both methods
                for m in METHODS:
                    results[m].append(measure(m, path))
            load_after = os.getloadavg()[0]
            ref, ours = results["rosbags"][0], results["mountcal"][0]
            if ref["n"] != ours["n"] or not np.allclose(ref["sum"], ours["sum"], rtol=1e-12):
                print(f"MISMATCH: rosbags {ref['n']} {ref['sum']}, mountcal {ours['n']} {ours['sum']}")
                failed += 1
                continue
            median = {m: statistics.median(r["seconds"] for r in rs) for m, rs in results.items()}
            print(f"1-min load average: {load_before:.2f} before, {load_after:.2f} after (2 idle cores: < 0.3)")
            print(f"{'method':<10}{'median s':>10}  {'peak RSS MiB':>12}  {'read MiB':>8}  runs s")
            for m, rs in results.items():
                runs = ", ".join(f"{r['seconds']:.3f}" for r in rs)
                peak = statistics.median(r["rss_peak_mib"] for r in rs)
                growth = statistics.median(r["rss_peak_mib"] - r["rss_before_mib"] for r in rs)
                print(f"{m:<10}{median[m]:>10.3f}  {peak:>12.0f}  {growth:>8.0f}  {runs}")
            print(f"speed-up: {median['rosbags'] / median['mountcal']:.1f}x  (samples: {ours['n']}, identical sums)")
    print("(peak RSS: whole process; read MiB: peak minus the RSS after imports; medians over runs)")
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
