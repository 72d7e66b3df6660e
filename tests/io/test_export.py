"""Sample logs written by the formats' real writers: read back, stop tables, calibration, regeneration.

Every format mountcal writes is read back through mountcal's readers and compared with the
simulated samples, within what the format can hold; the stop table of each is compared with the one
built from the libraries' own per-message path (python-can iteration + cantools ``decode_message``;
mcap-ros2-support decoding); the bundled samples in ``data/`` must calibrate to their truth and be
what the command in ``data/README.md`` writes.
"""

from __future__ import annotations

import hashlib
import json
import math
import shlex
import tomllib
from pathlib import Path
from typing import Any

import can
import cantools
import numpy as np
import pandas as pd
import pytest
from asammdf import MDF
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from mountcal.cli import main
from mountcal.core.conventions import G_N, normal_gravity
from mountcal.core.errors import InputError
from mountcal.core.result import Calibration
from mountcal.io import writers as export
from mountcal.io.can.read import read_can
from mountcal.io.mcap.read import read_mcap
from mountcal.io.ros2.definitions import ros2_definition
from mountcal.io.samples import Channel, Samples
from mountcal.simulate.stops import ParkingLog, simulate_parking_log
from mountcal.stops.detect import StopDetection
from mountcal.stops.headings import read_protocol, tabulate

REPO = Path(__file__).resolve().parents[2]
DATA = REPO / "data"
DBC = DATA / "imu_mm5_10.dbc"
MAPPING = DATA / "imu_mm5_10.toml"
FIX = (48.7758, 9.1829, 250.0)
CAN_FORMATS = ["blf", "asc", "log", "trc", "csv", "mf4"]
ALL_FORMATS = ["mcap", *CAN_FORMATS]
# SI per unit of the DBC's signals, stated here independently of the writer
SI_PER_UNIT = {"g": G_N, "°/s": math.pi / 180.0, "km/h": 1 / 3.6, "deg": 1.0, "degC": 1.0, "m": 1.0}
TIME_TOLERANCE_S = 2e-6  # text formats keep µs; python-can's float seconds ≈ 0.24 µs at Unix-epoch magnitudes


# --------------------------------------------------------------------------- a small session, every format


@pytest.fixture(scope="module")
def small_log() -> ParkingLog:
    """Four stops at 50 Hz: short enough to write every format quickly, long enough for stops."""
    return simulate_parking_log(
        4.0,
        -3.0,
        20.0,
        slope_deg=6.0,
        beta_deg=(0.0, 90.0, 180.0, 270.0),
        stop_s=24.0,
        drive_s=10.0,
        rate_hz=50.0,
        g_mps2=normal_gravity(FIX[0], FIX[2]),
        seed=7,
    )


@pytest.fixture(scope="module")
def written(small_log: ParkingLog, tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, Any, Path]]:
    """Each format written once: format → (log, WrittenLog, protocol sheet on that log's clock)."""
    folder = tmp_path_factory.mktemp("export")
    out = {}
    for fmt in ALL_FORMATS:
        path = folder / f"session.{fmt}"
        if fmt == "mcap":
            done = export.write_mcap(path, small_log, with_fix=FIX)
        else:
            done = export.write_can_log(path, small_log, dbc_path=DBC, with_fix=FIX)
        protocol = folder / f"protocol_{fmt}.csv"
        export.write_protocol(protocol, small_log, start_time_s=done.start_time_s)
        out[fmt] = (path, done, protocol)
    return out


def _every(log: ParkingLog, rate_hz: float) -> np.ndarray:
    """Indices of the samples a channel thinned to rate_hz keeps (the log is uniformly sampled)."""
    step = round((log.t_s.size - 1) / (log.t_s[-1] - log.t_s[0]) / rate_hz)
    return np.arange(0, log.t_s.size, step)


def _circular_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.abs((np.asarray(a) - np.asarray(b) + 180.0) % 360.0 - 180.0)


# --------------------------------------------------------------------------- ROS 2 definitions


