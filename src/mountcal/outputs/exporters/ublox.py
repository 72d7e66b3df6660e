"""u-blox ZED-F9R / ZED-F9K: the user-defined IMU-mount alignment (``CFG-SFIMU-IMU_MNTALG_*``).

u-blox's definition (ZED-F9R integration manual UBX-20039643, §"User-defined IMU-mount
alignment"; ZED-F9K integration manual UBX-20046189): the keys are the Euler angles that rotate
the *installation frame* (x forward, y right, z down) into the *IMU frame*: yaw about z first,
then pitch about the new y, then roll about the new x. So the IMU axes in installation
coordinates are the columns of ``Rz(yaw)·Ry(pitch)·Rx(roll)`` and ``a_inst = that · a_imu``.
With ``F = diag(1, −1, −1)`` (ISO 8855 → installation), ``Rz·Ry·Rx = F · rot_vs``.

Units and ranges (interface description, configuration keys): yaw U4, 1e-2 deg, 0…360;
pitch I2, 1e-2 deg, −90…90; roll I2, 1e-2 deg, −180…180. The automatic alignment
(``CFG-SFIMU-AUTO_MNTALG_ENA``) is switched off so the receiver uses these values.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from mountcal.conventions import euler_angles
from mountcal.outputs.exporters.common import Mounting, number, propagate_sigma

INSTALLATION_FROM_ISO = np.diag([1.0, -1.0, -1.0])  # x forward, y right, z down
KEYS = {  # name: (key ID, struct format of the value), from the interface description
    "CFG-SFIMU-AUTO_MNTALG_ENA": (0x10060027, "<B"),
    "CFG-SFIMU-IMU_MNTALG_YAW": (0x4006002D, "<I"),
    "CFG-SFIMU-IMU_MNTALG_PITCH": (0x3006002E, "<h"),
    "CFG-SFIMU-IMU_MNTALG_ROLL": (0x3006002F, "<h"),
}
SCALE_DEG = 1e-2
LAYERS = {"ram": 0x01, "bbr": 0x02, "flash": 0x04}
ACCURACY_NEEDED_DEG = 5.0  # the integration manuals ask for the angles to better than 5°


@dataclass(frozen=True)
class UbloxMount:
    """The IMU-mount angles in u-blox's convention: exact, as encoded, and their 1σ."""

    yaw_deg: float  # 0 ≤ yaw < 360
    pitch_deg: float  # −90 … 90
    roll_deg: float  # −180 … 180
    raw: dict[str, int]  # the key values as sent (units of 1e-2 deg; 0 for the automatic alignment)
    sigma_deg: tuple[float | None, float | None, float | None]  # yaw, pitch, roll
    mount: Mounting


def _angles_deg(rot_vs: Rotation) -> np.ndarray:
    c = Rotation.from_matrix(INSTALLATION_FROM_ISO @ rot_vs.as_matrix())
    return np.degrees(euler_angles(c, "ZYX"))  # yaw, pitch, roll


def ublox_mount(mount: Mounting) -> UbloxMount:
    """The IMU-mount angles of a mounting, wrapped into u-blox's ranges and encoded."""
    yaw, pitch, roll = _angles_deg(mount.rot_vs)
    yaw = float(yaw % 360.0)
    raw_yaw = round(yaw / SCALE_DEG) % 36000  # 359.996° encodes as 0, not as 36000
    raw = {
        "CFG-SFIMU-AUTO_MNTALG_ENA": 0,
        "CFG-SFIMU-IMU_MNTALG_YAW": raw_yaw,
        "CFG-SFIMU-IMU_MNTALG_PITCH": round(float(pitch) / SCALE_DEG),
        "CFG-SFIMU-IMU_MNTALG_ROLL": round(float(roll) / SCALE_DEG),
    }
    sig = propagate_sigma(lambda r: np.radians(_angles_deg(r)), mount, np.array([2 * np.pi] * 3))
    sigma = tuple(None if s is None else float(np.degrees(s)) for s in sig)
    return UbloxMount(yaw, float(pitch), float(roll), raw, (sigma[0], sigma[1], sigma[2]), mount)


