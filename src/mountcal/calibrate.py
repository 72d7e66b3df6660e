"""From a stop table to a :class:`~mountcal.result.Calibration`: method, model choice, honesty.

- ``method="full"`` (default): maximum likelihood on SO(3) (:mod:`mountcal.estimate.full`);
  ``model="auto"`` adds a constant bias only when a likelihood-ratio test (F-test when the stop
  noise is unknown) says the data call for it.
- ``method="paper"``: the paper's closed form (:mod:`mountcal.estimate.paper`), for comparison.

Yaw is reported only when the headings are measured from the uphill direction and the slope
makes it precise enough (MODEL.md §4); otherwise it is None with the reason.
"""

from __future__ import annotations

import importlib.metadata
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any, Literal

import numpy as np
from scipy import stats
from scipy.spatial.transform import Rotation

from mountcal.conventions import (
    G_N,
    GIMBAL_LOCK_PITCH_DEG,
    FloatArray,
    angles_from_rot_vs,
    normal_gravity,
)
from mountcal.errors import InputError, NotEnoughInformation
from mountcal.estimate import full, paper
from mountcal.estimate.geometry import span_ratio
from mountcal.result import Calibration
from mountcal.stoptable import StopTable

Method = Literal["full", "paper"]
BASE: tuple[str, ...] = ("rotation", "slope")
WITH_BIAS: tuple[str, ...] = ("rotation", "slope", "bias")
MODELS = {"rotation,slope": BASE, "rotation,slope,bias": WITH_BIAS}
MIN_DISTINCT_HEADINGS = 3
MAX_BIAS_TILT_SIGMA_DEG = 5.0  # beyond this a bias cannot be told from a tilt (level ground)
NULL_TOL = 1e-8
BAD_FIT_P = 1e-3  # a χ² this improbable means the model misses an effect  # relative eigenvalue below which a Fisher direction counts as unobservable


@dataclass(frozen=True)
class Options:
    """Settings of a calibration run (defaults are the CLI's)."""

    method: Method = "full"
    model: str = "auto"
    gravity_mps2: float | None = None
    max_yaw_sigma_deg: float = 5.0
    selection_alpha: float = 0.01


def calibrate(table: StopTable, options: Options | None = None) -> Calibration:
    """Estimate the mounting rotation (and slope, and bias when called for) from a stop table."""
    opts = options or Options()
    _check_geometry(table)
    g, g_source = _gravity(table, opts.gravity_mps2)
    if opts.method == "paper":
        return _paper(table, g, g_source, opts)
    if opts.method != "full":
        raise InputError("--method", "paper or full", repr(opts.method), "Choose one of them.")
    return _full(table, g, g_source, opts)


def parse_model(spec: str) -> tuple[str, ...] | None:
    """``"auto"`` → None; ``"rotation,slope[,bias]"`` → the terms."""
    key = ",".join(t.strip() for t in spec.split(","))
    if key == "auto":
        return None
    if key not in MODELS:
        raise InputError("--model", f"auto or one of {', '.join(MODELS)}", repr(spec), "Pick one of those.")
    return MODELS[key]


# --- the full estimator -------------------------------------------------------------------------


def _full(table: StopTable, g: float, g_source: str, opts: Options) -> Calibration:
    fixed = parse_model(opts.model)
    start = full.initial_state(table, g)
    base = full.fit(table, BASE, g, start)
    selection: dict[str, Any] = {"mode": "fixed" if fixed else "auto", "candidates": [_summary(base)]}
    chosen = base
    if fixed == WITH_BIAS:
        chosen = full.fit(table, WITH_BIAS, g, base.state)
        selection["candidates"].append(_summary(chosen))
    elif fixed is None:
        chosen = _select_bias(table, g, base, opts.selection_alpha, selection)
    selection["chosen"] = list(chosen.terms)
    return _result_from_fit(table, chosen, g, g_source, opts, selection)


