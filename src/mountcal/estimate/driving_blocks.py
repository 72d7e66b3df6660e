"""The driving checks' statistics: the intervals summed into units (:class:`Sums`), cue estimates from any subset
of them with a block-jackknife σ (:func:`estimate`, :func:`jackknife`), two estimates compared (:func:`compare`),
and the estimates of the log's parts (:func:`part_yaws`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from mountcal.core.conventions import FloatArray
from mountcal.core.driving_document import (
    Comparison,
    Estimate,
    Parts,
)
from mountcal.core.findings import Finding
from mountcal.core.pvalues import chi2_sf
from mountcal.estimate.driving_intervals import (
    IntArray,
    Intervals,
    yaw_from_sums,
)

if TYPE_CHECKING:
    pass


MIN_BLOCKS = 5  # blocks of units per side of a comparison: fewer give no σ worth a test


MAX_BLOCKS = 20


MIN_UNIT = 3  # intervals


PARTS = 4


def sum_units(unit: IntArray, values: FloatArray, n: int) -> FloatArray:
    """Σ ``values`` per unit (n units)."""
    return np.bincount(unit, values, n).astype(np.float64)


def units(iv: Intervals) -> IntArray:
    """The units the σ are built from: the segments, cut into pieces of at most so many consecutive intervals that a
    drive holds about ``4 × MAX_BLOCKS`` of them (never fewer than ``MIN_UNIT`` intervals), so that a short drive
    (a minute on a highway: three segments) still gives each half its blocks."""
    seg = iv.segment
    if seg.size == 0:
        return seg
    length = max(MIN_UNIT, int(np.ceil(seg.size / (4 * MAX_BLOCKS))))
    start = np.concatenate([[0], np.flatnonzero(np.diff(seg)) + 1])
    first = np.repeat(start, np.diff(np.concatenate([start, [seg.size]])))
    piece = (np.arange(seg.size) - first) // length
    new = np.concatenate([[True], (np.diff(seg) != 0) | (np.diff(piece) != 0)])
    return np.asarray(np.cumsum(new) - 1, dtype=np.int64)


def mean_times(unit: IntArray, t: FloatArray, n: int) -> FloatArray:
    return sum_units(unit, t, n) / np.maximum(np.bincount(unit, minlength=n), 1)


@dataclass(frozen=True)
class Sums:
    """Per-unit sums ``Σ w·x, Σ w·y, Σ w·c`` of an estimating equation, each unit's mean time and count."""

    a: FloatArray
    b: FloatArray
    c: FloatArray
    t_s: FloatArray
    count: FloatArray

    @classmethod
    def of(cls, unit: IntArray, t: FloatArray, w: FloatArray, x: FloatArray, y: FloatArray, c: FloatArray) -> Sums:
        n = int(unit.max()) + 1 if unit.size else 0
        return cls(
            sum_units(unit, w * x, n),
            sum_units(unit, w * y, n),
            sum_units(unit, w * c, n),
            mean_times(unit, t, n),
            np.bincount(unit, minlength=n).astype(float),
        )

    def every(self) -> np.ndarray:
        return np.ones(self.count.size, dtype=bool)


def longitudinal(a_x: float, a_y: float, c: float) -> float:
    """Yaw of the longitudinal equation ``Σ a·((Rz(yaw)·u)_y − v·ω) = 0`` from its sums."""
    return yaw_from_sums(a_x, a_y, c)[0]


def lateral(a_x: float, a_y: float, c: float) -> float:
    """Yaw of the lateral equation ``Σ v·ω·((Rz(yaw)·u)_x − s·a) = 0`` from its sums: ``r·cos(yaw + β) = C`` on the
    branch where the IMU follows ``v·ω`` (``r·sin(yaw + β) > 0``)."""
    r = float(np.hypot(a_x, a_y))
    phase = float(np.arccos(np.clip(c / r, -1.0, 1.0))) if r > 0 else 0.0
    return float(np.angle(np.exp(1j * (phase - np.arctan2(a_y, a_x)))))


Solve = Callable[[float, float, float], float]


def time_blocks(idx: np.ndarray, t_s: FloatArray) -> list[np.ndarray]:
    """``idx`` in time order, split into at most MAX_BLOCKS runs of consecutive units."""
    idx = idx[np.argsort(t_s[idx], kind="stable")]
    return [b for b in np.array_split(idx, min(idx.size, MAX_BLOCKS)) if b.size]


def estimate(sums: Sums, mask: np.ndarray, solve: Solve, inflate: float = 1.0) -> Estimate | None:
    """The yaw (deg) of the units in ``mask`` and its jackknife σ over blocks of consecutive units (× ``inflate``)."""
    idx = np.flatnonzero(mask & (sums.count > 0))
    if idx.size == 0:
        return None
    total = [float(x[idx].sum()) for x in (sums.a, sums.b, sums.c)]
    if np.hypot(total[0], total[1]) == 0:
        return None
    value = solve(*total)
    blocks = time_blocks(idx, sums.t_s)
    if len(blocks) < MIN_BLOCKS:
        return Estimate(float(np.degrees(value)), None, len(blocks))
    parts = [(sums.a, total[0]), (sums.b, total[1]), (sums.c, total[2])]
    loo = np.array([solve(*(tot - float(x[b].sum()) for x, tot in parts)) for b in blocks])
    d = np.angle(np.exp(1j * (loo - value)))
    k = len(blocks)
    sigma = float(np.sqrt((k - 1) / k * np.sum((d - d.mean()) ** 2))) * inflate
    return Estimate(float(np.degrees(value)), float(np.degrees(sigma)), k)


