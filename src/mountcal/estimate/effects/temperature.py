"""A bias drift per °C k (3 values, m/s²/°C): ``p + k (T − T̄)``, T̄ the stops' mean temperature.

``rotate`` does not undo it: the samples carry no temperature to evaluate it at.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mountcal.core.conventions import FloatArray
from mountcal.estimate.effects.base import BaseEffect
from mountcal.stops.table import TEMPERATURE, StopTable

MIN_TEMPERATURE_SPAN_C = 2.0


class Temperature(BaseEffect):
    name = "temperature"
    meaning = "a bias drift per °C, 3 values"
    needs = (TEMPERATURE,)
    order = 20
    requires = ("bias",)  # a bias that drifts with temperature has an offset too
    report_key = "temperature_mps2_per_c"
    unit = "m/s²/°C"

    def parameters(self, table: StopTable) -> tuple[str, ...]:
        return ("temp_x", "temp_y", "temp_z")

    def initial(self, table: StopTable, g_mps2: float) -> FloatArray:
        return np.zeros(3)

    def apply(self, table: StopTable, values: FloatArray, p: FloatArray, g0_mps2: float) -> Any:
        t = table.temperature_c
        dt = np.zeros(len(p)) if t is None else t - t.mean()
        return p + np.outer(dt, values), dt[:, None, None] * np.eye(3), None

    def candidate(self, table: StopTable, gravity_known: bool) -> bool:
        t = table.temperature_c
        return t is not None and float(np.ptp(t)) >= MIN_TEMPERATURE_SPAN_C


EFFECT = Temperature()
