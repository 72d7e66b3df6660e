"""Each stop's own heading error: a car parked by eye along a painted line, a compass or a course over ground read
at each stop, stands a degree or so off the heading it was given — independently at every stop.

On a slope α such an error ε moves the stop by ``ε · ∂prediction/∂β`` (g·sin α per radian, horizontal in the
vehicle frame): on a 5° slope 1° is 15 mm/s², a hundred times the noise of a 20 s stop mean. Unmodelled, the
residual tests name it ("single stops turned about the vertical") and the result is not confident, although the
angles are right. Modelled, it widens each stop's covariance along that direction by ``σ_h²``, with ``σ_h``
found by maximum likelihood as the random road tilt per stop is (``surface`` in :mod:`mountcal.loop.model_choice`):
searched with the mean model held at the current fit, then refined on the profile likelihood (the mean model
refitted). Yaw then rests less on each
stop's heading, and its statistical σ grows accordingly. A common error of all the headings shows nowhere in the
stops: it stays in the systematic budget (:mod:`mountcal.loop.systematic`).

The search stops at :data:`MAX_HEADING_SCATTER_DEG`: a larger error is not parking by eye but a wrong heading,
which the outlier step and the half-turn check name one stop at a time.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from scipy import optimize

from mountcal.core.conventions import FloatArray
from mountcal.core.pvalues import FAMILY_ALPHA, chi2_logsf, f_sf
from mountcal.core.result import Declined
from mountcal.estimate import full
from mountcal.loop.diagnose import DRIFT_MODES, time_order
from mountcal.loop.steps import Step, held_neg2loglik, neg2loglik
from mountcal.stops.table import StopTable

NAME = "heading_scatter"
MAX_HEADING_SCATTER_DEG = 5.0
MIN_STOPS = 4  # a variance needs residual degrees of freedom beyond the rotation and the slope
STRUCTURED = "the stops' heading errors follow"  # how a decline for structure opens (:func:`found_structured`)


def candidate(table: StopTable) -> bool:
    """The stops have given headings (their errors move them) and a known noise (the scatter is measured against)."""
    return (
        table.cov_s is not None and table.beta_rad is not None and table.headings != "none" and len(table) >= MIN_STOPS
    )


def with_heading_scatter(table: StopTable, tangents: FloatArray, sigma_rad: float) -> StopTable:
    """The table with each stop's covariance widened by ``σ_h² t tᵀ`` (``t``: its heading tangent, per radian)."""
    extra = sigma_rad**2 * np.einsum("ni,nj->nij", tangents, tangents)
    return replace(table, cov_s=table.cov_s + extra)


def heading_scatter_step(cur: Step, g: float, k: int) -> tuple[float, Step] | str | None:
    """The step that models each stop's heading error, with its Bonferroni-adjusted log p (``k`` candidates); None
    where the stops do not call for it (no scatter, or more than headings are off by); the reason it is declined
    where the headings' errors follow the time order or the heading (:func:`structure`)."""
    if not candidate(cur.table) or cur.fit.dof < 2:
        return None
    base = cur.table
    tangents = full.StaticModel(base, cur.terms, g).heading_tangents(cur.fit.state)
    resid = cur.fit.residual_s

    def held(log_sigma: float) -> float:
        return held_neg2loglik(resid, with_heading_scatter(base, tangents, float(np.exp(log_sigma))).cov_s)  # type: ignore[arg-type]

    lower, upper = float(np.log(np.radians(0.01))), float(np.log(np.radians(MAX_HEADING_SCATTER_DEG)))
    x = float(optimize.minimize_scalar(held, bounds=(lower, upper), method="bounded", options={"xatol": 0.01}).x)
    if x > upper - 0.05:
        return None  # more than headings are off by: not this effect

    def refitted(log_sigma: float) -> tuple[float, StopTable, full.Fit]:
        table = with_heading_scatter(base, tangents, float(np.exp(log_sigma)))
        fit = full.fit(table, cur.terms, g, cur.fit.state)
        return neg2loglik(table, fit), table, fit

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
    stat = max(neg2loglik(base, cur.fit) - value, 0.0)
    logp = float(chi2_logsf(stat, 1))
    pattern = structure(base, tangents, resid, float(np.exp(x)))
    if pattern is not None:
        return pattern
    rel = f" (1σ, ±{np.sqrt(2.0 / curvature):.0%})" if curvature > 0 else " (1σ)"
    reason = (
        f"each stop's own heading off by {np.degrees(np.exp(x)):.2g}°{rel} (parking by eye, a compass or a course "
        f"read at each stop); likelihood ratio χ²(1) = {stat:.1f}, p = {np.exp(logp):.3g}"
    )
    terms = (*cur.terms, NAME)
    return logp + np.log(k), Step(NAME, reason, terms, cur.excluded, table, replace(fit, terms=terms))


