"""A ROS topic stamped on another clock than the recorder's (a driver's boot time against log_time in Unix time):
moved onto the recorder's clock and said (mountcal/io/stamp_clock.py), so its samples overlap the other
channels and date the log; topics on the recorder's clock are read as stamped."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from rosbags.convert.converter import convert

from mountcal.cli import main
from mountcal.io.logs import read_log
from mountcal.io.samples import Channel, Samples
from mountcal.io.stamp_clock import NS, StampClocks
from mountcal.io.writers import IMU_TOPIC, ODOMETRY_TOPIC, START_TIME_S, write_mcap, write_protocol
from mountcal.simulate.drive import simulate_drive
from mountcal.simulate.stops import simulate_parking_log

BOOT_S = 100.0  # the IMU driver's clock at the log's start: seconds since its power-on
BOOT = {IMU_TOPIC: BOOT_S - START_TIME_S}  # header.stamp = log_time + this


@pytest.fixture(scope="module")
def parking(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:
    """A parking session (stops on a 5° slope, driven between) whose IMU is stamped in boot time while the
    odometry and log_time are Unix time; the same log stamped in Unix time; the protocol sheet in Unix time."""
    folder = tmp_path_factory.mktemp("parking")
    park = simulate_parking_log(5.0, 6.0, 7.0, seed=9)
    boot, unix, sheet = folder / "boot.mcap", folder / "unix.mcap", folder / "protocol.csv"
    write_mcap(boot, park, stamp_offsets_s=BOOT)
    write_mcap(unix, park)
    write_protocol(sheet, park)
    return boot, unix, sheet


def _result(path: Path) -> dict:  # type: ignore[type-arg]
    return json.loads(path.read_text(encoding="utf-8"))  # type: ignore[no-any-return]


def _within_sigma(doc: dict, truth: dict[str, float]) -> None:  # type: ignore[type-arg]
    for angle, value in truth.items():
        assert abs(doc["mounting"][angle] - value) < 3.0 * doc["uncertainty"][angle], angle


def test_a_boot_time_imu_is_moved_onto_the_recorders_clock_and_its_speed_overlaps(parking) -> None:  # type: ignore[no-untyped-def]
    boot, unix, _ = parking
    moved, stamped = read_log(boot), read_log(unix)
    speed = moved.channels["speed_mps"]
    assert speed.t_s[0] <= moved.t_s[0] + 1.0 and speed.t_s[-1] >= moved.t_s[-1] - 1.0  # one clock: they overlap
    assert moved.t_s[0] == pytest.approx(START_TIME_S, abs=1e-6)  # dated: the recorder's Unix time
    # one constant per topic: the stamps keep their own spacing (to float64's resolution at Unix magnitudes)
    assert np.max(np.abs(moved.t_s - stamped.t_s)) < 1e-6
    assert np.array_equal(speed.t_s, stamped.channels["speed_mps"].t_s)  # the odometry, on log_time, untouched
    clock = [c for c in moved.conventions if c.name == "stamp_clock"]
    assert len(clock) == 1 and clock[0].how == "inferred" and clock[0].by == "header.stamp against log_time"
    assert IMU_TOPIC in clock[0].value and f"{START_TIME_S - BOOT_S:+.3f} s" in clock[0].value
    assert ODOMETRY_TOPIC not in clock[0].value
    assert not any("clock" in n for n in moved.notes)


def test_a_boot_time_imu_calibrates_against_a_unix_time_protocol(parking, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    boot, _, sheet = parking
    out = tmp_path / "r.json"
    assert main(["calibrate", str(boot), "--protocol", str(sheet), "-o", str(out), "-q"]) == 0
    doc = _result(out)
    _within_sigma(doc, {"roll_deg": 5.0, "pitch_deg": 6.0, "yaw_deg": 7.0})
    assert doc["confident"]
    clock = [c for c in doc["provenance"]["conventions"] if c["name"] == "stamp_clock"]
    assert len(clock) == 1 and clock[0]["how"] == "inferred" and IMU_TOPIC in clock[0]["value"]
    assert not [c for c in doc["provenance"]["conventions"] if c["name"] == "protocol_clock"]  # taken as stated


def test_a_boot_time_imu_calibrates_from_its_drive(tmp_path: Path) -> None:
    """Before, the speed (Unix time) lay 54 years after the IMU (boot time): 'no driving at ≥ 3 m/s'."""
    drive = simulate_drive(4.0, -3.0, 25.0, duration_s=900.0, seed=6).to_samples()
    log, out = tmp_path / "drive.mcap", tmp_path / "r.json"
    write_mcap(log, drive, with_temperature=False, stamp_offsets_s=BOOT)
    assert main(["calibrate", str(log), "--use", "driving", "-o", str(out), "-q"]) == 0
    doc = _result(out)
    _within_sigma(doc, {"roll_deg": 4.0, "pitch_deg": -3.0, "yaw_deg": 25.0})
    assert [c["name"] for c in doc["provenance"]["conventions"]].count("stamp_clock") == 1


def test_a_ros2_bag_of_the_boot_time_log_reads_on_the_recorders_clock_too(parking, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    """The path every bag is read through (here a ROS 2 SQLite bag that rosbags converted): the same rule."""
    boot, _, _ = parking
    bag = tmp_path / "boot_bag"
    convert([boot], bag, "sqlite3", 9, None, "file", None, None, [], [], [], [])
    moved, direct = read_log(bag), read_log(boot)
    np.testing.assert_array_equal(moved.t_s, direct.t_s)
    np.testing.assert_array_equal(moved.channels["speed_mps"].t_s, direct.channels["speed_mps"].t_s)
    (clock,) = [c for c in moved.conventions if c.name == "stamp_clock"]
    assert IMU_TOPIC in clock.value and clock.by.startswith("header.stamp against the record time")


def test_the_stream_rotate_reads_moves_the_boot_time_imu_as_the_whole_read_does(parking, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    """``rotate`` reads an MCAP a batch at a time (iter_mcap). Before, its batches kept the IMU's boot-time stamps
    and carried no odometry: a log calibrated on Unix time was written 54 years earlier, and no speed came
    with it. Now each batch has its odometry, every topic on the recorder's clock, as :func:`read_log` gives."""
    import pandas as pd

    from mountcal.io.logs import iter_log

    boot, _, sheet = parking
    whole = read_log(boot)
    batches = list(iter_log(boot, max_samples=5000))
    np.testing.assert_array_equal(np.concatenate([b.t_s for b in batches]), whole.t_s)
    speed = [b.channels["speed_mps"] for b in batches if "speed_mps" in b.channels]
    np.testing.assert_array_equal(np.concatenate([c.t_s for c in speed]), whole.channels["speed_mps"].t_s)
    cal, out = tmp_path / "r.json", tmp_path / "v.parquet"
    assert main(["calibrate", str(boot), "--protocol", str(sheet), "-o", str(cal), "-q"]) == 0
    assert main(["rotate", "--calibration", str(cal), str(boot), "-o", str(out), "-q"]) == 0
    np.testing.assert_array_equal(pd.read_parquet(out)["t_s"].to_numpy(), whole.t_s)