def jackknife(values: FloatArray, weights: FloatArray, t_s: FloatArray, mask: np.ndarray) -> Estimate | None:
    """The weighted mean of per-unit ``values`` over ``mask`` and its jackknife σ over blocks of units."""
    idx = np.flatnonzero(mask & (weights > 0))
    if idx.size == 0:
        return None
    value = float(weights[idx] @ values[idx] / weights[idx].sum())
    blocks = time_blocks(idx, t_s)
    if len(blocks) < MIN_BLOCKS:
        return Estimate(value, None, len(blocks))
    loo = []
    for b in blocks:
        rest = np.setdiff1d(idx, b)
        loo.append(float(weights[rest] @ values[rest] / weights[rest].sum()))
    arr = np.asarray(loo)
    k = len(blocks)
    return Estimate(value, float(np.sqrt((k - 1) / k * np.sum((arr - arr.mean()) ** 2))), k)


def compare(test: str, what: str, one: Estimate | None, two: Estimate | None, unit: str = "deg") -> Comparison:
    """The z-test of two estimates of one quantity, or the reason there is none."""
    if one is None or two is None or one.sigma is None or two.sigma is None:
        blocks = [e.blocks for e in (one, two) if e is not None]
        why = f"no test: each side needs {MIN_BLOCKS} blocks of consecutive straight driving (has {blocks or 'none'})"
        return Comparison(test, what, unit, one, two, None, None, None, why)
    diff = one.value - two.value
    diff = wrap_deg(diff) if unit == "deg" else diff
    sigma = float(np.hypot(one.sigma, two.sigma))
    z = diff / sigma if sigma > 0 else float("inf")
    return Comparison(test, what, unit, one, two, diff, float(z), float(chi2_sf(z * z, 1)))


def comparison_finding(c: Comparison) -> Finding:
    """The comparison as a test of the family (a z-score: no dof)."""
    if c.z is None or c.p_value is None or c.one is None or c.two is None:
        return Finding(c.test, c.what, c.reason or "no test", None, None, None, None, c.reason)
    u = "°" if c.unit == "deg" else f" {c.unit}"
    size = (
        f"{c.one.value:.4g}{u} ± {c.one.sigma:.2g}{u} against {c.two.value:.4g}{u} ± {c.two.sigma:.2g}{u}: "
        f"{c.difference:+.3g}{u}"
    )
    return Finding(c.test, c.what, size, c.z, None, c.p_value, float(np.log10(max(c.p_value, 1e-300))))


def wrap_deg(d: float) -> float:
    return float((d + 180.0) % 360.0 - 180.0)


def half_mask(sums: Sums) -> np.ndarray:
    """Units of the first half in time (the split where half the intervals lie on each side)."""
    order = np.argsort(sums.t_s, kind="stable")
    cum = np.cumsum(sums.count[order])
    first = np.zeros(sums.count.size, dtype=bool)
    first[order[cum <= 0.5 * cum[-1]]] = True
    return first


def part_yaws(sums: Sums, inflate: float) -> Parts:
    """Yaw of PARTS consecutive parts (equal numbers of intervals) against their weighted mean."""
    order = np.argsort(sums.t_s, kind="stable")
    cum = np.cumsum(sums.count[order]) / max(float(sums.count.sum()), 1.0)
    label = np.empty(order.size, dtype=int)
    label[order] = np.minimum((cum * PARTS - 1e-9).astype(int), PARTS - 1)
    found = tuple(estimate(sums, label == k, longitudinal, inflate) for k in range(PARTS))
    ok = [e for e in found if e is not None and e.sigma]
    if len(ok) < 2:
        return Parts(found, None, None, None, None, f"no test: fewer than two parts with {MIN_BLOCKS} blocks")
    v = np.array([e.value for e in ok])
    v = v[0] + (v - v[0] + 180.0) % 360.0 - 180.0
    w = 1.0 / np.array([e.sigma for e in ok], dtype=float) ** 2
    mean = float(w @ v / w.sum())
    chi2 = float(np.sum(w * (v - mean) ** 2))
    return Parts(found, chi2, len(ok) - 1, float(chi2_sf(chi2, len(ok) - 1)), float(np.ptp(v)))


def parts_finding(parts: Parts) -> Finding:
    what = f"yaw of {PARTS} consecutive parts of the drive"
    if parts.chi2 is None or parts.p_value is None or parts.dof is None:
        return Finding("driving_parts", what, parts.reason or "no test", None, None, None, None, parts.reason)
    size = f"spread {parts.spread_deg:.3g}° over {parts.dof + 1} parts, χ²({parts.dof}) = {parts.chi2:.3g}"
    return Finding(
        "driving_parts", what, size, parts.chi2, parts.dof, parts.p_value, np.log10(max(parts.p_value, 1e-300))
    )


def widened(e: Estimate | None, sigma: float) -> Estimate | None:
    if e is None or e.sigma is None or sigma == 0:
        return e
    return Estimate(e.value, float(np.hypot(e.sigma, sigma)), e.blocks)


__all__ = [
    "MAX_BLOCKS",
    "MIN_BLOCKS",
    "MIN_UNIT",
    "PARTS",
    "Solve",
    "Sums",
    "compare",
    "comparison_finding",
    "estimate",
    "half_mask",
    "jackknife",
    "lateral",
    "longitudinal",
    "mean_times",
    "part_yaws",
    "parts_finding",
    "sum_units",
    "time_blocks",
    "units",
    "widened",
    "wrap_deg",
]