def _key_values(values: dict[str, int]) -> bytes:
    out = bytearray()
    for name, value in values.items():
        key, fmt = KEYS[name]
        out += struct.pack("<I", key) + struct.pack(fmt, value)
    return bytes(out)


def _frame(msg_class: int, msg_id: int, payload: bytes) -> bytes:
    """A UBX frame: sync chars, class, id, length, payload, 8-bit Fletcher checksum over class…payload."""
    body = struct.pack("<BBH", msg_class, msg_id, len(payload)) + payload
    ck_a = ck_b = 0
    for byte in body:
        ck_a = (ck_a + byte) & 0xFF
        ck_b = (ck_b + ck_a) & 0xFF
    return b"\xb5\x62" + body + bytes((ck_a, ck_b))


def ucenter_config(values: dict[str, int], layers: tuple[str, ...] = ("ram", "bbr", "flash")) -> str:
    """A u-center (generation 9) configuration file: one ``CFG-VALGET - 06 8B …`` line per layer.

    The format u-center's Receiver Configuration tool saves and loads: the hex of class, id, length
    and a VALGET payload (version 1, layer 0 RAM / 1 BBR / 2 Flash), without sync chars or checksum.
    """
    numbers = {"ram": 0, "bbr": 1, "flash": 2}
    lines = []
    for layer in layers:
        frame = _frame(0x06, 0x8B, struct.pack("<BBH", 1, numbers[layer], 0) + _key_values(values))
        lines.append("CFG-VALGET - " + frame[2:-2].hex(" ").upper())
    return "\n".join(lines) + "\n"


def valset(values: dict[str, int], layers: tuple[str, ...] = ("ram", "bbr", "flash")) -> bytes:
    """The ``UBX-CFG-VALSET`` message (version 0) that sets ``values``, with its checksum.

    Written here (a dozen lines of the documented frame) rather than with a UBX library, so that
    a library can check it independently in the tests.
    """
    mask = 0
    for layer in layers:
        mask |= LAYERS[layer]
    return _frame(0x06, 0x8A, struct.pack("<BBxx", 0, mask) + _key_values(values))


def ublox_text(m: UbloxMount) -> str:
    """u-center-style configuration text: key name, key ID, value in degrees; then the message."""
    lines = [f"# {h}" for h in m.mount.header]
    lines += [
        "# u-blox ZED-F9R/F9K user-defined IMU-mount alignment: Euler angles rotating the installation frame",
        "# (x forward, y right, z down) into the IMU frame, yaw then pitch then roll; layers RAM BBR Flash",
    ]
    sig = dict(zip(("YAW", "PITCH", "ROLL"), m.sigma_deg, strict=True))
    exact = {"YAW": m.yaw_deg, "PITCH": m.pitch_deg, "ROLL": m.roll_deg}
    for name, value in m.raw.items():
        key, _ = KEYS[name]
        if name.endswith("_ENA"):
            lines.append(f"{name} 0x{key:08x} {value}  # automatic IMU-mount alignment off")
            continue
        axis = name.rsplit("_", 1)[1]
        s = sig[axis]
        sigma = "σ not determined" if s is None else f"1σ {s:.3f} deg"
        lines.append(
            f"{name} 0x{key:08x} {value * SCALE_DEG:.2f}  # deg (raw {value}); exact {number(exact[axis])}, {sigma}"
        )
        if s is not None and s > ACCURACY_NEEDED_DEG:
            lines.append(f"# WARNING: {axis.lower()} 1σ {s:.1f}° exceeds the {ACCURACY_NEEDED_DEG:g}° u-blox asks for")
    lines.append("# UBX-CFG-VALSET: " + valset(m.raw).hex(" ").upper())
    return "\n".join(lines) + "\n"
