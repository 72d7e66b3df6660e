"""u-blox ZED-F9R (HPS): the user-defined IMU-mount alignment (``CFG-SFIMU-IMU_MNTALG_*``).

u-blox's definition (ZED-F9R Integration manual UBX-20039643, R10, 04-Apr-2025; quoted in
docs/exporters.md):

- IMU frame (§3.2.4.1.1): the accelerometer and gyroscope sensing axes, i.e. the axes of the
  module's own UBX-ESF-RAW / UBX-ESF-MEAS output; "Z-axis is pointing upwards from the top of the
  module" (Figure 2).
- Installation frame (§3.2.4.1.2): x to the front of the vehicle, y to its left, z up. That is ISO
  8855, mountcal's vehicle frame. (Not u-blox's *vehicle* frame of §3.2.7.4.2, x forward, y right,
  z down, which is only that of the attitude output.)
- The keys (§3.2.4.4.2) are "the Euler angles required to rotate the installation frame to the
  IMU-frame": yaw first, then pitch, then roll, each about the axis of the already turned frame.
  The IMU axes in installation coordinates are then the columns of ``Rz(yaw)·Ry(pitch)·Rx(roll)``,
  which maps IMU to installation coordinates: it is ``rot_vs`` itself, and the u-blox angles are
  mountcal's roll, pitch and yaw, with yaw wrapped into 0…360°. All zero: a module lying flat,
  z up out of its top, x forward.

The tolerance key (§3.2.4.4.2, CFG-SFIMU-IMU_MNTALG_TOLERANCE) says how well the angles are known:
LOW (0) "up to 2 degrees wrong", HIGH (1) "preferably within 5 degrees, and in any case no more than
10 degrees"; beyond that the manual points to the automatic alignment. mountcal bounds the error of
the configured rotation by 3σ of the result's rotation and chooses the level from that bound; when
the bound exceeds 10°, or yaw is not determined, it switches the receiver's automatic alignment on,
seeded with these angles (§3.2.7.3.1: the automatic estimate is composed with the user-defined
rotation). The key exists from firmware HPS 1.40 (release note UBXDOC-304424225-18286), so it is
sent in a message of its own: older firmware rejects that message, not the angles.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import TYPE_CHECKING

from mountcal.outputs.exporters.common import Exporter, ExportOptions, Mounting, number, propagate_sigma

if TYPE_CHECKING:
    import numpy as np
    from scipy.spatial.transform import Rotation

    from mountcal.core.result import Calibration

KEYS = {  # name: (key ID, struct format of the value), from the interface description (HPS 1.40)
    "CFG-SFIMU-AUTO_MNTALG_ENA": (0x10060027, "<B"),
    "CFG-SFIMU-IMU_MNTALG_YAW": (0x4006002D, "<I"),
    "CFG-SFIMU-IMU_MNTALG_PITCH": (0x3006002E, "<h"),
    "CFG-SFIMU-IMU_MNTALG_ROLL": (0x3006002F, "<h"),
    "CFG-SFIMU-IMU_MNTALG_TOLERANCE": (0x20060030, "<B"),
}
SCALE_DEG = 1e-2
LAYERS = {"ram": 0x01, "bbr": 0x02, "flash": 0x04}
TOLERANCE_LOW, TOLERANCE_HIGH = 0, 1
LOW_BOUND_DEG = 2.0  # LOW: "up to 2 degrees wrong"
PREFERRED_BOUND_DEG = 5.0  # HIGH: "preferably within 5 degrees" (also the accuracy §3.2.4.4.2 asks for)
HIGH_BOUND_DEG = 10.0  # HIGH: "in any case no more than 10 degrees"
COVERAGE_SIGMA = 3.0  # the error bound of the configured rotation: 3σ about the worst-known axis


@dataclass(frozen=True)
class UbloxMount:
    """The IMU-mount angles in u-blox's convention: exact, as encoded, their 1σ, and how they are to be used."""

    yaw_deg: float  # 0 ≤ yaw < 360
    pitch_deg: float  # −90 … 90
    roll_deg: float  # −180 … 180
    sigma_deg: tuple[float | None, float | None, float | None]  # yaw, pitch, roll
    error_bound_deg: float | None  # 3σ of the rotation about its worst-known axis; None: yaw not determined
    automatic: bool  # the receiver's automatic alignment is switched on, seeded with these angles
    tolerance: int  # TOLERANCE_LOW or TOLERANCE_HIGH
    reason: str  # why this tolerance (and alignment mode)
    mount: Mounting

    @property
    def angles(self) -> dict[str, int]:
        """The first message: alignment mode and angles (units of 1e-2 deg), understood by every HPS firmware."""
        return {
            "CFG-SFIMU-AUTO_MNTALG_ENA": int(self.automatic),
            "CFG-SFIMU-IMU_MNTALG_YAW": round(self.yaw_deg / SCALE_DEG) % 36000,  # 359.996° encodes as 0
            "CFG-SFIMU-IMU_MNTALG_PITCH": round(self.pitch_deg / SCALE_DEG),
            "CFG-SFIMU-IMU_MNTALG_ROLL": round(self.roll_deg / SCALE_DEG),
        }

    @property
    def messages(self) -> tuple[dict[str, int], dict[str, int]]:
        """The key values of the two VALSET messages: the angles, then the tolerance (HPS 1.40 and later)."""
        return self.angles, {"CFG-SFIMU-IMU_MNTALG_TOLERANCE": self.tolerance}