def _select_bias(table: StopTable, g: float, base: full.Fit, alpha: float, selection: dict[str, Any]) -> full.Fit:
    """Nested-model test: rotation,slope against rotation,slope,bias."""
    if base.dof - 3 < 1:
        selection["test"] = "not enough stops to test for a bias (needs 3n > parameters + 3)"
        return base
    tilt_sigma = _bias_model_tilt_sigma_deg(table, base, g)
    if tilt_sigma > MAX_BIAS_TILT_SIGMA_DEG:
        selection["test"] = (
            f"bias not separable from tilt: with a bias the tilt 1σ would be {tilt_sigma:.3g}° "
            f"at slope {np.degrees(base.state.slope_rad):.3g}° (limit {MAX_BIAS_TILT_SIGMA_DEG:g}°); "
            "park on a steeper slope to estimate a bias"
        )
        return base
    biased = full.fit(table, WITH_BIAS, g, base.state)
    selection["candidates"].append(_summary(biased))
    if base.noise_known:
        statistic = base.chi2 - biased.chi2
        p_value = float(stats.chi2.sf(statistic, 3))
        test = "likelihood-ratio test (χ², 3 dof; stop covariances known)"
    else:
        statistic = ((base.chi2 - biased.chi2) / 3.0) / (biased.chi2 / biased.dof)
        p_value = float(stats.f.sf(statistic, 3, biased.dof))
        test = f"F-test (3, {biased.dof} dof; stop noise estimated from the residuals)"
    selection.update(test=test, statistic=float(statistic), p_value=p_value, alpha=alpha)
    return biased if p_value < alpha else base


def _bias_model_tilt_sigma_deg(table: StopTable, base: full.Fit, g: float) -> float:
    """The larger tilt 1σ (deg) a bias fit would have at the base fit's point (its CRB)."""
    info, _ = full.information(table, base.state, WITH_BIAS, g)
    cov = np.linalg.pinv(info) * base.noise_scale**2
    return float(np.degrees(np.sqrt(max(cov[0, 0], cov[1, 1]))))


def _summary(f: full.Fit) -> dict[str, Any]:
    p = len(f.names)
    n_obs = f.dof + p
    s2 = 1.0 if f.noise_known else f.chi2 / max(f.dof, 1)
    return {
        "terms": list(f.terms),
        "chi2": f.chi2,
        "dof": f.dof,
        "residual_rms_mps2": float(np.sqrt(np.mean(f.residual_s**2))),
        "aic": float(f.chi2 / s2 + 2 * p) if f.noise_known else float(n_obs * np.log(f.chi2 / n_obs) + 2 * p),
    }


