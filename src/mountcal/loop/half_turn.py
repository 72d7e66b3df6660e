"""Is a stop that the others do not predict one whose heading is a half turn off?

A heading a half turn from the vehicle's own is a common slip at the seam where headings come in:
a course over ground is the direction of motion, so a vehicle that reversed into its spot reads a half
turn off; a heading typed from the wrong end of the vehicle does too. On a slope the two differ by
twice the slope in tilt, far above any stop's noise, so the stop's reading tells: it is predicted by
the fit of the others at β + 180° and not at β. Said where the stop is set aside, so the user learns
the likely cause and not only that the stop was dropped.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from mountcal.core.conventions import FloatArray
from mountcal.core.errors import FitFailed, NotEnoughInformation
from mountcal.core.pvalues import chi2_isf
from mountcal.estimate import full
from mountcal.stops.table import StopTable

FITS_P = 1e-3  # the flipped stop must sit on the others' model at this level (its χ² with 3 dof)
BETTER = 100.0  # and miss it at least this many times less than at its stated heading (in χ²)


def half_turn_note(table: StopTable, i: int, terms: tuple[str, ...], g: float, others: full.Fit) -> str | None:
    """Words for the reason stop ``i`` is set aside, when its reading fits its heading plus 180°; else None.

    ``others`` is the fit without stop ``i``; the stop's χ² is scaled by their χ²/dof when that exceeds 1
    (vibration or a road the noise model does not cover), so that a stop is judged as the others are.
    """
    if table.beta_rad is None or table.headings == "none":
        return None
    try:
        stated = float(_per_stop(table, terms, g, others)[i])
        turned = float(_per_stop(_all_turned(table), terms, g, others)[i])
    except (ValueError, IndexError, np.linalg.LinAlgError):  # a state the whole table does not fit (per-stop terms)
        return None
    scale = max(1.0, others.chi2 / others.dof) if others.dof > 0 else 1.0
    if turned / scale > chi2_isf(FITS_P, 3) or turned * BETTER > stated:
        return None
    return (
        f"its reading fits a heading a half turn away (β = {np.degrees(table.beta_rad[i] + np.pi) % 360:.0f}°, χ²(3) = "
        f"{turned / scale:.1f}): a stop entered in reverse where the headings are a course over ground (the "
        "direction of motion), or its heading written from the wrong end of the vehicle"
    )


def reversed_stops(table: StopTable, g: float) -> str | None:
    """Words naming the stops whose headings, turned by half a turn, make every stop fit; else None.

    For stops the model leaves unexplained: the stop gaining most from its heading turned is turned, the
    base model refitted, and so on, while each turn helps, until the stops fit (χ² at the level of
    :data:`FITS_P`, or within twice their stated noise) — at most a third of them (more is the whole session's
    reference turned, which the answer's own note on a backward yaw covers).
    """
    if table.beta_rad is None or table.headings == "none" or table.cov_s is None:
        return None
    n = len(table)
    turned: list[int] = []
    current = table
    try:
        fit = full.fit(current, full.BASE, g)
        while len(turned) < n // 3:
            gain = _per_stop(current, full.BASE, g, fit) - _per_stop(_all_turned(current), full.BASE, g, fit)
            gain[turned] = -np.inf
            i = int(np.argmax(gain))
            if gain[i] <= BETTER:
                return None
            turned.append(i)
            current = replace(current, beta_rad=_turn(current.beta_rad, [i]))  # type: ignore[arg-type]
            fit = full.fit(current, full.BASE, g, fit.state)
            if fit.dof > 0 and (fit.chi2 <= chi2_isf(FITS_P, fit.dof) or fit.chi2 <= 2.0 * fit.dof):
                break
        else:
            return None
    except (FitFailed, NotEnoughInformation, np.linalg.LinAlgError):
        return None
    named = ", ".join(f"{i + 1} (β = {np.degrees(table.beta_rad[i]) % 360:.0f}°)" for i in sorted(turned))
    return (
        f"stop{'s' if len(turned) > 1 else ''} {named} fit{'' if len(turned) > 1 else 's'} a heading half a turn away: "
        f"with {'their' if len(turned) > 1 else 'its'} β turned by 180° every stop fits (χ² = {fit.chi2:.1f} on "
        f"{fit.dof} dof) — stops entered in reverse where the headings are courses over ground (the direction of "
        "motion), or headings written from the wrong end of the vehicle. Correct those headings and calibrate again"
    )


def _turn(beta: FloatArray, stops: list[int]) -> FloatArray:
    out = beta.copy()
    out[stops] = (out[stops] + np.pi) % (2.0 * np.pi)
    return out


def _all_turned(table: StopTable) -> StopTable:
    assert table.beta_rad is not None
    return replace(table, beta_rad=_turn(table.beta_rad, list(range(len(table)))))


def _per_stop(table: StopTable, terms: tuple[str, ...], g: float, fit: full.Fit) -> FloatArray:
    """Each stop's χ² (3 dof) against the fitted model ``terms`` at ``fit``'s state."""
    r = full.StaticModel(table, terms, g).residual(fit.state).reshape(-1, 3)
    return np.asarray((r**2).sum(axis=1), dtype=np.float64)
