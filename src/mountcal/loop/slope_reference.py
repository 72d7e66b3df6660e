"""A slope measured apart from the sensor, checked against the slope the stops give.

On one slope a common scale of the sensor's two horizontal axes, or axes that tilt with the lateral
load (a compliant bracket, a phone cradle), changes only the size of the circle the stops trace: the
stops read as a steeper or flatter slope, and nothing in their residual shows it (docs/effects.md,
"What no residual can show"). So does the body leaning downhill on its suspension, by the same
fraction in roll and pitch: the stops measure the slope the *body* stands at. The reference is best
that too (a level on the body facing uphill and downhill, half the difference); the ground's slope
(a surveyed bay) differs from it by the suspension's lean: a car's roll gradient of 3–7°/g leans it
by 5–12 % of the slope across it, its pitch gradient by less along it.
A reference sees what the stops cannot: the fitted slope against the reference is
one more residual test, ``z = (α̂ − α_ref) / √(σ²_stat + σ²_ref)``, N(0, 1) to first order when
neither effect is there (Student's t with Welch–Satterthwaite degrees of freedom when the stop noise
was estimated).
It joins the family of residual tests (:func:`mountcal.core.pvalues.unexplained`); the slope it is checked
against is the stops', so the σ is the statistical one: an error of the sensor's scale within its
limits shows too, which is the point of a reference.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from mountcal.core.errors import InputError
from mountcal.core.findings import Finding
from mountcal.core.option_names import option
from mountcal.core.pvalues import chi2_logsf, f_logsf

TEST = "slope_reference"
WHAT = (
    "fitted slope against the given reference (the body's lean on its suspension, a common horizontal scale, axes "
    "tilting with the lateral load)"
)


@dataclass(frozen=True)
class SlopeReference:
    """The slope the body stands at (or the ground's), measured apart from the sensor, degrees, and its 1σ."""

    slope_deg: float
    sigma_deg: float

    def __post_init__(self) -> None:
        ok = (
            math.isfinite(self.slope_deg)
            and math.isfinite(self.sigma_deg)
            and 0.0 <= self.slope_deg < 90.0
            and self.sigma_deg > 0.0
        )
        if not ok:
            raise InputError(
                option("slope_reference"),
                "the slope in degrees (0 ≤ slope < 90) and its 1σ in degrees (> 0)",
                f"{self.slope_deg!r} and {self.sigma_deg!r}",
                "Give the surveyed or measured slope of the ground and its standard uncertainty, both in degrees.",
            )


def check(slope_deg: float | None, sigma_deg: float | None, ref: SlopeReference, noise_dof: int | None) -> Finding:
    """The finding of the fitted slope (``slope_deg`` ± its statistical ``sigma_deg``) against ``ref``.

    ``noise_dof``: the degrees of freedom the stop noise was estimated from (None: the table gave it).
    """
    if slope_deg is None or sigma_deg is None:
        why = "no test: the stops do not determine one slope with this model"
        return Finding(TEST, WHAT, why, None, 1, None, None, why)
    var_stat, var_ref = sigma_deg**2, ref.sigma_deg**2
    z2 = (slope_deg - ref.slope_deg) ** 2 / (var_stat + var_ref)
    if noise_dof is None:
        logp = float(chi2_logsf(z2, 1))
    else:  # Welch–Satterthwaite: only the stops' part of the variance was estimated
        dof = (var_stat + var_ref) ** 2 / (var_stat**2 / max(noise_dof, 1))
        logp = float(f_logsf(z2, 1, dof))
    diff = slope_deg - ref.slope_deg
    relative = f" ({100 * diff / ref.slope_deg:+.2g} % of it)" if ref.slope_deg > 0 else ""
    size = (
        f"{slope_deg:.3f} ± {sigma_deg:.3f}° from the stops, {ref.slope_deg:.3f} ± {ref.sigma_deg:.3f}° given: "
        f"{diff:+.3f}°{relative}"
    )
    return Finding(TEST, WHAT, size, z2, 1, math.exp(logp), logp / math.log(10))