def _result_from_fit(
    table: StopTable, f: full.Fit, g: float, g_source: str, opts: Options, selection: dict[str, Any]
) -> Calibration:
    names = list(f.names)
    k = 3 if "rot_z" in names else 2
    cov_rot = f.cov[:k, :k]
    grads = _euler_gradients(f.state.rot_vs, k)  # rows roll, pitch, yaw over δ
    null = _null_space(f.fisher)
    notes: list[str] = []
    if "not separable" in str(selection.get("test", "")):
        notes.append(
            "a constant accelerometer bias cannot be told from a tilt on this slope: if the sensor has a "
            "bias b, roll and pitch are off by up to b/g (20 mg → 1.1°) beyond their σ (MODEL.md §4)"
        )

    def sigma(grad: FloatArray, idx: slice | list[int]) -> float | None:
        c = np.zeros(len(names))
        c[idx] = grad
        if null.size and np.linalg.norm(null.T @ c) > 1e-6 * np.linalg.norm(c):
            return None
        return float(np.sqrt(max(float(c @ f.cov @ c), 0.0)))

    roll, pitch, yaw = (float(np.degrees(a)) for a in angles_from_rot_vs(f.state.rot_vs))
    s_roll = sigma(grads[0], slice(0, k))
    s_pitch = sigma(grads[1], slice(0, k))
    if s_roll is None or s_pitch is None:
        raise NotEnoughInformation(
            f"{table.source}: roll and pitch are not determined by these stops with the model "
            f"{', '.join(f.terms)} (the Fisher information is singular). On level ground a bias cannot be "
            "told from a tilt: park on a slope, or fit without a bias (--model rotation,slope)."
        )
    yaw_out: float | None = yaw
    s_yaw = sigma(grads[2], slice(0, k)) if k == 3 else None
    yaw_reason = _yaw_reason(table, s_yaw, f, opts)
    if yaw_reason is not None:
        yaw_out, s_yaw = None, None
    if f.noise_known and f.dof > 0 and stats.chi2.sf(f.chi2, f.dof) < BAD_FIT_P:
        notes.append(
            f"the model does not explain these stops: χ² = {f.chi2:.1f} on {f.dof} dof "
            f"(p = {stats.chi2.sf(f.chi2, f.dof):.2g}); the σ above assume it does and are too small"
        )
    if abs(pitch) > GIMBAL_LOCK_PITCH_DEG:
        notes.append(
            f"pitch {pitch:.2f}° is within {90 - GIMBAL_LOCK_PITCH_DEG:g}° of ±90°: roll and yaw are not separately "
            "meaningful there; use the rotation (quaternion) and the uncertainty about the vehicle axes."
        )

    i_slope = names.index("slope")
    slope = float(np.degrees(f.state.slope_rad))
    s_slope = sigma(np.ones(1), [i_slope])
    bias = bias_sigma = None
    if "bias" in f.terms:
        i_b = names.index("bias_x")
        bias = f.state.bias_s.copy()
        bias_sigma = np.sqrt(np.diag(f.cov)[i_b : i_b + 3])
    rot_sigma = np.degrees(np.sqrt(np.clip(np.diag(cov_rot), 0, None)))
    rotation_sigma = (
        float(rot_sigma[0]),
        float(rot_sigma[1]),
        float(rot_sigma[2]) if yaw_out is not None else None,
    )

    fit_info = {
        "chi2": f.chi2,
        "dof": f.dof,
        "p_value": float(stats.chi2.sf(f.chi2, f.dof)) if f.noise_known and f.dof > 0 else None,
        "noise": "per-stop covariance from the table" if f.noise_known else "common σ estimated from the residuals",
        "noise_scale_mps2": None if f.noise_known else f.noise_scale,
        "iterations": f.iterations,
        "headings": table.headings,
    }
    return Calibration(
        method="full",
        model=f.terms,
        rot_vs=f.state.rot_vs,
        roll_deg=roll,
        pitch_deg=pitch,
        yaw_deg=yaw_out,
        roll_sigma_deg=float(np.degrees(s_roll)),
        pitch_sigma_deg=float(np.degrees(s_pitch)),
        yaw_sigma_deg=None if s_yaw is None else float(np.degrees(s_yaw)),
        yaw_reason=yaw_reason,
        slope_deg=slope,
        slope_sigma_deg=None if s_slope is None else float(np.degrees(s_slope)),
        rotation_sigma_deg=rotation_sigma,
        bias_mps2=bias,
        bias_sigma_mps2=bias_sigma,
        gravity_mps2=g,
        gravity_source=g_source,
        residual_rms_mps2=float(np.sqrt(np.mean(f.residual_s**2))),
        residual_s=f.residual_s,
        fit=fit_info,
        observability=_observability(table, f, g),
        model_selection=selection,
        provenance=_provenance(table, "full", f.terms),
        notes=tuple(notes),
    )


