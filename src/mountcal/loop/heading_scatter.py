"""Each stop's own heading error: a car parked by eye along a painted line, a compass or a course over ground read
at each stop, stands a degree or so off the heading it was given — independently at every stop.

On a slope α such an error ε moves the stop by ``ε · ∂prediction/∂β`` (g·sin α per radian, horizontal in the
vehicle frame): on a 5° slope 1° is 15 mm/s², a hundred times the noise of a 20 s stop mean. Unmodelled, the
residual tests name it ("single stops turned about the vertical") and the result is not confident, although the
angles are right. Modelled, it widens each stop's covariance along that direction by ``σ_h²``, with ``σ_h``
found by maximum likelihood (the mean model held at the current fit, then refitted at the optimum), as the
random road tilt per stop is (``surface`` in :mod:`mountcal.loop.model_choice`), then refined on the profile
likelihood (the mean model refitted) at the vertex of its parabola. Yaw then rests less on each
stop's heading, and its statistical σ grows accordingly. A common error of all the headings shows nowhere in the
stops: it stays in the systematic budget (:mod:`mountcal.loop.systematic`).

The search stops at :data:`MAX_HEADING_SCATTER_DEG`: a larger error is not parking by eye but a wrong heading,
which the outlier step and the half-turn check name one stop at a time.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy import optimize

from mountcal.core.conventions import FloatArray
from mountcal.core.pvalues import chi2_logsf
from mountcal.estimate import full
from mountcal.loop.steps import Step
from mountcal.stops.table import StopTable

NAME = "heading_scatter"
MAX_HEADING_SCATTER_DEG = 5.0
MIN_STOPS = 4  # a variance needs residual degrees of freedom beyond the rotation and the slope


def candidate(table: StopTable) -> bool:
    """The stops have given headings (their errors move them) and a known noise (the scatter is measured against)."""
    return (
        table.cov_s is not None and table.beta_rad is not None and table.headings != "none" and len(table) >= MIN_STOPS
    )


def with_heading_scatter(table: StopTable, tangents: FloatArray, sigma_rad: float) -> StopTable:
    """The table with each stop's covariance widened by ``σ_h² t tᵀ`` (``t``: its heading tangent, per radian)."""
    extra = sigma_rad**2 * np.einsum("ni,nj->nij", tangents, tangents)
    return replace(table, cov_s=table.cov_s + extra)


def heading_scatter_step(cur: Step, g: float, k: int) -> tuple[float, Step] | None:
    """The step that models each stop's heading error, with its Bonferroni-adjusted log p (``k`` candidates), or
    None where the stops do not call for it (no scatter, or more than headings are off by)."""
    if not candidate(cur.table) or cur.fit.dof < 2:
        return None
    base = cur.table
    tangents = full.StaticModel(base, cur.terms, g).heading_tangents(cur.fit.state)
    resid = cur.fit.residual_s

    def held(log_sigma: float) -> float:
        cov = with_heading_scatter(base, tangents, float(np.exp(log_sigma))).cov_s
        chi2 = np.einsum("ni,ni->", resid, np.linalg.solve(cov, resid[..., None])[..., 0])  # type: ignore[arg-type]
        return float(chi2 + np.sum(np.linalg.slogdet(cov)[1]))  # type: ignore[arg-type]

    lower, upper = float(np.log(np.radians(0.01))), float(np.log(np.radians(MAX_HEADING_SCATTER_DEG)))
    x = float(optimize.minimize_scalar(held, bounds=(lower, upper), method="bounded", options={"xatol": 0.01}).x)
    if x > upper - 0.05:
        return None  # more than headings are off by: not this effect

    def refitted(log_sigma: float) -> tuple[float, StopTable, full.Fit]:
        table = with_heading_scatter(base, tangents, float(np.exp(log_sigma)))
        fit = full.fit(table, cur.terms, g, cur.fit.state)
        return _neg2loglik(table, fit), table, fit

    h = 0.05
    value, table, fit = refitted(x)
    below, above = refitted(x - h)[0], refitted(x + h)[0]
    curvature = (above - 2 * value + below) / h**2  # of the profile likelihood: the mean model refitted
    shift = -(above - below) / (2 * h * curvature) if curvature > 0 else 0.0
    if abs(shift) <= 2 * h and x + shift <= upper:  # its optimum, the vertex of the parabola
        x += shift
        value, table, fit = refitted(x)
    else:  # refitting moves the optimum far (yaw takes up part of the headings' scatter): search the profile
        near = (max(lower, x - 1.0), min(upper, x + 1.0))
        x = float(optimize.minimize_scalar(lambda t: refitted(t)[0], bounds=near, method="bounded",
                                           options={"xatol": 0.01}).x)  # fmt: skip
        value, table, fit = refitted(x)
        curvature = (refitted(x + h)[0] - 2 * value + refitted(x - h)[0]) / h**2
    if x > upper - 0.05:
        return None
    stat = max(_neg2loglik(base, cur.fit) - value, 0.0)
    logp = float(chi2_logsf(stat, 1))
    rel = f" (1σ, ±{np.sqrt(2.0 / curvature):.0%})" if curvature > 0 else " (1σ)"
    reason = (
        f"each stop's own heading off by {np.degrees(np.exp(x)):.2g}°{rel} (parking by eye, a compass or a course "
        f"read at each stop); likelihood ratio χ²(1) = {stat:.1f}, p = {np.exp(logp):.3g}"
    )
    terms = (*cur.terms, NAME)
    return logp + np.log(k), Step(NAME, reason, terms, cur.excluded, table, replace(fit, terms=terms))


def _neg2loglik(table: StopTable, fit: full.Fit) -> float:
    return fit.chi2 + float(np.sum(np.linalg.slogdet(table.cov_s)[1]))  # type: ignore[arg-type]


__all__ = ["MAX_HEADING_SCATTER_DEG", "NAME", "candidate", "heading_scatter_step", "with_heading_scatter"]
