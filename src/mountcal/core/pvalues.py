"""Tail probabilities of the χ² and F distributions, from ``scipy.special``.

The same values as ``scipy.stats.chi2.sf`` / ``logsf`` / ``isf`` and ``scipy.stats.f.sf`` / ``logsf`` (which
evaluate these functions too), without importing ``scipy.stats``: that import alone costs about
0.4 s, paid by every command and by every fleet worker server at start-up.

Where the probability underflows (below ~1e-308) scipy's log is −inf; a written result must hold
finite numbers, so there the log tail comes from the continued fractions of the incomplete gamma
and beta functions, evaluated in log space (Numerical Recipes §6.2, §6.4).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from scipy import special

if TYPE_CHECKING:
    from mountcal.core.findings import Finding

FAMILY_ALPHA = 0.01  # all tests together flag a fit that explains the stops with at most this probability


def chi2_sf(x: Any, dof: Any) -> Any:
    """P(χ²(dof) > x)."""
    return special.chdtrc(dof, np.maximum(x, 0.0))


def chi2_isf(p: Any, dof: Any) -> Any:
    """The x with P(χ²(dof) > x) = p: the threshold a χ² statistic is tested against."""
    return special.chdtri(dof, p)


def chi2_logsf(x: Any, dof: Any) -> Any:
    """log P(χ²(dof) > x), finite where the probability underflows."""
    x = np.maximum(x, 0.0)
    out = _log_tail(special.chdtrc(dof, x), special.chdtr(dof, x))
    return _refine(out, lambda xi, d: _log_upper_gamma(d / 2.0, xi / 2.0), x, dof)


def f_sf(x: Any, dfn: Any, dfd: Any) -> Any:
    """P(F(dfn, dfd) > x)."""
    return special.fdtrc(dfn, dfd, np.maximum(x, 0.0))


def f_logsf(x: Any, dfn: Any, dfd: Any) -> Any:
    """log P(F(dfn, dfd) > x), finite where the probability underflows."""
    x = np.maximum(x, 0.0)
    out = _log_tail(special.fdtrc(dfn, dfd, x), special.fdtr(dfn, dfd, x))
    # P(F > x) = I_z(dfd/2, dfn/2) with z = dfd / (dfd + dfn·x)
    return _refine(out, lambda xi, m, d: _log_beta_lower(d / 2.0, m / 2.0, d / (d + m * xi)), x, dfn, dfd)


def nested_test(small_chi2: float, big_chi2: float, extra: int, noise_known: bool, big_dof: int) -> tuple[float, str]:
    """log p and its description for ``extra`` more parameters: the likelihood ratio χ²(extra) when the
    noise is known, the F-test when it was estimated from the residuals (the one test of nested models)."""
    if noise_known:
        stat = max(small_chi2 - big_chi2, 0.0)
        return float(chi2_logsf(stat, extra)), f"likelihood ratio χ²({extra}) = {stat:.1f}"
    dof = max(big_dof, 1)
    f_stat = ((small_chi2 - big_chi2) / extra) / (big_chi2 / dof)
    return float(f_logsf(max(f_stat, 0.0), extra, dof)), f"F({extra}, {big_dof}) = {f_stat:.2f}"


def _log_tail(sf: Any, cdf: Any) -> Any:
    """log(sf), from log1p(−cdf) where sf is near 1 (more accurate there), −inf where sf is 0."""
    with np.errstate(divide="ignore"):
        out = np.where(sf > 0.5, np.log1p(-cdf), np.log(sf))
    return out[()] if out.ndim == 0 else out


def _refine(out: Any, log_tail: Any, x: Any, *dofs: Any) -> Any:
    """Replace the −inf entries of ``out`` (underflowed tails) by ``log_tail(x, *dofs)``."""
    arr = np.array(out, dtype=float, ndmin=1)
    bad = np.flatnonzero(np.isneginf(arr))
    if bad.size:
        args = np.broadcast_arrays(
            np.array(x, dtype=float, ndmin=1), *(np.array(d, dtype=float, ndmin=1) for d in dofs)
        )
        arr = np.broadcast_to(arr, args[0].shape).copy()
        bad = np.flatnonzero(np.isneginf(arr))
        for i in bad:  # only the few underflowed entries: a scalar loop is fine
            arr[i] = log_tail(*(float(a.flat[i]) for a in args))
    return arr[0] if np.ndim(out) == 0 else arr.reshape(np.shape(out) or arr.shape)


def _log_upper_gamma(a: float, x: float) -> float:
    """log Q(a, x), the regularised upper incomplete gamma, by its continued fraction (x > a + 1)."""
    tiny = 1e-300
    b = x + 1.0 - a
    c, d = 1.0 / tiny, 1.0 / b
    h = d
    for i in range(1, 10_000):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        d = tiny if abs(d) < tiny else d
        c = b + an / c
        c = tiny if abs(c) < tiny else c
        d = 1.0 / d
        h *= d * c
        if abs(d * c - 1.0) < 1e-15:
            break
    return float(-x + a * np.log(x) - special.gammaln(a) + np.log(h))


def _log_beta_lower(a: float, b: float, z: float) -> float:
    """log I_z(a, b), the regularised incomplete beta, by its continued fraction (z < (a+1)/(a+b+2))."""
    tiny = 1e-300
    qab, qap, qam = a + b, a + 1.0, a - 1.0
    c, d = 1.0, 1.0 - qab * z / qap
    d = 1.0 / (tiny if abs(d) < tiny else d)
    h = d
    for m in range(1, 10_000):
        m2 = 2 * m
        for aa in (m * (b - m) * z / ((qam + m2) * (a + m2)), -(a + m) * (qab + m) * z / ((a + m2) * (qap + m2))):
            d = 1.0 + aa * d
            d = 1.0 / (tiny if abs(d) < tiny else d)
            c = 1.0 + aa / c
            c = tiny if abs(c) < tiny else c
            h *= d * c
        if abs(d * c - 1.0) < 1e-15:
            break
    return float(a * np.log(z) + b * np.log1p(-z) - np.log(a) - special.betaln(a, b) + np.log(h))


def unexplained(findings: list[Finding], alpha: float = FAMILY_ALPHA) -> list[Finding]:
    """The findings Holm's step-down procedure rejects: all tests together flag a clean fit with probability ≤ α."""
    tested = sorted((f for f in findings if f.p_value is not None), key=lambda f: f.p_value or 0.0)
    out = []
    for j, f in enumerate(tested):
        if (f.p_value or 0.0) > alpha / (len(tested) - j):
            break
        out.append(f)
    return out


__all__ = ["FAMILY_ALPHA", "chi2_logsf", "chi2_sf", "f_logsf", "f_sf", "nested_test", "unexplained"]
