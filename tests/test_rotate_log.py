"""Whole logs into the vehicle frame: exact on every format, the identity back, MCAP copied
through, atomic output (also under SIGKILL), bounded chunks, drops counted, bad input refused,
and the notebook examples run as doctests. Logs are written by the real writers (mcap-ros2,
python-can + cantools)."""

from __future__ import annotations

import doctest
import hashlib
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import can
import cantools
import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from mcap_ros2.writer import Writer as Ros2Writer

import mountcal.apply.rotate_log
import mountcal.core.errors
from mountcal import calibrate, simulate_preset
from mountcal.apply.rotate import acc_to_sensor, rate_to_sensor
from mountcal.apply.rotate_log import rotate_log, to_frame
from mountcal.calibration.fit import Options
from mountcal.cli import main
from mountcal.core.result import Calibration
from mountcal.io.logs import read_log
from mountcal.io.mcap.write import IMU_DEFINITION
from mountcal.io.reader import LogOptions
from mountcal.simulate.drive import simulate_drive

T0_NS = 1_714_557_600_000_000_000
DBC = Path(__file__).resolve().parent / "data" / "imu_acc_gyro.dbc"  # two 6-byte messages, 16-bit signals


@pytest.fixture(scope="module")
def drive():  # type: ignore[no-untyped-def]
    return simulate_drive(duration_s=30.0, seed=11)


@pytest.fixture(scope="module")
def cal() -> Calibration:
    """A calibration with a fitted bias (so its removal is exercised)."""
    table, _ = simulate_preset("zhang2011", seed=1, bias_mps2=np.array([0.1, -0.05, 0.2]))
    result = calibrate(table, Options(model="rotation,slope,bias"))
    assert result.bias_mps2 is not None
    return result


