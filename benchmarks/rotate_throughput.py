"""Throughput and peak memory of ``mountcal rotate`` (read → rotate → write Parquet) against the
conventional per-message path, on hours-long logs written by the real writers.

Logs (generated once into ``--workdir`` and reused): a simulated drive
(:func:`mountcal.simulate.drive.simulate_drive`) as

- ROS 2 MCAP, ``sensor_msgs/msg/Imu`` at 200 Hz, written with ``mcap_ros2.writer.Writer`` (zstd
  chunks of 1 MiB, its default);
- BLF, a 100 Hz IMU as two CAN messages per sample (accelerations, angular rates; 16-bit signals),
  encoded by cantools and written with ``can.BLFWriter``; with ``--bus-hz N`` also a BLF carrying
  N frames/s of other traffic (20 ids) beside the IMU, as a vehicle bus would.

Methods, each run in a fresh subprocess so its peak RSS is its own:

- ``mountcal``: :func:`mountcal.apply.rotate_log.rotate_log` — streamed in chunks of 100 000 samples,
  vectorized decoding, one Parquet row group per chunk;
- ``conventional``: the libraries' per-message path — MCAP: ``mcap`` reader with the
  ``mcap_ros2`` decoder (``iter_decoded_messages``); BLF: ``can.BLFReader`` + cantools
  ``decode_message`` per frame, pairing each acceleration frame with the next rate frame; then
  lists → numpy → one rotation of the whole array → ``pandas.DataFrame.to_parquet``.

Run from the repository root::

    .venv/bin/python benchmarks/rotate_throughput.py --hours 1 4 --workdir /tmp/rotate-bench

The conventional path is timed on the 1-hour logs only (``--conventional-hours`` to change it).
"""

from __future__ import annotations

import argparse
import importlib
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

# the IMU of the BLF logs: two 6-byte messages of three 16-bit signals (shared with the tests)
DBC = Path(__file__).resolve().parents[1] / "tests" / "data" / "imu_acc_gyro.dbc"
T0_NS = 1_714_557_600_000_000_000


# --------------------------------------------------------------------------- generating the logs


