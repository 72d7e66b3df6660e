"""`mountcal export`: each vendor's documented example, and round trips through each vendor's formula.

Every vendor formula here is written from the vendor's documentation with this file's own
elementary rotations — not with mountcal's conventions module — so a sign or order slip in the
exporters is caught. The round trips take a gravity vector and a forward acceleration, as the
sensor reads them, through the exported parameters and compare with ``rot_vs`` (≤ 1e-9 m/s²).
"""

from __future__ import annotations

import io
import json
import re
import xml.etree.ElementTree as ET
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml
from pyubx2 import GET, SET, UBXReader, calc_checksum
from scipy.spatial.transform import Rotation

from mountcal.calibration.fit import calibrate
from mountcal.cli import main
from mountcal.core.errors import InputError, NotEnoughInformation
from mountcal.core.result import Calibration
from mountcal.outputs.exporters import Frames, builtin, export, read_parent_pose
from mountcal.simulate.stops import simulate_stops

G = 9.80665
TOL = 1e-9


def rx(deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def ry(deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rz(deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def from_axes(x: tuple[float, ...], y: tuple[float, ...], z: tuple[float, ...]) -> np.ndarray:
    """rot_vs from where the sensor's x, y, z axes point in the ISO 8855 vehicle frame (its columns)."""
    return np.column_stack([x, y, z]).astype(float)


def sensor_readings(rot_vs: np.ndarray) -> np.ndarray:
    """Gravity (parked level) and a 2 m/s² forward acceleration, as the sensor reads them."""
    return np.array([rot_vs.T @ [0.0, 0.0, G], rot_vs.T @ [2.0, 0.0, 0.0]])


@pytest.fixture(scope="module")
def base() -> Calibration:
    table, _ = simulate_stops(5.0, 6.0, 7.0, seed=3)
    return calibrate(table)


def with_rotation(cal: Calibration, matrix: np.ndarray) -> Calibration:
    """The calibration with another (exact) mounting rotation and its σ."""
    return replace(cal, rot_vs=Rotation.from_matrix(matrix), yaw_deg=0.0)


ORIENTATIONS = {  # (roll, pitch, yaw) of simulated mountings, degrees, incl. a box on its side and upside down
    "small": (5.0, 6.0, 7.0),
    "on its side": (88.0, -20.0, 130.0),
    "upside down": (178.0, 3.0, -95.0),
    "nose down": (-30.0, -75.0, 200.0),
}


@pytest.fixture(scope="module", params=list(ORIENTATIONS))
def simulated(request: pytest.FixtureRequest) -> Calibration:
    roll, pitch, yaw = ORIENTATIONS[request.param]
    rot = Rotation.from_matrix(rz(yaw) @ ry(pitch) @ rx(roll))
    table, _ = simulate_stops(rot_vs=rot, seed=11)
    cal = calibrate(table)
    assert cal.yaw_deg is not None and cal.confident
    return cal


# ---------------------------------------------------------------- u-blox ----------------------------------


def ublox_to_vehicle(yaw: float, pitch: float, roll: float, a_imu: np.ndarray) -> np.ndarray:
    """u-blox (ZED-F9R Integration manual UBX-20039643 R10, §3.2.4.4.2): the angles rotate the installation
    frame (§3.2.4.1.2: x front, y left, z up) into the IMU frame, yaw (z), then pitch (new y), then roll
    (new x): the IMU axes in installation coordinates are the columns of Rz·Ry·Rx. The installation frame is
    ISO 8855 itself."""
    return ((rz(yaw) @ ry(pitch) @ rx(roll)) @ a_imu.T).T


def ublox_values(text: str) -> dict[str, tuple[float, float | None]]:
    """Key → (value in degrees as set, exact value) from the u-center-style text."""
    out = {}
    for m in re.finditer(r"^(CFG-SFIMU-\S+) 0x[0-9a-f]{8} (\S+)(?:.*exact (\S+),)?", text, re.M):
        out[m.group(1)] = (float(m.group(2)), None if m.group(3) is None else float(m.group(3)))
    return out


UBLOX_NAMES = ("AUTO_MNTALG_ENA", "IMU_MNTALG_YAW", "IMU_MNTALG_PITCH", "IMU_MNTALG_ROLL", "IMU_MNTALG_TOLERANCE")


def decode_ubx(data: bytes) -> dict[str, int]:
    """Every CFG-SFIMU key of every UBX-CFG-VALSET in ``data``, read by pyubx2 (which checks each checksum)."""
    out: dict[str, int] = {}
    messages = 0
    for _, msg in UBXReader(io.BytesIO(data), msgmode=SET, quitonerror=2):
        assert msg.identity == "CFG-VALSET"
        messages += 1
        out |= {n: getattr(msg, f"CFG_SFIMU_{n}") for n in UBLOX_NAMES if hasattr(msg, f"CFG_SFIMU_{n}")}
    assert messages == 2  # the angles, then the tolerance (a key older firmware rejects) on its own
    return out


UBLOX_MANUAL = {  # the manual's single-angle examples (§3.2.4.4.2, and ZED-F9K UBX-20046189): each a rotation
    # about one installation axis (x front, y left, z up), right-handed; the text gives the axes, its Figure 5
    # (not available as text) the physical pictures
    # yaw 344.0° about z (up): the IMU's x turned 16° clockwise seen from above, to the right of forward
    "yaw": (
        (344.0, 0.0, 0.0),
        from_axes(
            (np.cos(np.radians(16)), -np.sin(np.radians(16)), 0),
            (np.sin(np.radians(16)), np.cos(np.radians(16)), 0),
            (0, 0, 1),
        ),
    ),
    # pitch 26.5° about y (left): the IMU's x tilted 26.5° down, its z tilted forward
    "pitch": (
        (0.0, 26.5, 0.0),
        from_axes(
            (np.cos(np.radians(26.5)), 0, -np.sin(np.radians(26.5))),
            (0, 1, 0),
            (np.sin(np.radians(26.5)), 0, np.cos(np.radians(26.5))),
        ),
    ),
    # roll −23.5° about x (front): the IMU's y (left) tilted 23.5° down
    "roll": (
        (0.0, 0.0, -23.5),
        from_axes(
            (1, 0, 0),
            (0, np.cos(np.radians(23.5)), -np.sin(np.radians(23.5))),
            (0, np.sin(np.radians(23.5)), np.cos(np.radians(23.5))),
        ),
    ),
}


@pytest.mark.parametrize("case", list(UBLOX_MANUAL))
def test_ublox_manual_single_angle_examples(base: Calibration, case: str) -> None:
    (yaw, pitch, roll), matrix = UBLOX_MANUAL[case]
    cal = with_rotation(base, matrix)
    values = ublox_values(str(export(cal, "ublox")))
    assert values["CFG-SFIMU-IMU_MNTALG_YAW"][0] == yaw
    assert values["CFG-SFIMU-IMU_MNTALG_PITCH"][0] == pitch
    assert values["CFG-SFIMU-IMU_MNTALG_ROLL"][0] == roll
    assert values["CFG-SFIMU-AUTO_MNTALG_ENA"][0] == 0
    raw = decode_ubx(bytes(export(cal, "ublox-ubx")))
    assert {k: raw[k] for k in UBLOX_NAMES[:4]} == {
        "AUTO_MNTALG_ENA": 0,
        "IMU_MNTALG_YAW": round(yaw * 100),
        "IMU_MNTALG_PITCH": round(pitch * 100),
        "IMU_MNTALG_ROLL": round(roll * 100),
    }


def test_ublox_flat_level_aligned_module_exports_zeros(base: Calibration) -> None:
    """A module lying flat (reads +g on its z, out of its top), its x forward: yaw, pitch and roll all 0."""
    cal = with_rotation(base, from_axes((1, 0, 0), (0, 1, 0), (0, 0, 1)))
    values = ublox_values(str(export(cal, "ublox")))
    assert [values[f"CFG-SFIMU-IMU_MNTALG_{k}"][0] for k in ("YAW", "PITCH", "ROLL")] == [0.0, 0.0, 0.0]
    raw = decode_ubx(bytes(export(cal, "ublox-ubx")))
    assert (raw["IMU_MNTALG_YAW"], raw["IMU_MNTALG_PITCH"], raw["IMU_MNTALG_ROLL"]) == (0, 0, 0)


def test_ublox_round_trip_exact_angles(simulated: Calibration) -> None:
    values = ublox_values(str(export(simulated, "ublox")))
    yaw, pitch, roll = (values[f"CFG-SFIMU-IMU_MNTALG_{k}"][1] for k in ("YAW", "PITCH", "ROLL"))
    assert yaw is not None and pitch is not None and roll is not None
    assert 0 <= yaw < 360 and -90 <= pitch <= 90 and -180 <= roll <= 180
    a_s = sensor_readings(simulated.rot_vs.as_matrix())
    np.testing.assert_allclose(ublox_to_vehicle(yaw, pitch, roll, a_s), simulated.rot_vs.apply(a_s), rtol=0, atol=TOL)


def test_ublox_bytes_decode_to_the_text_and_stay_within_the_resolution(simulated: Calibration) -> None:
    values = ublox_values(str(export(simulated, "ublox")))
    raw = decode_ubx(bytes(export(simulated, "ublox-ubx")))
    for key in ("YAW", "PITCH", "ROLL"):
        assert raw[f"IMU_MNTALG_{key}"] == round(values[f"CFG-SFIMU-IMU_MNTALG_{key}"][0] * 100)
    assert raw["IMU_MNTALG_TOLERANCE"] == values["CFG-SFIMU-IMU_MNTALG_TOLERANCE"][0]
    a_s = sensor_readings(simulated.rot_vs.as_matrix())
    sent = ublox_to_vehicle(
        raw["IMU_MNTALG_YAW"] / 100, raw["IMU_MNTALG_PITCH"] / 100, raw["IMU_MNTALG_ROLL"] / 100, a_s
    )
    half_step = np.radians(0.005) * 3  # at most half a 0.01° step on each of the three angles
    assert np.max(np.linalg.norm(sent - simulated.rot_vs.apply(a_s), axis=1) / G) <= half_step


@pytest.mark.parametrize("seed", range(5))
def test_ublox_bytes_round_trip_on_the_grid(base: Calibration, seed: int) -> None:
    """A mounting whose u-blox angles are whole hundredths of a degree survives the bytes exactly."""
    rng = np.random.default_rng(seed)
    yaw, pitch, roll = (
        rng.integers(-18000, 36000) / 100,
        rng.integers(-8900, 8900) / 100,
        rng.integers(-18000, 18000) / 100,
    )
    matrix = rz(yaw) @ ry(pitch) @ rx(roll)
    raw = decode_ubx(bytes(export(with_rotation(base, matrix), "ublox-ubx")))
    assert raw["IMU_MNTALG_YAW"] == round(yaw * 100) % 36000  # wrapped into 0…360° as U4
    a_s = sensor_readings(matrix)
    back = ublox_to_vehicle(
        raw["IMU_MNTALG_YAW"] / 100, raw["IMU_MNTALG_PITCH"] / 100, raw["IMU_MNTALG_ROLL"] / 100, a_s
    )
    np.testing.assert_allclose(back, (matrix @ a_s.T).T, rtol=0, atol=TOL)


def test_ublox_ucenter_file_lines_decode_to_the_same_values(simulated: Calibration) -> None:
    """u-center's generation-9 configuration file: ``CFG-VALGET - 06 8B …`` lines, one per message and layer."""
    raw = decode_ubx(bytes(export(simulated, "ublox-ubx")))
    lines = str(export(simulated, "ublox-ucenter")).splitlines()
    assert len(lines) == 6
    got: dict[str, int] = {}
    for i, line in enumerate(lines):
        name, dash, hexdata = line.split(" ", 2)
        assert (name, dash) == ("CFG-VALGET", "-")
        data = bytes.fromhex(hexdata)
        msg = UBXReader.parse(b"\xb5\x62" + data + calc_checksum(data), msgmode=GET)
        assert msg.identity == "CFG-VALGET" and msg.layer == i % 3
        got |= {k: getattr(msg, f"CFG_SFIMU_{k}") for k in UBLOX_NAMES if hasattr(msg, f"CFG_SFIMU_{k}")}
    assert got == raw


def test_ublox_yaw_just_below_360_wraps_to_0(base: Calibration) -> None:
    raw = decode_ubx(bytes(export(with_rotation(base, rz(-0.004)), "ublox-ubx")))
    assert raw["IMU_MNTALG_YAW"] == 0  # 359.996° rounds to 360.00°, which u-blox's 0…360 range holds as 0


@pytest.mark.parametrize(
    ("sigma_deg", "tolerance", "automatic"),
    [(0.3, 0, 0), (0.66, 0, 0), (0.7, 1, 0), (2.0, 1, 0), (3.3, 1, 0), (3.4, 1, 1), (20.0, 1, 1)],
)
def test_ublox_tolerance_follows_the_sigma(base: Calibration, sigma_deg: float, tolerance: int, automatic: int) -> None:
    """§3.2.4.4.2: LOW = "up to 2 degrees wrong", HIGH = within 5°, "in any case no more than 10 degrees",
    beyond that the automatic alignment; the error bound is 3σ about the worst-known vehicle axis."""
    cal = replace(with_rotation(base, rz(30) @ rx(4)), rotation_sigma_deg=(0.1, sigma_deg, 0.2))
    raw = decode_ubx(bytes(export(cal, "ublox-ubx")))
    assert (raw["IMU_MNTALG_TOLERANCE"], raw["AUTO_MNTALG_ENA"]) == (tolerance, automatic)
    text = str(export(cal, "ublox"))
    assert f"{3 * sigma_deg:.1f}°" in text or f"{3 * sigma_deg:.2f}°" in text  # the bound is stated


def test_ublox_undetermined_yaw_hands_over_to_the_automatic_alignment(base: Calibration) -> None:
    """A yaw written as 0 on request is not configured as known: the receiver's own alignment is switched on."""
    cal = replace(base, yaw_deg=None, yaw_sigma_deg=None, yaw_reason="level ground")
    raw = decode_ubx(bytes(export(cal, "ublox-ubx", yaw="zero")))
    assert (raw["AUTO_MNTALG_ENA"], raw["IMU_MNTALG_YAW"], raw["IMU_MNTALG_TOLERANCE"]) == (1, 0, 1)
    assert "YAW NOT DETERMINED" in str(export(cal, "ublox", yaw="zero"))


# ---------------------------------------------------------------- NovAtel ---------------------------------

ISO_FROM_NOVATEL_VEHICLE = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # x right, y fwd, z up


def novatel_to_vehicle(x: float, y: float, z: float, a_body: np.ndarray) -> np.ndarray:
    """NovAtel OEM7: rotate the IMU body frame about Z, then the new X, then the new Y onto the vehicle frame:
    the vehicle axes in body coordinates are the columns of Rz·Rx·Ry, so a_vehicle = (Rz·Rx·Ry)ᵀ a_body."""
    a_nov = (rz(z) @ rx(x) @ ry(y)).T @ a_body.T
    return (ISO_FROM_NOVATEL_VEHICLE @ a_nov).T


def novatel_values(text: str) -> list[float]:
    line = next(ln for ln in text.splitlines() if ln.startswith("SETINSROTATION"))
    fields = line.split()
    assert fields[1] == "RBV"
    return [float(v) for v in fields[2:]]


NOVATEL_EXAMPLES = {
    # SMART7 Installation and Operation User Manual, rotational offsets example: IMU Y along the vehicle Y
    # (forward), a 180° rotation about Y makes Z and X coincide: IMU x left, z down → SETINSROTATION RBV 0 180 0
    "smart7": ((0.0, 180.0, 0.0), from_axes((0, 1, 0), (1, 0, 0), (0, 0, -1))),
    # OEM7 SPAN manual, "Rotational Offsets - Example": X −90, Y 0, Z +90 — the IMU of APN-065's example 2,
    # described there in words: X axis down, Y axis to the right, Z axis backwards
    "oem7": ((-90.0, 0.0, 90.0), from_axes((0, 0, -1), (0, -1, 0), (-1, 0, 0))),
}


@pytest.mark.parametrize("case", list(NOVATEL_EXAMPLES))
def test_novatel_manual_examples(base: Calibration, case: str) -> None:
    expected, matrix = NOVATEL_EXAMPLES[case]
    got = novatel_values(str(export(with_rotation(base, matrix), "novatel")))
    np.testing.assert_allclose(got[:3], expected, rtol=0, atol=1e-9)
    assert all(0.25 <= s <= 45 for s in got[3:])  # NovAtel's range of the standard deviations


def test_novatel_round_trip_and_sigma(simulated: Calibration) -> None:
    got = novatel_values(str(export(simulated, "novatel")))
    assert all(-180 <= v <= 180 for v in got[:3])
    a_s = sensor_readings(simulated.rot_vs.as_matrix())
    np.testing.assert_allclose(novatel_to_vehicle(*got[:3], a_s), simulated.rot_vs.apply(a_s), rtol=0, atol=TOL)
    assert got[3:] == [max(0.25, s) for s in got[3:]]


def test_novatel_sigma_is_propagated_to_its_angles(base: Calibration) -> None:
    """With σ large enough to pass NovAtel's 0.25° floor, a level mounting's Z σ is the σ about vertical."""
    cal = replace(with_rotation(base, np.eye(3)), rotation_sigma_deg=(1.0, 2.0, 3.0))
    sd = novatel_values(str(export(cal, "novatel")))[3:]
    # ISO x (forward) is NovAtel y, ISO y (left) is NovAtel −x: σ about NovAtel X, Y, Z = 2, 1, 3
    np.testing.assert_allclose(sd, [2.0, 1.0, 3.0], rtol=1e-6)


# ---------------------------------------------------------------- ROS 2 -----------------------------------


def quat_rotate(q_xyzw: np.ndarray, v: np.ndarray) -> np.ndarray:
    """tf2: a transform parent → child maps child coordinates to parent ones, p = q v q* (Hamilton)."""
    x, y, z, w = q_xyzw
    u = np.array([x, y, z])
    return v + 2 * np.cross(u, np.cross(u, v) + w * v)


def urdf_rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """URDF origin rpy: fixed-axis roll about x, then pitch about y, then yaw about z (radians)."""
    return rz(np.degrees(yaw)) @ ry(np.degrees(pitch)) @ rx(np.degrees(roll))


def static_tf_args(text: str) -> dict[str, str]:
    line = next(ln for ln in text.splitlines() if ln.startswith("ros2 run tf2_ros static_transform_publisher"))
    tokens = line.split()[4:]
    return dict(zip(tokens[0::2], tokens[1::2], strict=True))


def urdf_origin(text: str) -> tuple[ET.Element, list[float], list[float]]:
    joint = ET.fromstring(text)  # the comments before the element are skipped by the parser
    origin = joint.find("origin")
    assert origin is not None
    return joint, [float(v) for v in origin.get("xyz", "").split()], [float(v) for v in origin.get("rpy", "").split()]


def test_ros_urdf_specification_example(base: Calibration) -> None:
    """The URDF joint specification's example origin ``xyz="0 0 1" rpy="0 0 3.1416"`` comes back as written."""
    matrix = urdf_rpy_matrix(0.0, 0.0, 3.1416)
    cal = with_rotation(base, matrix)
    frames = Frames(parent="link1", child="link2", translation_m=(0.0, 0.0, 1.0))
    joint, xyz, rpy = urdf_origin(str(export(cal, "urdf", frames=frames)))
    assert joint.get("type") == "fixed"
    assert joint.find("parent").get("link") == "link1"  # type: ignore[union-attr]
    assert joint.find("child").get("link") == "link2"  # type: ignore[union-attr]
    assert xyz == [0.0, 0.0, 1.0]
    np.testing.assert_allclose(rpy[:2], [0.0, 0.0], atol=1e-11)
    assert rpy[2] == pytest.approx(3.1416 - 2 * np.pi, abs=1e-11)  # the same angle, written within (−π, π]
    args = static_tf_args(str(export(cal, "ros2-static-tf", frames=frames)))
    assert (args["--frame-id"], args["--child-frame-id"]) == ("link1", "link2")
    q = [float(args[k]) for k in ("--qx", "--qy", "--qz", "--qw")]
    expected = np.array([0, 0, np.sin(3.1416 / 2), np.cos(3.1416 / 2)])
    np.testing.assert_allclose(q, -expected, atol=1e-11)  # −q, the same rotation, written with w ≥ 0


def test_ros_round_trips(simulated: Calibration) -> None:
    a_s = sensor_readings(simulated.rot_vs.as_matrix())
    expected = simulated.rot_vs.apply(a_s)
    args = static_tf_args(str(export(simulated, "ros2-static-tf")))
    assert (args["--frame-id"], args["--child-frame-id"]) == ("base_link", "imu_link")
    q = np.array([float(args[k]) for k in ("--qx", "--qy", "--qz", "--qw")])
    np.testing.assert_allclose([quat_rotate(q, v) for v in a_s], expected, rtol=0, atol=TOL)
    _, _, rpy = urdf_origin(str(export(simulated, "urdf")))
    np.testing.assert_allclose((urdf_rpy_matrix(*rpy) @ a_s.T).T, expected, rtol=0, atol=TOL)
    tf2 = str(export(simulated, "tf2"))
    match = re.search(r"tf2::Quaternion q\((\S+), (\S+), (\S+), (\S+)\);", tf2)
    assert match is not None
    q2 = np.array([float(v) for v in match.groups()])
    np.testing.assert_allclose([quat_rotate(q2, v) for v in a_s], expected, rtol=0, atol=TOL)


# ---------------------------------------------------------------- Autoware --------------------------------

# Autoware's sample_sensor_kit_description/config/sensors_calibration.yaml: the kit's base in base_link
# (yaw −0.0364 rad = −2.1°), and the IMU's entry of its sensor_kit_calibration.yaml
SAMPLE_SENSORS_CALIBRATION = """\
base_link:
  sensor_kit_base_link:
    x: 0.9
    y: 0.0
    z: 2.0
    roll: -0.001
    pitch: 0.015
    yaw: -0.0364
"""
SAMPLE_IMU_ENTRY = {"x": 0.0, "y": 0.0, "z": 0.0, "roll": 3.14159265359, "pitch": 0.0, "yaw": 3.14159265359}


@pytest.fixture
def kit_pose(tmp_path: Path) -> Path:
    path = tmp_path / "sensors_calibration.yaml"
    path.write_text(SAMPLE_SENSORS_CALIBRATION, encoding="utf-8")
    return path


def kit_rotation(path: Path) -> np.ndarray:
    pose = yaml.safe_load(path.read_text(encoding="utf-8"))["base_link"]["sensor_kit_base_link"]
    return urdf_rpy_matrix(pose["roll"], pose["pitch"], pose["yaw"])


def test_autoware_sample_kit_imu_entry_comes_back_through_the_kit_pose(base: Calibration, kit_pose: Path) -> None:
    """The sample kit's IMU (rpy π, 0, π in sensor_kit_base_link, itself turned 2.1° in base_link): a calibration
    of that IMU in base_link exports the entry Autoware's file holds."""
    e = SAMPLE_IMU_ENTRY
    in_base = kit_rotation(kit_pose) @ urdf_rpy_matrix(e["roll"], e["pitch"], e["yaw"])
    frames = Frames(child="tamagawa/imu_link", parent_pose=read_parent_pose(kit_pose, "sensor_kit_base_link"))
    frames = replace(frames, parent="sensor_kit_base_link")
    doc = yaml.safe_load(str(export(with_rotation(base, in_base), "autoware", frames=frames)))
    entry = doc["sensor_kit_base_link"]["tamagawa/imu_link"]
    np.testing.assert_allclose(
        urdf_rpy_matrix(entry["roll"], entry["pitch"], entry["yaw"]),
        urdf_rpy_matrix(e["roll"], e["pitch"], e["yaw"]),
        rtol=0,
        atol=1e-11,
    )
    # the entry a kit taken as parallel to base_link would get is off by the kit's own turn (2.1° yaw, 0.9° pitch)
    as_if_parallel = replace(frames, parent="base_link", parent_pose=None)
    wrong = yaml.safe_load(str(export(with_rotation(base, in_base), "autoware", frames=as_if_parallel)))
    r_wrong = urdf_rpy_matrix(*(wrong["base_link"]["tamagawa/imu_link"][k] for k in ("roll", "pitch", "yaw")))
    angle = Rotation.from_matrix(r_wrong.T @ urdf_rpy_matrix(e["roll"], e["pitch"], e["yaw"])).magnitude()
    assert np.degrees(angle) == pytest.approx(np.degrees(Rotation.from_matrix(kit_rotation(kit_pose)).magnitude()))
    assert np.degrees(angle) > 2.0


def test_autoware_round_trip(simulated: Calibration, kit_pose: Path) -> None:
    frames = Frames(parent="sensor_kit_base_link", parent_pose=read_parent_pose(kit_pose, "sensor_kit_base_link"))
    doc = yaml.safe_load(str(export(simulated, "autoware", frames=frames)))
    entry = doc["sensor_kit_base_link"]["imu_link"]
    a_s = sensor_readings(simulated.rot_vs.as_matrix())
    in_base = kit_rotation(kit_pose) @ urdf_rpy_matrix(entry["roll"], entry["pitch"], entry["yaw"])
    np.testing.assert_allclose((in_base @ a_s.T).T, simulated.rot_vs.apply(a_s), rtol=0, atol=TOL)


def test_autoware_needs_the_parent_pose_unless_the_parent_is_base_link(base: Calibration) -> None:
    with pytest.raises(InputError, match="parent_pose"):
        export(base, "autoware")
    doc = yaml.safe_load(str(export(base, "autoware", frames=Frames(parent="base_link"))))
    assert set(doc) == {"base_link"}


def test_parent_pose_file_errors_name_the_file_and_what_it_should_hold(tmp_path: Path, kit_pose: Path) -> None:
    kit = tmp_path / "sensor_kit_calibration.yaml"
    kit.write_text("sensor_kit_base_link:\n  imu_link: {x: 0, y: 0, z: 0, roll: 0, pitch: 0, yaw: 0}\n", "utf-8")
    with pytest.raises(InputError, match=r"sensor_kit_calibration.yaml.*sensors_calibration.yaml"):
        read_parent_pose(kit, "sensor_kit_base_link")
    bad = tmp_path / "bad.yaml"
    bad.write_text(SAMPLE_SENSORS_CALIBRATION.replace("yaw: -0.0364", "yaw: -2.1deg"), "utf-8")
    with pytest.raises(InputError, match=r"bad.yaml: base_link/sensor_kit_base_link/yaw.*'-2.1deg'"):
        read_parent_pose(bad, "sensor_kit_base_link")
    with pytest.raises(InputError, match=r"missing\.yaml"):
        read_parent_pose(tmp_path / "missing.yaml", "sensor_kit_base_link")
    with pytest.raises(InputError, match="other_link"):
        read_parent_pose(kit_pose, "other_link")


def test_frames_are_refused_where_a_format_has_none(base: Calibration, kit_pose: Path) -> None:
    """A parent, child, translation or pose given to a format without frames is refused, not ignored."""
    for fmt in ("ublox", "ublox-ubx", "novatel", "json"):
        with pytest.raises(InputError, match="Leave them out"):
            export(base, fmt, frames=Frames(parent="chassis"))
    pose = read_parent_pose(kit_pose, "sensor_kit_base_link")
    with pytest.raises(InputError, match="no pose of its own"):
        export(base, "urdf", frames=Frames(parent="base_link", parent_pose=pose))


def test_ros_formats_compose_the_parent_pose_too(base: Calibration, kit_pose: Path) -> None:
    frames = Frames(parent="sensor_kit_base_link", parent_pose=read_parent_pose(kit_pose, "sensor_kit_base_link"))
    a_s = sensor_readings(base.rot_vs.as_matrix())
    _, _, rpy = urdf_origin(str(export(base, "urdf", frames=frames)))
    in_base = kit_rotation(kit_pose) @ urdf_rpy_matrix(*rpy)
    np.testing.assert_allclose((in_base @ a_s.T).T, base.rot_vs.apply(a_s), rtol=0, atol=TOL)
    args = static_tf_args(str(export(base, "ros2-static-tf", frames=frames)))
    q = np.array([float(args[k]) for k in ("--qx", "--qy", "--qz", "--qw")])
    np.testing.assert_allclose(
        [kit_rotation(kit_pose) @ quat_rotate(q, v) for v in a_s], base.rot_vs.apply(a_s), rtol=0, atol=TOL
    )


# ---------------------------------------------------------------- JSON / YAML -----------------------------


def test_rotation_documents_agree_with_each_other_and_round_trip(simulated: Calibration) -> None:
    doc = json.loads(str(export(simulated, "json")))
    assert yaml.safe_load(str(export(simulated, "yaml"))) == doc
    a_s = sensor_readings(simulated.rot_vs.as_matrix())
    expected = simulated.rot_vs.apply(a_s)
    w, x, y, z = doc["quaternion_wxyz"]["value"]
    assert doc["quaternion_xyzw"]["value"] == [x, y, z, w]
    np.testing.assert_allclose([quat_rotate(np.array([x, y, z, w]), v) for v in a_s], expected, atol=TOL)
    np.testing.assert_allclose((np.array(doc["matrix"]["value"]) @ a_s.T).T, expected, atol=TOL)
    axis, angle = np.array(doc["axis_angle"]["axis"]), doc["axis_angle"]["angle_rad"]
    rodrigues = [
        v * np.cos(angle) + np.cross(axis, v) * np.sin(angle) + axis * (axis @ v) * (1 - np.cos(angle)) for v in a_s
    ]
    np.testing.assert_allclose(rodrigues, expected, atol=TOL)
    yaw, pitch, roll = doc["euler_zyx"]["yaw_pitch_roll_deg"]
    np.testing.assert_allclose((rz(yaw) @ ry(pitch) @ rx(roll) @ a_s.T).T, expected, atol=TOL)


def test_rotation_sigma_matches_the_result_where_they_coincide(simulated: Calibration) -> None:
    """The ZYX Euler σ is the result's own roll/pitch/yaw σ; the rotation-vector σ of a small rotation is the
    σ about the vehicle axes; every σ is positive and finite. The σ about each axis carry no correlation, so
    they coincide for the statistical part (nearly uncorrelated axes); the sensor's systematic part couples the
    axes (a cross-axis error tilts about x and y together) and is left out here."""
    part = simulated.systematic
    assert part is not None
    stat = part.statistical
    simulated = replace(
        simulated,
        roll_sigma_deg=stat["roll_deg"],
        pitch_sigma_deg=stat["pitch_deg"],
        yaw_sigma_deg=stat["yaw_deg"],
        rotation_sigma_deg=(stat["rotation_x_deg"], stat["rotation_y_deg"], stat["rotation_z_deg"]),
    )
    doc = json.loads(str(export(simulated, "json")))
    sig_yaw, sig_pitch, sig_roll = doc["euler_zyx"]["sigma_deg"]
    np.testing.assert_allclose(
        [sig_roll, sig_pitch, sig_yaw],
        [simulated.roll_sigma_deg, simulated.pitch_sigma_deg, simulated.yaw_sigma_deg],
        rtol=0.05,
    )
    flat = [s for k in ("quaternion_xyzw", "matrix") for s in np.ravel(doc[k]["sigma"])]
    assert all(np.isfinite(s) and s >= 0 for s in flat)
    assert max(flat) > 0


def test_monte_carlo_agrees_with_the_propagated_quaternion_sigma(base: Calibration) -> None:
    """First-order propagation, checked by sampling rotations with the stated σ about the vehicle axes."""
    cal = replace(with_rotation(base, rz(40) @ ry(-30) @ rx(60)), rotation_sigma_deg=(0.5, 1.0, 2.0))
    doc = json.loads(str(export(cal, "json")))
    rng = np.random.default_rng(0)
    deltas = rng.normal(size=(20000, 3)) * np.radians([0.5, 1.0, 2.0])
    q = (Rotation.from_rotvec(deltas) * cal.rot_vs).as_quat()
    q *= np.sign(q @ np.array(doc["quaternion_xyzw"]["value"]))[:, None]
    np.testing.assert_allclose(q.std(axis=0), doc["quaternion_xyzw"]["sigma"], rtol=0.03)


# ---------------------------------------------------------------- refusals and the CLI --------------------


def test_undetermined_yaw_is_refused_by_every_format_unless_told(base: Calibration) -> None:
    cal = replace(
        base,
        yaw_deg=None,
        yaw_sigma_deg=None,
        yaw_reason="level ground",
        rotation_sigma_deg=(base.rotation_sigma_deg[0], base.rotation_sigma_deg[1], None),
    )
    for fmt in builtin():
        with pytest.raises(NotEnoughInformation, match="yaw is not determined"):
            export(cal, fmt)
    doc = json.loads(str(export(cal, "json", yaw="zero")))
    assert doc["yaw_assumed_zero"] is True
    yaw, pitch, roll = doc["euler_zyx"]["yaw_pitch_roll_deg"]
    assert yaw == pytest.approx(0.0, abs=1e-12)
    assert (roll, pitch) == pytest.approx((cal.roll_deg, cal.pitch_deg), abs=1e-9)  # the tilt is kept exactly
    assert doc["euler_zyx"]["sigma_deg"][0] is None  # no σ is invented for the yaw
    assert "YAW NOT DETERMINED" in str(export(cal, "novatel", yaw="zero"))


def test_unconfident_result_is_refused_unless_accepted(base: Calibration) -> None:
    cal = replace(base, confident=False)
    with pytest.raises(NotEnoughInformation, match="not confident"):
        export(cal, "ublox")
    assert "NOT confident" in str(export(cal, "ublox", accept_unconfident=True))


def test_cli_without_o_is_refused_naming_o_and_stdout(
    base: Calibration, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Results go to stdout only when asked (docs/commands.md): no -o is a usage error naming -o FILE and -o -."""
    result = tmp_path / "r.json"
    base.save(result)
    with pytest.raises(SystemExit) as usage:
        main(["export", str(result), "--to", "novatel"])
    out, err = capsys.readouterr()
    assert usage.value.code == 2 and out == ""
    assert "required: -o/--output" in err and "-o - writes to stdout" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.json"]  # nothing written beside it


def test_cli_writes_files_and_stdout(base: Calibration, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    result = tmp_path / "r.json"
    base.save(result)
    assert main(["export", str(result), "--to", "novatel", "-o", "-"]) == 0
    assert "SETINSROTATION RBV" in capsys.readouterr().out
    assert main(["export", str(result), "--to", "urdf", "-o", "-", "--parent", "chassis", "--child", "imu"]) == 0
    assert '<parent link="chassis"/>' in capsys.readouterr().out
    out = tmp_path / "m.ubx"
    assert main(["export", str(result), "--to", "ublox-ubx", "-o", str(out)]) == 0
    assert decode_ubx(out.read_bytes())["AUTO_MNTALG_ENA"] == 0


def test_cli_bad_input_writes_nothing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out.txt"
    missing = tmp_path / "missing.json"
    assert main(["export", str(missing), "--to", "ublox", "-o", str(out)]) == 2
    assert "missing.json" in capsys.readouterr().err
    broken = tmp_path / "broken.json"
    broken.write_text("{not json", encoding="utf-8")
    assert main(["export", str(broken), "--to", "json", "-o", str(out)]) == 2
    assert "invalid JSON" in capsys.readouterr().err
    assert not out.exists() and list(tmp_path.iterdir()) == [broken]


def test_cli_never_overwrites_the_result(base: Calibration, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    result = tmp_path / "r.json"
    base.save(result)
    before = result.read_bytes()
    assert main(["export", str(result), "--to", "yaml", "-o", str(result)]) == 2
    assert "never overwrites its input" in capsys.readouterr().err
    assert result.read_bytes() == before


def test_cli_refuses_undetermined_yaw_without_output(
    base: Calibration, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    result = tmp_path / "r.json"
    replace(base, yaw_deg=None, yaw_sigma_deg=None, yaw_reason="level ground").save(result)
    out = tmp_path / "out.txt"
    assert main(["export", str(result), "--to", "urdf", "-o", str(out)]) == 3
    assert "--yaw-undetermined zero" in capsys.readouterr().err
    assert not out.exists()
    assert main(["export", str(result), "--to", "urdf", "-o", str(out), "--yaw-undetermined", "zero"]) == 0
    assert "YAW NOT DETERMINED" in out.read_text(encoding="utf-8")


def test_cli_parent_pose_and_its_refusals(
    base: Calibration, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    result = tmp_path / "r.json"
    base.save(result)
    out = tmp_path / "entry.yaml"
    assert main(["export", str(result), "--to", "autoware", "-o", str(out)]) == 2
    assert "--parent-pose" in capsys.readouterr().err and not out.exists()
    pose = tmp_path / "sensors_calibration.yaml"
    pose.write_text(SAMPLE_SENSORS_CALIBRATION, encoding="utf-8")
    assert main(["export", str(result), "--to", "autoware", "--parent-pose", str(pose), "-o", str(out)]) == 0
    assert "sensor_kit_base_link" in yaml.safe_load(out.read_text(encoding="utf-8"))
    assert main(["export", str(result), "--to", "ublox", "--parent-pose", str(pose), "-o", "-"]) == 2
    assert "Leave them out" in capsys.readouterr().err
    missing = str(tmp_path / "no.yaml")
    assert main(["export", str(result), "--to", "urdf", "--parent", "kit", "--parent-pose", missing, "-o", "-"]) == 2
    assert "no.yaml" in capsys.readouterr().err
    assert main(["export", str(result), "--to", "urdf", "--parent-pose", str(pose), "-o", "-"]) == 2  # base_link: none
    assert "--parent sensor_kit_base_link" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("fmt", "name", "ok"),
    [
        ("ublox", "mount.ubx", False),  # text where the receiver expects UBX bytes
        ("ublox-ubx", "mount.txt", False),
        ("ublox-ubx", "mount.ubx", True),
        ("json", "rotation.yaml", False),
        ("yaml", "rotation.yaml", True),
        ("urdf", "imu.yaml", False),
        ("novatel", "rbv.txt", True),
        ("novatel", "rbv", True),  # no suffix: nothing claimed
    ],
)
def test_cli_output_suffix_means_its_format(
    base: Calibration, tmp_path: Path, capsys: pytest.CaptureFixture[str], fmt: str, name: str, ok: bool
) -> None:
    result = tmp_path / "r.json"
    base.save(result)
    out = tmp_path / name
    code = main(["export", str(result), "--to", fmt, "-o", str(out)])
    assert (code == 0) == ok and out.exists() == ok
    if not ok:
        assert "--to" in capsys.readouterr().err
