"""What a fit records beside its numbers: the gravity it used and where that came from (:func:`local_gravity`),
its provenance, and the doubts that keep a result from confident (:func:`fit_doubts`)."""

from __future__ import annotations

from datetime import UTC, datetime

import numpy as np

from mountcal.core.conventions import (
    G_N,
    FloatArray,
    normal_gravity,
)
from mountcal.core.option_names import option
from mountcal.core.result import (
    Convention,
    Provenance,
)
from mountcal.core.version import software_version
from mountcal.stops.identity import fingerprint
from mountcal.stops.table import StopTable

GIVEN = "given by the user"


# "Confident" promises the answer is usable: tilt within 10° at 5σ, so its 1σ must stay under 2°.
MAX_CONFIDENT_TILT_SIGMA_DEG = 2.0


MIN_NOISE_DOF = 10  # a noise estimated from fewer residual values is itself too uncertain to vouch for the σ


def gravity_convention(g_source: str) -> Convention:
    if g_source == GIVEN:
        return Convention("gravity", "given", "stated", f"{option('gravity')} (in m/s², checked to be Earth's)")
    if g_source.startswith("WGS 84"):
        return Convention("gravity", g_source, "inferred", "the stops' lat_deg (and alt_m)")
    return Convention("gravity", "9.80665 m/s²", "default", "no position in the input: standard gravity gₙ")


def fit_doubts(branch: str | None, tilt_sigma_deg: float, noise_dof: int | None) -> list[str]:
    """Reasons, besides unexplained structure, why an answer is not to be trusted as it stands.

    ``noise_dof``: the degrees of freedom the stop noise was estimated from (None: the table gave it).
    """
    out = [branch] if branch else []
    if tilt_sigma_deg > MAX_CONFIDENT_TILT_SIGMA_DEG:
        out.append(
            f"the tilt is uncertain by {tilt_sigma_deg:.3g}° (1σ; over {MAX_CONFIDENT_TILT_SIGMA_DEG:g}°): more stops, "
            "a steeper slope or a quieter sensor would pin it down"
        )
    if noise_dof is not None and noise_dof < MIN_NOISE_DOF:
        out.append(
            f"the stop noise is estimated from only {noise_dof} residual degrees of freedom, so the σ themselves are "
            "uncertain: add stops, or give each stop's noise (sx, sy, sz, n)"
        )
    return out


def local_gravity(lat_deg: FloatArray | None, alt_m: FloatArray | None, given: float | None) -> tuple[float, str]:
    """Gravity and its source: ``given``, else WGS 84 normal gravity at the mean position, else standard."""
    if given is not None:  # checked where it was given (Options)
        return float(given), GIVEN
    if lat_deg is not None and lat_deg.size and np.all(np.isfinite(lat_deg)):
        lat = float(np.mean(lat_deg))
        alt = float(np.mean(alt_m)) if alt_m is not None and alt_m.size else 0.0
        return normal_gravity(lat, alt), f"WGS 84 normal gravity at latitude {lat:.4f}°, height {alt:.0f} m"
    return (
        G_N,
        "assumed standard gravity 9.80665 m/s² (no position known); local gravity differs by up to ±0.27 %",
    )


def fit_provenance(table: StopTable, method: str, terms: tuple[str, ...]) -> Provenance:
    return Provenance(
        input=table.source,
        software=f"mountcal {software_version()}",
        method=method,
        model=terms,
        created_utc=datetime.now(UTC).isoformat(timespec="seconds"),
        input_sha256=(table.sha256,) if table.sha256 else (),
        stops_fingerprint=fingerprint(table),  # lets `report --stops` check it has the right table
        incomplete_inputs=table.incomplete,
    )


__all__ = [
    "GIVEN",
    "MAX_CONFIDENT_TILT_SIGMA_DEG",
    "MIN_NOISE_DOF",
    "fit_doubts",
    "fit_provenance",
    "gravity_convention",
    "local_gravity",
]
