"""Systematic (GUM Type B) uncertainty: the sensor errors the final model does not fit, moved into the angles.

A sensor error δ (scale, cross-axis, bias, bias drift per °C; or what remains of them after a
triad calibration) changes every stop by ``A δ`` (``A`` = ∂prediction/∂δ at the fitted
specific forces). The estimator turns a change ``Δa`` of the stops into a change ``K Δa`` of
its parameters, ``K = (JᵀWJ)⁻¹JᵀW`` the gain of the final fit. So what the stops can see of δ
is absorbed by the fitted terms or left in the residual, and only what they cannot see moves
the angles::

    Cov_sys = K A Σ_δ Aᵀ Kᵀ

Σ_δ holds standard uncertainties: a datasheet limit ±a is a rectangular distribution,
u = a/√3 (GUM 4.3.7); a triad calibration gives its own covariance. Terms the final model fits
contribute nothing (exactly: their columns of ``A`` are columns of ``J``). The statistical σ
and this systematic σ are independent; the total σ is their root sum of squares.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.linalg import block_diag

from mountcal.core.angles import ANGLE_NAMES, AngleValues
from mountcal.core.conventions import FloatArray
from mountcal.core.option_names import option
from mountcal.core.result import Systematic
from mountcal.estimate import effects as registry
from mountcal.estimate import full
from mountcal.estimate.bound import euler_gradients
from mountcal.estimate.sensor_errors import SensorErrors
from mountcal.io.sensor_spec import SensorSpec
from mountcal.stops.table import StopTable

if TYPE_CHECKING:
    from mountcal.core.result import Calibration

HEADING = "heading"  # the name the headings' error is reported under in ``propagated``


def _effect_of(table: StopTable) -> dict[str, registry.Effect]:
    """The effect each sensor error (a parameter of the static model) belongs to."""
    return {p: e for e in registry.registered().values() for p in e.parameters(table)}


def _headings_seen(table: StopTable, model: full.StaticModel, errors: SensorErrors) -> bool:
    """Whether the given headings set yaw (relative to the uphill direction), so their common error moves it.

    Each stop's own heading error scatters that stop off the model: the residual shows it, and the
    statistical part (its Birge ratio) and the residual tests count it. A common error shows nowhere.
    """
    return errors.heading_u_rad > 0 and model.fit_yaw and not model.fit_beta and table.headings == "uphill"


def propagate(
    table: StopTable,
    state: full.State,
    fitted: tuple[str, ...],
    terms: tuple[str, ...],
    g_mps2: float,
    errors: SensorErrors,
    noise_scale: float = 1.0,
) -> tuple[FloatArray, tuple[str, ...], float, FloatArray]:
    """``K A Σ_δ Aᵀ Kᵀ`` over the fitted parameters ``fitted``, the error names that entered, the part of χ²
    the errors' mean explains, and the part of the covariance that is the headings' common error.

    An error the stops can see but the final model does not fit (a bias on a slope the selection
    loop found insignificant) is bounded by the data as well as by its limit: Σ_δ is updated with
    the information the residual holds on δ, ``I_δ = (A − J K A)ᵀ(A − J K A) / s²`` (a Bayesian
    update of the Type B prior), and δ's mean given the residual enters as μμᵀ (it is not
    corrected, so it is an error). Directions of δ the stops cannot see keep the full limit.
    """
    effect = _effect_of(table)
    keep = [
        i
        for i, name in enumerate(errors.names)
        if effect[name].name not in terms
        and all(getattr(table, c, None) is not None for c in effect[name].needs)  # no temperatures: no drift to map
    ]
    used = tuple(errors.names[i] for i in keep)
    extra = tuple(dict.fromkeys(effect[n].name for n in used))
    model = full.StaticModel(table, tuple(dict.fromkeys((*terms, *extra))), g_mps2)
    headings = _headings_seen(table, model, errors)
    none = np.zeros((len(fitted), len(fitted)))
    if not keep and not headings:
        return none, (), 0.0, none
    jac, heading_column = model.with_heading_offset(state)  # whitened: W is inside both J and A
    residual = -model.residual(state)  # the sign that makes r ≈ −A δ + noise, as the Jacobian is −∂prediction
    j = jac[:, [model.names.index(n) for n in fitted]]
    a = jac[:, [model.names.index(n) for n in used]]
    prior = errors.cov[np.ix_(keep, keep)]
    if headings:  # their common error: a rotation about the vertical, yaw one for one, no residual at all
        a = np.column_stack([a, heading_column])
        prior = block_diag(prior, [[errors.heading_u_rad**2]])
        used = (*used, HEADING)
    gain_a = full.inverse_information(j.T @ j) @ (j.T @ a)  # K A
    seen = (a - j @ gain_a) / noise_scale  # what of each error the residual shows (whitened, unit noise)
    post, mean = _updated(prior, seen, residual / noise_scale)
    explained = float(np.sum((seen @ mean) ** 2)) if np.isfinite(noise_scale) else 0.0
    # the residual sees nothing of a common heading error (its column is the yaw's): its part stands alone
    heading_cov = errors.heading_u_rad**2 * np.outer(gain_a[:, -1], gain_a[:, -1]) if headings else none
    return gain_a @ (post + np.outer(mean, mean)) @ gain_a.T, used, explained, heading_cov


def _updated(prior: FloatArray, seen: FloatArray, residual: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Σ_δ narrowed by the residual, (Σ⁻¹ + BᵀB)⁻¹, and δ's mean given the residual (B: what the stops see of δ).

    Where the stops see nothing of δ the limit stays; where they see it, the residual bounds it,
    and its mean (an error the final model leaves in the residual) counts in full.
    """
    w, v = np.linalg.eigh(prior)
    root = (v * np.sqrt(np.clip(w, 0.0, None))) @ v.T
    post = root @ np.linalg.inv(np.eye(len(prior)) + root @ seen.T @ seen @ root) @ root
    return post, post @ seen.T @ residual