def drive(hours: float, rate_hz: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    from mountcal.simulate.drive import simulate_drive

    d = simulate_drive(duration_s=hours * 3600.0, rate_hz=rate_hz, seed=0)
    return d.t_s, d.acc_s, d.gyro_s


def write_mcap(path: Path, hours: float) -> None:
    from mcap_ros2.writer import Writer

    from mountcal.io.mcap.write import IMU_DEFINITION

    t, acc, gyro = drive(hours, 200.0)
    tmp = path.with_suffix(".part")
    with open(tmp, "wb") as f:
        w = Writer(f)
        schema = w.register_msgdef("sensor_msgs/msg/Imu", IMU_DEFINITION)
        cov = [0.0] * 9
        for i in range(t.size):
            ns = T0_NS + round(t[i] * 1e9)
            a, g = acc[i], gyro[i]
            w.write_message(
                "/imu/data",
                schema,
                {
                    "header": {"stamp": {"sec": ns // 10**9, "nanosec": ns % 10**9}, "frame_id": "imu_link"},
                    "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
                    "orientation_covariance": [-1.0, *cov[1:]],
                    "angular_velocity": {"x": g[0], "y": g[1], "z": g[2]},
                    "angular_velocity_covariance": cov,
                    "linear_acceleration": {"x": a[0], "y": a[1], "z": a[2]},
                    "linear_acceleration_covariance": cov,
                },
                log_time=ns,
                publish_time=ns,
                sequence=i,
            )
        w.finish()
    tmp.rename(path)


def write_blf(path: Path, dbc: Path, hours: float, bus_hz: float = 0.0) -> None:
    """The IMU's frames, plus (``bus_hz`` > 0) other traffic: 20 ids, 8 random bytes each, in total
    ``bus_hz`` frames per second, as a vehicle bus would carry beside the IMU."""
    import can
    import cantools

    t, acc, gyro = drive(hours, 100.0)
    db = cantools.database.load_file(dbc)
    acc_msg, gyro_msg = db.get_message_by_name("IMU_ACC"), db.get_message_by_name("IMU_GYRO")
    rng = np.random.default_rng(1)
    per_sample = bus_hz / 100.0  # other frames between two IMU samples, on average
    tmp = path.with_suffix(".part.blf")
    with can.BLFWriter(str(tmp)) as w:
        for i in range(t.size):
            for k in range(rng.poisson(per_sample) if per_sample else 0):
                w.on_message_received(
                    can.Message(
                        timestamp=T0_NS * 1e-9 + t[i] + 5e-4 + k * 1e-4,
                        arbitration_id=0x400 + int(rng.integers(20)),
                        is_extended_id=False,
                        channel=0,
                        data=rng.bytes(8),
                    )
                )
            ts = T0_NS * 1e-9 + t[i]
            a, g = acc[i], gyro[i]
            w.on_message_received(
                can.Message(
                    timestamp=ts,
                    arbitration_id=256,
                    is_extended_id=False,
                    channel=0,
                    data=acc_msg.encode({"AccelerationX": a[0], "AccelerationY": a[1], "AccelerationZ": a[2]}),
                )
            )
            w.on_message_received(
                can.Message(
                    timestamp=ts + 2e-4,
                    arbitration_id=257,
                    is_extended_id=False,
                    channel=0,
                    data=gyro_msg.encode({"AngularRateX": g[0], "AngularRateY": g[1], "AngularRateZ": g[2]}),
                )
            )
    tmp.rename(path)


def prepare(workdir: Path, hours: list[float], bus_hz: float) -> tuple[dict[tuple[str, float], Path], Path, Path]:
    from mountcal import calibrate, simulate_preset
    from mountcal.calibration.fit import Options

    workdir.mkdir(parents=True, exist_ok=True)
    cal = workdir / "result.json"
    if not cal.exists():
        table, _ = simulate_preset("zhang2011", seed=1, bias_mps2=np.array([0.1, -0.05, 0.2]))
        calibrate(table, Options(model="rotation,slope,bias")).save(cal)
    logs = {}
    for h in hours:
        for kind in ("mcap", "blf", *(("bus",) if bus_hz and h == min(hours) else ())):
            name = f"imu_{h:g}h.{kind}" if kind != "bus" else f"imu_{h:g}h_bus{bus_hz:g}hz.blf"
            path = workdir / name
            if not path.exists():
                t0 = time.perf_counter()
                if kind == "mcap":
                    write_mcap(path, h)
                else:
                    write_blf(path, DBC, h, bus_hz if kind == "bus" else 0.0)
                print(
                    f"wrote {path} ({path.stat().st_size / 1e6:.0f} MB) in {time.perf_counter() - t0:.0f} s", flush=True
                )
            logs[(kind, h)] = path
    return logs, DBC, cal


# --------------------------------------------------------------------------- the two methods


def run_mountcal(src: Path, out: Path, cal_path: Path, dbc: Path) -> int:
    from mountcal.apply.rotate_log import rotate_log
    from mountcal.core.result import Calibration
    from mountcal.io.reader import LogOptions

    opts = LogOptions(dbc=str(dbc)) if src.suffix == ".blf" else LogOptions()
    return rotate_log(src, Calibration.load(cal_path), out, options=opts).samples_out


def run_conventional(src: Path, out: Path, cal_path: Path, dbc: Path) -> int:
    import pandas as pd

    from mountcal.core.result import Calibration

    cal = Calibration.load(cal_path)
    t: list[float] = []
    acc: list[tuple[float, float, float]] = []
    gyro: list[tuple[float, float, float]] = []
    if src.suffix == ".mcap":
        from mcap.reader import make_reader
        from mcap_ros2.decoder import DecoderFactory

        with open(src, "rb") as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            for _, _, _, m in reader.iter_decoded_messages(topics=["/imu/data"]):
                t.append(m.header.stamp.sec + m.header.stamp.nanosec * 1e-9)
                a, g = m.linear_acceleration, m.angular_velocity
                acc.append((a.x, a.y, a.z))
                gyro.append((g.x, g.y, g.z))
    else:
        import can
        import cantools

        db = cantools.database.load_file(dbc)
        pending: tuple[float, tuple[float, float, float]] | None = None
        for msg in can.BLFReader(str(src)):
            if msg.arbitration_id == 256:
                d = db.decode_message(256, msg.data)
                pending = (msg.timestamp, (d["AccelerationX"], d["AccelerationY"], d["AccelerationZ"]))
            elif msg.arbitration_id == 257 and pending is not None:
                d = db.decode_message(257, msg.data)
                t.append(pending[0])
                acc.append(pending[1])
                gyro.append((d["AngularRateX"], d["AngularRateY"], d["AngularRateZ"]))
                pending = None
    a_s, g_s = np.array(acc), np.array(gyro)
    bias = cal.bias_mps2 if cal.bias_mps2 is not None else np.zeros(3)
    a_v, g_v = cal.rot_vs.apply(a_s - bias), cal.rot_vs.apply(g_s)
    df = pd.DataFrame(
        {"t_s": t, "ax": a_v[:, 0], "ay": a_v[:, 1], "az": a_v[:, 2], "gx": g_v[:, 0], "gy": g_v[:, 1], "gz": g_v[:, 2]}
    )
    df.to_parquet(out, index=False)
    return len(df)


def child(method: str, src: Path, out: Path, cal: Path, dbc: Path) -> None:
    """One timed run; the libraries are imported first, so the time is the work, not the start-up."""
    for name in (
        "can",
        "cantools",
        "mcap_ros2.decoder",
        "pandas",
        "pyarrow.parquet",
        "mountcal.apply.rotate_log",
        "mountcal.io.can.read",
        "mountcal.io.mcap.read",
    ):
        importlib.import_module(name)

    t0 = time.perf_counter()
    n = (run_mountcal if method == "mountcal" else run_conventional)(src, out, cal, dbc)
    seconds = time.perf_counter() - t0
    print(json.dumps({"samples": n, "seconds": seconds, "peak_rss_mb": peak_rss_mb()}))


def peak_rss_mb() -> float:
    """This process's peak resident set (VmHWM). Not ``ru_maxrss``: Linux carries that across
    ``exec`` from the forked parent, so a child would report the parent's peak."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return float(line.split()[1]) / 1024.0
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def measure(method: str, src: Path, workdir: Path, cal: Path, dbc: Path, runs: int) -> dict[str, float]:
    out = workdir / f"out_{method}_{src.stem}_{src.suffix[1:]}.parquet"
    results = []
    for _ in range(runs):
        cmd = [sys.executable, __file__, "--child", method, str(src), str(out), str(cal), str(dbc)]
        done = subprocess.run(cmd, capture_output=True, text=True, check=True)
        results.append(json.loads(done.stdout.strip().splitlines()[-1]))
        out.unlink(missing_ok=True)
    best = min(results, key=lambda r: r["seconds"])
    return {**best, "peak_rss_mb": max(r["peak_rss_mb"] for r in results)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--hours", type=float, nargs="+", default=[1.0, 4.0])
    parser.add_argument("--conventional-hours", type=float, nargs="*", default=[1.0])
    parser.add_argument("--runs", type=int, default=1, help="timed runs per method (the fastest is reported)")
    parser.add_argument(
        "--bus-hz",
        type=float,
        default=0.0,
        help="also a BLF with this much other CAN traffic (frames/s) beside the IMU",
    )
    parser.add_argument("--workdir", type=Path, default=Path("/tmp/mountcal-rotate-bench"))
    parser.add_argument("--child", nargs=5, metavar=("METHOD", "SRC", "OUT", "CAL", "DBC"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        method, src, out, cal, dbc = args.child
        child(method, Path(src), Path(out), Path(cal), Path(dbc))
        return
    logs, dbc, cal = prepare(args.workdir, args.hours, args.bus_hz)
    print("| log | size MB | samples | method | seconds | samples/s | peak RSS MB | speed-up |")
    print("|---|---|---|---|---|---|---|---|")
    peaks: dict[str, dict[float, float]] = {"mcap": {}, "blf": {}, "bus": {}}
    for (kind, h), src in sorted(logs.items(), key=lambda kv: (kv[0][1], kv[0][0])):
        ours = measure("mountcal", src, args.workdir, cal, dbc, args.runs)
        peaks[kind][h] = ours["peak_rss_mb"]
        rows = [("mountcal", ours, "")]
        if h in args.conventional_hours:
            theirs = measure("conventional", src, args.workdir, cal, dbc, args.runs)
            assert theirs["samples"] == ours["samples"], (theirs, ours)
            rows.append(("conventional", theirs, ""))
            rows[0] = ("mountcal", ours, f"{theirs['seconds'] / ours['seconds']:.1f}×")
        for name, r, speedup in rows:
            print(
                f"| {h:g} h {kind.upper() if kind != 'bus' else f'BLF + {args.bus_hz:g} frames/s bus'} | "
                f"{src.stat().st_size / 1e6:.0f} | {r['samples']:.0f} | {name} | "
                f"{r['seconds']:.2f} | {r['samples'] / r['seconds']:,.0f} | {r['peak_rss_mb']:.0f} | {speedup} |",
                flush=True,
            )
    for kind, by_hours in peaks.items():
        if len(by_hours) > 1:
            lo, hi = min(by_hours), max(by_hours)
            change = by_hours[hi] / by_hours[lo] - 1.0
            print(
                f"{kind}: peak RSS {by_hours[lo]:.0f} MB at {lo:g} h, {by_hours[hi]:.0f} MB at {hi:g} h ({change:+.1%})"
            )


if __name__ == "__main__":
    main()