def _angles_deg(rot_vs: Rotation) -> np.ndarray:
    import numpy as np

    from mountcal.core.conventions import euler_angles

    return np.degrees(euler_angles(rot_vs, "ZYX"))  # yaw, pitch, roll: installation frame = ISO 8855


def _tolerance(mount: Mounting) -> tuple[float | None, bool, int, str]:
    import numpy as np

    if any(s is None for s in mount.sigma_rad):
        return (
            None,
            True,
            TOLERANCE_HIGH,
            "yaw is not determined: the receiver's automatic alignment is switched on, seeded with roll and pitch",
        )
    bound = COVERAGE_SIGMA * float(np.degrees(max(s for s in mount.sigma_rad if s is not None)))
    if bound > HIGH_BOUND_DEG:
        return (
            bound,
            True,
            TOLERANCE_HIGH,
            f"error bound {bound:.1f}° (3σ) exceeds the {HIGH_BOUND_DEG:g}° of HIGH tolerance: the receiver's "
            "automatic alignment is switched on, seeded with these angles",
        )
    if bound > LOW_BOUND_DEG:
        extra = f"; above the {PREFERRED_BOUND_DEG:g}° u-blox prefers" if bound > PREFERRED_BOUND_DEG else ""
        return bound, False, TOLERANCE_HIGH, f"HIGH: error bound {bound:.2f}° (3σ) ≤ {HIGH_BOUND_DEG:g}°{extra}"
    return bound, False, TOLERANCE_LOW, f"LOW: error bound {bound:.2f}° (3σ) ≤ {LOW_BOUND_DEG:g}°"


def ublox_mount(mount: Mounting) -> UbloxMount:
    """The IMU-mount angles of a mounting, wrapped into u-blox's ranges, with their σ and tolerance."""
    import numpy as np

    yaw, pitch, roll = _angles_deg(mount.rot_vs)
    sig = propagate_sigma(lambda r: np.radians(_angles_deg(r)), mount, np.array([2 * np.pi] * 3))
    sigma = tuple(None if s is None else float(np.degrees(s)) for s in sig)
    bound, automatic, tolerance, reason = _tolerance(mount)
    return UbloxMount(
        yaw_deg=float(yaw % 360.0),
        pitch_deg=float(pitch),
        roll_deg=float(roll),
        sigma_deg=(sigma[0], sigma[1], sigma[2]),
        error_bound_deg=bound,
        automatic=automatic,
        tolerance=tolerance,
        reason=reason,
        mount=mount,
    )


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