def angle_sigmas(
    cov: FloatArray, names: tuple[str, ...], rot_vs: Any, yaw: bool, slope: bool
) -> dict[str, float | None]:
    """1σ of roll, pitch, (yaw), (slope) and the rotation about each vehicle axis, degrees, from a covariance."""
    k = 3 if "rot_z" in names else 2
    grads = euler_gradients(rot_vs, k)
    rot = cov[:k, :k]

    def deg(var: float) -> float:
        return float(np.degrees(np.sqrt(max(var, 0.0))))

    angles = AngleValues(
        roll_deg=deg(grads[0] @ rot @ grads[0]),
        pitch_deg=deg(grads[1] @ rot @ grads[1]),
        yaw_deg=deg(grads[2] @ rot @ grads[2]) if yaw and k == 3 else None,
        slope_deg=deg(cov[names.index("slope"), names.index("slope")]) if slope and "slope" in names else None,
    )
    rotation = tuple(deg(rot[i, i]) if i < k and (i < 2 or yaw) else None for i in range(3))
    return Systematic.part(angles, rotation)  # as the result file keeps a part


def combine(
    cal: Calibration,
    sys_sigma: dict[str, float | None],
    errors: SensorErrors,
    used: tuple[str, ...],
    sensor_only: dict[str, float | None] | None = None,
) -> Calibration:
    """``cal`` with total σ in its fields, both parts in ``systematic``, and a note when systematic dominates
    (naming the headings when it is mostly theirs: ``sensor_only`` is the part without them)."""
    stat = Systematic.part(cal.angles.sigmas, cal.rotation_sigma_deg)
    sys_sigma = {k: (sys_sigma.get(k) if stat[k] is not None else None) for k in stat}
    stat_a, sys_a = Systematic.angles_of(stat), Systematic.angles_of(sys_sigma)

    def total(s: float | None, t: float | None) -> float | None:
        return None if s is None else float(np.hypot(s, t or 0.0))

    tilt_and_yaw = ANGLE_NAMES[:3]

    part = Systematic(
        statistical=stat,
        systematic=sys_sigma,
        source=errors.source,
        limits=errors.limits,
        propagated=used,
        default_spec=errors.limits.source == _DEFAULT_SRC,
        dominant=any((a := sys_a[k]) is not None and (b := stat_a[k]) is not None and a > b for k in tilt_and_yaw),
    )
    notes = list(cal.notes)
    if part.default_spec:
        notes.append(
            "no sensor spec given: the systematic σ assumes the default class (an uncalibrated consumer MEMS "
            "accelerometer: ±3 % scale, ±2 % cross-axis, ±80 mg bias; headings within ±1° of the fall line in common); "
            f"give {option('sensor_spec')} or {option('triad')} for your sensor"
        )
    if part.dominant:
        over = [k for k in tilt_and_yaw if (sys_a[k] or 0.0) > (stat_a[k] or np.inf)]
        # the systematic σ without the headings' part
        without = sys_a if sensor_only is None else Systematic.angles_of(sensor_only)
        by_headings = [k for k in over if (without[k] or 0.0) < (sys_a[k] or 0.0) / 2**0.5]

        def both(k: str) -> str:
            return f"{k} σ {stat_a[k]:.3g}° statistical, {sys_a[k]:.3g}° systematic"

        if by_sensor := [k for k in over if k not in by_headings]:
            worst = max(by_sensor, key=lambda k: sys_a[k] or 0.0)
            notes.append(
                f"the error is dominated by sensor errors these stops cannot see "
                f"({', '.join(_short(tuple(n for n in used if n != HEADING)))}): {both(worst)}; a triad calibration "
                f"(`mountcal triad`, then {option('triad')}) or stops on two slopes of different inclination would "
                "remove it"
            )
        for k in by_headings:
            notes.append(
                f"{both(k)}: it is limited by how well the headings are known against the fall line "
                f"(±{errors.limits.heading_deg}°), which no residual can show. Give heading_deg in "
                f"{option('sensor_spec')} if they are better known (surveyed marks, a dual-antenna GNSS heading), "
                "or log a drive with vehicle speed (yaw from driving needs no heading)"
            )
    sigmas = AngleValues(*(total(s, sys_a[k]) for k, s in stat_a.items()))
    rot = zip(Systematic.rotation_of(stat), Systematic.rotation_of(sys_sigma), strict=True)
    x, y, z = (total(s, t) for s, t in rot)
    return replace(
        cal.with_angles(cal.angles.with_sigmas(sigmas)),
        rotation_sigma_deg=(x, y, z),
        systematic=part,
        notes=tuple(notes),
    )


