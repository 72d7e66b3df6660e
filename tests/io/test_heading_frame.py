"""A ROS odometry heading is a compass heading only in a frame that faces east: REP 105's ``odom`` frame starts
wherever the odometry started. β from such a heading and ``--uphill-azimuth-deg`` leave the yaw resting on
that frame's alignment, which the data cannot show (mountcal/io/heading_frame.py), in every ROS container.

Before: an MCAP (and its ROS 2 and ROS 1 bags) whose odometry frame ``odom`` was turned 40° from east (clockwise) gave
yaw 47.0° ± 0.6° (truth 7°), *confident*, the heading said to be "a compass heading, clockwise from north".
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.convert.converter import convert

from mountcal.cli import main
from mountcal.io.heading_frame import earth_aligned
from mountcal.io.logs import read_log
from mountcal.io.writers import START_TIME_S, write_mcap, write_protocol
from mountcal.simulate.stops import simulate_parking_log

OFFSET_DEG = 40.0  # the odometry frame's x axis, clockwise from east: its yaw reads 40° less than ENU


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The same parking session (yaw 7°, uphill azimuth 30°) with its odometry in an ``odom`` frame turned
    40° from east (its headings 40° less than the compass's), and in a frame named ``enu``."""
    folder = tmp_path_factory.mktemp("heading_frame")
    park = simulate_parking_log(5.0, 6.0, 7.0, seed=9)
    turned = replace(park, heading_deg=(park.heading_deg + OFFSET_DEG) % 360.0)  # yaw from the odom x axis
    paths = {"odom": folder / "odom.mcap", "enu": folder / "enu.mcap", "sheet": folder / "protocol.csv"}
    write_mcap(paths["odom"], turned, odometry_frame="odom")
    write_mcap(paths["enu"], park, odometry_frame="enu")
    write_protocol(paths["sheet"], park)
    paths["db3"] = folder / "odom_db3"
    convert([paths["odom"]], paths["db3"], "sqlite3", 9, None, "file", None, None, [], [], [], [])
    paths["bag"] = folder / "odom.bag"
    convert([paths["db3"]], paths["bag"], None, None, None, "file", None, None, [], [], [], [])
    return paths


def _calibrate(log: Path, tmp_path: Path, *extra: str) -> dict[str, Any]:
    out = tmp_path / "r.json"
    assert main(["calibrate", str(log), *extra, "-o", str(out), "-q"]) == 0
    return json.loads(out.read_text(encoding="utf-8"))  # type: ignore[no-any-return]


def _failed(doc: dict[str, Any]) -> list[str]:
    return [c["name"] for c in doc["checks"] if c["passed"] is False]


def _frame(doc: dict[str, Any]) -> dict[str, str]:
    (frame,) = [c for c in doc["provenance"]["conventions"] if c["name"] == "heading_frame"]
    return frame  # type: ignore[no-any-return]


@pytest.mark.parametrize("kind", ["odom", "db3", "bag"])
def test_an_odom_frame_heading_with_an_uphill_azimuth_is_not_confident(
    logs: dict[str, Path], kind: str, tmp_path: Path
) -> None:
    doc = _calibrate(logs[kind], tmp_path, "--uphill-azimuth-deg", "30")
    assert abs(doc["mounting"]["yaw_deg"] - (7.0 + OFFSET_DEG)) < 2.0  # the offset the data cannot show ...
    assert not doc["confident"]  # ... so the answer is not a confident one
    assert "heading_frame" in _failed(doc)
    frame = _frame(doc)
    assert frame["how"] == "default" and frame["value"].startswith("odom") and "/odom" in frame["by"]


def test_a_heading_in_a_frame_named_enu_is_stated_and_confident(logs: dict[str, Path], tmp_path: Path) -> None:
    doc = _calibrate(logs["enu"], tmp_path, "--uphill-azimuth-deg", "30")
    assert doc["confident"] and "heading_frame" not in _failed(doc)
    assert abs(doc["mounting"]["yaw_deg"] - 7.0) < 3.0 * doc["uncertainty"]["yaw_deg"]
    assert _frame(doc)["how"] == "stated"


def test_a_protocol_does_not_rest_on_the_odometry_frame(logs: dict[str, Path], tmp_path: Path) -> None:
    doc = _calibrate(logs["odom"], tmp_path, "--protocol", str(logs["sheet"]))
    assert doc["confident"] and "heading_frame" not in _failed(doc)
    assert abs(doc["mounting"]["yaw_deg"] - 7.0) < 3.0 * doc["uncertainty"]["yaw_deg"]


def test_every_container_states_the_odometry_frame(logs: dict[str, Path]) -> None:
    for kind in ("odom", "db3", "bag"):
        samples = read_log(logs[kind])
        (frame,) = [c for c in samples.conventions if c.name == "heading_frame"]
        assert frame.how == "default" and frame.value.startswith("odom"), kind
        assert np.isfinite(samples.channels["heading_deg"].value).all()


@pytest.mark.parametrize(
    ("name", "aligned"),
    [
        ("enu", True),
        ("/utm", True),
        ("world_enu", True),
        ("utm_local", True),
        ("odom", False),
        ("map", False),
        ("odom_ned", True),
        ("/local_origin_ned", True),
        ("ned", True),
        ("planned", False),
        ("", False),
        ("menu", False),
    ],
)
def test_only_a_name_that_says_east_north_up_or_north_east_down_states_it(name: str, aligned: bool) -> None:
    assert earth_aligned(name) is aligned


