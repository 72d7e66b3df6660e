"""A bias drift per °C k (3 values, m/s²/°C): ``p + k (T − T̄)``, T̄ the stops' mean temperature.

``rotate`` does not undo it: the samples carry no temperature to evaluate it at.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from mountcal.core.conventions import FloatArray
from mountcal.core.result import EffectValue
from mountcal.estimate.effects.base import BaseEffect
from mountcal.stops.table import TEMPERATURE, StopTable

if TYPE_CHECKING:
    from mountcal.io.sensor_spec import SensorSpec

NAMES = ("temp_x", "temp_y", "temp_z")
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
        return NAMES

    def initial(self, table: StopTable, g_mps2: float) -> FloatArray:
        return np.zeros(3)

    def apply(self, table: StopTable, values: FloatArray, p: FloatArray, g0_mps2: float) -> Any:
        t = table.temperature_c
        dt = np.zeros(len(p)) if t is None else t - t.mean()
        return p + np.outer(dt, values), dt[:, None, None] * np.eye(3), None

    def candidate(self, table: StopTable, gravity_known: bool) -> bool:
        t = table.temperature_c
        return t is not None and float(np.ptp(t)) >= MIN_TEMPERATURE_SPAN_C

    def unusable(self, table: StopTable) -> str | None:
        t = table.temperature_c
        span = float(np.ptp(t)) if t is not None else 0.0
        if t is None or span >= MIN_TEMPERATURE_SPAN_C:
            return None
        return (
            f"needs stops at different temperatures (a span of at least {MIN_TEMPERATURE_SPAN_C:g} °C), found a "
            f"span of {span:.3g} °C: a drift per °C cannot be measured"
        )

    def spec_limits(self, spec: SensorSpec) -> dict[str, float]:
        return dict.fromkeys(NAMES, spec.bias_tempco_mps2_per_c)

    def label(self, parameter: str) -> str:
        return "bias drift per °C"

    def covariate(self, table: StopTable) -> tuple[str, FloatArray] | None:
        if table.temperature_c is None or not np.ptp(table.temperature_c) > 0:
            return None
        t = table.temperature_c - table.temperature_c.mean()
        return "residual against temperature (drift, curvature)", np.column_stack([t, t**2 - np.mean(t**2)])

    def transfer(
        self, values: Mapping[str, FloatArray], fitted_on: StopTable, predict_on: StopTable
    ) -> dict[str, FloatArray]:
        """The offset it requires holds at the mean temperature of the stops fitted; a prediction of other stops
        uses theirs."""
        if self.name not in values or fitted_on.temperature_c is None or predict_on.temperature_c is None:
            return {}
        shift = float(np.mean(predict_on.temperature_c) - np.mean(fitted_on.temperature_c))
        offset = self.requires[0]
        return {offset: values[offset] + values[self.name] * shift}

    def summary(self, reported: EffectValue) -> str | None:
        return None  # not in the text summary (never was): the result's effects hold it


EFFECT = Temperature()