def _yaw_reason(table: StopTable, s_yaw: float | None, f: full.Fit, opts: Options) -> str | None:
    if table.headings == "none":
        return "no headings: the stops carry no β, so the rotation about the vertical is unobservable"
    if table.headings == "relative":
        return (
            "headings are relative (an unknown common offset from the uphill direction): "
            "yaw and that offset cannot be separated"
        )
    slope = np.degrees(f.state.slope_rad)
    if s_yaw is None:
        return f"slope {slope:.3g}° gives no information on yaw (level ground)"
    if np.degrees(s_yaw) > opts.max_yaw_sigma_deg:
        return (
            f"slope {slope:.3g}° too small to determine yaw: its 1σ would be {np.degrees(s_yaw):.3g}° "
            f"(limit {opts.max_yaw_sigma_deg:g}°); yaw precision grows as 1/sin(slope)"
        )
    return None


def _observability(table: StopTable, f: full.Fit, g: float) -> dict[str, Any]:
    scale = np.sqrt(np.clip(np.diag(f.fisher), 1e-300, None))
    eig = np.linalg.eigvalsh(f.fisher / np.outer(scale, scale))
    rank = int(np.sum(eig > NULL_TOL * eig.max()))
    crb: dict[str, Any] = {}
    for terms in (BASE, WITH_BIAS):
        info, names = full.information(table, f.state, terms, g)
        try:
            cov = np.linalg.inv(info) * f.noise_scale**2
        except np.linalg.LinAlgError:
            crb[",".join(terms)] = None
            continue
        k = 3 if "rot_z" in names else 2
        grads = _euler_gradients(f.state.rot_vs, k)
        sig = [float(np.degrees(np.sqrt(max(c @ cov[:k, :k] @ c, 0.0)))) for c in grads]
        crb[",".join(terms)] = {
            "roll_deg": sig[0],
            "pitch_deg": sig[1],
            "yaw_deg": sig[2] if k == 3 else None,
            "slope_deg": float(np.degrees(np.sqrt(cov[k, k]))),
        }
    return {
        "parameters": list(f.names),
        "n_parameters": len(f.names),
        "fisher_rank": rank,
        "condition_number": float(eig.max() / eig.min()) if eig.min() > 0 else None,
        "crb_1sigma": crb,
        "crb_note": "Cramér–Rao bounds for this stop set at the fitted point, per model"
        + ("" if f.noise_known else ", with the noise σ estimated from the residuals"),
    }


def _euler_gradients(rot: Rotation, k: int, h: float = 1e-7) -> FloatArray:
    """∂(roll, pitch, yaw)/∂δ for a left perturbation δ about the vehicle axes; shape (3, k)."""
    grads = np.zeros((3, k))
    for j in range(k):
        d = np.zeros(3)
        d[j] = h
        up = np.array(angles_from_rot_vs(Rotation.from_rotvec(d) * rot))
        down = np.array(angles_from_rot_vs(Rotation.from_rotvec(-d) * rot))
        grads[:, j] = np.angle(np.exp(1j * (up - down))) / (2 * h)
    return grads


def _null_space(fisher: FloatArray) -> FloatArray:
    scale = np.sqrt(np.clip(np.diag(fisher), 1e-300, None))
    eig, vec = np.linalg.eigh(fisher / np.outer(scale, scale))
    null = vec[:, eig < NULL_TOL * eig.max()]
    return null / scale[:, None] if null.size else null  # back to parameter coordinates


# --- the paper's method --------------------------------------------------------------------------


