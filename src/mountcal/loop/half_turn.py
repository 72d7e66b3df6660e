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
from scipy import stats

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
    keep = np.zeros(len(table), dtype=bool)
    keep[i] = True
    one = table.subset(keep)
    flipped = replace(one, beta_rad=(table.beta_rad[i : i + 1] + np.pi) % (2.0 * np.pi))
    try:
        stated = _chi2(one, terms, g, others)
        turned = _chi2(flipped, terms, g, others)
    except (ValueError, IndexError, np.linalg.LinAlgError):  # a per-site term the lone stop cannot carry
        return None
    scale = max(1.0, others.chi2 / others.dof) if others.dof > 0 else 1.0
    if turned / scale > stats.chi2.isf(FITS_P, 3) or turned * BETTER > stated:
        return None
    return (
        f"its reading fits a heading a half turn away (β = {np.degrees(table.beta_rad[i] + np.pi) % 360:.0f}°, χ²(3) = "
        f"{turned / scale:.1f}): a stop entered in reverse where the headings are a course over ground (the "
        "direction of motion), or its heading written from the wrong end of the vehicle"
    )


def _chi2(one: StopTable, terms: tuple[str, ...], g: float, fit: full.Fit) -> float:
    r = full.StaticModel(one, terms, g).residual(fit.state)
    return float(r @ r)