def test_a_heading_in_a_north_east_down_frame_is_the_compass_heading_in_every_container(
    logs: dict[str, Path], tmp_path: Path
) -> None:
    """MAVROS and PX4 publish odometry in NED frames (``local_origin_ned``, ``odom_ned``): yaw about the down axis,
    clockwise from north — the compass heading itself, not 90° − yaw. Before, it was taken as ENU: every heading
    mirrored about north-east, the stops' headings running the wrong way round."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from scipy.spatial.transform import Rotation

    park = simulate_parking_log(5.0, 6.0, 7.0, seed=9)
    ned = tmp_path / "ned.mcap"
    write_mcap(ned, park, odometry_frame="local_origin_ned")
    with open(ned, "rb") as f:  # the writer, read independently: NED yaw (intrinsic Z of ZYX) = compass heading
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        odom = [m for _, _, _, m in reader.iter_decoded_messages(topics=["/odom"])]
    q = odom[len(odom) // 2].pose.pose.orientation
    stamp = odom[len(odom) // 2].header.stamp
    t = stamp.sec + stamp.nanosec * 1e-9 - START_TIME_S
    truth = float(park.heading_deg[np.searchsorted(park.t_s, t, side="right") - 1])
    yaw = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_euler("ZYX", degrees=True)[0] % 360.0
    assert abs((yaw - truth + 180.0) % 360.0 - 180.0) < 0.01
    db3, bag = tmp_path / "ned_db3", tmp_path / "ned.bag"
    convert([ned], db3, "sqlite3", 9, None, "file", None, None, [], [], [], [])
    convert([db3], bag, None, None, None, "file", None, None, [], [], [], [])
    compass = read_log(logs["enu"]).channels["heading_deg"].value
    for log in (ned, db3, bag):
        samples = read_log(log)
        np.testing.assert_allclose(samples.channels["heading_deg"].value, compass, atol=1e-6)
        (frame,) = [c for c in samples.conventions if c.name == "heading_frame"]
        assert frame.how == "stated" and "north-east-down" in frame.value, log
    doc = _calibrate(ned, tmp_path, "--uphill-azimuth-deg", "30")
    assert doc["confident"] and "heading_frame" not in _failed(doc)
    assert abs(doc["mounting"]["yaw_deg"] - 7.0) < 3.0 * doc["uncertainty"]["yaw_deg"]


def test_a_stop_table_of_such_a_log_keeps_the_odometry_frame(logs: dict[str, Path], tmp_path: Path) -> None:
    """`mountcal stops` writes the frame into the column heading_frame: the table calibrates as the log does."""
    table = tmp_path / "stops.csv"
    assert main(["stops", str(logs["odom"]), "--uphill-azimuth-deg", "30", "-o", str(table), "-q"]) == 0
    doc = _calibrate(table, tmp_path)
    assert not doc["confident"] and "heading_frame" in _failed(doc)
    assert _frame(doc)["by"].endswith("column heading_frame)")
    stated = tmp_path / "stated.csv"  # β from a protocol sheet: nothing rests on the odometry frame
    assert main(["stops", str(logs["odom"]), "--protocol", str(logs["sheet"]), "-o", str(stated), "-q"]) == 0
    assert "heading_frame" not in stated.read_text(encoding="utf-8").splitlines()[0].split(",")
    assert _calibrate(stated, tmp_path)["confident"]


def test_big_endian_cdr_is_refused_as_what_it_is(tmp_path: Path) -> None:
    """Valid big-endian CDR (rosbags' serializer) was refused as 'damaged or mislabelled'."""
    from mcap.writer import Writer
    from rosbags.typesys import Stores, get_typestore

    from mountcal.core.errors import InputError
    from mountcal.io.writers import ros2_definition

    store = get_typestore(Stores.ROS2_HUMBLE)
    imu, header, time = (
        store.types[t] for t in ("sensor_msgs/msg/Imu", "std_msgs/msg/Header", "builtin_interfaces/msg/Time")
    )
    vector, quaternion = store.types["geometry_msgs/msg/Vector3"], store.types["geometry_msgs/msg/Quaternion"]
    path = tmp_path / "big_endian.mcap"
    with open(path, "wb") as f:
        writer = Writer(f)
        writer.start(profile="ros2", library="test")
        schema = writer.register_schema(
            "sensor_msgs/msg/Imu", "ros2msg", ros2_definition("sensor_msgs/msg/Imu").encode()
        )
        channel = writer.register_channel("/imu/data", "cdr", schema)
        for i in range(200):
            t_ns = 1_700_000_000 * 10**9 + i * 10_000_000
            message = imu(
                header=header(stamp=time(sec=t_ns // 10**9, nanosec=t_ns % 10**9), frame_id="imu_link"),
                orientation=quaternion(0.0, 0.0, 0.0, 1.0),
                orientation_covariance=np.full(9, -1.0),
                angular_velocity=vector(0.0, 0.0, 0.01),
                angular_velocity_covariance=np.zeros(9),
                linear_acceleration=vector(0.1, 0.2, 9.8),
                linear_acceleration_covariance=np.zeros(9),
            )
            data = bytes(store.serialize_cdr(message, "sensor_msgs/msg/Imu", little_endian=False))
            writer.add_message(channel, t_ns, data, t_ns)
        writer.finish()
    with pytest.raises(InputError) as err:
        read_log(path)
    text = str(err.value)
    assert "big-endian CDR" in text and "little_endian=True" in text and "damaged" not in text
