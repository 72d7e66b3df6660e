"""Speed and course over ground from NMEA 0183 sentences (``nmea_msgs/msg/Sentence``): RMC and VTG.

- ``$xxRMC,time,status,lat,N,lon,E,sog_knots,cog_deg,date,…``: used when status is ``A`` (valid);
- ``$xxVTG,cog_true,T,cog_mag,M,sog_knots,N,sog_kmh,K[,mode]``: used unless the mode is ``N`` (not valid).

A sentence whose ``*hh`` checksum does not match its text is not used (counted). Speed in m/s (1 knot =
1852/3600 m/s); course in degrees clockwise from true north, NaN where the sentence gives none.
"""

from __future__ import annotations

from functools import reduce

import numpy as np

from mountcal.io.samples import FloatArray

KNOT = 1852.0 / 3600.0


def _checksum_ok(text: str) -> bool:
    body, star, given = text.partition("*")
    if not star:
        return True  # no checksum written: nothing to check
    try:
        return reduce(lambda a, c: a ^ ord(c), body.lstrip("$!"), 0) == int(given[:2], 16)
    except ValueError:
        return False


def _number(field: str) -> float:
    try:
        return float(field)
    except ValueError:
        return float("nan")


def parse(sentences: list[bytes]) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Speed (m/s) and course (deg) of each sentence (NaN where it gives none), and 1.0 where its
    checksum failed (else 0.0)."""
    n = len(sentences)
    speed, course, bad = np.full(n, np.nan), np.full(n, np.nan), np.zeros(n)
    for i, raw in enumerate(sentences):
        text = raw.decode("ascii", "replace").strip()
        if not _checksum_ok(text):
            bad[i] = 1.0
            continue
        fields = text.split("*", 1)[0].split(",")
        kind = fields[0][-3:]
        if kind == "RMC" and len(fields) > 8 and fields[2] == "A":
            speed[i], course[i] = _number(fields[7]) * KNOT, _number(fields[8])
        elif kind == "VTG" and len(fields) > 5 and not (len(fields) > 9 and fields[9].startswith("N")):
            speed[i], course[i] = _number(fields[5]) * KNOT, _number(fields[1])
    return speed, course, bad


__all__ = ["KNOT", "parse"]