def test_ros2_definitions_are_concatenated_as_rosbag2_does() -> None:
    """Top-level text first, then each dependency once, depth first, in sorted order."""
    text = ros2_definition("nav_msgs/msg/Odometry")
    assert text.startswith("std_msgs/Header header\n")
    names = [line[5:] for line in text.splitlines() if line.startswith("MSG: ")]
    assert names == [
        "geometry_msgs/PoseWithCovariance",
        "geometry_msgs/Pose",
        "geometry_msgs/Point",
        "geometry_msgs/Quaternion",
        "geometry_msgs/TwistWithCovariance",
        "geometry_msgs/Twist",
        "geometry_msgs/Vector3",
        "std_msgs/Header",
        "builtin_interfaces/Time",
    ]
    separators = [i for i, line in enumerate(text.splitlines()) if line == "=" * 80]
    assert len(separators) == len(names)
    imu = ros2_definition("sensor_msgs/msg/Imu")
    assert [line[5:] for line in imu.splitlines() if line.startswith("MSG: ")] == [
        "geometry_msgs/Quaternion",
        "geometry_msgs/Vector3",
        "std_msgs/Header",
        "builtin_interfaces/Time",
    ]


# --------------------------------------------------------------------------- read back: MCAP


def test_mcap_reads_back_exactly(small_log: ParkingLog, written: dict[str, tuple[Path, Any, Path]]) -> None:
    path, done, _ = written["mcap"]
    s = read_mcap(path)
    t0 = done.start_time_s
    np.testing.assert_allclose(s.t_s - t0, small_log.t_s, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(s.acc_s, small_log.acc_s)
    assert s.gyro_s is not None
    np.testing.assert_array_equal(s.gyro_s, small_log.gyro_s)
    assert s.dropped == {}
    fast, slow = _every(small_log, 10.0), _every(small_log, 1.0)
    np.testing.assert_array_equal(s.channels["speed_mps"].value, small_log.speed_mps[fast])
    np.testing.assert_allclose(s.channels["speed_mps"].t_s - t0, small_log.t_s[fast], atol=1e-6)
    assert _circular_deg(s.channels["heading_deg"].value, small_log.heading_deg[fast]).max() < 1e-9
    np.testing.assert_array_equal(s.channels["temperature_c"].value, small_log.temperature_c[slow])
    for key, value in zip(("lat_deg", "lon_deg", "alt_m"), FIX, strict=True):
        np.testing.assert_array_equal(s.channels[key].value, np.full(slow.size, value))
    assert done.messages == {"/imu/data": small_log.t_s.size, "/imu/temperature": slow.size,
                             "/gnss/fix": slow.size, "/odom": fast.size}  # fmt: skip


def test_mcap_per_message_reader_sees_standard_messages(
    small_log: ParkingLog, written: dict[str, tuple[Path, Any, Path]]
) -> None:
    """mcap-ros2-support decodes every message with the schemas as written; ROS conventions hold."""
    path, done, _ = written["mcap"]
    counts: dict[str, int] = {}
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        for schema, channel, _, ros in reader.iter_decoded_messages(log_time_order=False):
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            assert channel.message_encoding == "cdr" and schema is not None and schema.encoding == "ros2msg"
            if schema.name == "sensor_msgs/msg/Imu" and counts[channel.topic] == 1:
                assert ros.header.frame_id == "imu_link"
                assert ros.orientation_covariance[0] == -1.0  # no orientation estimate
                acc = [ros.linear_acceleration.x, ros.linear_acceleration.y, ros.linear_acceleration.z]
                np.testing.assert_array_equal(acc, small_log.acc_s[0])
    assert counts == done.messages


# --------------------------------------------------------------------------- read back: CAN


def _signal(db: Any, text: str) -> Any:
    message, signal = text.split(".")
    return db.get_message_by_name(message).get_signal_by_name(signal)


def _step_si(signal: Any) -> float:
    return float(signal.scale) * SI_PER_UNIT[signal.unit]


@pytest.mark.parametrize("fmt", CAN_FORMATS)
def test_can_log_reads_back_within_quantisation(
    fmt: str, small_log: ParkingLog, written: dict[str, tuple[Path, Any, Path]]
) -> None:
    path, done, _ = written[fmt]
    db = cantools.database.load_file(DBC)
    roles = tomllib.loads(MAPPING.read_text())["signals"]
    s = read_can(path, DBC, mapping=MAPPING)
    t0 = done.start_time_s
    assert s.dropped == {}
    np.testing.assert_allclose(s.t_s - t0, small_log.t_s, rtol=0, atol=TIME_TOLERANCE_S)
    for k, role in enumerate(("ax", "ay", "az")):
        half_step = _step_si(_signal(db, roles[role])) / 2
        assert np.abs(s.acc_s[:, k] - small_log.acc_s[:, k]).max() <= half_step * (1 + 1e-6)
    assert s.gyro_s is not None
    saturated = 0
    for k, role in enumerate(("gx", "gy", "gz")):
        signal = _signal(db, roles[role])
        lo, hi = float(signal.minimum) * math.pi / 180, float(signal.maximum) * math.pi / 180
        truth = small_log.gyro_s[:, k]
        saturated += int(((truth < lo) | (truth > hi)).sum())  # a real MM5.10 saturates there too
        assert np.abs(s.gyro_s[:, k] - np.clip(truth, lo, hi)).max() <= _step_si(signal) / 2 * (1 + 1e-6)
    assert sum(done.saturated.values()) == saturated
    fast, slow = _every(small_log, 10.0), _every(small_log, 1.0)
    expected = {
        "speed_mps": (fast, small_log.speed_mps[fast], "speed"),
        "heading_deg": (fast, small_log.heading_deg[fast], "heading"),
        "temperature_c": (slow, small_log.temperature_c[slow], "temperature"),
        "lat_deg": (slow, np.full(slow.size, FIX[0]), "latitude"),
        "lon_deg": (slow, np.full(slow.size, FIX[1]), "longitude"),
        "alt_m": (slow, np.full(slow.size, FIX[2]), "altitude"),
    }
    for key, (index, value, role) in expected.items():
        channel = s.channels[key]
        np.testing.assert_allclose(channel.t_s - t0, small_log.t_s[index], rtol=0, atol=TIME_TOLERANCE_S)
        error = _circular_deg(channel.value, value) if key == "heading_deg" else np.abs(channel.value - value)
        assert error.max() <= _step_si(_signal(db, roles[role])) / 2 * (1 + 1e-6), key


def test_mf4_embeds_the_dbc(written: dict[str, tuple[Path, Any, Path]]) -> None:
    path, done, _ = written["mf4"]
    with MDF(path) as mdf:
        data, name, _ = mdf.extract_attachment(index=0)
        assert Path(name).name == DBC.name and bytes(data) == DBC.read_bytes()
        # pinned to the first frame (0.25 ms before the first sample), not to the wall clock of writing
        assert 0 <= done.start_time_s - mdf.header.start_time.timestamp() < 0.002


def test_samples_can_be_written_too(written: dict[str, tuple[Path, Any, Path]], tmp_path: Path) -> None:
    """A reader's Samples (channels on their own clocks) go back out unchanged (MCAP) or quantised (BLF)."""
    samples = read_mcap(written["mcap"][0])
    again = read_mcap(export.write_mcap(tmp_path / "again.mcap", samples, start_time_s=0.0).path)
    np.testing.assert_array_equal(again.t_s, samples.t_s)
    np.testing.assert_array_equal(again.acc_s, samples.acc_s)
    for key, channel in samples.channels.items():
        if key == "heading_deg":  # stored as a quaternion: exact but for rounding
            assert _circular_deg(again.channels[key].value, channel.value).max() < 1e-9
        else:
            np.testing.assert_array_equal(again.channels[key].value, channel.value, err_msg=key)
    blf = read_can(export.write_can_log(tmp_path / "again.blf", samples, dbc_path=DBC, start_time_s=0.0).path, DBC)
    np.testing.assert_allclose(blf.t_s, samples.t_s, rtol=0, atol=TIME_TOLERANCE_S)
    assert np.abs(blf.acc_s - samples.acc_s).max() <= 0.000127465 * G_N / 2 * (1 + 1e-6)


# --------------------------------------------------------------------------- stop tables: mountcal vs per-message


def _can_library_samples(path: Path) -> Samples:
    """The conventional path: python-can iterates the log, cantools decodes each frame."""
    db = cantools.database.load_file(DBC)
    roles = tomllib.loads(MAPPING.read_text())["signals"]
    wanted = {db.get_message_by_name(text.split(".")[0]).frame_id for text in roles.values()}
    frames: dict[int, tuple[list[float], list[dict[str, Any]]]] = {i: ([], []) for i in wanted}
    with can.LogReader(path) as reader:
        for msg in reader:
            if msg.arbitration_id in wanted and not (msg.is_error_frame or msg.is_remote_frame):
                frames[msg.arbitration_id][0].append(msg.timestamp)
                frames[msg.arbitration_id][1].append(db.decode_message(msg.arbitration_id, msg.data))

    def column(role: str) -> tuple[np.ndarray, np.ndarray]:
        message, signal = roles[role].split(".")
        times, values = frames[db.get_message_by_name(message).frame_id]
        unit = db.get_message_by_name(message).get_signal_by_name(signal).unit
        return np.array(times), np.array([v[signal] for v in values], dtype=float) * SI_PER_UNIT[unit]

    t_ref, _ = column("ax")

    def aligned(role: str) -> np.ndarray:
        """The partner frame nearest each ax frame (the earlier on a tie), within one period."""
        t_k, v_k = column(role)
        period = np.median(np.diff(t_k[:1000]))
        after = np.clip(np.searchsorted(t_k, t_ref), 0, t_k.size - 1)
        before = np.clip(after - 1, 0, None)
        index = np.where(np.abs(t_ref - t_k[before]) <= np.abs(t_k[after] - t_ref), before, after)
        assert np.all(np.abs(t_k[index] - t_ref) <= period)
        return v_k[index]

    acc = np.column_stack([aligned(r) for r in ("ax", "ay", "az")])
    gyro = np.column_stack([aligned(r) for r in ("gx", "gy", "gz")])
    channels = {
        key: Channel(*column(role))
        for key, role in (
            ("speed_mps", "speed"),
            ("heading_deg", "heading"),
            ("temperature_c", "temperature"),
            ("lat_deg", "latitude"),
            ("lon_deg", "longitude"),
            ("alt_m", "altitude"),
        )
    }
    return Samples(t_ref, acc, gyro, channels, source=str(path))


def _mcap_library_samples(path: Path) -> Samples:
    """The conventional path: mcap-ros2-support decodes each message into Python objects."""
    imu: list[list[float]] = []
    aux: dict[str, list[tuple[float, float]]] = {}
    with path.open("rb") as f:
        for schema, _, _, ros in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            t = ros.header.stamp.sec + ros.header.stamp.nanosec * 1e-9
            if schema.name == "sensor_msgs/msg/Imu":
                a, w = ros.linear_acceleration, ros.angular_velocity
                imu.append([t, a.x, a.y, a.z, w.x, w.y, w.z])
            elif schema.name == "sensor_msgs/msg/Temperature":
                aux.setdefault("temperature_c", []).append((t, ros.temperature))
            elif schema.name == "sensor_msgs/msg/NavSatFix":
                for key, value in (("lat_deg", ros.latitude), ("lon_deg", ros.longitude), ("alt_m", ros.altitude)):
                    aux.setdefault(key, []).append((t, value))
            elif schema.name == "nav_msgs/msg/Odometry":
                q = ros.pose.pose.orientation
                yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
                aux.setdefault("speed_mps", []).append((t, ros.twist.twist.linear.x))
                aux.setdefault("heading_deg", []).append((t, (90.0 - math.degrees(yaw)) % 360.0))
    rows = np.array(imu)
    channels = {k: Channel(np.array(v)[:, 0], np.array(v)[:, 1]) for k, v in aux.items()}
    return Samples(rows[:, 0], rows[:, 1:4], rows[:, 4:7], channels, source=str(path))


@pytest.mark.parametrize("fmt", ALL_FORMATS)
def test_stops_match_the_per_message_library_path(
    fmt: str, written: dict[str, tuple[Path, Any, Path]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path, _, protocol = written[fmt]
    out = tmp_path / "stops.parquet"
    can_args = [] if fmt == "mcap" else ["--dbc", str(DBC), "--mapping", str(MAPPING)]
    assert main(["stops", str(path), *can_args, "--protocol", str(protocol), "-o", str(out)]) == 0
    capsys.readouterr()
    fast = pd.read_parquet(out)
    reference = _mcap_library_samples(path) if fmt == "mcap" else _can_library_samples(path)
    slow = tabulate(reference, StopDetection(), read_protocol(str(protocol))).table.to_frame()
    assert list(fast.columns) == list(slow.columns)
    assert fast["beta_deg"].tolist() == [0.0, 90.0, 180.0, 270.0]  # every stop inside its protocol row
    np.testing.assert_allclose(fast["t_s"], slow["t_s"], rtol=0, atol=1e-6)
    np.testing.assert_array_equal(fast["n"], slow["n"])
    assert fast["heading_ref"].tolist() == slow["heading_ref"].tolist() == ["uphill"] * 4
    for name in fast.columns.drop("heading_ref"):
        np.testing.assert_allclose(fast[name], slow[name], rtol=1e-9, atol=0, err_msg=name)


# --------------------------------------------------------------------------- the bundled samples


def _truth() -> dict[str, Any]:
    return json.loads((DATA / "parking_truth.json").read_text())


@pytest.mark.parametrize("name", ["parking.mcap", "parking.blf", "parking.mf4"])
def test_bundled_sample_calibrates_to_its_truth(name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    result = tmp_path / "result.json"
    can_args = [] if name.endswith(".mcap") else ["--dbc", str(DBC), "--mapping", str(MAPPING)]
    protocol = str(DATA / "parking_protocol.csv")
    assert main(["calibrate", str(DATA / name), *can_args, "--protocol", protocol, "-o", str(result)]) == 0
    assert "found 12 stops; headings: protocol sheet" in capsys.readouterr().err  # status goes to stderr
    cal, truth = Calibration.load(result), _truth()
    for angle in ("roll", "pitch", "yaw"):
        estimate, sigma = getattr(cal, f"{angle}_deg"), getattr(cal, f"{angle}_sigma_deg")
        assert estimate is not None and sigma is not None and sigma > 0
        assert _circular_deg(estimate, truth[f"{angle}_deg"]) < 4 * sigma, angle


def _documented_command() -> list[str]:
    """The regeneration command of the parking samples, as data/README.md gives it."""
    for line in (DATA / "README.md").read_text(encoding="utf-8").splitlines():
        if line.startswith("| `parking.mcap`"):
            return shlex.split(line.rsplit("`", 2)[-2])
    raise AssertionError("data/README.md has no row for parking.mcap")


def _mf4_content(path: Path) -> tuple[Any, ...]:
    with MDF(path) as mdf:
        signal = mdf.get("CAN_DataFrame", group=0, raw=True)
        return mdf.header.start_time, signal.timestamps.tobytes(), signal.samples.tobytes()


def test_bundled_samples_are_what_the_documented_command_writes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Regenerated: MCAP, BLF, protocol and truth byte for byte; the MF4's decoded frames and start
    (asammdf stamps its file history with the wall-clock time of writing)."""
    command = _documented_command()
    assert command[:3] == ["mountcal", "simulate", "--log"]
    dbc_before = hashlib.sha256(DBC.read_bytes()).hexdigest()
    args = [str(tmp_path / Path(a).name) if a.startswith("data/parking") else a for a in command[1:]]
    args = [str(REPO / a) if a.startswith("data/") else a for a in args]
    assert main(args) == 0
    err = capsys.readouterr().err  # what was written, on stderr
    assert "wrote" in err and "saturated at the DBC range" not in err  # the rates stay inside the MM5.10's range
    for name in ("parking.mcap", "parking.blf", "parking_protocol.csv", "parking_truth.json"):
        assert (tmp_path / name).read_bytes() == (DATA / name).read_bytes(), name
    assert _mf4_content(tmp_path / "parking.mf4") == _mf4_content(DATA / "parking.mf4")
    assert hashlib.sha256(DBC.read_bytes()).hexdigest() == dbc_before  # the input is only read


def test_sample_data_stays_small() -> None:
    assert sum(p.stat().st_size for p in DATA.iterdir() if p.is_file()) < 5_000_000


@pytest.mark.real_data
def test_dbc_copies_the_bosch_mm5_10_messages(real_data: Path) -> None:
    """MM5_10_TX1..TX3 as in the Bosch DBC; what we added (Pitch_Rate, SIM_*) overlaps nothing of it."""
    bosch = cantools.database.load_file(real_data / "dbc" / "bosch_abs_m5_mm5.10_abs.dbc")
    ours = cantools.database.load_file(DBC)
    fields = ("start", "length", "byte_order", "is_signed", "scale", "offset", "minimum", "maximum", "unit")
    for name in ("MM5_10_TX1", "MM5_10_TX2", "MM5_10_TX3"):
        theirs, mine = bosch.get_message_by_name(name), ours.get_message_by_name(name)
        assert (mine.frame_id, mine.length, mine.is_extended_frame) == (
            theirs.frame_id,
            theirs.length,
            theirs.is_extended_frame,
        )
        for signal in theirs.signals:
            copy = mine.get_signal_by_name(signal.name)
            assert [getattr(copy, f) for f in fields] == [getattr(signal, f) for f in fields], signal.name
        bosch_bits = {b for s in theirs.signals for b in range(s.start, s.start + s.length)}
        added = [s for s in mine.signals if s.name not in {t.name for t in theirs.signals}]
        assert [s.name for s in added] == (["Pitch_Rate"] if name == "MM5_10_TX3" else [])
        assert all(not bosch_bits & set(range(s.start, s.start + s.length)) for s in added)
    bosch_ids = {m.frame_id for m in bosch.messages}
    assert all(m.frame_id not in bosch_ids for m in ours.messages if m.name.startswith("SIM_"))


# --------------------------------------------------------------------------- bad requests


def test_writer_refuses_a_dbc_without_the_layout(small_log: ParkingLog, tmp_path: Path) -> None:
    """tests/data/mm5_imu.dbc has the Bosch MM5.10 messages but no Pitch_Rate nor SIM_*: nothing is written."""
    target = tmp_path / "x.blf"
    target.write_bytes(b"earlier content")
    with pytest.raises(InputError, match=r"MM5_10_TX3\.Pitch_Rate.*no such message\.signal"):
        export.write_can_log(target, small_log, dbc_path=REPO / "tests" / "data" / "mm5_imu.dbc")
    assert target.read_bytes() == b"earlier content"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.blf"]  # no temporary left behind


def test_writer_refuses_unknown_suffixes(small_log: ParkingLog, tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"\.blf"):
        export.write_log(tmp_path / "x.bag", small_log, dbc_path=DBC)
    with pytest.raises(InputError, match="DBC"):
        export.write_log(tmp_path / "x.blf", small_log)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (["--log", "x.blf"], "DBC"),
        (["--log", "x.mcap", "x.asc", "--dbc", str(DBC), "--protocol", "p.csv"], "ASC"),
        (["--log", "x.mcap", "-o", "stops.csv"], "-o"),
        (["--log", "x.mcap", "x.mcap"], "different paths"),
        (["--log", "x.mcap", "--dbc", str(DBC), "--protocol", str(DBC)], "the --dbc file"),
        ([], "neither"),
    ],
)
def test_simulate_log_refuses_bad_requests_and_writes_nothing(
    argv: list[str], says: str, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    assert main(["simulate", *argv]) == 2
    assert says in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []
