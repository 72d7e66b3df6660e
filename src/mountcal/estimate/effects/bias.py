"""A constant accelerometer bias b (3 values, m/s², sensor frame): ``p + b``."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from mountcal.core.conventions import FloatArray
from mountcal.core.result import EffectValue
from mountcal.estimate.effects.base import BaseEffect, reported_vector
from mountcal.stops.table import StopTable

if TYPE_CHECKING:
    from mountcal.io.sensor_spec import SensorSpec

NAMES = ("bias_x", "bias_y", "bias_z")
MAX_BIAS_G = 0.5  # an offset this large is not an accelerometer bias (consumer MEMS: < 0.1 g) but a sign or unit error


class Bias(BaseEffect):
    name = "bias"
    meaning = "a constant accelerometer bias, 3 values"
    order = 20
    report_key = "bias_mps2"  # also the v2 result's own field (Calibration.bias_mps2): effects.offset_of reads it
    unit = "m/s²"
    offset = True
    inseparable_note = (
        "a constant accelerometer bias cannot be told from a tilt with these stops: if the sensor has a "
        "bias b, roll and pitch are off by up to b/g (20 mg → 1.1°) beyond their σ (docs/conventions.md §4)"
    )

    def parameters(self, table: StopTable) -> tuple[str, ...]:
        return NAMES

    def initial(self, table: StopTable, g_mps2: float) -> FloatArray:
        return np.zeros(3)

    def apply(self, table: StopTable, values: FloatArray, p: FloatArray, g0_mps2: float) -> Any:
        return p + values, np.broadcast_to(np.eye(3), (len(p), 3, 3)), None

    def implausible(self, values: FloatArray, g_mps2: float) -> str | None:
        size_g = float(np.linalg.norm(values)) / g_mps2
        if size_g > MAX_BIAS_G:
            return (
                f"the fitted bias |b| = {size_g:.2f} g exceeds {MAX_BIAS_G:g} g: no accelerometer has such a bias "
                "(a negated axis or a wrong unit?)"
            )
        return None

    def correct(self, acc_s: FloatArray, reported: EffectValue) -> FloatArray:
        return acc_s - reported_vector(reported, 3)

    def restore(self, acc_s: FloatArray, reported: EffectValue) -> FloatArray:
        return acc_s + reported_vector(reported, 3)

    def spec_limits(self, spec: SensorSpec) -> dict[str, float]:
        return dict.fromkeys(NAMES, spec.bias_mps2)

    def summary(self, reported: EffectValue) -> str | None:
        if any(s is None for s in reported.sigma):
            return None
        b = ", ".join(f"{v:+.4f} ± {s:.4f}" for v, s in zip(reported.value, reported.sigma, strict=True))
        return f"bias   ({b}) m/s² (sensor x, y, z)"


EFFECT = Bias()
