"""Scale and cross-axis errors E (6 values, symmetric): ``(I + E) p``.

Its antisymmetric part would be a rotation, so E is symmetric. On one slope the Fisher information
of E with the tilt is singular (the stops lie on one cone); stops on two slopes of different
inclination make it full rank (docs/effects.md).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from mountcal.core.conventions import FloatArray
from mountcal.core.result import EffectValue
from mountcal.estimate.effects.base import BaseEffect
from mountcal.stops.table import StopTable

if TYPE_CHECKING:
    from mountcal.io.sensor_spec import SensorSpec

SCALE_NAMES = ("scale_xx", "scale_yy", "scale_zz", "cross_xy", "cross_xz", "cross_yz")


def scale_matrix(e: FloatArray) -> FloatArray:
    """I + E from E_xx, E_yy, E_zz, E_xy, E_xz, E_yz."""
    return np.eye(3) + np.array([[e[0], e[3], e[4]], [e[3], e[1], e[5]], [e[4], e[5], e[2]]], dtype=np.float64)


class Scale(BaseEffect):
    name = "scale"
    meaning = "scale and cross-axis errors, 6 values"
    order = 10
    report_key = "scale"
    unit = "1"

    def parameters(self, table: StopTable) -> tuple[str, ...]:
        return SCALE_NAMES

    def initial(self, table: StopTable, g_mps2: float) -> FloatArray:
        return np.zeros(6)

    def apply(self, table: StopTable, values: FloatArray, p: FloatArray, g0_mps2: float) -> Any:
        z = np.zeros(len(p))
        px, py, pz = p.T
        cols = [(px, z, z), (z, py, z), (z, z, pz), (py, px, z), (pz, z, px), (z, pz, py)]
        m = scale_matrix(values)
        return p @ m.T, np.stack([np.column_stack(c) for c in cols], axis=2), m

    def components(self, names: tuple[str, ...]) -> tuple[str, ...]:
        return names

    def spec_limits(self, spec: SensorSpec) -> dict[str, float]:
        return {n: spec.scale if n.startswith("scale_") else spec.cross_axis for n in SCALE_NAMES}

    def label(self, parameter: str) -> str:
        return "scale" if parameter.startswith("scale_") else "cross-axis"

    def summary(self, reported: EffectValue) -> str | None:
        return None  # not in the text summary (never was): the result's effects hold it

    def correct(self, acc_s: FloatArray, reported: EffectValue) -> FloatArray:
        return np.asarray(np.linalg.solve(self._matrix(reported), acc_s.T).T)

    def restore(self, acc_s: FloatArray, reported: EffectValue) -> FloatArray:
        return np.asarray(acc_s @ self._matrix(reported).T)

    @staticmethod
    def _matrix(reported: EffectValue) -> FloatArray:
        given = dict(zip(reported.components, reported.value, strict=False))
        if set(given) != set(SCALE_NAMES):
            raise ValueError(f"effects scale must hold {', '.join(SCALE_NAMES)}, found {', '.join(given)}")
        e = np.array([given[n] for n in SCALE_NAMES], dtype=float)
        m = scale_matrix(e)
        if not np.all(np.isfinite(m)) or abs(np.linalg.det(m)) < 0.5:
            raise ValueError(f"effects.scale gives a singular or non-finite scale matrix {m.tolist()}")
        return m


EFFECT = Scale()
