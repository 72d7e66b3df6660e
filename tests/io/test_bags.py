"""ROS 1 bags and ROS 2 bag folders, written by rosbags' own writers or real recordings, read through the
registry: the same recording in every container gives the same samples and the same answer."""

from __future__ import annotations

import re
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap_ros2.writer import Writer as Ros2McapWriter
from rosbags.convert.converter import convert
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from mountcal import calibrate_log, read_log
from mountcal.cli import main
from mountcal.core.errors import InputError
from mountcal.io.logs import inspect_log
from mountcal.io.reader import LogOptions
from mountcal.io.samples import Samples

REPO = Path(__file__).resolve().parents[2]
PARKING = REPO / "data" / "parking.mcap"
PROTOCOL = REPO / "data" / "parking_protocol.csv"


def _convert(src: Path, dst: Path, storage: str = "mcap", typestore: Any = None) -> Path:
    convert([src], dst, storage, 9, None, "file", None, typestore, [], [], [], [])
    return dst


def assert_same_samples(a: Samples, b: Samples) -> None:
    assert len(a) == len(b) > 0
    np.testing.assert_array_equal(a.t_s, b.t_s)
    np.testing.assert_array_equal(a.acc_s, b.acc_s)
    assert (a.gyro_s is None) == (b.gyro_s is None)
    if a.gyro_s is not None:
        np.testing.assert_array_equal(a.gyro_s, b.gyro_s)
    assert sorted(a.channels) == sorted(b.channels)
    for key, ch in a.channels.items():
        np.testing.assert_array_equal(ch.t_s, b.channels[key].t_s)
        np.testing.assert_array_equal(ch.value, b.channels[key].value)
    assert a.dropped == b.dropped


# --------------------------------------------------------------------------- the parking demo in ROS 2 bags


