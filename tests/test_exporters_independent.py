"""Every export format, read back independently, agrees with the result's rotation (issue 23).

The mountings are built physically — from what the sensor reads at rest (gravity's reaction, +g "up")
and when the vehicle accelerates forward — not from any Euler convention. Each format is read by a
decoder written here from its vendor's documented meaning: pyubx2 parses the UBX bytes, PyYAML and
ElementTree the text, and the rotation is built with scipy in the vendor's documented frames and
order. mountcal's own code is used only to produce the result and the export.
"""

from __future__ import annotations

import io
import json
import re
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml
from pyubx2 import GET, SET, UBXReader, calc_checksum
from scipy.spatial.transform import Rotation

from mountcal.calibration.fit import calibrate
from mountcal.core.result import Calibration
from mountcal.outputs.exporters import Frames, builtin, export, read_parent_pose
from mountcal.simulate.stops import simulate_stops

C200, S200 = np.cos(np.radians(200)), np.sin(np.radians(200))
MOUNTINGS = {  # in the sensor's own axes: (where it reads gravity's +g, where it reads a forward acceleration)
    "level": ((0, 0, 1), (1, 0, 0)),  # flat, z up out of its top, x forward
    "tilted": ((-0.12, 0.09, 1.0), (1.0, 0.05, 0.12)),  # a few degrees nose up and rolled, not on any axis
    "on its side": ((0, 1, 0), (1, 0, 0)),  # its y axis points up, x forward (so z points right)
    "upside down": ((0, 0, -1), (1, 0, 0)),  # z points down, x forward (so y points right)
    "yaw 200°": ((0, 0, 1), (C200, -S200, 0)),  # flat, turned 200° counter-clockwise seen from above
}
SAMPLE_KIT_POSE = (  # Autoware's sample kit, sensors_calibration.yaml
    "base_link:\n  sensor_kit_base_link: {x: 0.9, y: 0.0, z: 2.0, roll: -0.001, pitch: 0.015, yaw: -0.0364}\n"
)
UBLOX_RESOLUTION_RAD = 3 * np.radians(0.005)  # half a 0.01° step on each of the three angles
TOL_RAD = 1e-9


def vehicle_from_sensor(up_s: tuple[float, ...], forward_s: tuple[float, ...]) -> np.ndarray:
    """The matrix taking sensor coordinates to vehicle ones (x forward, y left, z up), from the two readings.

    Its rows are the vehicle's axes in sensor coordinates: up, the forward reading made orthogonal to up,
    and left = up × forward.
    """
    up = np.asarray(up_s, float) / np.linalg.norm(up_s)
    fwd = np.asarray(forward_s, float)
    fwd = fwd - (fwd @ up) * up
    fwd /= np.linalg.norm(fwd)
    return np.vstack([fwd, np.cross(up, fwd), up])


@pytest.fixture(scope="module", params=list(MOUNTINGS))
def mounted(request: pytest.FixtureRequest) -> tuple[str, np.ndarray, Calibration]:
    truth = vehicle_from_sensor(*MOUNTINGS[request.param])
    table, _ = simulate_stops(rot_vs=Rotation.from_matrix(truth), seed=23)
    cal = calibrate(table)
    assert cal.yaw_deg is not None and cal.confident
    return request.param, truth, cal


