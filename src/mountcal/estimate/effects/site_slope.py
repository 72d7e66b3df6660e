"""One slope per site (the ``site`` column): the base force's α taken per site instead of one for all.

It changes how the static model parameterises the slope (:mod:`mountcal.estimate.full` gives each
site its own ``slope_<site>``), so it adds nothing to the chain itself.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mountcal.core.conventions import FloatArray
from mountcal.core.result import EffectValue
from mountcal.estimate.effects.base import BaseEffect
from mountcal.stops.table import SITE, StopTable


class SiteSlope(BaseEffect):
    name = "site_slope"
    meaning = "one slope per site"
    needs = (SITE,)
    order = 0
    report_key = "site_slope_deg"
    unit = "°"
    kind = "site"
    slope_per_site = True

    def parameters(self, table: StopTable) -> tuple[str, ...]:
        return ()

    def initial(self, table: StopTable, g_mps2: float) -> FloatArray:
        return np.zeros(0)

    def apply(self, table: StopTable, values: FloatArray, p: FloatArray, g0_mps2: float) -> Any:
        return p, np.zeros((len(p), 3, 0)), None

    def candidate(self, table: StopTable, gravity_known: bool) -> bool:
        return table.site is not None and np.unique(table.site).size > 1

    def unusable(self, table: StopTable) -> str | None:
        if table.site is None or np.unique(table.site).size >= 2:
            return None
        return "needs stops at two or more sites, found one"

    def summary(self, reported: EffectValue) -> str | None:
        return None  # not in the text summary (never was): the result's effects hold it

    def extra(self, table: StopTable) -> int:
        return len(np.unique(table.site)) - 1 if table.site is not None else 0

    def report(self, values: FloatArray, sigma: FloatArray, names: tuple[str, ...]) -> EffectValue:
        """``values``: the per-site slopes ``slope_<site>`` (rad), reported in degrees per site."""
        return super().report(np.degrees(values), np.degrees(sigma), names)

    def components(self, names: tuple[str, ...]) -> tuple[str, ...]:
        return tuple(n.removeprefix("slope_") for n in names)


EFFECT = SiteSlope()