def write_mcap(path: Path, drive, *, nan_rows: tuple[int, ...] = ()) -> None:  # type: ignore[no-untyped-def]
    """A ROS 2 MCAP (mcap-ros2 writer): IMU, a status string topic, an attachment and metadata."""
    with open(path, "wb") as f:
        w = Ros2Writer(f, chunk_size=64 * 1024)
        imu = w.register_msgdef("sensor_msgs/msg/Imu", IMU_DEFINITION)
        status = w.register_msgdef("std_msgs/msg/String", "string data")
        for i in range(drive.t_s.size):
            t = T0_NS + round(drive.t_s[i] * 1e9)
            acc = [float("nan")] * 3 if i in nan_rows else drive.acc_s[i].tolist()
            msg = {
                "header": {"stamp": {"sec": t // 10**9, "nanosec": t % 10**9}, "frame_id": "imu_link"},
                "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
                "orientation_covariance": [0.01, 0, 0, 0, 0.01, 0, 0, 0, 0.01],
                "angular_velocity": dict(zip("xyz", drive.gyro_s[i].tolist(), strict=True)),
                "angular_velocity_covariance": [1e-4, 0, 0, 0, 2e-4, 0, 0, 0, 3e-4],
                "linear_acceleration": dict(zip("xyz", acc, strict=True)),
                "linear_acceleration_covariance": [1e-2, 0, 0, 0, 2e-2, 0, 0, 0, 3e-2],
            }
            w.write_message("/imu/data", imu, msg, log_time=t + 2000, publish_time=t + 1000, sequence=i)
            if i % 50 == 0:
                w.write_message("/status", status, {"data": f"ok {i}"}, log_time=t, publish_time=t, sequence=i)
        w._writer.add_attachment(
            create_time=T0_NS, log_time=T0_NS, name="notes.txt", media_type="text/plain", data=b"x"
        )
        w._writer.add_metadata(name="vehicle", data={"id": "car-1"})
        w.finish()


def write_blf(path: Path, dbc_path: Path, drive) -> None:  # type: ignore[no-untyped-def]
    """A BLF (python-can writer), frames encoded by cantools from the DBC."""
    db = cantools.database.load_file(dbc_path)
    acc_msg, gyro_msg = db.get_message_by_name("IMU_ACC"), db.get_message_by_name("IMU_GYRO")
    with can.BLFWriter(str(path)) as w:
        for i in range(drive.t_s.size):
            t = T0_NS * 1e-9 + drive.t_s[i]
            a = dict(zip(("AccelerationX", "AccelerationY", "AccelerationZ"), drive.acc_s[i], strict=True))
            g = dict(zip(("AngularRateX", "AngularRateY", "AngularRateZ"), drive.gyro_s[i], strict=True))
            for msg, values, dt in ((acc_msg, a, 0.0), (gyro_msg, g, 2e-4)):
                data = msg.encode(values)
                w.on_message_received(
                    can.Message(
                        timestamp=t + dt, arbitration_id=msg.frame_id, data=data, is_extended_id=False, channel=0
                    )
                )


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory, drive) -> dict[str, tuple[Path, LogOptions]]:  # type: ignore[no-untyped-def]
    folder = tmp_path_factory.mktemp("logs")
    frame = to_frame(drive.to_samples())
    frame.to_csv(folder / "drive.csv", index=False)
    frame.to_parquet(folder / "drive.parquet", index=False)
    write_mcap(folder / "drive.mcap", drive)
    write_blf(folder / "drive.blf", DBC, drive)
    return {
        "csv": (folder / "drive.csv", LogOptions()),
        "parquet": (folder / "drive.parquet", LogOptions()),
        "mcap": (folder / "drive.mcap", LogOptions()),
        "blf": (folder / "drive.blf", LogOptions(dbc=str(DBC))),
    }


def read_output(path: Path, fmt: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """t_s, acc, gyro of a rotated output, read back with the formats' own readers."""
    if fmt == "parquet":
        df = pd.read_parquet(path)
    elif fmt == "csv":
        df = pd.read_csv(path)
    else:
        msgs = list(read_ros2_messages(str(path), topics=[t for t in _topics(path) if t.endswith("vehicle")]))
        m = msgs
        t = np.array([x.header.stamp.sec + x.header.stamp.nanosec * 1e-9 for x in m])
        acc = np.array([[x.linear_acceleration.x, x.linear_acceleration.y, x.linear_acceleration.z] for x in m])
        gyro = np.array([[x.angular_velocity.x, x.angular_velocity.y, x.angular_velocity.z] for x in m])
        return t, acc, gyro
    return df["t_s"].to_numpy(), df[["ax", "ay", "az"]].to_numpy(), df[["gx", "gy", "gz"]].to_numpy()


def read_ros2_messages(path: str, topics: list[str]) -> list:  # type: ignore[type-arg]
    """Decoded messages of some topics (the mcap reader with the ROS 2 decoder)."""
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [d for _, _, _, d in reader.iter_decoded_messages(topics=topics)]


def _topics(path: Path) -> list[str]:
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    return [c.topic for c in summary.channels.values()]


# --------------------------------------------------------------------------- exactness


@pytest.mark.parametrize("fmt", ["parquet", "csv", "mcap"])
@pytest.mark.parametrize("source", ["csv", "parquet", "mcap", "blf"])
def test_rotation_is_exact_against_a_float64_matrix_reference(
    logs,
    cal: Calibration,
    tmp_path: Path,
    source: str,
    fmt: str,  # type: ignore[no-untyped-def]
) -> None:
    path, opts = logs[source]
    out = tmp_path / f"out.{fmt}"
    report = rotate_log(path, cal, out, options=opts, chunk_samples=1000)
    s = read_log(path, opts)
    assert report.samples_in == report.samples_out == len(s)
    rot = cal.rot_vs.as_matrix()
    assert cal.bias_mps2 is not None
    ref_acc = (s.acc_s - cal.bias_mps2) @ rot.T
    assert s.gyro_s is not None
    ref_gyro = s.gyro_s @ rot.T
    t, acc, gyro = read_output(out, fmt)
    np.testing.assert_allclose(t, s.t_s, rtol=0, atol=1e-6 if fmt == "mcap" else 0)
    np.testing.assert_allclose(acc, ref_acc, rtol=0, atol=1e-12)
    np.testing.assert_allclose(gyro, ref_gyro, rtol=0, atol=1e-12)


@pytest.mark.parametrize("fmt", ["parquet", "csv", "mcap"])
def test_single_thread_output_equals_overlapped(logs, cal: Calibration, tmp_path: Path, fmt: str, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """Without helper threads (OMP_NUM_THREADS=1) the chunks are encoded inline: the same rows."""
    path, opts = logs["blf"]
    rotate_log(path, cal, tmp_path / f"a.{fmt}", options=opts, chunk_samples=1000)
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    rotate_log(path, cal, tmp_path / f"b.{fmt}", options=opts, chunk_samples=1000)
    for a, b in zip(read_output(tmp_path / f"a.{fmt}", fmt), read_output(tmp_path / f"b.{fmt}", fmt), strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_sensor_to_vehicle_to_sensor_is_the_identity(logs, tmp_path: Path, seed: int) -> None:  # type: ignore[no-untyped-def]
    table, _ = simulate_preset("zhang2011", seed=seed, roll_deg=40.0 * seed - 30, yaw_deg=120.0 * seed)
    cal = calibrate(table, Options(model="rotation,slope,bias"))
    path, opts = logs["parquet"]
    rotate_log(path, cal, tmp_path / "v.parquet")
    df = pd.read_parquet(tmp_path / "v.parquet")
    s = read_log(path, opts)
    # np.array: pandas ≥ 3 hands out read-only views, which scipy's Rotation.apply refuses
    back_acc = acc_to_sensor(np.array(df[["ax", "ay", "az"]].to_numpy()), cal)
    back_gyro = rate_to_sensor(np.array(df[["gx", "gy", "gz"]].to_numpy()), cal)
    np.testing.assert_allclose(back_acc, s.acc_s, rtol=0, atol=1e-12)
    np.testing.assert_allclose(back_gyro, s.gyro_s, rtol=0, atol=1e-12)


# --------------------------------------------------------------------------- MCAP copied through


def test_mcap_output_keeps_every_channel_and_message_and_adds_the_vehicle_topic(
    logs,
    cal: Calibration,
    tmp_path: Path,  # type: ignore[no-untyped-def]
) -> None:
    src, _ = logs["mcap"]
    out = tmp_path / "v.mcap"
    report = rotate_log(src, cal, out)
    assert report.topic == "/imu/data/vehicle" and report.copied_channels == 2
    with open(src, "rb") as f_in, open(out, "rb") as f_out:
        r_in, r_out = make_reader(f_in), make_reader(f_out)
        s_in, s_out = r_in.get_summary(), r_out.get_summary()
        assert s_in is not None and s_out is not None and s_in.statistics and s_out.statistics
        topics_out = {c.topic: (cid, c) for cid, c in s_out.channels.items()}
        for cid, ch in s_in.channels.items():
            cid_out, ch_out = topics_out[ch.topic]
            assert s_out.schemas[ch_out.schema_id].data == s_in.schemas[ch.schema_id].data
            assert s_out.statistics.channel_message_counts[cid_out] == s_in.statistics.channel_message_counts[cid]
        new_id, new = topics_out["/imu/data/vehicle"]
        assert s_out.schemas[new.schema_id].name == "sensor_msgs/msg/Imu" and new.message_encoding == "cdr"
        n_imu = s_in.statistics.channel_message_counts[topics_out["/imu/data"][0]]
        assert s_out.statistics.channel_message_counts[new_id] == n_imu == report.samples_out
        # every original message byte for byte, with its log and publish time and sequence
        original = [(c.topic, m.sequence, m.log_time, m.publish_time, m.data) for _, c, m in r_in.iter_messages()]
        copied = [
            (c.topic, m.sequence, m.log_time, m.publish_time, m.data)
            for _, c, m in r_out.iter_messages()
            if c.topic != "/imu/data/vehicle"
        ]
        assert copied == original
        imu_times = [(m.sequence, m.log_time, m.publish_time) for _, c, m in r_in.iter_messages(topics=["/imu/data"])]
        new_times = [(m.sequence, m.log_time, m.publish_time) for _, c, m in r_out.iter_messages(topics=[new.topic])]
        assert new_times == imu_times
        assert [a.data for a in r_out.iter_attachments()] == [a.data for a in r_in.iter_attachments()] == [b"x"]
        assert [m.metadata for m in r_out.iter_metadata()] == [{"id": "car-1"}]
    # the rotated messages: frame_id base_link, stamps kept, orientation and covariances turned
    v = read_ros2_messages(str(out), topics=["/imu/data/vehicle"])[:5]
    o = read_ros2_messages(str(src), topics=["/imu/data"])[:5]
    rot = cal.rot_vs.as_matrix()
    for a, b in zip(v, o, strict=True):
        assert a.header.frame_id == "base_link"
        assert (a.header.stamp.sec, a.header.stamp.nanosec) == (b.header.stamp.sec, b.header.stamp.nanosec)
        cov = np.reshape(b.linear_acceleration_covariance, (3, 3))
        np.testing.assert_allclose(np.reshape(a.linear_acceleration_covariance, (3, 3)), rot @ cov @ rot.T, atol=1e-15)
        q = [a.orientation.x, a.orientation.y, a.orientation.z, a.orientation.w]
        np.testing.assert_allclose(np.abs(q), np.abs(cal.rot_vs.inv().as_quat()), atol=1e-12)


def test_nan_imu_messages_are_kept_one_for_one_and_counted(cal: Calibration, tmp_path: Path, drive) -> None:  # type: ignore[no-untyped-def]
    src = tmp_path / "nan.mcap"
    write_mcap(src, drive, nan_rows=(3, 7, 11))
    report = rotate_log(src, cal, tmp_path / "v.mcap")
    assert report.nonfinite == 3 and report.samples_out == drive.t_s.size
    assert any("NaN" in line for line in report.lines())
    to_parquet = rotate_log(src, cal, tmp_path / "v.parquet")  # the MCAP reader drops them: counted
    assert to_parquet.samples_out == drive.t_s.size - 3
    assert to_parquet.dropped == {"imu_nonfinite": 3}


# --------------------------------------------------------------------------- atomic, bounded, counted


KILL_SCRIPT = """
import sys, time
import mountcal.io.table.write as writers
real_write = writers.ParquetSamples.write
def slow_write(self, *args):
    real_write(self, *args)
    print("chunk written", file=sys.stderr, flush=True)
    time.sleep(30)
writers.ParquetSamples.write = slow_write
from mountcal.cli import main
sys.exit(main(sys.argv[1:]))
"""


def test_a_process_killed_mid_write_leaves_no_output_file(logs, cal: Calibration, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    src, _ = logs["csv"]
    result = tmp_path / "result.json"
    cal.save(result)
    work = tmp_path / "out"
    work.mkdir()
    out = work / "v.parquet"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-c",
            KILL_SCRIPT,
            "rotate",
            str(src),
            "--calibration",
            str(result),
            "-o",
            str(out),
            "--chunk",
            "500",
        ],
        stderr=subprocess.PIPE,
        text=True,
    )
    assert proc.stderr is not None
    with proc.stderr:
        try:
            lines = iter(proc.stderr.readline, "")
            assert "chunk written" in (line.strip() for line in lines)  # the first row group is on disk
            os.kill(proc.pid, signal.SIGKILL)
        finally:
            proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL
    assert list(work.iterdir()) == []  # no output, and no temporary file either


def test_chunks_are_bounded_and_every_sample_is_written(logs, cal: Calibration, tmp_path: Path, drive) -> None:  # type: ignore[no-untyped-def]
    src, _ = logs["parquet"]
    out = tmp_path / "v.parquet"
    report = rotate_log(src, cal, out, chunk_samples=700)
    n = drive.t_s.size
    assert report.samples_out == n and report.largest_chunk <= 700
    assert report.chunks == -(-n // 700)
    meta = pq.ParquetFile(out).metadata
    assert meta.num_rows == n and max(meta.row_group(i).num_rows for i in range(meta.num_row_groups)) <= 700
    assert b"vehicle" in meta.metadata[b"mountcal.frame"]
    applied = json.loads(meta.metadata[b"mountcal.calibration"])  # every angle with its σ, as the result has them
    for name in ("roll", "pitch", "yaw"):
        sigma = cal.angles.sigma(name)  # type: ignore[arg-type]
        assert sigma is not None and applied[f"{name}_sigma_deg"] == sigma
        assert applied[f"{name}_deg"] == cal.angles.value(name)  # type: ignore[arg-type]


def test_dropped_rows_are_counted_and_reported(cal: Calibration, tmp_path: Path, drive, capsys) -> None:  # type: ignore[no-untyped-def]
    df = to_frame(drive.to_samples())
    df.loc[[5, 50, 500], "ay"] = np.nan
    src = tmp_path / "holes.csv"
    df.to_csv(src, index=False)
    result = tmp_path / "result.json"
    cal.save(result)
    assert main(["rotate", str(src), "--calibration", str(result), "-o", str(tmp_path / "v.csv")]) == 0
    text = capsys.readouterr().err  # status goes to stderr
    assert "non-finite sample rows: 3" in text and f"wrote {len(df) - 3} vehicle-frame samples" in text
    assert len(pd.read_csv(tmp_path / "v.csv")) == len(df) - 3


def test_split_logs_are_joined_in_time_order(cal: Calibration, tmp_path: Path, drive) -> None:  # type: ignore[no-untyped-def]
    df = to_frame(drive.to_samples())
    half = len(df) // 2
    df.iloc[half:].to_csv(tmp_path / "a.csv", index=False)  # the later half has the earlier name
    df.iloc[:half].to_csv(tmp_path / "b.csv", index=False)
    rotate_log([tmp_path / "a.csv", tmp_path / "b.csv"], cal, tmp_path / "v.parquet")
    assert np.array_equal(pd.read_parquet(tmp_path / "v.parquet")["t_s"].to_numpy(), df["t_s"].to_numpy())


# --------------------------------------------------------------------------- bad input


def sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_bad_input_is_refused_clearly_without_output(
    logs,
    cal: Calibration,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],  # type: ignore[no-untyped-def]
) -> None:
    result = tmp_path / "result.json"
    cal.save(result)
    src, _ = logs["csv"]
    before = sha(src)
    out = tmp_path / "v.parquet"
    cases = [
        (["rotate", str(src), "--calibration", str(result), "-o", str(src)], "never overwrites"),
        (["rotate", str(src), "--calibration", str(result), "-o", str(result)], "never overwrites"),
        (["rotate", str(tmp_path / "missing.csv"), "--calibration", str(result), "-o", str(out)], "no such file"),
        (["rotate", str(src), "--calibration", str(tmp_path / "none.json"), "-o", str(out)], "calibration JSON"),
        (["rotate", str(logs["mcap"][0]), "--calibration", str(result), "-o", str(out), "--topic", "/x"], "/x"),
    ]
    bad = tmp_path / "bad.csv"
    pd.DataFrame({"t_s": [0.0, 0.1], "ax": [0.0, 0.1]}).to_csv(bad, index=False)
    cases.append((["rotate", str(bad), "--calibration", str(result), "-o", str(out)], "columns t_s, ax, ay, az"))
    in_g = tmp_path / "g.csv"
    frame = pd.read_csv(src)
    frame[["ax", "ay", "az"]] /= 9.80665
    frame.to_csv(in_g, index=False)
    cases.append((["rotate", str(in_g), "--calibration", str(result), "-o", str(out)], "ax=ax:g,ay=ay:g,az=az:g"))
    for argv, words in cases:
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith("mountcal: error:") and words in err and "Traceback" not in err
        assert not out.exists()
    assert sha(src) == before and sha(result) == sha(result)


def test_an_mcap_output_from_several_mcap_files_is_refused(logs, cal: Calibration, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    src, _ = logs["mcap"]
    with pytest.raises(mountcal.core.errors.InputError, match="one MCAP file"):
        rotate_log([src, src], cal, tmp_path / "v.mcap")


# --------------------------------------------------------------------------- notebooks and real logs


def test_the_notebook_examples_run_as_doctests() -> None:
    result = doctest.testmod(mountcal.apply.rotate_log, optionflags=doctest.ELLIPSIS)
    assert result.attempted >= 10 and result.failed == 0


def test_to_frame_holds_each_channel_at_its_latest_value(drive) -> None:  # type: ignore[no-untyped-def]
    s = drive.to_samples()
    df = to_frame(s)
    speed = s.channels["speed_mps"]
    i = 777
    latest = speed.value[np.searchsorted(speed.t_s, df["t_s"].iloc[i], side="right") - 1]
    assert df["speed_mps"].iloc[i] == latest and np.isnan(df["speed_mps"].iloc[0])  # delayed channel: not yet
    assert df.attrs["frame"] == "sensor" and list(df.columns[:7]) == ["t_s", "ax", "ay", "az", "gx", "gy", "gz"]


@pytest.mark.real_data
def test_a_real_canedge_log_rotates_sample_for_sample(real_data: Path, cal: Calibration, tmp_path: Path) -> None:
    log = real_data / "canedge" / "3BA199E2_car_DK_2021-07-26" / "00000165" / "00000002-60FEB8E3.MF4"
    opts = LogOptions(dbc=str(real_data / "canedge" / "dbc" / "gnss.dbc"), channel=2)
    report = rotate_log(log, cal, tmp_path / "v.parquet", options=opts, chunk_samples=20_000)
    s = read_log(log, opts)
    assert report.samples_out == len(s) and report.dropped == s.dropped
    df = pd.read_parquet(tmp_path / "v.parquet")
    assert cal.bias_mps2 is not None
    np.testing.assert_allclose(
        df[["ax", "ay", "az"]].to_numpy(), (s.acc_s - cal.bias_mps2) @ cal.rot_vs.as_matrix().T, rtol=0, atol=1e-12
    )