@pytest.fixture(scope="module")
def parking_bags(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("parking")
    return {storage: _convert(PARKING, d / f"parking_{storage}", storage) for storage in ("sqlite3", "mcap")}


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_the_parking_demo_in_a_ros2_bag_gives_the_demos_answer(parking_bags: dict[str, Path], storage: str) -> None:
    folder = parking_bags[storage]
    assert {p.suffix for p in folder.iterdir()} == {".yaml", ".db3" if storage == "sqlite3" else ".mcap"}
    demo = calibrate_log(PARKING, protocol=PROTOCOL)
    bag = calibrate_log(folder, protocol=PROTOCOL)
    assert_same_samples(demo.samples, bag.samples)
    for name in ("roll_deg", "pitch_deg", "yaw_deg", "slope_deg", "roll_sigma_deg", "pitch_sigma_deg", "yaw_sigma_deg"):
        assert abs(getattr(bag.calibration, name) - getattr(demo.calibration, name)) <= 1e-9, name
    assert bag.used == demo.used


def test_a_lone_db3_reads_as_its_bag(parking_bags: dict[str, Path]) -> None:
    folder = parking_bags["sqlite3"]
    assert_same_samples(read_log(folder), read_log(next(folder.glob("*.db3"))))


def test_inspect_lists_a_ros2_bags_topics(parking_bags: dict[str, Path]) -> None:
    for folder in parking_bags.values():
        info = inspect_log(folder)
        demo = inspect_log(PARKING)
        got = {s.name: (s.kind, s.count, round(s.rate_hz, 6), s.fields) for s in info.streams}
        want = {s.name: (s.kind, s.count, round(s.rate_hz, 6), s.fields) for s in demo.streams}
        assert got == want
        assert info.duration_s == pytest.approx(demo.duration_s, abs=1e-6)


# --------------------------------------------------------------------------- a real ROS 1 bag and its MCAP


@pytest.fixture(scope="module")
def test1(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    from tests.conftest import REAL_DATA

    bag = REAL_DATA / "robot_localization" / "test1.bag"
    if not bag.is_file():
        pytest.skip(f"real recordings not found at {REAL_DATA}")
    d = tmp_path_factory.mktemp("test1")
    folder = _convert(bag, d / "test1_mcap", "mcap", get_typestore(Stores.ROS2_HUMBLE))
    return {"bag": bag, "mcap": next(folder.glob("*.mcap")), "folder": folder}


@pytest.mark.real_data
def test_a_real_ros1_bag_and_its_mcap_give_identical_samples(test1: dict[str, Path]) -> None:
    bag, mcap = read_log(test1["bag"]), read_log(test1["mcap"])  # the bag reader and the MCAP reader
    assert_same_samples(bag, mcap)
    assert_same_samples(bag, read_log(test1["folder"]))
    assert len(bag) == 11865 and bag.gyro_s is not None
    assert sorted(bag.channels) == ["alt_m", "heading_deg", "lat_deg", "lon_deg", "speed_mps"]
    assert np.median(bag.acc_s[:, 1]) == pytest.approx(9.79, abs=0.05)  # mounted on its side: gravity on +y


@pytest.mark.real_data
def test_a_real_ros1_bag_and_its_mcap_give_the_same_answer(
    test1: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    loose = ["--max-acc-std", "0.5", "--max-gyro-rate", "0.05", "--min-stop-s", "4"]
    outs = {}
    for kind in ("bag", "mcap"):
        (tmp_path / kind).mkdir()
        table = tmp_path / kind / "stops.csv"
        assert main(["stops", str(test1[kind]), "-o", str(table), *loose]) == 0
        code = main(["calibrate", str(test1[kind]), *loose])
        err = capsys.readouterr().err.replace(str(test1[kind]), "LOG").replace(str(tmp_path / kind), "DIR")
        outs[kind] = (code, err, table.read_text())
    assert outs["bag"] == outs["mcap"]
    code, err, table = outs["bag"]
    assert code == 3 and "expected at least 3 stops, found 1" in err  # one stop: a true refusal, the same in both
    assert len(table.splitlines()) == 2


@pytest.mark.real_data
def test_inspect_lists_a_ros1_bags_topics(test1: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["inspect", str(test1["bag"])]) == 0
    out = capsys.readouterr().err  # the listing is the command's summary, on stderr
    assert "ros1 bag, 395.3 s" in out
    for line in ("/imu/data", "sensor_msgs/msg/Imu", "11865 msgs", "30.01 Hz", "/fix", "sensor_msgs/msg/NavSatFix"):
        assert line in out
    bag = {s.name: (s.kind, s.count, round(s.rate_hz, 3)) for s in inspect_log(test1["bag"]).streams}
    mcap = {s.name: (s.kind, s.count, round(s.rate_hz, 3)) for s in inspect_log(test1["mcap"]).streams}
    assert bag == mcap


# --------------------------------------------------------------------------- a driver's message wrapping an Imu

VN = "vn_msgs/msg/CommonGroup"
VN_DEFINITION = """std_msgs/Header header
uint32 group_fields
string sensor_name
float32[] status_words
sensor_msgs/Imu imu
geometry_msgs/Vector3 magnetic_field
float32 temperature
"""
N_VN = 300


def _vn_messages(store: Any, ros1: bool) -> list[Any]:
    t = store.types
    time = t["builtin_interfaces/msg/Time"]
    vec = t["geometry_msgs/msg/Vector3"]
    rng = np.random.default_rng(7)
    out = []
    for i in range(N_VN):
        head = {"stamp": time(sec=1_700_000_000 + i // 100, nanosec=(i % 100) * 10_000_000), "frame_id": "vn100"}
        if ros1:
            head["seq"] = i
        header = t["std_msgs/msg/Header"](**head)
        acc, gyro = rng.normal([0.1, -0.2, 9.8], 0.01), rng.normal(0.0, 0.001, 3)
        imu = t["sensor_msgs/msg/Imu"](
            header=header,
            orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
            orientation_covariance=np.zeros(9),
            angular_velocity=vec(x=gyro[0], y=gyro[1], z=gyro[2]),
            angular_velocity_covariance=np.zeros(9),
            linear_acceleration=vec(x=acc[0], y=acc[1], z=acc[2]),
            linear_acceleration_covariance=np.zeros(9),
        )
        out.append(
            t[VN](
                header=header,
                group_fields=5,
                sensor_name="VN-100 " + "x" * (i % 5),  # a string of varying length before the Imu
                status_words=np.arange(i % 3, dtype=np.float32),  # and a sequence of varying length
                imu=imu,
                magnetic_field=vec(x=0.2, y=0.0, z=0.4),
                temperature=25.0,
            )
        )
    return out


def _store(ros1: bool) -> Any:
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    store.register(get_types_from_msg(VN_DEFINITION, VN))
    return store


def _ns(msg: Any) -> int:
    return int(msg.header.stamp.sec) * 10**9 + int(msg.header.stamp.nanosec)


@pytest.fixture(scope="module")
def vn_logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The same VectorNav-style messages on /vn/common, written by four writers."""
    d = tmp_path_factory.mktemp("vn")
    logs: dict[str, Any] = {}
    store1 = _store(True)
    msgs1 = _vn_messages(store1, True)
    bag = d / "vn.bag"
    writer1 = Writer1(bag)
    writer1.set_compression(Writer1.CompressionFormat.LZ4)
    with writer1 as writer:
        conn = writer.add_connection("/vn/common", VN, typestore=store1)
        for m in msgs1:
            writer.write(conn, _ns(m), store1.serialize_ros1(m, VN))
    logs["bag"] = bag
    store2 = _store(False)
    msgs = _vn_messages(store2, False)
    for plugin, name in ((StoragePlugin.SQLITE3, "vn_db3"), (StoragePlugin.MCAP, "vn_mcapbag")):
        with Writer2(d / name, version=9, storage_plugin=plugin) as writer:
            conn = writer.add_connection("/vn/common", VN, typestore=store2)
            for m in msgs:
                writer.write(conn, _ns(m), store2.serialize_cdr(m, VN))
        logs[name] = d / name
    logs["mcap"] = write_vn_mcap(d / "vn.mcap")
    logs["msgs"] = msgs
    return logs


def write_vn_mcap(path: Path) -> Path:
    """The VectorNav-style messages on /vn/common as a ROS 2 MCAP, written by mcap-ros2."""
    store = _store(False)
    definition = store.generate_msgdef(VN, ros_version=2)[0]
    with open(path, "wb") as f, Ros2McapWriter(f) as writer:
        schema = writer.register_msgdef(VN, definition)
        for m in _vn_messages(store, False):
            writer.write_message("/vn/common", schema, _as_dict(m), log_time=_ns(m) + 1000)
    return path


def _as_dict(msg: Any) -> Any:
    if hasattr(msg, "__dataclass_fields__"):
        return {k: _as_dict(getattr(msg, k)) for k in msg.__dataclass_fields__ if k != "__msgtype__"}
    if isinstance(msg, np.ndarray):
        return msg.tolist()
    if isinstance(msg, list):
        return [_as_dict(m) for m in msg]
    return msg


@pytest.mark.parametrize("kind", ["bag", "vn_db3", "vn_mcapbag", "mcap"])
def test_a_custom_message_wrapping_an_imu_reads_with_field(vn_logs: dict[str, Any], kind: str) -> None:
    msgs = vn_logs["msgs"]
    got = read_log(vn_logs[kind], LogOptions(topic="/vn/common", field="imu"))
    assert len(got) == N_VN
    want_t = np.array([m.imu.header.stamp.sec + m.imu.header.stamp.nanosec * 1e-9 for m in msgs])
    np.testing.assert_array_equal(got.t_s, want_t)
    acc = np.array(
        [[m.imu.linear_acceleration.x, m.imu.linear_acceleration.y, m.imu.linear_acceleration.z] for m in msgs]
    )
    gyro = np.array([[m.imu.angular_velocity.x, m.imu.angular_velocity.y, m.imu.angular_velocity.z] for m in msgs])
    np.testing.assert_array_equal(got.acc_s, acc)
    assert got.gyro_s is not None
    np.testing.assert_array_equal(got.gyro_s, gyro)
    assert any("field imu" in n for n in got.notes)
    vector = read_log(vn_logs[kind], LogOptions(topic="/vn/common", field="imu.linear_acceleration"))
    np.testing.assert_array_equal(vector.acc_s, acc)
    assert vector.gyro_s is None and any("no gyro" in n for n in vector.notes)
    alone = read_log(vn_logs[kind], LogOptions(field="imu"))  # the only topic with that field
    np.testing.assert_array_equal(alone.acc_s, acc)


@pytest.mark.parametrize("kind", ["bag", "vn_db3", "mcap"])
def test_without_field_the_refusal_names_the_option_that_reads_it(
    vn_logs: dict[str, Any], kind: str, capsys: pytest.CaptureFixture[str]
) -> None:
    path = str(vn_logs[kind])
    assert main(["calibrate", path]) == 2
    err = capsys.readouterr().err
    assert "--topic /vn/common --field imu" in err and "Traceback" not in err
    assert main(["calibrate", path, "--topic", "/vn/common"]) == 2
    err = capsys.readouterr().err
    assert "vn_msgs/msg/CommonGroup" in err and "--topic /vn/common --field imu" in err
    assert main(["calibrate", path, "--topic", "/vn/common", "--field", "magnetic"]) == 2
    err = capsys.readouterr().err
    assert "--field imu" in err and "magnetic_field" not in err  # a magnetometer is no accelerometer
    with pytest.raises(InputError, match=re.escape("LogOptions.topic='/vn/common' LogOptions.field='imu'.")):
        read_log(path)


# --------------------------------------------------------------------------- what ROS 1 bags hold, and damage


def _bag(path: Path, compression: str | None = None, n: int = 4000, chunk_bytes: int = 1 << 20) -> list[Any]:
    """A ROS 1 bag of ``n`` Imu messages at 100 Hz (frame ids of varying length) and odometry at 10 Hz."""
    store = get_typestore(Stores.ROS1_NOETIC)
    t = store.types
    vec = t["geometry_msgs/msg/Vector3"]
    msgs = []
    writer = Writer1(path)
    if compression:
        writer.set_compression(Writer1.CompressionFormat[compression.upper()])
    writer.chunk_threshold = chunk_bytes
    with writer:
        conn = writer.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=store)
        odom = writer.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=store)
        for i in range(n):
            header = t["std_msgs/msg/Header"](
                seq=i,
                stamp=t["builtin_interfaces/msg/Time"](sec=100 + i // 100, nanosec=(i % 100) * 10**7),
                frame_id="imu" * (i % 3),
            )
            m = t["sensor_msgs/msg/Imu"](
                header=header,
                orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=np.zeros(9),
                angular_velocity=vec(x=0.001 * i, y=0.0, z=-0.001),
                angular_velocity_covariance=np.zeros(9),
                linear_acceleration=vec(x=0.5, y=float(i % 7), z=9.8),
                linear_acceleration_covariance=np.zeros(9),
            )
            msgs.append(m)
            writer.write(conn, 100 * 10**9 + i * 10**7 + 5, store.serialize_ros1(m, "sensor_msgs/msg/Imu"))
            if i % 10 == 0:
                o = store.types["nav_msgs/msg/Odometry"](
                    header=header,
                    child_frame_id="base_link",
                    pose=t["geometry_msgs/msg/PoseWithCovariance"](
                        pose=t["geometry_msgs/msg/Pose"](
                            position=t["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
                            orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                        ),
                        covariance=np.zeros(36),
                    ),
                    twist=t["geometry_msgs/msg/TwistWithCovariance"](
                        twist=t["geometry_msgs/msg/Twist"](
                            linear=vec(x=1.5, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.0)
                        ),
                        covariance=np.zeros(36),
                    ),
                )
                writer.write(odom, 100 * 10**9 + i * 10**7 + 7, store.serialize_ros1(o, "nav_msgs/msg/Odometry"))
    return msgs


def _values(msgs: list[Any]) -> tuple[Any, Any, Any]:
    t = np.array([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in msgs])
    acc = np.array([[m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z] for m in msgs])
    gyro = np.array([[m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z] for m in msgs])
    return t, acc, gyro


@pytest.mark.parametrize("compression", [None, "bz2", "lz4"])
def test_a_ros1_bag_reads_in_every_compression_and_chunking(tmp_path: Path, compression: str | None) -> None:
    path = tmp_path / "imu.bag"
    msgs = _bag(path, compression, chunk_bytes=20_000)  # many chunks
    got = read_log(path)
    t, acc, gyro = _values(msgs)
    np.testing.assert_array_equal(got.t_s, t)
    np.testing.assert_array_equal(got.acc_s, acc)
    np.testing.assert_array_equal(got.gyro_s, gyro)
    speed = got.channels["speed_mps"]
    assert speed.t_s.size == 400 and np.all(speed.value == 1.5)
    assert got.channels["heading_deg"].value[0] == pytest.approx(90.0)  # identity orientation: facing east


def _truncated(src: Path, dst: Path, keep: float) -> Path:
    data = src.read_bytes()
    dst.write_bytes(data[: int(len(data) * keep)])
    return dst


def test_damaged_and_unusual_ros1_bags_are_refused_with_what_to_do(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    good = tmp_path / "good.bag"
    _bag(good, n=500)
    raw = good.read_bytes()
    cases: dict[str, tuple[bytes, str]] = {
        "cut.bag": (raw[: len(raw) * 6 // 10], "rosbag reindex"),
        "old.bag": (b"#ROSBAG V1.2\n" + raw[13:], "rosbag fix"),
        "text.bag": (b"hello, not a bag\n" * 10, "Pass a ROS 1 bag"),
        "empty.bag": (b"", "Pass a ROS 1 bag"),
    }
    unindexed = bytearray(raw)
    at = raw.index(b"index_pos=") + len(b"index_pos=")
    unindexed[at : at + 8] = bytes(8)
    cases["unindexed.bag"] = (bytes(unindexed), "rosbag reindex")
    for name, (data, todo) in cases.items():
        path = tmp_path / name
        path.write_bytes(data)
        assert main(["calibrate", str(path)]) == 2, name
        err = capsys.readouterr().err
        assert todo in err and "Traceback" not in err and str(path) in err, (name, err)
        assert path.read_bytes() == data  # the input is never modified


def test_a_chunk_larger_than_the_block_limit_is_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "big.bag"
    _bag(path, n=6000, chunk_bytes=3 << 20)
    monkeypatch.setenv("MOUNTCAL_MAX_BLOCK_MB", "1")
    with pytest.raises(InputError, match="MOUNTCAL_MAX_BLOCK_MB"):
        read_log(path)


def test_a_folder_without_metadata_is_no_bag_and_its_db3_files_read_alone(
    parking_bags: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "lost"
    folder.mkdir()
    db3 = next(parking_bags["sqlite3"].glob("*.db3"))
    shutil.copy(db3, folder / db3.name)
    assert main(["calibrate", str(folder)]) == 2
    assert ".db3" in capsys.readouterr().err  # the formats listed name the file that reads
    assert_same_samples(read_log(folder / db3.name), read_log(parking_bags["sqlite3"]))


# --------------------------------------------------------------------------- speed from GNSS velocity and NMEA

RMC = "$GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W*6A"  # NMEA 0183's textbook examples
VTG = "$GPVTG,054.7,T,034.4,M,005.5,N,010.2,K*48"


def _gnss_bag(path: Path, velocity: bool, nmea: bool) -> None:
    """A still IMU at 100 Hz with a GNSS fix; a GNSS velocity (east 3, north 4 m/s) and a commanded one
    (10 m/s, not a measurement); NMEA sentences: RMC, VTG, a corrupted RMC and a GGA (no speed)."""
    store = get_typestore(Stores.ROS1_NOETIC)
    store.register(get_types_from_msg("std_msgs/Header header\nstring sentence\n", "nmea_msgs/msg/Sentence"))
    t = store.types
    vec = t["geometry_msgs/msg/Vector3"]

    def header(i: int) -> Any:
        return t["std_msgs/msg/Header"](
            seq=i, stamp=t["builtin_interfaces/msg/Time"](sec=10 + i // 100, nanosec=(i % 100) * 10**7), frame_id="gps"
        )

    with Writer1(path) as writer:
        imu = writer.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=store)
        fix = writer.add_connection("/fix", "sensor_msgs/msg/NavSatFix", typestore=store)
        vel = writer.add_connection("/vel", "geometry_msgs/msg/TwistStamped", typestore=store)
        cmd = writer.add_connection("/cmd_vel_stamped", "geometry_msgs/msg/TwistStamped", typestore=store)
        sentence = writer.add_connection("/nmea_sentence", "nmea_msgs/msg/Sentence", typestore=store)
        for i in range(2000):
            ns = (10 + i // 100) * 10**9 + (i % 100) * 10**7
            m = t["sensor_msgs/msg/Imu"](
                header=header(i),
                orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=np.zeros(9),
                angular_velocity=vec(x=0.0, y=0.0, z=0.0),
                angular_velocity_covariance=np.zeros(9),
                linear_acceleration=vec(x=0.0, y=0.0, z=9.8),
                linear_acceleration_covariance=np.zeros(9),
            )
            writer.write(imu, ns, store.serialize_ros1(m, "sensor_msgs/msg/Imu"))
            if i % 20:
                continue
            status = t["sensor_msgs/msg/NavSatStatus"](status=0, service=1)
            f = t["sensor_msgs/msg/NavSatFix"](
                header=header(i),
                status=status,
                latitude=48.1,
                longitude=11.5,
                altitude=500.0,
                position_covariance=np.zeros(9),
                position_covariance_type=0,
            )
            writer.write(fix, ns, store.serialize_ros1(f, "sensor_msgs/msg/NavSatFix"))
            for conn, v in ((vel, (3.0, 4.0)), (cmd, (10.0, 0.0))):
                if velocity:
                    twist = t["geometry_msgs/msg/Twist"](
                        linear=vec(x=v[0], y=v[1], z=0.5), angular=vec(x=0.0, y=0.0, z=0.0)
                    )
                    msg = t["geometry_msgs/msg/TwistStamped"](header=header(i), twist=twist)
                    writer.write(conn, ns, store.serialize_ros1(msg, "geometry_msgs/msg/TwistStamped"))
            if nmea:
                text = [
                    RMC,
                    VTG,
                    RMC.replace("022.4", "023.4"),
                    "$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47",
                ][(i // 20) % 4]
                msg = t["nmea_msgs/msg/Sentence"](header=header(i), sentence=text)
                writer.write(sentence, ns, store.serialize_ros1(msg, "nmea_msgs/msg/Sentence"))


def test_speed_from_a_gnss_velocity_not_from_a_command(tmp_path: Path) -> None:
    path = tmp_path / "gnss.bag"
    _gnss_bag(path, velocity=True, nmea=True)
    got = read_log(path)
    speed = got.channels["speed_mps"]
    assert speed.t_s.size == 100 and np.all(speed.value == 5.0)  # |(3, 4)|: horizontal, not the command's 10
    assert "heading_deg" not in got.channels  # a Twist's frame is not known to be east-north-up
    assert any("GNSS velocity /vel" in n for n in got.notes) and any("/nmea_sentence" in n for n in got.notes)


def test_speed_and_course_from_nmea_sentences(tmp_path: Path) -> None:
    path = tmp_path / "nmea.bag"
    _gnss_bag(path, velocity=False, nmea=True)
    got = read_log(path)
    speed, heading = got.channels["speed_mps"], got.channels["heading_deg"]
    assert speed.t_s.size == 50  # RMC and VTG of each four sentences
    np.testing.assert_allclose(np.unique(speed.value), [5.5 * 1852 / 3600, 22.4 * 1852 / 3600])
    np.testing.assert_allclose(np.unique(heading.value), [54.7, 84.4])
    assert got.dropped["nmea_bad_checksum"] == 25 and got.dropped["nmea_sentences_without_speed"] == 25


@pytest.mark.parametrize(("storage", "mode"), [("sqlite3", "message"), ("sqlite3", "file"), ("mcap", "file")])
def test_a_compressed_ros2_bag_reads_as_the_demo(tmp_path: Path, storage: str, mode: str) -> None:
    folder = tmp_path / "bag"
    convert([PARKING], folder, storage, 9, "zstd", mode, None, None, [], [], [], [])
    got = read_log(folder)
    assert_same_samples(read_log(PARKING), got)
    assert any("one by one" in n for n in got.notes) == (mode == "message")


def test_a_ros2_mcap_bag_compressed_message_by_message_is_refused_with_the_converter(tmp_path: Path) -> None:
    folder = tmp_path / "bag"
    convert([PARKING], folder, "mcap", 9, "zstd", "message", None, None, [], [], [], [])
    with pytest.raises(InputError, match="ros2 bag convert"):
        read_log(folder)