def structure(table: StopTable, tangents: FloatArray, resid: FloatArray, sigma_rad: float) -> str | None:
    """Why the stops' heading errors are not scatter, or None: they follow the time order (a heading source that
    drifts, an integrating gyro) or the heading itself (a compass's deviation). Such errors have a common part
    too, which moves yaw and shows in no residual: modelled as scatter, they would pass as explained.

    Each stop's heading error ``ε_i = tᵀC⁻¹r / tᵀC⁻¹t`` (its variance ``1 / tᵀC⁻¹t`` from the noise, plus ``σ_h²``)
    is regressed, weighted, on a mean, the first cosine modes of the time order and the 1β, 2β harmonics; an F-test
    at the residual tests' level says whether they explain more than scatter does.
    """
    solved = np.linalg.solve(table.cov_s, np.stack([tangents, resid], axis=2))  # type: ignore[arg-type]
    info = np.einsum("ni,ni->n", tangents, solved[:, :, 0])
    eps = np.einsum("ni,ni->n", tangents, solved[:, :, 1]) / info
    weight = 1.0 / (1.0 / info + sigma_rad**2)
    n = len(eps)
    rank = np.empty(n)
    rank[time_order(table)] = np.arange(n)
    beta = np.asarray(table.beta_rad)
    columns = {"the time order": np.cos(np.pi * np.outer(rank + 0.5, np.arange(1, DRIFT_MODES + 1)) / n)}
    distinct = np.unique(np.round(np.mod(beta, 2 * np.pi), 6)).size
    harmonics = [np.column_stack([np.cos(h * beta), np.sin(h * beta)]) for h in (1, 2) if 2 * h < distinct]
    if harmonics:
        columns["the heading"] = np.hstack(harmonics)
    found = []
    for name, x in columns.items():
        design = np.column_stack([np.ones(n), x])
        dof = n - design.shape[1]
        if dof < 2:
            continue
        root = np.sqrt(weight)
        total = float(np.sum(weight * (eps - np.average(eps, weights=weight)) ** 2))
        fitted, *_ = np.linalg.lstsq(design * root[:, None], eps * root, rcond=None)
        left = float(np.sum(weight * (eps - design @ fitted) ** 2))
        f = ((total - left) / x.shape[1]) / max(left / dof, 1e-300)
        if float(f_sf(f, x.shape[1], dof)) < FAMILY_ALPHA:
            found.append(name)
    if not found:
        return None
    return (
        f"{STRUCTURED} {' and '.join(found)} (a heading source that drifts or deviates), not scatter: their common "
        "part would move yaw unseen"
    )


def found_structured(declined: Sequence[Declined]) -> bool:
    """Whether an earlier round found the headings' errors structured: a stop set aside since does not make them
    scatter (the rest of a drift is a smaller drift, which the fewer stops may not show)."""
    return any(d.effect == NAME and d.why.startswith(STRUCTURED) for d in declined)


__all__ = [
    "MAX_HEADING_SCATTER_DEG",
    "NAME",
    "candidate",
    "found_structured",
    "heading_scatter_step",
    "structure",
    "with_heading_scatter",
]
