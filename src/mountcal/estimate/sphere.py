"""Multi-position sensor calibration: bias, scale and cross-axis from static stops in many orientations.

When the stops point gravity along many sensor directions (the six-position test, a hand-held
session) the mounting is not the question: each stop has its own orientation and only its
magnitude is known. The model (docs/conventions.md §6, the M matrix) is

    | (I + E)⁻¹ (a_i − b) | = g,   E symmetric (its antisymmetric part is a rotation),

with terms ``bias`` (b), ``scale`` (E's diagonal) and ``cross_axis`` (E's off-diagonal). Unlike a
vehicle parked on one slope, these data separate all nine parameters; :func:`loop` adds them in
turn and keeps each one only when the likelihood ratio calls for it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import optimize

from mountcal.core.conventions import FloatArray
from mountcal.core.pvalues import chi2_sf, f_sf

TERMS = ("bias", "scale", "cross_axis")
PLAUSIBLE = {"bias": 1.0, "scale": 0.05, "cross_axis": 0.05}  # a 1σ beyond these means "not determined"


@dataclass(frozen=True)
class SphereFit:
    """One fit: parameter names, values, covariance, and the per-stop magnitude residual (m/s²)."""

    terms: tuple[str, ...]
    names: tuple[str, ...]
    values: FloatArray
    cov: FloatArray
    chi2: float
    dof: int
    residual_mps2: FloatArray  # shape (n,): |(I+E)⁻¹(a − b)| − g

    def bias(self) -> FloatArray:
        return _unpack(self.values, self.terms)[0]

    def scale_matrix(self) -> FloatArray:
        return _unpack(self.values, self.terms)[1]

    def sigma(self) -> FloatArray:
        return np.sqrt(np.clip(np.diag(self.cov), 0, None))

    def correct(self, acc_s: FloatArray) -> FloatArray:
        """Apply the calibration: (I + E)⁻¹ (a − b), shape (n, 3)."""
        return (acc_s - self.bias()) @ np.linalg.inv(self.scale_matrix()).T


def _names(terms: tuple[str, ...]) -> tuple[str, ...]:
    out: list[str] = []
    if "bias" in terms:
        out += ["bias_x", "bias_y", "bias_z"]
    if "scale" in terms:
        out += ["scale_x", "scale_y", "scale_z"]
    if "cross_axis" in terms:
        out += ["cross_xy", "cross_xz", "cross_yz"]
    return tuple(out)


def _unpack(x: FloatArray, terms: tuple[str, ...]) -> tuple[FloatArray, FloatArray]:
    i = 0
    b = np.zeros(3)
    e = np.zeros((3, 3))
    if "bias" in terms:
        b, i = x[i : i + 3], i + 3
    if "scale" in terms:
        e[np.diag_indices(3)] = x[i : i + 3]
        i += 3
    if "cross_axis" in terms:
        xy, xz, yz = x[i : i + 3]
        e[0, 1] = e[1, 0] = xy
        e[0, 2] = e[2, 0] = xz
        e[1, 2] = e[2, 1] = yz
    return b, np.eye(3) + e


def fit(
    acc_s: FloatArray,
    g_mps2: float,
    terms: tuple[str, ...],
    cov_s: FloatArray | None = None,
    start: FloatArray | None = None,
) -> SphereFit:
    """Maximum likelihood of the magnitude model (first order in the noise along each stop's direction)."""
    names = _names(terms)
    n = acc_s.shape[0]
    sigma = np.ones(n)
    if cov_s is not None:
        u = acc_s / np.linalg.norm(acc_s, axis=1)[:, None]
        sigma = np.sqrt(np.einsum("ni,nij,nj->n", u, cov_s, u))

    def residual(x: FloatArray) -> FloatArray:
        b, m = _unpack(x, terms)
        corrected = np.linalg.solve(m, (acc_s - b).T).T
        return np.asarray((np.linalg.norm(corrected, axis=1) - g_mps2) / sigma, dtype=np.float64)

    x0 = np.zeros(len(names)) if start is None else start
    if names:
        sol = optimize.least_squares(residual, x0, method="lm", xtol=1e-14, ftol=1e-14, gtol=1e-14)
        x, jac = sol.x, sol.jac
    else:
        x, jac = np.zeros(0), np.zeros((n, 0))
    r = residual(x)
    chi2 = float(r @ r)
    dof = n - len(names)
    scale2 = 1.0 if cov_s is not None else (chi2 / dof if dof > 0 else np.nan)
    cov = np.linalg.pinv(jac.T @ jac) * scale2 if names else np.zeros((0, 0))
    return SphereFit(terms, names, x, cov, chi2, dof, r * sigma)


def loop(
    acc_s: FloatArray, g_mps2: float, cov_s: FloatArray | None = None, alpha: float = 0.001
) -> list[tuple[SphereFit, str]]:
    """Nested steps: nothing → bias → + scale → + cross-axis, each kept only if it passes at ``alpha``."""
    steps = [(fit(acc_s, g_mps2, (), cov_s), "start: the raw sensor (no correction)")]
    for term in TERMS:
        cur = steps[-1][0]
        terms = (*cur.terms, term)
        if acc_s.shape[0] - len(_names(terms)) < 1:
            break
        start = np.concatenate([cur.values, np.zeros(3)])
        new = fit(acc_s, g_mps2, terms, cov_s, start)
        extra = len(new.names) - len(cur.names)
        if cov_s is not None:
            stat = max(cur.chi2 - new.chi2, 0.0)
            p = float(chi2_sf(stat, extra))
            test = f"likelihood ratio χ²({extra}) = {stat:.1f}, p = {p:.3g}"
        else:
            f_stat = ((cur.chi2 - new.chi2) / extra) / (new.chi2 / max(new.dof, 1))
            p = float(f_sf(f_stat, extra, max(new.dof, 1)))
            test = f"F({extra}, {new.dof}) = {f_stat:.2f}, p = {p:.3g}"
        if p >= alpha:
            break
        sig = new.sigma()[len(cur.names) :]
        if new.dof < 3 or np.any(sig > PLAUSIBLE[term]):
            steps.append(
                (cur, f"{term} declined: not separable with these stops (1σ up to {sig.max():.3g}; {new.dof} dof left)")
            )
            break
        steps.append((new, f"{term}: {test}"))
    return steps


def summary(f: SphereFit) -> dict[str, Any]:
    """Values ± σ by name, and the fit quality (JSON-ready)."""
    s = f.sigma()
    return {
        "terms": list(f.terms),
        "values": {n: {"value": float(v), "sigma": float(e)} for n, v, e in zip(f.names, f.values, s, strict=True)},
        "chi2": f.chi2,
        "dof": f.dof,
        "residual_rms_mps2": float(np.sqrt(np.mean(f.residual_mps2**2))),
    }
