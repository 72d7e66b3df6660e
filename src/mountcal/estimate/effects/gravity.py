"""Local gravity g, fitted (1 value, m/s²): the base force scaled by g / g₀.

Not a sensor error, so ``rotate`` leaves the samples as they are.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mountcal.core.conventions import FloatArray
from mountcal.core.result import EffectValue
from mountcal.estimate.effects.base import BaseEffect
from mountcal.stops.table import StopTable

EARTH_GRAVITY_MPS2 = (9.77, 9.835)  # normal gravity: 9.780 (equator) to 9.832 (poles) at sea level, less with height


class Gravity(BaseEffect):
    name = "gravity"
    meaning = "local gravity, fitted"
    order = 0
    report_key = "gravity_mps2"
    unit = "m/s²"
    kind = "site"
    gravity_index = 0

    def parameters(self, table: StopTable) -> tuple[str, ...]:
        return ("gravity",)

    def initial(self, table: StopTable, g_mps2: float) -> FloatArray:
        return np.array([g_mps2])

    def apply(self, table: StopTable, values: FloatArray, p: FloatArray, g0_mps2: float) -> Any:
        ratio = float(values[0]) / g0_mps2
        return p * ratio, (p / g0_mps2)[:, :, None], ratio * np.eye(3)

    def candidate(self, table: StopTable, gravity_known: bool) -> bool:
        return not gravity_known

    def covered_by(self) -> tuple[str, str] | None:
        return (
            "bias",
            "with the position unknown, an offset of |a| from standard gravity is a vertical bias as far as these "
            "stops can tell: the bias term covers it",
        )

    def implausible(self, values: FloatArray, g_mps2: float) -> str | None:
        g = float(values[0])
        if not EARTH_GRAVITY_MPS2[0] <= g <= EARTH_GRAVITY_MPS2[1]:
            return (
                f"the fitted g = {g:.4f} m/s² is outside Earth's range {EARTH_GRAVITY_MPS2[0]}–{EARTH_GRAVITY_MPS2[1]} "
                "m/s²: the offset is not gravity (a vertical bias or a scale error?)"
            )
        return None

    def components(self, names: tuple[str, ...]) -> tuple[str, ...]:
        return ("",)

    def summary(self, reported: EffectValue) -> str | None:
        return None  # the summary's gravity line says it, with its source


EFFECT = Gravity()