def ucenter_config(messages: tuple[dict[str, int], ...], layers: tuple[str, ...] = ("ram", "bbr", "flash")) -> str:
    """A u-center (generation 9) configuration file: one ``CFG-VALGET - 06 8B …`` line per message and layer.

    The format u-center's Receiver Configuration tool saves and loads: the hex of class, id, length
    and a VALGET payload (version 1, layer 0 RAM / 1 BBR / 2 Flash), without sync chars or checksum.
    """
    numbers = {"ram": 0, "bbr": 1, "flash": 2}
    lines = []
    for values in messages:
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


def valsets(m: UbloxMount) -> bytes:
    """Both VALSET messages, angles first: what to write to the receiver's port."""
    return b"".join(valset(values) for values in m.messages)


def ublox_text(m: UbloxMount) -> str:
    """u-center-style configuration text: key name, key ID, value in degrees; then the messages in hex."""
    lines = [f"# {h}" for h in m.mount.header]
    lines += [
        "# u-blox ZED-F9R user-defined IMU-mount alignment (Integration manual UBX-20039643 R10, §3.2.4.4.2):",
        "# the Euler angles rotating the installation frame (x forward, y left, z up) into the IMU frame (the axes",
        "# of UBX-ESF-RAW), yaw, then pitch, then roll about the turned axes; all 0 = module flat, z up, x forward",
    ]
    sig = dict(zip(("YAW", "PITCH", "ROLL"), m.sigma_deg, strict=True))
    exact = {"YAW": m.yaw_deg, "PITCH": m.pitch_deg, "ROLL": m.roll_deg}
    for name, value in m.angles.items():
        key, _ = KEYS[name]
        if name.endswith("_ENA"):
            use = "on, seeded with the angles below" if m.automatic else "off: the angles below are used as set"
            lines.append(f"{name} 0x{key:08x} {value}  # automatic IMU-mount alignment {use}")
            continue
        axis = name.rsplit("_", 1)[1]
        s = sig[axis]
        sigma = "σ not determined" if s is None else f"1σ {s:.3f} deg"
        lines.append(
            f"{name} 0x{key:08x} {value * SCALE_DEG:.2f}  # deg (raw {value}); exact {number(exact[axis])}, {sigma}"
        )
    from mountcal.core.conventions import GIMBAL_LOCK_PITCH_DEG

    if abs(m.pitch_deg) > GIMBAL_LOCK_PITCH_DEG:
        lines.append(
            "# pitch near ±90°: yaw and roll are not separately defined; the rotation is exact, but the receiver's "
            "UBX-ESF-ALG may show another split of it (manual §3.2.7.3.4)"
        )
    name = "CFG-SFIMU-IMU_MNTALG_TOLERANCE"
    lines.append(f"{name} 0x{KEYS[name][0]:08x} {m.tolerance}  # {m.reason}")
    first, second = (valset(v).hex(" ").upper() for v in m.messages)
    lines.append(f"# UBX-CFG-VALSET (mode and angles), layers RAM BBR Flash: {first}")
    lines.append(f"# UBX-CFG-VALSET (tolerance; firmware before HPS 1.40 rejects this message only): {second}")
    return "\n".join(lines) + "\n"


def _text(cal: Calibration, options: ExportOptions) -> str:
    return ublox_text(ublox_mount(options.mounting(cal)))


def _ucenter(cal: Calibration, options: ExportOptions) -> str:
    return ucenter_config(ublox_mount(options.mounting(cal)).messages)


def _ubx(cal: Calibration, options: ExportOptions) -> bytes:
    return valsets(ublox_mount(options.mounting(cal)))


EXPORTERS = (
    Exporter(
        "ublox", (".txt",), "u-blox ZED-F9R (HPS): the IMU-mount keys, readable, with the VALSET messages in hex", _text
    ),
    Exporter("ublox-ucenter", (".txt",), "u-blox: a u-center configuration file (CFG-VALGET lines)", _ucenter),
    Exporter("ublox-ubx", (".ubx",), "u-blox: the two UBX-CFG-VALSET messages, binary, for the receiver's port", _ubx),
)
