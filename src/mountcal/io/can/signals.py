"""DBC signals in SI: the unit spellings of CAN databases and the message lookup, for reader and writer.

A signal's unit is normalised (lower case, spaces and ``·`` removed, ``⁻²`` → ``^-2``, ``²`` → ``^2``,
``°`` → ``deg``) and looked up per kind of quantity; the reader multiplies by the scale and adds the
offset, the writer inverts that. A message is named by its name (possibly defined twice) or its id.
"""

from __future__ import annotations

import math
from typing import Any

# standard gravity, m/s², for signals in g: the value of mountcal.core.conventions.G_N (a test checks it),
# not imported from there, which would load scipy into every CAN read
G_N = 9.80665

# unit spellings (as normalise_unit leaves them) → (scale, offset) to SI
UNITS: dict[str, dict[str, tuple[float, float]]] = {
    "accel": {
        **dict.fromkeys(("m/s^2", "m/s2", "m/s/s", "ms^-2", "ms-2", "mps2", "m/sec^2", "m/sec2"), (1.0, 0.0)),
        **dict.fromkeys(("g", "gn", "g0"), (G_N, 0.0)),
        "mg": (G_N / 1000.0, 0.0),
    },
    "gyro": {
        **dict.fromkeys(("deg/s", "degs^-1", "dps", "degree/s", "degrees/s", "deg/sec"), (math.pi / 180.0, 0.0)),
        **dict.fromkeys(("rad/s", "rads^-1", "rad/sec"), (1.0, 0.0)),
        "mrad/s": (1e-3, 0.0),
    },
    "speed": {
        **dict.fromkeys(("m/s", "mps", "m/sec"), (1.0, 0.0)),
        **dict.fromkeys(("km/h", "kmh", "kph", "km/hr"), (1.0 / 3.6, 0.0)),
        "mph": (0.44704, 0.0),
        **dict.fromkeys(("kn", "kt", "knot", "knots"), (1852.0 / 3600.0, 0.0)),
    },
    "angle": {
        **dict.fromkeys(("deg", "degree", "degrees"), (1.0, 0.0)),
        **dict.fromkeys(("rad", "radian", "radians"), (180.0 / math.pi, 0.0)),
    },
    "length": {"m": (1.0, 0.0), "km": (1000.0, 0.0), "ft": (0.3048, 0.0)},
    "temperature": {
        **dict.fromkeys(("degc", "c", "celsius", "degreec", "degreesc"), (1.0, 0.0)),
        "k": (1.0, -273.15),
        **dict.fromkeys(("degf", "f", "fahrenheit"), (5.0 / 9.0, -32.0 * 5.0 / 9.0)),
    },
}


UNIT_KIND = {
    "ax": "accel",
    "ay": "accel",
    "az": "accel",
    "gx": "gyro",
    "gy": "gyro",
    "gz": "gyro",
    "temperature": "temperature",
    "speed": "speed",
    "heading": "angle",
    "latitude": "angle",
    "longitude": "angle",
    "altitude": "length",
}


UNIT_HINT = {
    "accel": "m/s^2 or g",
    "gyro": "deg/s or rad/s",
    "speed": "m/s, km/h, mph or kn",
    "angle": "deg or rad",
    "length": "m, km or ft",
    "temperature": "degC, K or degF",
}


def message_refs(db: Any, text: str) -> list[Any]:
    """Messages named ``text``: a name (possibly defined twice) or an id, hex 0x.. or decimal."""
    by_name = [m for m in db.messages if m.name == text]
    if by_name:
        return by_name
    try:
        ident = int(text, 0)
    except ValueError:
        return []
    return [m for m in db.messages if int(m.frame_id) == ident]


def normalise_unit(unit: str) -> str:
    """A unit spelling as :data:`UNITS` lists it."""
    text = unit.strip().lower().replace(" ", "").replace("·", "").replace("⁻²", "^-2").replace("⁻¹", "^-1")
    return text.replace("²", "^2").replace("°", "deg")


def si_scale(role: str, unit: str) -> tuple[float, float] | None:
    """(scale, offset) with SI = value · scale + offset for a ``role``'s signal in ``unit``; None if unknown."""
    return UNITS[UNIT_KIND[role]].get(normalise_unit(unit))


__all__ = ["UNITS", "UNIT_HINT", "UNIT_KIND", "message_refs", "normalise_unit", "si_scale"]