def assess(cal: Calibration, table: StopTable, fit: full.Fit, errors: SensorErrors) -> Calibration:
    """Propagate ``errors`` through the final fit and fold them into ``cal``'s σ."""
    state = fit.state
    cov, used, explained, heading_cov = propagate(
        table, state, fit.names, fit.terms, state.g_mps2, errors, fit.noise_scale
    )
    birge = cal.fit.birge_ratio
    if birge > 1.0 and fit.noise_known and fit.dof > 0:  # the structure the sensor errors explain is in sys already
        rest = float(np.sqrt(max(1.0, (fit.chi2 - explained) / fit.dof)))
        cal = _rescaled(cal, rest / birge, rest)
    yaw, slope = cal.yaw_deg is not None, cal.slope_deg is not None
    sig = angle_sigmas(cov, fit.names, state.rot_vs, yaw, slope)
    # which part dominates decides what the note tells the user to do
    sensor_only = angle_sigmas(cov - heading_cov, fit.names, state.rot_vs, yaw, slope) if HEADING in used else None
    return combine(cal, sig, errors, used, sensor_only)


def _rescaled(cal: Calibration, factor: float, birge: float) -> Calibration:
    """The statistical σ with the Birge ratio of what the sensor errors leave unexplained."""

    def times(x: float | None) -> float | None:
        return None if x is None else x * factor

    x, y, z = (times(s) for s in cal.rotation_sigma_deg)
    return replace(
        cal.with_angles(cal.angles.widened(factor)),
        rotation_sigma_deg=(x, y, z),
        fit=replace(cal.fit, birge_ratio=birge, birge_note="χ² less what the sensor errors' mean explains"),
    )


def _short(names: tuple[str, ...]) -> list[str]:
    """What a person calls each error (as its effect says), each once."""
    effects = {p: e for e in registry.registered().values() for p in e.spec_limits(SensorSpec())}
    return list(dict.fromkeys(effects[n].label(n) if n in effects else n for n in names))


def summary_line(part: Systematic) -> str:
    """One line for the CLI summary: both parts of the tilt and yaw σ, and where the limits come from."""
    st, sy = part.statistical_angles, part.systematic_angles
    both = ", ".join(f"{k} {s:.3g}° / {sy[k] or 0.0:.3g}°" for k, s in st.items(ANGLE_NAMES[:3]) if s is not None)
    return f"σ statistical / systematic: {both} (sensor: {part.source})"


_DEFAULT_SRC = SensorSpec().source
