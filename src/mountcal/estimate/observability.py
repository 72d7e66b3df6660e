"""Which effects these stops can separate from the mounting, and which protocol would (docs/effects.md).

For every registered effect not in the fitted model, the Fisher information of the model with it is
checked at the fitted point: on the stops as they are, then on designed sessions — the same slope's
headings repeated on two, then three slopes of different inclination (a ``site`` each, headings 30°
apart). Only the rank matters (an effect the information does not see cannot be separated, however
many stops), so the designs need no data: the Jacobian depends on the geometry alone.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from mountcal.estimate import effects as registry
from mountcal.estimate import full
from mountcal.stops.table import StopTable

HEADINGS_DEG = np.arange(0.0, 360.0, 30.0)
EXTRA_SLOPE_DEG = 5.0  # each further slope of a design is this much steeper
PROTOCOLS = (
    (2, "two slopes of different inclination (a site column; each slope's headings from its own uphill)"),
    (3, "three slopes of different inclination (a site column)"),
)


def separability(table: StopTable, fit: full.Fit, g_mps2: float) -> list[dict[str, Any]]:
    """Per effect not in the model (alone, and with the offset when the model has none): whether these stops
    separate it and, if not, the first protocol that would. The slope per site is no such effect: the
    protocols are made of sites."""
    out = []
    offset = registry.offset().name
    tried = [e for e in registry.registered().values() if e.name not in fit.terms and not e.slope_per_site]
    usable = [e for e in tried if all(getattr(table, c, None) is not None for c in e.needs)]
    # One information matrix for the model with every usable effect: at their start (no effect) they leave
    # the other columns as they are, so each smaller model's information is a block of it.
    every = (*fit.terms, *(e.name for e in usable))
    info, names = full.information(table, fit.state, every, g_mps2)
    params = {e.name: e.parameters(table) for e in registry.chain(every)}
    owner = [registry.owner(n, params) for n in names]
    for effect in tried:
        missing = [c for c in effect.needs if getattr(table, c, None) is None]
        if missing:
            out.append({"effect": effect.name, "separable": False, "why": f"needs the {', '.join(missing)} column"})
            continue
        sets: list[tuple[str, ...]] = [(effect.name,)]
        if offset not in fit.terms and effect.name != offset and not effect.needs:
            sets.append((offset, effect.name))
        for added in sets:
            terms = (*fit.terms, *(r for r in effect.requires if r not in fit.terms), *added)
            keep = [i for i, o in enumerate(owner) if o not in params or o in terms]
            here = full.fisher_rank(info[np.ix_(keep, keep)]) == len(keep)
            out.append({"effect": " with ".join(reversed(added)), **_verdict(here, fit, terms, g_mps2)})
    return out


def _verdict(here: bool, fit: full.Fit, terms: tuple[str, ...], g: float) -> dict[str, Any]:
    if here:
        return {"separable": True, "why": "separable with these stops"}
    if effects_need_columns(terms):
        return {"separable": False, "why": "not separable with these stops"}
    for sites, name in PROTOCOLS:
        design, state = _design(fit.state, sites)
        if _full_rank(design, state, (*terms, registry.site_term()), g):
            return {"separable": False, "why": f"not separable with these stops; {name} would separate it"}
    return {"separable": False, "why": "not separable with these stops, nor on up to three slopes"}


def effects_need_columns(terms: tuple[str, ...]) -> bool:
    """Does any of the terms need a stop-table column (the designs carry none)?"""
    return any(registry.get(t).needs for t in terms if t in registry.registered())


def _full_rank(table: StopTable, state: full.State, terms: tuple[str, ...], g: float) -> bool:
    info, _ = full.information(table, state, terms, g)
    return full.fisher_rank(info) == int(info.shape[0])


def _design(state: full.State, sites: int) -> tuple[StopTable, full.State]:
    """A session on ``sites`` slopes (the fitted one, then steeper), 12 headings each, and its state."""
    n = HEADINGS_DEG.size
    slope = float(np.mean(state.slope_rad))
    slopes = slope + np.radians(EXTRA_SLOPE_DEG) * np.arange(sites)
    table = StopTable(
        acc_s=np.zeros((n * sites, 3)),
        beta_rad=np.tile(np.radians(HEADINGS_DEG), sites),
        headings="uphill",
        site=np.repeat([f"slope{k}" for k in range(sites)], n),
        source="<design>",
    )
    return table, replace(state, slope_rad=slopes, beta_rad=np.zeros(0))
