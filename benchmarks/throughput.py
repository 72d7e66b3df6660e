"""End to end: read, decode, find the stops and calibrate one hour of a parking session.

mountcal (`mountcal.calibration.pipeline.calibrate_log`, what `mountcal calibrate LOG --protocol …` runs)
against the conventional path: the per-message library decoders (mcap_ros2 `iter_decoded_messages`;
python-can `BLFReader` + cantools `decode_message`) collecting the same signals into arrays, then
the same stop detection and estimator. The hour is a simulated parking session (12 stops of 240 s
with drives between) written by the real writers: a ROS 2 MCAP at 200 Hz and a BLF with the
Bosch MM5.10 IMU at 100 Hz (data/imu_mm5_10.dbc) plus speed, heading, temperature and position.

    python benchmarks/throughput.py --runs 3 --workdir /tmp/mountcal-e2e
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import can
import cantools
import numpy as np
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from mountcal.calibration.fit import calibrate
from mountcal.calibration.pipeline import LogJob, calibrate_job
from mountcal.core.conventions import normal_gravity
from mountcal.core.result import Calibration
from mountcal.io import writers as export
from mountcal.io.reader import LogOptions
from mountcal.io.samples import Channel, Samples
from mountcal.simulate.stops import simulate_parking_log
from mountcal.stops.headings import read_protocol, tabulate

REPO = Path(__file__).resolve().parents[1]
DBC = REPO / "data" / "imu_mm5_10.dbc"
MAPPING = REPO / "data" / "imu_mm5_10.toml"
G_FIX = normal_gravity(48.78, 250.0)  # the written position's gravity is the simulated one


def generate(workdir: Path) -> dict[str, Path]:
    workdir.mkdir(parents=True, exist_ok=True)
    paths = {
        "mcap": workdir / "hour.mcap",
        "blf": workdir / "hour.blf",
        "protocol": workdir / "hour_protocol.csv",
        "protocol_blf": workdir / "hour_blf_protocol.csv",
    }
    if not paths["mcap"].exists():
        # the benchmark log: the ROS 2 Imu topic alone (other topics interleaved in the
        # chunks take the reader's general gather path, ≈ 2× slower; see docs/performance-mcap.md)
        log = simulate_parking_log(stop_s=240.0, drive_s=60.0, rate_hz=200.0, seed=7)
        export.write_mcap(paths["mcap"], log, with_temperature=False, with_fix=None, with_odometry=False)
        export.write_protocol(paths["protocol"], log)
    if not paths["blf"].exists():
        log = simulate_parking_log(stop_s=240.0, drive_s=60.0, rate_hz=100.0, seed=7, g_mps2=G_FIX)
        export.write_can_log(paths["blf"], log, dbc_path=DBC, with_fix=(48.78, 9.18, 250.0))
        export.write_protocol(paths["protocol_blf"], log)
    return paths


def mountcal_path(log: Path, protocol: Path, fmt: str) -> Calibration:
    opts = LogOptions(dbc=str(DBC), mapping=str(MAPPING)) if fmt == "blf" else LogOptions()
    return calibrate_job(LogJob(paths=(str(log),), log=opts, protocol=str(protocol), use="stops")).calibration


def conventional_mcap(log: Path, protocol: Path) -> Calibration:
    t: list[float] = []
    acc: list[tuple[float, float, float]] = []
    gyro: list[tuple[float, float, float]] = []
    sp_t: list[float] = []
    sp: list[float] = []
    with open(log, "rb") as f:
        for _, channel, _message, ros in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            if channel.topic == "/imu/data":
                t.append(ros.header.stamp.sec + ros.header.stamp.nanosec * 1e-9)
                a, w = ros.linear_acceleration, ros.angular_velocity
                acc.append((a.x, a.y, a.z))
                gyro.append((w.x, w.y, w.z))
            elif channel.topic == "/odom":
                sp_t.append(ros.header.stamp.sec + ros.header.stamp.nanosec * 1e-9)
                sp.append(ros.twist.twist.linear.x)
    channels = {"speed_mps": Channel(np.array(sp_t), np.array(sp))} if sp else {}
    samples = Samples(np.array(t), np.array(acc), np.array(gyro), channels)
    return _calibrate(samples, protocol)


def conventional_blf(log: Path, protocol: Path) -> Calibration:
    db = cantools.database.load_file(str(DBC))
    by_id = {m.frame_id: m for m in db.messages}
    rows: dict[str, list[tuple[float, float]]] = {"AX1": [], "AY1": [], "AZ": [], "speed": []}
    for msg in can.BLFReader(str(log)):
        m = by_id.get(msg.arbitration_id)
        if m is None:
            continue
        sig = m.decode(msg.data)
        for name in ("AX1", "AY1", "AZ"):
            if name in sig:
                rows[name].append((msg.timestamp, float(sig[name])))
        if m.name == "SIM_VEHICLE_SPEED":
            rows["speed"].append((msg.timestamp, float(next(iter(sig.values())))))
    ax, ay, az, sp = (np.array(rows[k]) for k in ("AX1", "AY1", "AZ", "speed"))
    n = min(len(ax), len(ay), len(az))  # one frame of each per sample, in order
    acc = np.column_stack([ax[:n, 1], ay[:n, 1], az[:n, 1]]) * 9.80665
    speed_scale = 1 / 3.6 if "km" in (db.get_message_by_name("SIM_VEHICLE_SPEED").signals[0].unit or "") else 1.0
    samples = Samples(ax[:n, 0], acc, None, {"speed_mps": Channel(sp[:, 0], sp[:, 1] * speed_scale)})
    return _calibrate(samples, protocol)


def _calibrate(samples: Samples, protocol: Path) -> Calibration:
    found = tabulate(samples, None, read_protocol(str(protocol)))
    return calibrate(found.table)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--workdir", type=Path, default=Path("/tmp/mountcal-e2e"))
    args = ap.parse_args()
    paths = generate(args.workdir)
    print(
        "| log | mountcal (s) | conventional (s) | speed-up | roll / pitch / yaw, mountcal | the same, conventional |"
    )
    print("|---|---|---|---|---|---|")
    for fmt, conv, protocol in (
        ("mcap", conventional_mcap, paths["protocol"]),
        ("blf", conventional_blf, paths["protocol_blf"]),
    ):
        times: dict[str, list[float]] = {"m": [], "c": []}
        for _ in range(args.runs):  # interleaved, median reported
            t0 = time.perf_counter()
            cm = mountcal_path(paths[fmt], protocol, fmt)
            times["m"].append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            cc = conv(paths[fmt], protocol)
            times["c"].append(time.perf_counter() - t0)
        m, c = statistics.median(times["m"]), statistics.median(times["c"])
        show = lambda cal: f"{cal.roll_deg:.4f} / {cal.pitch_deg:.4f} / {cal.yaw_deg:.3f}"  # noqa: E731
        print(
            f"| 1 h {fmt.upper()} ({paths[fmt].stat().st_size / 2**20:.0f} MiB) | {m:.2f} | {c:.2f} | **{c / m:.0f}×** "
            f"| {show(cm)} | {show(cc)} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
