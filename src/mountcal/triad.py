"""A triad calibration (bias, scale, cross-axis with their covariance), applied to stops before the mounting fit.

It comes from a multi-position session fitted by :mod:`mountcal.estimate.sphere` (``mountcal
triad``), saved as a ``mountcal.triad`` JSON. The correction is the sphere model's
``a ← (I + E)⁻¹ (a − b)``; what remains uncertain of b and E (their covariance) is a systematic
error common to every stop, which :mod:`mountcal.systematic` carries into the angles in place of
the datasheet's scale, cross-axis and bias limits.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from mountcal.atomic import atomic_path
from mountcal.conventions import FloatArray
from mountcal.errors import InputError
from mountcal.estimate import sphere
from mountcal.estimate.effects.scale import SCALE_NAMES
from mountcal.result_file import read_json
from mountcal.sensor_spec import SensorSpec
from mountcal.stoptable import StopTable
from mountcal.systematic import BIAS_NAMES, TEMP_NAMES, SensorErrors, from_spec

FORMAT = "mountcal.triad"
FORMAT_VERSION = 1
# The sphere fit's parameter order (bias, scale, cross-axis), in the static model's names.
NAMES = BIAS_NAMES + SCALE_NAMES


@dataclass(frozen=True)
class Triad:
    """b (m/s², sensor frame), E (xx, yy, zz, xy, xz, yz) and their 9×9 covariance in the order of ``NAMES``."""

    bias_mps2: FloatArray
    scale_e: FloatArray
    cov: FloatArray  # rows and columns of names not in ``fitted`` are zero
    source: str
    fitted: tuple[str, ...] = NAMES  # what the session determined; the others keep the sensor spec's limits

    @property
    def matrix(self) -> FloatArray:
        """I + E."""
        e = self.scale_e
        return np.eye(3) + np.array([[e[0], e[3], e[4]], [e[3], e[1], e[5]], [e[4], e[5], e[2]]])

    def correct(self, table: StopTable) -> StopTable:
        """The stops as the calibrated sensor reads them, ``(I + E)⁻¹ (a − b)``, their covariance mapped alike."""
        inv = np.linalg.inv(self.matrix)
        cov = None if table.cov_s is None else np.einsum("ij,njk,lk->nil", inv, table.cov_s, inv)
        return replace(table, acc_s=(table.acc_s - self.bias_mps2) @ inv.T, cov_s=cov)

    def errors(self, spec: SensorSpec) -> SensorErrors:
        """What remains uncertain after the correction: the triad's covariance, and the spec's bias drift per °C."""
        cov = np.zeros((12, 12))
        cov[:9, :9] = self.cov
        spec_u2 = from_spec(spec)  # names BIAS, TEMP, SCALE: the datasheet's rectangular variances
        for i, name in enumerate(NAMES):
            if name not in self.fitted:
                j = spec_u2.names.index(name)
                cov[i, i] = spec_u2.cov[j, j]
        cov[9:, 9:] = np.eye(3) * spec.bias_tempco_mps2_per_c**2 / 3.0
        sigma = np.sqrt(np.diag(self.cov))
        limits = {
            "source": f"triad calibration {self.source}",
            "triad_sigma": {n: float(s) for n, s in zip(NAMES, sigma, strict=True) if n in self.fitted},
            "from_spec": {n: float(np.sqrt(cov[i, i])) for i, n in enumerate(NAMES) if n not in self.fitted},
            "bias_tempco_mps2_per_c": spec.bias_tempco_mps2_per_c,
        }
        return SensorErrors(NAMES + TEMP_NAMES, cov, f"triad calibration {self.source}", limits)

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "format_version": FORMAT_VERSION,
            "source": self.source,
            "model": "a_calibrated = (I + E)^-1 (a_raw - b), E symmetric",
            "names": list(NAMES),
            "fitted": list(self.fitted),
            "values": [*map(float, self.bias_mps2), *map(float, self.scale_e)],
            "covariance": self.cov.tolist(),
        }

    def save(self, path: str | Path) -> None:
        with atomic_path(path) as tmp:
            tmp.write_text(json.dumps(self.to_dict(), indent=2, allow_nan=False) + "\n", encoding="utf-8")


def from_sphere(fit: sphere.SphereFit, source: str) -> Triad:
    """A triad from a sphere fit (of bias and scale, or of all three terms)."""
    values, cov = np.zeros(9), np.zeros((9, 9))
    idx = [_SPHERE_TO_MODEL[n] for n in fit.names]
    values[idx] = fit.values
    cov[np.ix_(idx, idx)] = fit.cov
    return Triad(values[:3], values[3:], cov, source, tuple(NAMES[i] for i in idx))


# sphere.py names → positions in NAMES (bias_x…, scale_xx…, cross_xy…)
_SPHERE_TO_MODEL = {
    **{f"bias_{a}": i for i, a in enumerate("xyz")},
    **{f"scale_{a}": 3 + i for i, a in enumerate("xyz")},
    **{f"cross_{p}": 6 + i for i, p in enumerate(("xy", "xz", "yz"))},
}


def load(path: str | Path) -> Triad:
    """Read a ``mountcal.triad`` JSON; anything else, or an unusable value, is refused naming the file."""
    doc = read_json(Path(path))
    todo = "Pass a file written by `mountcal triad -o` (an imucal JSON first goes through `mountcal triad`)."
    if not isinstance(doc, dict) or doc.get("format") != FORMAT or doc.get("format_version") != FORMAT_VERSION:
        found = doc.get("cal_type", doc.get("format")) if isinstance(doc, dict) else type(doc).__name__
        raise InputError(str(path), f"a {FORMAT} JSON, version {FORMAT_VERSION}", repr(found), todo)
    try:
        values = np.asarray(doc["values"], dtype=float)
        cov = np.asarray(doc["covariance"], dtype=float)
        fitted = tuple(str(n) for n in doc.get("fitted", NAMES))
        ok = set(fitted) <= set(NAMES)
        ok = (
            values.shape == (9,)
            and cov.shape == (9, 9)
            and bool(np.all(np.isfinite(values)) and np.all(np.isfinite(cov)))
        )
        ok = ok and bool(np.allclose(cov, cov.T)) and bool(np.all(np.linalg.eigvalsh(cov) > -1e-12 * cov.max()))
        ok = ok and bool(np.all(np.abs(values[3:]) < 0.5))
    except (KeyError, TypeError, ValueError):
        ok = False
    if not ok:
        raise InputError(str(path), "9 finite values (|E| < 0.5) and a symmetric 9×9 covariance", "other values", todo)
    return Triad(values[:3], values[3:], cov, str(doc.get("source", path)), fitted)
