"""Tail probabilities of the χ² and F distributions, from ``scipy.special``.

The same values as ``scipy.stats.chi2.sf`` / ``logsf`` and ``scipy.stats.f.sf`` / ``logsf`` (which
evaluate these functions too), without importing ``scipy.stats``: that import alone costs about
0.4 s, paid by every command and by every fleet worker server at start-up.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import special


def chi2_sf(x: Any, dof: Any) -> Any:
    """P(χ²(dof) > x)."""
    return special.chdtrc(dof, np.maximum(x, 0.0))


def chi2_logsf(x: Any, dof: Any) -> Any:
    """log P(χ²(dof) > x); −inf where the probability underflows."""
    x = np.maximum(x, 0.0)
    return _log_tail(special.chdtrc(dof, x), special.chdtr(dof, x))


def f_sf(x: Any, dfn: Any, dfd: Any) -> Any:
    """P(F(dfn, dfd) > x)."""
    return special.fdtrc(dfn, dfd, np.maximum(x, 0.0))


def f_logsf(x: Any, dfn: Any, dfd: Any) -> Any:
    """log P(F(dfn, dfd) > x); −inf where the probability underflows."""
    x = np.maximum(x, 0.0)
    return _log_tail(special.fdtrc(dfn, dfd, x), special.fdtr(dfn, dfd, x))


def _log_tail(sf: Any, cdf: Any) -> Any:
    """log(sf), from log1p(−cdf) where sf is near 1 (more accurate there), −inf where sf is 0."""
    with np.errstate(divide="ignore"):
        out = np.where(sf > 0.5, np.log1p(-cdf), np.log(sf))
    return out[()] if out.ndim == 0 else out


__all__ = ["chi2_logsf", "chi2_sf", "f_logsf", "f_sf"]
