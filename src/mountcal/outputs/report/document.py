"""Reading a calibration result for display: angles ± σ, model steps, effects, in words.

The typed result (:mod:`mountcal.core.result`) is the source of truth; these helpers only format it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from mountcal.core.angles import ANGLE_NAMES
from mountcal.core.result import Calibration, EffectValue, ModelStep

ANGLES = ANGLE_NAMES


@dataclass(frozen=True)
class Estimate:
    """A value with its 1σ; ``value`` None when not determined (``reason`` then says why)."""

    value: float | None
    sigma: float | None
    reason: str | None = None

    @property
    def determined(self) -> bool:
        return self.value is not None


def angle_estimates(entry: Calibration | ModelStep | Mapping[str, Estimate]) -> dict[str, Estimate]:
    """Roll, pitch, yaw and slope in degrees with their 1σ, from a calibration or a model step.

    A mapping of angle name to :class:`Estimate` (e.g. a yaw from elsewhere) is taken as it is;
    the angles it lacks are "not given".
    """
    if isinstance(entry, Mapping):
        return {name: entry.get(name, Estimate(None, None, "not given")) for name in ANGLES}
    a = entry.angles
    why = {"yaw": a.yaw_reason, "slope": None if a.slope_deg is not None else "not determined"}
    return {name: Estimate(a.value(name), a.sigma(name), why.get(name)) for name in ANGLES}


def step_label(index: int, step: ModelStep) -> str:
    """``1. start``, ``2. + bias``: the step's number (from 0) and what it added."""
    return f"{index + 1}. {'+ ' if index else ''}{step.added}"


def moved_deg(step: ModelStep) -> dict[str, float]:
    """How far each determined angle moved from the previous step, degrees."""
    if step.moved is None:
        return {}
    return {name: value for name, value in step.moved.items() if value is not None}


def format_effect(effect: EffectValue) -> str:
    """An effect's value ± σ as text, per component (``(x, y, z)`` for a vector), with its unit."""
    unit = f" {effect.unit}" if effect.unit and effect.unit != "°" else effect.unit
    parts = [
        (f"{label}: " if label not in ("", "x", "y", "z") else "") + _pm_plain(v, s)
        for label, v, s in zip(effect.components, effect.value, effect.sigma, strict=True)
    ]
    return (parts[0] if len(parts) == 1 else f"({', '.join(parts)})") + unit


def _pm_plain(value: float, sigma: float | None) -> str:
    return format_pm(value, sigma, "") if sigma is not None else f"{value:.4g}"


def format_pm(value: float | None, sigma: float | None, unit: str = "°") -> str:
    """``value ± σ`` with as many decimals as two significant digits of σ; "not determined" for None."""
    if value is None:
        return "not determined"
    if sigma is None or not math.isfinite(sigma) or sigma <= 0:
        return f"{value:.4g}{unit}"
    decimals = min(max(1 - math.floor(math.log10(sigma)), 0), 8)
    return f"{value:.{decimals}f}{unit} ± {sigma:.{decimals}f}{unit}"
