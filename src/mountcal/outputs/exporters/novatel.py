"""NovAtel SPAN (OEM7): ``SETINSROTATION RBV X Y Z [XSD YSD ZSD]``.

NovAtel's definition (OEM7 SPAN Installation and Operation User Manual, §"Rotational Offsets";
OEM7 Commands and Logs Reference, SETINSROTATION): offsets are "the rotation from the IMU Body
frame to the frame of interest", here the vehicle frame (x right, y forward, z up); "the order of
rotations is Z, X, Y", all right-handed, degrees, each within ±180; the optional standard
deviations are degrees within 0.25…45 (default 3.0).

Rotating the IMU body axes about z, the new x, the new y until they coincide with the vehicle axes
makes the vehicle axes, in body coordinates, the columns of ``C = Rz(Z)·Rx(X)·Ry(Y)``; so
``a_body = C · a_vehicle`` and, with ``P`` taking NovAtel's vehicle frame to ISO 8855,
``rot_vs = P · Cᵀ``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from mountcal.core.errors import NotEnoughInformation
from mountcal.outputs.exporters.common import Exporter, ExportOptions, Mounting, number, propagate_sigma

if TYPE_CHECKING:
    import numpy as np
    from scipy.spatial.transform import Rotation

    from mountcal.core.result import Calibration

ISO_FROM_NOVATEL = ((0.0, 1.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 0.0, 1.0))  # (right, fwd, up) → (fwd, left, up)
SD_RANGE_DEG = (0.25, 45.0)


@dataclass(frozen=True)
class NovatelRotation:
    """The RBV angles (X, Y, Z as the command lists them) and the standard deviations sent."""

    xyz_deg: tuple[float, float, float]
    sd_deg: tuple[float, float, float]  # as sent: within NovAtel's 0.25…45
    sigma_deg: tuple[float | None, float | None, float | None]  # propagated 1σ before clipping
    notes: tuple[str, ...]
    mount: Mounting


def _xyz_deg(rot_vs: Rotation) -> np.ndarray:
    import numpy as np
    from scipy.spatial.transform import Rotation

    from mountcal.core.conventions import euler_angles

    c = Rotation.from_matrix(rot_vs.as_matrix().T @ np.array(ISO_FROM_NOVATEL))
    z, x, y = euler_angles(c, "ZXY")
    return np.degrees([x, y, z])


def novatel_rotation(mount: Mounting) -> NovatelRotation:
    """The RBV rotation of a mounting, with σ propagated to NovAtel's angles."""
    import numpy as np

    xyz = _xyz_deg(mount.rot_vs)
    sig = propagate_sigma(lambda r: np.radians(_xyz_deg(r)), mount, np.array([2 * np.pi] * 3))
    sigma = [None if s is None else float(np.degrees(s)) for s in sig]
    lo, hi = SD_RANGE_DEG
    notes: list[str] = []
    if any(s is not None and s > hi for s in sigma):
        # Near X = ±90° (gimbal lock) Z and Y are not separately defined and their σ diverges while the
        # rotation is well known: state the σ of small rotations about NovAtel's vehicle x, y, z instead.
        sx, sy, sz = mount.sigma_rad  # about ISO x (forward), y (left), z (up)
        sigma = [None if s is None else float(np.degrees(s)) for s in (sy, sx, sz)]
        notes.append("X near ±90° (gimbal lock): standard deviations of small rotations about the vehicle axes")
    sd: list[float] = []
    for axis, s in zip("XYZ", sigma, strict=True):
        if s is None:
            sd.append(hi)
            notes.append(f"{axis} standard deviation unknown (the result has none): sent as NovAtel's maximum {hi:g}°")
        elif s > hi:
            raise NotEnoughInformation(
                f"the {axis} rotation's 1σ is {s:.1f}°, beyond the {hi:g}° NovAtel accepts: the calibration "
                "does not determine this mounting well enough to configure SPAN with it."
            )
        elif s < lo:
            sd.append(lo)
            notes.append(f"{axis} 1σ {s:.3f}° raised to NovAtel's minimum {lo:g}°")
        else:
            sd.append(s)
    return NovatelRotation(
        (float(xyz[0]), float(xyz[1]), float(xyz[2])),
        (sd[0], sd[1], sd[2]),
        (sigma[0], sigma[1], sigma[2]),
        tuple(notes),
        mount,
    )


def novatel_text(r: NovatelRotation) -> str:
    """The abbreviated ASCII command, with comment lines stating the frames and σ."""
    lines = [f"# {h}" for h in r.mount.header]
    lines.append("# NovAtel SPAN (OEM7): rotation from the IMU body frame (the axes marked on the IMU) to the vehicle")
    lines.append("# frame (x right, y forward, z up), about Z, then the new X, then the new Y, right-handed; degrees;")
    lines.append('# standard deviations 1σ. Calibrate on the body axes: RAWIMU/RAWIMUS/RAWIMUSX log -y ("-(Y Accel')
    lines.append('# Output)"), so negate that field first. Send only the SETINSROTATION line.')
    lines += [f"# {n}" for n in r.notes]
    angles = " ".join(number(v) for v in r.xyz_deg)
    sds = " ".join(number(v, 4) for v in r.sd_deg)
    lines.append(f"SETINSROTATION RBV {angles} {sds}")
    return "\n".join(lines) + "\n"


def _write(cal: Calibration, options: ExportOptions) -> str:
    return novatel_text(novatel_rotation(options.mounting(cal)))


EXPORTERS = (
    Exporter(
        "novatel", (".txt",), "NovAtel SPAN (OEM7): the `SETINSROTATION RBV` command, with standard deviations", _write
    ),
)
