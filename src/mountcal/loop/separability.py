"""Whether an effect can be told apart from the mounting and from the others with these stops: how much it
would widen the tilt, whether the model already covers it, and how much of it the headings alias
(:func:`heading_share`); the model choice declines an effect that fails (:mod:`mountcal.loop.model_choice`)."""

from __future__ import annotations

import numpy as np

from mountcal.core.conventions import FloatArray
from mountcal.core.errors import NotEnoughInformation
from mountcal.core.option_names import option
from mountcal.estimate import effects as registry
from mountcal.estimate import full
from mountcal.loop.diagnose import (
    heading_harmonics,
    projection_test,
)
from mountcal.loop.steps import Step
from mountcal.stops.table import StopTable

# The heading harmonics a covariate term must explain more than (docs/effects.md, "Unexplained structure"): the
# patterns of the effects tied to the vehicle's heading (a lean, a cross slope, compass errors) are 1β and 2β.
MAX_TILT_SIGMA_DEG = 5.0  # an effect that would leave the tilt this uncertain is not separable
PLACE_COLUMNS = ("site", "lat_deg", "lon_deg", "alt_m")  # where a stop is: the geometry, not a logged covariate
ALIAS_HARMONICS = (1, 2)


# The level of that check: it confirms one candidate the loop has already chosen (no search over many, so no
# Bonferroni). Passing it wrongly is a confident wrong answer, failing it wrongly only a flag: 1 %.
ALIAS_ALPHA = 0.01


# A covariate whose variance the heading harmonics explain at least this share of is taken to follow the headings:
# only then can a term driven by it take a heading pattern up whole, and only then does the guard act (a tent of
# temperatures once around the circle: 0.99; a ramp over one circle: 0.76).
ALIAS_SHARE = 0.9


def covers(cur: Step, term: str, names: list[str], g: float) -> bool:
    """Is ``term`` in the model, or a candidate the stops separate?"""
    return term in cur.terms or (term in names and inseparable(cur, (*cur.terms, term), g) is None)


def inseparable(cur: Step, terms: tuple[str, ...], g: float) -> str | None:
    """Why the data cannot separate the new term from the model, or None when they can."""
    info, names = full.information(cur.table, cur.fit.state, terms, g)
    null = full.null_space(info, normalised=True)
    if null.size:
        params = {e.name: e.parameters(cur.table) for e in registry.chain(terms)}
        groups = sorted({registry.owner(names[j], params) for j in np.flatnonzero(np.abs(null).max(axis=1) > 0.1)})
        return f"confounded with {', '.join(g for g in groups if g != terms[-1]) or 'itself'} in these stops"
    cov = np.linalg.inv(info) * cur.fit.noise_scale**2
    tilt = float(np.degrees(np.sqrt(max(cov[0, 0], cov[1, 1]))))
    if tilt > MAX_TILT_SIGMA_DEG:
        return f"not separable from the tilt: with it the tilt 1σ would be {tilt:.3g}°"
    return None


def heading_alias(cur: Step, f: full.Fit, name: str) -> str | None:
    """Why a term driven by a logged covariate (temperature, …) is no explanation: what it explains is a heading
    pattern; or None.

    Its columns are tested beyond the current model, the terms it brings and the low heading harmonics
    (:data:`ALIAS_HARMONICS`, per axis): when the stops visited the headings in an order that the covariate
    follows (the sensor warming up around the circle and cooling on the way back), the term would take any
    heading-dependent effect as its own and leave nothing for the residual tests. It must then explain
    something at :data:`ALIAS_ALPHA` that no heading pattern does. Terms of the geometry (scale, slopes) predict their
    heading pattern from the rotation; the Fisher rank tests those.
    """
    effect = registry.get(name)
    beta = cur.table.beta_rad if cur.table.beta_rad is not None else cur.fit.state.beta_rad
    if not any(c not in PLACE_COLUMNS for c in effect.needs) or beta is None or beta.size != len(cur.table):
        return None
    if heading_share(cur.table, effect, beta) < ALIAS_SHARE:
        return None  # the covariate is no heading pattern itself: it cannot take one up whole
    model = full.StaticModel(cur.table, f.terms, f.state.g_mps2)
    jac = model.jacobian(f.state)
    own = list(f.owned[name])
    rest = [i for i in range(jac.shape[1]) if i not in own]
    harmonics = heading_harmonics(model.whiten, beta, ALIAS_HARMONICS)
    if harmonics is None:
        return None
    r = full.StaticModel(cur.table, cur.terms, f.state.g_mps2).residual(cur.fit.state)
    finding = projection_test(r, jac[:, own], np.hstack([jac[:, rest], harmonics]), name, cur.fit)
    if finding.p_value is None or finding.p_value < ALIAS_ALPHA:
        return None
    return (
        f"what it would explain is a heading pattern: beyond the 1β and 2β harmonics of heading it explains "
        f"Δχ² = {finding.statistic:.3g} on {finding.dof} (p = {finding.p_value:.3g} ≥ {ALIAS_ALPHA:g}); its "
        f"{', '.join(effect.needs)} follows the "
        "order the headings were visited in — visit them in another order (or the circle twice) to separate it"
    )


def heading_share(table: StopTable, effect: registry.Effect, beta: FloatArray) -> float:
    """The share of the variance of the effect's logged covariates (temperature) that the heading harmonics
    (:data:`ALIAS_HARMONICS`) explain: 1 when the covariate follows the order the headings were visited in
    (it rises and falls once around the circle), about 0.76 for a ramp over one circle, near 0 when the
    headings were visited in another order."""
    h = np.column_stack(
        [np.ones(beta.size)] + [f(k * beta) for k in ALIAS_HARMONICS if 2 * k < beta.size for f in (np.cos, np.sin)]
    )
    share = 0.0
    for column in (c for c in effect.needs if c not in PLACE_COLUMNS):
        x = getattr(table, column, None)
        if x is None or np.ptp(x) == 0:
            continue
        x = np.asarray(x, dtype=float) - np.mean(x)
        fitted = h @ np.linalg.lstsq(h, x, rcond=None)[0]
        share = max(share, float(fitted @ fitted / (x @ x)))
    return share


def refuse_inseparable(base: Step, fixed: tuple[str, ...], g: float) -> None:
    """A fixed model whose terms these stops cannot separate is refused, naming the first such term."""
    for i in range(len(full.BASE), len(fixed)):
        problem = inseparable(base, fixed[: i + 1], g)
        if problem:
            raise NotEnoughInformation(
                f"{base.table.source}: the term {fixed[i]} of {option('model', ','.join(fixed))} cannot be fitted: "
                f"it is {problem}. Leave it out of {option('model')} (or use {option('model', 'auto')}, which adds "
                "only what the stops separate)."
            )


__all__ = [
    "ALIAS_ALPHA",
    "ALIAS_HARMONICS",
    "ALIAS_SHARE",
    "MAX_TILT_SIGMA_DEG",
    "PLACE_COLUMNS",
    "covers",
    "heading_alias",
    "heading_share",
    "inseparable",
    "refuse_inseparable",
]
