"""A sensor's errors as the static model's parameters: standard uncertainties from a datasheet's limits
(:func:`from_spec`) or from a triad calibration, for the systematic σ (:mod:`mountcal.loop.systematic`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from mountcal.core.conventions import FloatArray
from mountcal.estimate.effects.scale import SCALE_NAMES
from mountcal.io.sensor_spec import SensorSpec

BIAS_NAMES = ("bias_x", "bias_y", "bias_z")
TEMP_NAMES = ("temp_x", "temp_y", "temp_z")


@dataclass(frozen=True)
class SensorErrors:
    """Standard uncertainties of sensor errors, by the static model's parameter names (full.StaticModel)."""

    names: tuple[str, ...]
    cov: FloatArray
    source: str
    limits: dict[str, Any]
    heading_u_rad: float = 0.0  # the headings' common error against the fall line (1σ)


def from_spec(spec: SensorSpec) -> SensorErrors:
    """A datasheet's ± limits as independent rectangular distributions (u = a/√3)."""
    limits = [spec.bias_mps2] * 3 + [spec.bias_tempco_mps2_per_c] * 3 + [spec.scale] * 3 + [spec.cross_axis] * 3
    names = BIAS_NAMES + TEMP_NAMES + SCALE_NAMES
    return SensorErrors(
        names, np.diag(np.square(limits) / 3.0), spec.source, spec.to_dict(), heading_u(spec.heading_deg)
    )


def heading_u(limit_deg: float) -> float:
    """The standard uncertainty, radians, of headings known to ± ``limit_deg`` (rectangular)."""
    return float(np.radians(limit_deg) / np.sqrt(3.0))


__all__ = ["BIAS_NAMES", "TEMP_NAMES", "SensorErrors", "from_spec", "heading_u"]
