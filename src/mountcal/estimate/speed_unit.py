"""The speed channel's unit, as the IMU measures it: the note on the drive's speed scale.

The drive measures the IMU's longitudinal specific force over d(speed)/dt (``speed_scale``, 1 for a true speed).
A tyre radius or a GNSS speed's filter moves it by a few per cent; a speed logged in km/h, mph or knots and read
as m/s moves it to 1/3.6, 0.447 or 0.514 (and one in m/s said to be km/h, to 3.6). Near one of those factors the
note names the unit, and what states it: the angles do not depend on the speed's scale (only its direction of
change), but every speed the log's other uses read does.
"""

from __future__ import annotations

MPS_PER = {"km/h": 1.0 / 3.6, "mph": 0.44704, "kn": 1852.0 / 3600.0}  # one unit in m/s
CLOSE = 0.05  # relative: a unit's factor, not a tyre's few per cent (the factors lie 15 % apart and more)


def unit_of_scale(scale: float, sigma: float) -> str | None:
    """The unit slip a speed scale shows: ``"km/h"`` (km/h read as m/s), ``"m/s as km/h"``, ..., or None."""
    if not (scale > 0 and sigma < CLOSE * scale):
        return None
    for unit, factor in MPS_PER.items():
        if abs(scale / factor - 1.0) < CLOSE:
            return unit
        if abs(scale * factor - 1.0) < CLOSE:
            return f"m/s as {unit}"
    return None


def speed_factor(scale: float | None, sigma: float | None) -> float:
    """m/s per unit of the speed as read: the factor of the unit slip the scale shows (1/3.6 for km/h read as m/s,
    3.6 for m/s stated to be km/h), else 1. What reads a distance from the speed (the grade from the altitude)
    multiplies by it, so that the angles do not depend on the speed's unit."""
    unit = None if scale is None or sigma is None else unit_of_scale(scale, sigma)
    if unit is None:
        return 1.0
    if unit.startswith("m/s as "):
        return 1.0 / MPS_PER[unit.removeprefix("m/s as ")]
    return MPS_PER[unit]


def scale_note(scale: float, sigma: float, z: float, gyro: bool) -> str:
    """The result's note on a speed scale beyond its σ: the unit slip it shows, else the usual causes."""
    said = (
        f"the IMU's longitudinal acceleration is {scale:.3f} ± {sigma:.3f} × d(speed)/dt (errors in both counted; "
        f"{abs(z):.1f}σ from 1)"
    )
    unit = unit_of_scale(scale, sigma)
    if unit is not None and not unit.startswith("m/s"):
        return (
            f"{said}: {MPS_PER[unit]:.4g}, a speed logged in {unit} and read as m/s. The angles do not depend on the "
            f"speed's scale (the grade from the altitude reads the distance in {unit}); state its unit for the rest: "
            f"a table's column map (speed=COLUMN:{unit}), a CAN mapping's [units] speed or the DBC signal's unit"
        )
    if unit is not None:
        stated = unit.removeprefix("m/s as ")
        return (
            f"{said}: {1.0 / MPS_PER[stated]:.4g}, a speed in m/s stated to be in {stated}. The angles do not depend "
            "on the speed's scale (the grade from the altitude reads the distance in m/s); correct the unit stated "
            "for the speed (column map, CAN mapping or DBC)"
        )
    return f"{said}: a speed scale error (tyre radius, a GNSS speed's filter), an accelerometer scale error" + (
        "" if gyro else ", or the body pitching on its suspension under load (no gyro to remove it)"
    )


__all__ = ["MPS_PER", "scale_note", "speed_factor", "unit_of_scale"]