def _paper(table: StopTable, g: float, g_source: str, opts: Options) -> Calibration:
    if opts.model not in ("auto", "rotation,slope"):
        raise InputError(
            "--model",
            "auto or rotation,slope with --method paper",
            repr(opts.model),
            "The paper's method fits no bias; use --method full for other models.",
        )
    est, cov, noise_scale, residual = paper.paper_method(table, g)
    roll, pitch, yaw = (float(np.degrees(a)) for a in angles_from_rot_vs(est.rot_vs))
    sig = np.degrees(np.sqrt(np.clip(np.diag(cov), 0, None)))
    notes = []
    yaw_reason = None
    if table.headings == "relative":
        yaw_reason = "headings are relative (an unknown common offset): yaw and that offset cannot be separated"
    elif sig[2] > opts.max_yaw_sigma_deg:
        yaw_reason = f"yaw 1σ {sig[2]:.3g}° exceeds the limit {opts.max_yaw_sigma_deg:g}°: slope too small"
    slope = None if est.slope_rad is None else float(np.degrees(est.slope_rad))
    if est.slope_rad is None:
        notes.append(
            f"step 2 failed: cos α = {est.cos_slope:.6f} > 1 from the opposite-heading pairs (a vertical bias, scale "
            "error or wrong g); slope not determined. The full estimator takes α from the circle's radius instead."
        )
    return Calibration(
        method="paper",
        model=BASE,
        rot_vs=est.rot_vs,
        roll_deg=roll,
        pitch_deg=pitch,
        yaw_deg=None if yaw_reason else yaw,
        roll_sigma_deg=float(sig[0]),
        pitch_sigma_deg=float(sig[1]),
        yaw_sigma_deg=None if yaw_reason else float(sig[2]),
        yaw_reason=yaw_reason,
        slope_deg=slope,
        slope_sigma_deg=None if slope is None else float(sig[3]),
        rotation_sigma_deg=(None, None, None),
        bias_mps2=None,
        bias_sigma_mps2=None,
        gravity_mps2=g,
        gravity_source=g_source,
        residual_rms_mps2=float(np.sqrt(np.mean(residual**2))),
        residual_s=residual,
        fit={
            "pairs": est.n_pairs,
            "cos_slope": est.cos_slope,
            "headings": table.headings,
            "noise": "per-stop covariance from the table" if table.cov_s is not None else "common σ from residuals",
            "noise_scale_mps2": None if table.cov_s is not None else noise_scale,
            "uncertainty": "first-order propagation of the stop noise through the paper's steps",
        },
        observability={},
        model_selection={"mode": "fixed", "chosen": list(BASE)},
        provenance=_provenance(table, "paper", BASE),
        notes=tuple(notes),
    )


# --- shared ------------------------------------------------------------------------------------


def _check_geometry(table: StopTable) -> None:
    if table.beta_rad is not None and table.headings != "none":
        distinct = np.unique(np.round(np.degrees(table.beta_rad) % 360.0, 3))
        if distinct.size < MIN_DISTINCT_HEADINGS:
            raise NotEnoughInformation(
                f"{table.source}: expected stops at ≥ {MIN_DISTINCT_HEADINGS} different headings, found "
                f"{distinct.size} ({', '.join(f'{b:g}°' for b in distinct)}). The stops must span a circle: "
                "park at more headings (the paper uses 12, 30° apart)."
            )
    if span_ratio(table.acc_s) < 1e-6:
        raise NotEnoughInformation(
            f"{table.source}: the stop means lie on a line, so they span no plane. Park at more different headings."
        )


def _gravity(table: StopTable, given: float | None) -> tuple[float, str]:
    if given is not None:
        return float(given), "given by the user"
    if table.lat_deg is not None and np.all(np.isfinite(table.lat_deg)):
        lat = float(np.mean(table.lat_deg))
        alt = float(np.mean(table.alt_m)) if table.alt_m is not None else 0.0
        return normal_gravity(lat, alt), f"WGS 84 normal gravity at latitude {lat:.4f}°, height {alt:.0f} m"
    return (
        G_N,
        "assumed standard gravity 9.80665 m/s² (no position known); local gravity differs by up to ±0.27 %",
    )


def _provenance(table: StopTable, method: str, terms: tuple[str, ...]) -> dict[str, Any]:
    try:
        version = importlib.metadata.version("mountcal")
    except importlib.metadata.PackageNotFoundError:
        version = "unknown"
    return {
        "input": table.source,
        "input_sha256": table.sha256 or None,
        "software": f"mountcal {version}",
        "method": method,
        "model": list(terms),
        "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
    }
