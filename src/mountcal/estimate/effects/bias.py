"""A constant accelerometer bias b (3 values, m/s², sensor frame): ``p + b``."""

from __future__ import annotations

from typing import Any

import numpy as np

from mountcal.core.conventions import FloatArray
from mountcal.core.result import EffectValue
from mountcal.estimate.effects.base import BaseEffect, reported_vector
from mountcal.stops.table import StopTable

MAX_BIAS_G = 0.5  # an offset this large is not an accelerometer bias (consumer MEMS: < 0.1 g) but a sign or unit error


class Bias(BaseEffect):
    name = "bias"
    meaning = "a constant accelerometer bias, 3 values"
    order = 20
    report_key = "bias_mps2"
    unit = "m/s²"

    def parameters(self, table: StopTable) -> tuple[str, ...]:
        return ("bias_x", "bias_y", "bias_z")

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


EFFECT = Bias()
