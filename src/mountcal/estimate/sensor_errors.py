"""A sensor's errors as the static model's parameters: standard uncertainties from a datasheet's limits
(:func:`from_spec`) or from a triad calibration, for the systematic σ (:mod:`mountcal.loop.systematic`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mountcal.core.conventions import FloatArray
from mountcal.core.sensor_limits import SensorLimits
from mountcal.estimate import effects as registry
from mountcal.estimate.effects.bias import NAMES as BIAS_NAMES  # a triad calibration's own terms (estimate.triad)
from mountcal.estimate.effects.temperature import NAMES as TEMP_NAMES
from mountcal.io.sensor_spec import SensorSpec


@dataclass(frozen=True)
class SensorErrors:
    """Standard uncertainties of sensor errors, by the static model's parameter names (full.StaticModel)."""

    names: tuple[str, ...]
    cov: FloatArray
    source: str
    limits: SensorLimits
    heading_u_rad: float = 0.0  # the headings' common error against the fall line (1σ)


def from_spec(spec: SensorSpec) -> SensorErrors:
    """A datasheet's ± limits as independent rectangular distributions (u = a/√3): of every effect's parameters
    the datasheet bounds (:meth:`~mountcal.estimate.effects.base.Effect.spec_limits`), the built-in effects in
    their ``--model`` order."""
    by_name = {k: v for e in registry.registered().values() for k, v in e.spec_limits(spec).items()}
    names, limits = tuple(by_name), list(by_name.values())
    return SensorErrors(
        names, np.diag(np.square(limits) / 3.0), spec.source, spec.limits(), heading_u(spec.heading_deg)
    )


def heading_u(limit_deg: float) -> float:
    """The standard uncertainty, radians, of headings known to ± ``limit_deg`` (rectangular)."""
    return float(np.radians(limit_deg) / np.sqrt(3.0))


__all__ = ["BIAS_NAMES", "TEMP_NAMES", "SensorErrors", "from_spec", "heading_u"]