def test_stamps_on_the_recorders_clock_are_read_as_stamped(parking) -> None:  # type: ignore[no-untyped-def]
    _, unix, _ = parking
    samples = read_log(unix)
    park = simulate_parking_log(5.0, 6.0, 7.0, seed=9)
    stamps = int(START_TIME_S) * NS + np.round(park.t_s * 1e9).astype(np.int64)  # as write_mcap stamps them
    assert np.array_equal(samples.t_s, (stamps // NS).astype(np.float64) + (stamps % NS).astype(np.float64) * 1e-9)
    assert not any(c.name == "stamp_clock" for c in samples.conventions)
    assert samples.notes == ()


# --------------------------------------------------------------------------- the rule, on arrays


def _samples(n: int) -> Samples:
    t = np.arange(n) * 0.01
    return Samples(t, np.zeros((n, 3)), channels={"speed_mps": Channel(t.copy(), np.zeros(n))})


def _stamps(t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ns = np.round(t_s * 1e9).astype(np.int64)
    return ns // NS, ns % NS


def _told(record_minus_stamp_s: np.ndarray, stamp_s: np.ndarray, topic: str = "/imu") -> StampClocks:
    clocks = StampClocks("log_time")
    sec, nanosec = _stamps(stamp_s)
    record = np.round((stamp_s + record_minus_stamp_s) * 1e9).astype(np.int64)
    clocks.add(topic, sec, nanosec, record, ["imu"])
    return clocks


def test_latency_of_a_few_seconds_and_a_replayed_log_are_left_as_stamped() -> None:
    samples, n = _samples(1000), 1000
    stamp = START_TIME_S + np.arange(n) * 0.01
    lag = np.random.default_rng(1).uniform(0.001, 2.0, n)  # a recorder under load, up to 2 s behind
    assert _told(lag, stamp).settle(samples) is samples
    assert _told(np.full(n, 86_400.0), stamp).settle(samples) is samples  # recorded again a day later: all dated


def test_a_clock_that_jumps_is_said_and_counted_not_moved() -> None:
    samples, n = _samples(1000), 1000
    offset = np.where(np.arange(n) < 600, START_TIME_S, 0.002)  # boot time, then synchronised to Unix time
    stamp = START_TIME_S + np.arange(n) * 0.01 - offset + 0.002
    settled = _told(offset, stamp).settle(samples)
    assert np.array_equal(settled.t_s, samples.t_s) and not settled.conventions
    (note,) = [n for n in settled.notes if "not steady" in n]
    assert "/imu" in note and "40 % of its messages" in note


def _with_odometry(imu_offset_s: float, odom_offset_s: float, n: int = 1000) -> StampClocks:
    stamp = START_TIME_S + np.arange(n) * 0.01
    clocks = _told(np.full(n, imu_offset_s), stamp)
    sec, nanosec = _stamps(stamp)
    clocks.add("/odom", sec, nanosec, np.round((stamp + odom_offset_s) * 1e9).astype(np.int64), ["speed_mps"])
    return clocks


def test_a_dated_clock_is_moved_only_beside_a_topic_on_the_recorders() -> None:
    samples = _samples(1000)
    # the IMU's clock an hour behind (a time zone), the odometry on log_time: the IMU is moved onto it
    settled = _with_odometry(3600.0, 0.05).settle(samples)
    assert np.allclose(settled.t_s - samples.t_s, 3600.0)
    assert np.array_equal(settled.channels["speed_mps"].t_s, samples.channels["speed_mps"].t_s)
    assert [c.name for c in settled.conventions] == ["stamp_clock"] and "another clock" in settled.conventions[0].value
    # both far from the recorder, an hour apart: which is right the data cannot tell; left, and said
    apart = _with_odometry(3600.0, 7200.0).settle(samples)
    assert np.array_equal(apart.t_s, samples.t_s) and not apart.conventions
    assert any("different clocks" in n and "/imu +3600.000 s" in n for n in apart.notes)


def test_a_topic_with_unset_stamps_among_boot_stamps_is_not_moved() -> None:
    samples, n = _samples(1000), 1000
    stamp = BOOT_S + np.arange(n) * 0.01
    sec, nanosec = _stamps(stamp)
    sec[::10], nanosec[::10] = 0, 0  # timed by the recorder (the reader's rule for a zero stamp)
    record = np.round((stamp + START_TIME_S - BOOT_S) * 1e9).astype(np.int64)
    clocks = StampClocks("log_time")
    clocks.add("/imu", sec, nanosec, record, ["imu"])
    settled = clocks.settle(samples)
    assert np.array_equal(settled.t_s, samples.t_s) and not settled.conventions
    assert any("100 of its messages carry no stamp" in n for n in settled.notes)