@pytest.fixture(scope="module")
def kit_pose(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("autoware") / "sensors_calibration.yaml"
    path.write_text(SAMPLE_KIT_POSE, encoding="utf-8")
    return path


# ------------------------------------------------------------------------ decoders, one per format ---------


def ublox_rotation(values: dict[str, int]) -> np.ndarray:
    """ZED-F9R Integration manual UBX-20039643 R10: the keys (1e-2 deg) are the Euler angles rotating the
    installation frame (§3.2.4.1.2: x front, y left, z up) into the IMU frame, yaw, then pitch, then roll about
    the turned axes (§3.2.4.4.2): the IMU axes in installation coordinates are the columns of that rotation."""
    assert values["CFG_SFIMU_AUTO_MNTALG_ENA"] == 0  # the angles are used as set
    assert values["CFG_SFIMU_IMU_MNTALG_TOLERANCE"] in (0, 1)
    assert 0 <= values["CFG_SFIMU_IMU_MNTALG_YAW"] < 36000 and abs(values["CFG_SFIMU_IMU_MNTALG_PITCH"]) <= 9000
    ypr = [values[f"CFG_SFIMU_IMU_MNTALG_{k}"] / 100 for k in ("YAW", "PITCH", "ROLL")]
    return Rotation.from_euler("ZYX", ypr, degrees=True).as_matrix()  # scipy: upper case = intrinsic


def sfimu_keys(msg: object) -> dict[str, int]:
    return {k: int(getattr(msg, k)) for k in dir(msg) if k.startswith("CFG_SFIMU_")}


def read_ubx(data: bytes) -> np.ndarray:
    values: dict[str, int] = {}
    for _, msg in UBXReader(io.BytesIO(data), msgmode=SET, quitonerror=2):
        assert msg.identity == "CFG-VALSET" and (msg.ram, msg.bbr, msg.flash) == (1, 1, 1)
        values |= sfimu_keys(msg)
    return ublox_rotation(values)


def read_ucenter(text: str) -> np.ndarray:
    """u-center generation 9 configuration file: lines ``CFG-VALGET - <class id length payload in hex>``."""
    values: dict[str, int] = {}
    for line in text.splitlines():
        data = bytes.fromhex(line.removeprefix("CFG-VALGET - "))
        values |= sfimu_keys(UBXReader.parse(b"\xb5\x62" + data + calc_checksum(data), msgmode=GET))
    return ublox_rotation(values)


def read_ublox_text(text: str) -> np.ndarray:
    """The readable text: the key lines in degrees must say what the embedded VALSET messages say."""
    shown = {
        m.group(1).replace("-", "_"): float(m.group(2))
        for m in re.finditer(r"^(CFG-SFIMU-IMU_MNTALG_(?:YAW|PITCH|ROLL)) 0x[0-9a-f]{8} (\S+)", text, re.M)
    }
    hexes = re.findall(r"^# UBX-CFG-VALSET[^:]*: ([0-9A-F ]+)$", text, re.M)
    data = b"".join(bytes.fromhex(h) for h in hexes)
    rot = read_ubx(data)
    first = UBXReader.parse(data[: 8 + int.from_bytes(data[4:6], "little")], msgmode=SET)
    sent = {k: v / 100 for k, v in sfimu_keys(first).items() if k in shown}
    assert shown == sent
    return rot


def read_novatel(text: str) -> np.ndarray:
    """OEM7 SETINSROTATION RBV X Y Z: "the rotation from the IMU body frame, to the frame of interest. The order
    of rotations is Z, X, Y. All rotations are right handed." Turning the body axes about Z, the new X, the new Y
    onto the vehicle frame (x right, y forward, z up) makes the vehicle axes, in body coordinates, the columns
    of that rotation."""
    fields = next(ln for ln in text.splitlines() if ln.startswith("SETINSROTATION")).split()
    assert fields[1] == "RBV" and len(fields) == 8
    x, y, z, *sd = (float(v) for v in fields[2:])
    assert all(-180 <= a <= 180 for a in (x, y, z)) and all(0.25 <= s <= 45 for s in sd)
    vehicle_in_body = Rotation.from_euler("ZXY", [z, x, y], degrees=True).as_matrix()
    iso_from_novatel = np.array([[0, 1, 0], [-1, 0, 0], [0, 0, 1]])  # (right, forward, up) → (forward, left, up)
    return iso_from_novatel @ vehicle_in_body.T


def read_static_tf(text: str) -> np.ndarray:
    """``static_transform_publisher --qx --qy --qz --qw --frame-id P --child-frame-id C``: C's orientation in P,
    mapping C coordinates to P coordinates (P must be a REP 103 body frame: x forward, y left, z up)."""
    line = next(ln for ln in text.splitlines() if ln.startswith("ros2 run tf2_ros static_transform_publisher"))
    args = dict(zip(line.split()[4::2], line.split()[5::2], strict=True))
    assert args["--frame-id"] == "base_link"
    return Rotation.from_quat([float(args[k]) for k in ("--qx", "--qy", "--qz", "--qw")]).as_matrix()


def read_urdf(text: str) -> np.ndarray:
    """URDF joint origin rpy: "roll, pitch, yaw", about the fixed x, y, z axes (extrinsic x-y-z), radians."""
    joint = ET.fromstring(text)
    assert joint.find("parent").get("link") == "base_link"  # type: ignore[union-attr]
    rpy = [float(v) for v in joint.find("origin").get("rpy", "").split()]  # type: ignore[union-attr]
    return Rotation.from_euler("xyz", rpy).as_matrix()  # scipy: lower case = extrinsic, fixed axes


def read_tf2(text: str) -> np.ndarray:
    match = re.search(r"tf2::Quaternion q\((\S+), (\S+), (\S+), (\S+)\);", text)
    assert match is not None
    return Rotation.from_quat([float(v) for v in match.groups()]).as_matrix()  # tf2: x, y, z, w


def read_autoware(text: str, kit_pose: Path) -> np.ndarray:
    """sensor_kit_calibration.yaml entry {x, y, z, roll, pitch, yaw}: a URDF joint origin in sensor_kit_base_link,
    which sensors_calibration.yaml places in base_link; the two joints chain."""
    entry = yaml.safe_load(text)["sensor_kit_base_link"]["imu_link"]
    kit = yaml.safe_load(kit_pose.read_text(encoding="utf-8"))["base_link"]["sensor_kit_base_link"]
    kit_in_base = Rotation.from_euler("xyz", [kit[k] for k in ("roll", "pitch", "yaw")])
    return (kit_in_base * Rotation.from_euler("xyz", [entry[k] for k in ("roll", "pitch", "yaw")])).as_matrix()


def read_rotation_document(doc: dict[str, object]) -> np.ndarray:
    """mountcal.rotation: rot_vs, sensor to ISO 8855 vehicle coordinates; every parameterisation says the same."""
    matrix = np.array(doc["matrix"]["value"])  # type: ignore[index]
    x, y, z, w = doc["quaternion_xyzw"]["value"]  # type: ignore[index]
    yaw, pitch, roll = doc["euler_zyx"]["yaw_pitch_roll_rad"]  # type: ignore[index]
    for other in (Rotation.from_quat([x, y, z, w]), Rotation.from_euler("ZYX", [yaw, pitch, roll])):
        np.testing.assert_allclose(other.as_matrix(), matrix, rtol=0, atol=1e-12)
    return matrix


DECODERS: dict[str, tuple[Callable[[str | bytes, Path], np.ndarray], float]] = {
    "ublox": (lambda out, kit: read_ublox_text(str(out)), UBLOX_RESOLUTION_RAD),
    "ublox-ucenter": (lambda out, kit: read_ucenter(str(out)), UBLOX_RESOLUTION_RAD),
    "ublox-ubx": (lambda out, kit: read_ubx(bytes(out)), UBLOX_RESOLUTION_RAD),  # type: ignore[arg-type]
    "novatel": (lambda out, kit: read_novatel(str(out)), TOL_RAD),
    "ros2-static-tf": (lambda out, kit: read_static_tf(str(out)), TOL_RAD),
    "urdf": (lambda out, kit: read_urdf(str(out)), TOL_RAD),
    "tf2": (lambda out, kit: read_tf2(str(out)), TOL_RAD),
    "autoware": (lambda out, kit: read_autoware(str(out), kit), TOL_RAD),
    "json": (lambda out, kit: read_rotation_document(json.loads(str(out))), TOL_RAD),
    "yaml": (lambda out, kit: read_rotation_document(yaml.safe_load(str(out))), TOL_RAD),
}


def test_every_format_has_an_independent_reader() -> None:
    assert set(DECODERS) == set(builtin())


@pytest.mark.parametrize("fmt", list(DECODERS))
def test_independent_reading_agrees_with_the_result(
    mounted: tuple[str, np.ndarray, Calibration], fmt: str, kit_pose: Path
) -> None:
    name, _, cal = mounted
    frames = None
    if fmt == "autoware":
        frames = Frames(parent="sensor_kit_base_link", parent_pose=read_parent_pose(kit_pose, "sensor_kit_base_link"))
    decode, tolerance = DECODERS[fmt]
    got = decode(export(cal, fmt, frames=frames), kit_pose)
    # agrees with the result's rotation: the angle of the rotation between them
    assert Rotation.from_matrix(got.T @ cal.rot_vs.as_matrix()).magnitude() <= tolerance, name
    # and, within the calibration's accuracy, with the physics: gravity up, forward forward
    up, forward = (np.asarray(v, float) for v in MOUNTINGS[name])
    up /= np.linalg.norm(up)
    forward -= (forward @ up) * up  # what remains of the forward reading once gravity's part is taken out
    np.testing.assert_allclose(got @ up, [0, 0, 1], atol=0.01)
    np.testing.assert_allclose(got @ (forward / np.linalg.norm(forward)), [1, 0, 0], atol=0.01)


def test_flat_level_aligned_ublox_module_is_all_zero() -> None:
    """The acceptance case on its own: a flat module, z up out of its top, x forward, exports 0/0/0 (exactly)."""
    table, _ = simulate_stops(rot_vs=Rotation.from_matrix(vehicle_from_sensor(*MOUNTINGS["level"])), seed=23)
    cal = calibrate(table)
    exact = replace(cal, rot_vs=Rotation.identity(), yaw_deg=0.0)
    values: dict[str, int] = {}
    for _, msg in UBXReader(io.BytesIO(bytes(export(exact, "ublox-ubx"))), msgmode=SET, quitonerror=2):
        values |= sfimu_keys(msg)
    assert [values[f"CFG_SFIMU_IMU_MNTALG_{k}"] for k in ("YAW", "PITCH", "ROLL")] == [0, 0, 0]
    # and the calibrated one (not exactly identity) lies within 3σ of that: yaw near 0 or near 360
    values = {}
    for _, msg in UBXReader(io.BytesIO(bytes(export(cal, "ublox-ubx"))), msgmode=SET, quitonerror=2):
        values |= sfimu_keys(msg)
    yaw, pitch, roll = (values[f"CFG_SFIMU_IMU_MNTALG_{k}"] / 100 for k in ("YAW", "PITCH", "ROLL"))
    assert cal.yaw_sigma_deg is not None and min(yaw, 360 - yaw) < 3 * cal.yaw_sigma_deg
    assert abs(pitch) < 3 * cal.pitch_sigma_deg and abs(roll) < 3 * cal.roll_sigma_deg
