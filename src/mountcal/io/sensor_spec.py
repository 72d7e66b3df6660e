"""An accelerometer's datasheet limits: what the sensor may be off by, before any calibration.

The limits are the ± bounds a datasheet states. mountcal reads them as rectangular
distributions (GUM 4.3.7: a limit ±a with no further knowledge is a standard uncertainty
a/√3) and propagates them in :mod:`mountcal.loop.systematic`.

The default class is an uncalibrated consumer MEMS accelerometer, from the InvenSense
MPU-6000/6050 product specification (rev. 3.4, §6.2, ±2 g range): sensitivity "initial
calibration tolerance ±3 %", "cross-axis sensitivity ±2 %", zero-g "initial calibration
tolerance ±80 mg" (Z; ±50 mg X, Y), zero-g change over 0–70 °C ±60 mg (Z; ±35 mg X, Y), i.e.
0.86 mg/°C. Other consumer parts state limits of the same order (a few % in scale and
cross-axis, tens of mg in offset).

The headings are the protocol's, not the sensor's, but they limit yaw the same way: yaw comes from
the stops' pattern against their headings relative to the uphill direction, so a common error of
those headings moves yaw one for one, and no residual can show it. The default, ±1°, is a vehicle
parked by eye at marks laid out against the fall line; surveyed marks or a dual-antenna GNSS
heading are better (0.1–0.3°), headings from a single antenna's course over ground or a compass
worse. The limit is that of the headings' common error (their reference against the fall line);
each stop's own error scatters the stops, which the residual shows and the statistical part counts.

A spec file (TOML or JSON) gives any of these keys; the others keep the default::

    scale = 0.03                 # ± fraction of the reading
    cross_axis = 0.02            # ± fraction of the other axis' reading
    bias_mps2 = 0.785            # ± m/s² (or bias_mg = 80)
    bias_tempco_mps2_per_c = 0.0084   # ± m/s² per °C (or bias_tempco_mg_per_c = 0.86)
    heading_deg = 1.0            # ± degrees: the headings' common error against the fall line
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

from mountcal.core import paths
from mountcal.core.errors import InputError
from mountcal.core.ranges import QUANTITIES
from mountcal.core.sensor_limits import SensorLimits

MG = 9.80665e-3  # m/s² per mg


@dataclass(frozen=True)
class SensorSpec:
    """± limits of the sensor errors (fractions, m/s², m/s² per °C) and where they come from."""

    scale: float = 0.03
    cross_axis: float = 0.02
    bias_mps2: float = 80 * MG
    bias_tempco_mps2_per_c: float = 60 * MG / 70
    source: str = "default class: uncalibrated consumer MEMS (MPU-6050 datasheet limits)"
    heading_deg: float = 1.0  # the protocol's: the headings' common error against the fall line

    @property
    def is_default(self) -> bool:
        return self.source == DEFAULT.source

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def limits(self) -> SensorLimits:
        """These limits as a result states them."""
        return SensorLimits(**self.to_dict())


DEFAULT = SensorSpec()
_KEYS = {
    "scale": ("scale", 1.0),
    "cross_axis": ("cross_axis", 1.0),
    "bias_mps2": ("bias_mps2", 1.0),
    "bias_mg": ("bias_mps2", MG),
    "bias_tempco_mps2_per_c": ("bias_tempco_mps2_per_c", 1.0),
    "bias_tempco_mg_per_c": ("bias_tempco_mps2_per_c", MG),
    "heading_deg": ("heading_deg", 1.0),
}


def read_spec(path: str | Path) -> SensorSpec:
    """A spec from a TOML or JSON datasheet file; unknown keys or bad values are refused."""
    path = Path(path)
    todo = f"Give a TOML or JSON file with any of {', '.join(_KEYS)} (non-negative numbers)."
    doc = paths.read_document(path, "a sensor spec", toml=path.suffix.lower() != ".json")  # not /dev/zero
    if not isinstance(doc, dict):
        raise InputError(str(path), "a table of limits", type(doc).__name__, todo)
    unknown = sorted(set(doc) - set(_KEYS))
    if unknown:
        raise InputError(str(path), f"keys among {', '.join(_KEYS)}", f"unknown keys {', '.join(unknown)}", todo)
    values: dict[str, Any] = {}
    for key, value in doc.items():
        if isinstance(value, bool) or not isinstance(value, int | float) or not QUANTITIES["spec_limit"].holds(value):
            raise InputError(str(path), f"{key}: {QUANTITIES['spec_limit'].expected()}", repr(value), todo)
        field, unit = _KEYS[key]
        values[field] = float(value) * unit
    if values.get("scale", 0) >= 0.5 or values.get("cross_axis", 0) >= 0.5:
        raise InputError(str(path), "scale and cross_axis as fractions (0.03 for 3 %)", repr(doc), todo)
    if values.get("heading_deg", 0) > 90:
        raise InputError(str(path), "heading_deg: a limit in degrees, at most 90", repr(doc["heading_deg"]), todo)
    return replace(DEFAULT, **values, source=f"sensor spec {path}")
