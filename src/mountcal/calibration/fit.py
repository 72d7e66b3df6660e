"""From a stop table to a :class:`~mountcal.core.result.Calibration`: method, model choice, honesty.

- ``method="full"`` (default): maximum likelihood on SO(3) (:mod:`mountcal.estimate.full`);
  ``model="auto"`` adds an effect (:mod:`mountcal.estimate.effects`) only when a likelihood-ratio test
  (F-test when the stop noise is unknown) says the data call for it.
- ``method="paper"``: the paper's closed form (:mod:`mountcal.estimate.paper`), for comparison.

Yaw is reported only when the headings are measured from the uphill direction and the slope
makes it precise enough (docs/conventions.md §4); otherwise it is None with the reason.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from mountcal.calibration.options import Options
from mountcal.calibration.record import (
    GIVEN,
    MAX_CONFIDENT_TILT_SIGMA_DEG,
    fit_doubts,
    fit_provenance,
    gravity_convention,
    local_gravity,
)
from mountcal.core.conventions import (
    G_N,
    GIMBAL_LOCK_PITCH_DEG,
    FloatArray,
    angles_from_rot_vs,
)
from mountcal.core.errors import FitFailed, InputError, NotEnoughInformation
from mountcal.core.option_names import option
from mountcal.core.pvalues import chi2_logsf, chi2_sf, unexplained
from mountcal.core.result import (
    Angles,
    AngleValues,
    Calibration,
    Convention,
    FitQuality,
    ModelSelection,
    ModelStep,
    Observability,
    Separability,
)
from mountcal.estimate import effects as registry
from mountcal.estimate import full, paper
from mountcal.estimate.bound import crb_deg, euler_gradients
from mountcal.estimate.geometry import span_ratio
from mountcal.estimate.observability import separability
from mountcal.estimate.sensor_errors import SensorErrors, from_spec
from mountcal.io.frame import with_frame_note
from mountcal.io.input_conventions import merged
from mountcal.loop import crosscheck, plausibility, slope_reference
from mountcal.loop import terms as model_terms
from mountcal.loop.half_turn import reversed_stops
from mountcal.loop.model_choice import close_the_loop, effect_values
from mountcal.loop.sign import other_table_sign, turned_once, with_turn_note
from mountcal.loop.steps import Loop, Step
from mountcal.loop.systematic import assess
from mountcal.stops.table import StopTable, check_count

BASE = full.BASE
WITH_OFFSET: tuple[str, ...] = (*BASE, registry.offset().name)  # the paper's model with a constant offset
MIN_DISTINCT_HEADINGS = 3


def calibrate(table: StopTable, options: Options | None = None, *, sign_by_caller: bool = False) -> Calibration:
    """Estimate the mounting rotation (and slope, and bias when called for) from a stop table.

    Besides the fit, the stops' headings are checked against their pattern (a mirrored sensor is
    refused, :func:`mountcal.loop.crosscheck.stops_sense`) and the answer's plausibility
    (:mod:`mountcal.loop.plausibility`); the checks and the input's conventions are in the result.
    An acceleration sign only assumed (a stop table of a Sensor Logger recording from iOS, its column
    ``acceleration_sign``) is turned round once where the stops go round mirrored (:mod:`mountcal.loop.sign`),
    and leaves the result not confident where no handedness check confirms it; ``sign_by_caller``: a log's
    pipeline does both on its samples (:mod:`mountcal.calibration.pipeline`), with the drive's turns too.
    """
    opts = options or Options()
    if sign_by_caller:
        return _calibrate(table, opts, False)
    cal = turned_once(lambda t: _calibrate(t, opts, True), table, other_table_sign, _conventions)
    return with_turn_note(cal, table.conventions)


def _conventions(table: StopTable) -> tuple[Convention, ...]:
    return table.conventions


def _calibrate(table: StopTable, opts: Options, check_sign: bool) -> Calibration:
    if opts.triad is not None:
        table = opts.triad.correct(table)
    _check_geometry(table)
    sense = crosscheck.stops_sense(table)  # before the fit: a mirror image fits as the mirror branch
    if opts.slope_reference is not None:
        _check_slope_reference(table, opts)
    g, g_source = local_gravity(table.lat_deg, table.alt_m, opts.gravity_mps2)
    if opts.method == "paper":
        cal = _paper(table, g, g_source, opts)
    else:
        cal = _full(table, g, g_source, opts)
    stated = merged(table.conventions, (gravity_convention(g_source),))
    checks = [
        *plausibility.convention_checks(stated),
        sense,
        crosscheck.heading_agreement(table),
        *plausibility.answer_checks(cal),
    ]
    signed = plausibility.sign_check(stated, checks) if check_sign else None  # a sign only assumed: confirmed?
    if signed is not None:
        checks.append(signed[0])
        stated = merged(stated, (signed[1],))
    notes = with_frame_note(cal.notes, stated)  # stops of rotated samples: the angles are what is left over
    backward = plausibility.backward_yaw_note(cal, table.headings)
    notes = notes if backward is None else (*notes, backward)
    cal = replace(cal, provenance=replace(cal.provenance, conventions=stated), notes=notes)
    return plausibility.with_checks(cal, checks)


def check_model(table: StopTable, terms: tuple[str, ...]) -> None:
    """Refuse a fixed model whose terms need a column the table lacks, or values it does not vary (the effect
    says why, :meth:`~mountcal.estimate.effects.base.Effect.unusable`)."""
    known = model_terms.by_name()
    for name in terms:
        missing = [c for c in known[name].needs if getattr(table, _FIELD.get(c, c), None) is None]
        if missing:
            raise InputError(
                f"{table.source} with {option('model', ','.join(terms))}",
                f"the column {', '.join(missing)} for the term {name}",
                "no such column",
                f"Add the column, or leave {name} out of {option('model')} (or use {option('model', 'auto')}).",
            )
    effects = registry.registered()
    for name in terms:
        why = effects[name].unusable(table) if name in effects else None
        if why is not None:
            raise NotEnoughInformation(f"{table.source}: the term {name} {why}. Leave {name} out of {option('model')}.")


_FIELD = {"temperature_c": "temperature_c", "site": "site"}


# --- the full estimator -------------------------------------------------------------------------


def _full(table: StopTable, g: float, g_source: str, opts: Options) -> Calibration:
    fixed = opts.terms
    if fixed is not None:
        check_model(table, fixed)
    from_position = g_source.startswith("WGS 84")
    try:
        loop = close_the_loop(
            table,
            g,
            gravity_known=from_position or g_source == GIVEN,
            alpha=opts.selection_alpha,
            fixed=fixed,
            g_prior=G_N if from_position else None,
        )
    except FitFailed as err:
        raise FitFailed(_not_converged(table, fixed, str(err))) from err
    final = loop.final
    f = final.fit
    angles = _angles(final.table, f, opts)
    if angles.roll_sigma_deg is None or angles.pitch_sigma_deg is None:
        raise NotEnoughInformation(
            f"{table.source}: roll and pitch are not determined by these stops with the model "
            f"{', '.join(f.terms)} (the Fisher information is singular). On level ground a bias cannot be "
            f"told from a tilt: park on a slope, or fit without a bias ({option('model', 'rotation,slope')})."
        )
    notes: list[str] = []
    declined = tuple(loop.declined)
    inseparable = [d.effect for d in declined if "separable" in d.why or "confounded" in d.why]
    for name in dict.fromkeys(inseparable):
        note = registry.get(name).inseparable_note if name in registry.registered() else None
        if note is not None:
            notes.append(note)
    findings = list(loop.findings)
    if opts.slope_reference is not None:
        noise_dof = None if f.noise_known else f.dof
        findings.append(
            slope_reference.check(angles.slope_deg, angles.slope_sigma_deg, opts.slope_reference, noise_dof)
        )
    flagged = unexplained(findings)
    birge = 1.0
    if flagged:
        if f.noise_known and f.dof > 0:
            birge = max(1.0, float(np.sqrt(f.chi2 / f.dof)))
        notes.append(
            "the best model leaves structure unexplained ("
            + "; ".join(f"{u.what}: {u.size}" for u in flagged)
            + f"); the σ are widened ×{birge:.2f} (Birge ratio) and the result is not confident"
        )
        turned = reversed_stops(table, g)  # what a heading slip explains (said, not applied)
        if turned is not None:
            notes.append(turned)
    if any(u.test == slope_reference.TEST for u in flagged):
        notes.append(
            "the stops read the body at another slope than the reference. If the reference is the ground's, the body "
            "leaning downhill on its suspension (a car's roll gradient of 3–7°/g: 5–12 % of the slope) is the likely "
            "cause: measure the body's inclination instead (a level on the body facing uphill and downhill, half the "
            "difference). Otherwise: a common scale error of the sensor's horizontal axes, axes that tilt with the "
            "lateral load (a compliant mount or cradle), or a wrong reference; the stops alone cannot tell these from "
            "the slope"
            + (
                ""
                if opts.triad is not None
                else f". A triad calibration (`mountcal triad`, then {option('triad')}) removes the scale error"
            )
        )
    tilt_sigma = max(angles.roll_sigma_deg, angles.pitch_sigma_deg) * birge
    doubts = [*loop.doubts, *fit_doubts(f.branch, tilt_sigma, None if f.noise_known else f.dof)]
    notes += [d + "; the result is not confident" for d in doubts]
    pitch = angles.pitch_deg
    if abs(pitch) > GIMBAL_LOCK_PITCH_DEG:
        notes.append(
            f"pitch {pitch:.2f}° is within {90 - GIMBAL_LOCK_PITCH_DEG:g}° of ±90°: roll and yaw are not separately "
            "meaningful there; use the rotation (quaternion) and the uncertainty about the vehicle axes."
        )
    model = list(f.terms)
    gravity = registry.gravity_term()
    if from_position and gravity not in model:
        model.append(gravity)
    if final.excluded:
        model.append("outlier")

    k = 3 if "rot_z" in f.names else 2
    rot_sigma = np.degrees(np.sqrt(np.clip(np.diag(f.cov[:k, :k]), 0, None))) * birge
    effects = effect_values(f)
    bias, bias_sigma = registry.offset_fields(effects, birge)
    tested = f.noise_known and f.dof > 0
    fit_info = FitQuality(
        noise="per-stop covariance from the table" if f.noise_known else "common σ estimated from the residuals",
        headings=table.headings,
        chi2=f.chi2,
        dof=f.dof,
        p_value=float(chi2_sf(f.chi2, f.dof)) if tested else None,
        log10_p=float(chi2_logsf(f.chi2, f.dof)) / math.log(10) if tested else None,
        noise_scale_mps2=None if f.noise_known else f.noise_scale,
        iterations=f.iterations,
        excluded_stops=tuple(i + 1 for i in final.excluded),
        birge_ratio=birge,
        branch=f.branch,
    )
    selection = ModelSelection(
        mode="fixed" if fixed else "auto",
        chosen=tuple(model),
        alpha=opts.selection_alpha,
        steps=tuple(s.added for s in loop.steps),
        declined=declined,
    )
    cal = Calibration(
        method="full",
        model=tuple(model),
        rot_vs=f.state.rot_vs,
        **Calibration.angle_fields(angles.widened(birge)),
        rotation_sigma_deg=(
            float(rot_sigma[0]),
            float(rot_sigma[1]),
            float(rot_sigma[2]) if angles.yaw_deg is not None else None,
        ),
        bias_mps2=bias,
        bias_sigma_mps2=bias_sigma,
        gravity_mps2=f.state.g_mps2,
        gravity_source="fitted to the stops" if gravity in f.terms else g_source,
        residual_rms_mps2=float(np.sqrt(np.mean(f.residual_s**2))),
        residual_s=_all_residuals(table, final),
        fit=fit_info,
        observability=_observability(final.table, f, g),
        model_selection=selection,
        provenance=fit_provenance(table, "full", tuple(model)),
        notes=tuple(notes),
        model_steps=_steps(loop, opts),
        unexplained=tuple(flagged),
        diagnostics=tuple(findings),
        effects=effects,
        confident=not flagged and not doubts,
    )
    return _with_systematic(cal, final.table, f, opts)


def _with_systematic(cal: Calibration, table: StopTable, f: full.Fit, opts: Options) -> Calibration:
    """The σ made total (statistical and systematic, :mod:`mountcal.loop.systematic`); confident only if the
    total allows."""
    out = assess(cal, table, f, sensor_errors(opts))
    # the tilt's own σ (about the vehicle's x and y axes): roll's σ grows as 1/cos(pitch) near ±90° without the
    # tilt being any less known
    tilt = max(s for s in out.rotation_sigma_deg[:2] if s is not None)
    doubts = fit_doubts(None, tilt, None)
    if doubts and max(cal.roll_sigma_deg, cal.pitch_sigma_deg) <= MAX_CONFIDENT_TILT_SIGMA_DEG:
        out = replace(out, confident=False, notes=(*out.notes, *(d + "; the result is not confident" for d in doubts)))
    return out


def _check_slope_reference(table: StopTable, opts: Options) -> None:
    """Refuse a slope reference the fit cannot check: one slope is given, the stops must be on one slope."""
    if opts.method == "paper":
        raise InputError(
            option("slope_reference"),
            option("method", "full"),
            option("method", "paper"),
            f"The reference is checked by the full estimator's residual tests; use {option('method', 'full')}.",
        )
    sites = [] if table.site is None else np.unique(table.site.astype(str)).tolist()
    if len(sites) > 1:
        raise InputError(
            f"{table.source} with {option('slope_reference')}",
            "stops on one slope",
            f"{len(sites)} sites ({', '.join(sites[:5])}{', …' if len(sites) > 5 else ''})",
            "Calibrate each site's stops with its own reference, or leave the reference out.",
        )


def sensor_errors(opts: Options) -> SensorErrors:
    """The sensor errors left for the systematic part: the triad's covariance when one is applied, else the spec."""
    return opts.triad.errors(opts.spec) if opts.triad is not None else from_spec(opts.spec)


def _angles(table: StopTable, f: full.Fit, opts: Options) -> Angles:
    """Roll, pitch, yaw, slope in degrees with 1σ (None where the data cannot determine them)."""
    k = 3 if "rot_z" in f.names else 2
    grads = euler_gradients(f.state.rot_vs, k)  # rows roll, pitch, yaw over δ
    null = full.null_space(f.fisher)

    def sigma(grad: FloatArray, idx: slice | list[int]) -> float | None:
        c = np.zeros(len(f.names))
        c[idx] = grad
        if null.size and np.linalg.norm(null.T @ c) > 1e-6 * np.linalg.norm(c):
            return None
        return float(np.degrees(np.sqrt(max(float(c @ f.cov @ c), 0.0))))

    roll, pitch, yaw = (float(np.degrees(a)) for a in angles_from_rot_vs(f.state.rot_vs))
    s_yaw = sigma(grads[2], slice(0, k)) if k == 3 else None
    yaw_reason = _yaw_reason(table, None if s_yaw is None else np.radians(s_yaw), f, opts)
    slope_names = [i for i, n in enumerate(f.names) if n.startswith("slope")]
    single = len(slope_names) == 1
    return Angles(
        roll_deg=roll,
        roll_sigma_deg=sigma(grads[0], slice(0, k)),
        pitch_deg=pitch,
        pitch_sigma_deg=sigma(grads[1], slice(0, k)),
        yaw_deg=None if yaw_reason else yaw,
        yaw_sigma_deg=None if yaw_reason else s_yaw,
        yaw_reason=yaw_reason,
        slope_deg=float(np.degrees(f.state.slope_rad[0])) if single else None,
        slope_sigma_deg=sigma(np.ones(1), slope_names) if single else None,
    )


def _steps(loop: Loop, opts: Options) -> tuple[ModelStep, ...]:
    """The before/after table: each model step with its fit quality, angles ± σ and what moved."""
    out: list[ModelStep] = []
    prev: Angles | None = None
    for step in loop.steps:
        f = step.fit
        a = _angles(step.table, f, opts)
        moved = None
        if prev is not None:
            moved = AngleValues(
                *(
                    None if now is None or before is None else float(now - before)
                    for now, before in (
                        (a.roll_deg, prev.roll_deg),
                        (a.pitch_deg, prev.pitch_deg),
                        (a.yaw_deg, prev.yaw_deg),
                        (a.slope_deg, prev.slope_deg),
                    )
                )
            )
        out.append(
            ModelStep(
                added=step.added,
                reason=step.reason,
                terms=tuple(f.terms),
                excluded_stops=tuple(i + 1 for i in step.excluded),
                gravity_mps2=f.state.g_mps2,
                chi2=f.chi2,
                dof=f.dof,
                residual_rms_mps2=float(np.sqrt(np.mean(f.residual_s**2))),
                loo_rms_mps2=step.loo_rms_mps2,
                angles=a,
                moved=moved,
                effects=effect_values(f),
            )
        )
        prev = a
    return tuple(out)


def _all_residuals(table: StopTable, step: Step) -> FloatArray:
    """Residual of every stop of the table (excluded ones predicted by the final model; NaN if not)."""
    if not step.excluded:
        return step.fit.residual_s
    out = np.full((len(table), 3), np.nan)
    keep = np.setdiff1d(np.arange(len(table)), step.excluded)
    out[keep] = step.fit.residual_s
    if table.headings != "none":
        pred = full.StaticModel(table, step.fit.terms, step.fit.state.g_mps2).predict(step.fit.state)
        out[list(step.excluded)] = table.acc_s[list(step.excluded)] - pred[list(step.excluded)]
    return out


def _yaw_reason(table: StopTable, s_yaw: float | None, f: full.Fit, opts: Options) -> str | None:
    if table.headings == "none":
        return "no headings: the stops carry no β, so the rotation about the vertical is unobservable"
    if table.headings == "relative":
        return (
            "headings are relative (an unknown common offset from the uphill direction): "
            "yaw and that offset cannot be separated"
        )
    slope = np.degrees(f.state.slope_rad[0])
    if s_yaw is None:
        return f"slope {slope:.3g}° gives no information on yaw (level ground)"
    if np.degrees(s_yaw) > opts.max_yaw_sigma_deg:
        return (
            f"slope {slope:.3g}° too small to determine yaw: its 1σ would be {np.degrees(s_yaw):.3g}° "
            f"(limit {opts.max_yaw_sigma_deg:g}°); yaw precision grows as 1/sin(slope)"
        )
    return None


def _observability(table: StopTable, f: full.Fit, g: float) -> Observability:
    scale = np.sqrt(np.clip(np.diag(f.fisher), 1e-300, None))
    eig = np.linalg.eigvalsh(f.fisher / np.outer(scale, scale))
    rank = full.fisher_rank(f.fisher)
    crb: dict[str, AngleValues | None] = {}
    for terms in dict.fromkeys((BASE, WITH_OFFSET, f.terms)):
        crb[",".join(terms)] = crb_deg(table, f.state, terms, g, f.noise_scale)
    return Observability(
        parameters=tuple(f.names),
        fisher_rank=rank,
        condition_number=float(eig.max() / eig.min()) if eig.min() > 0 else None,
        crb_1sigma=crb,
        crb_note="Cramér–Rao bounds for this stop set at the fitted point, per model"
        + ("" if f.noise_known else ", with the noise σ estimated from the residuals"),
        separability=tuple(Separability(**v) for v in separability(table, f, g)),
    )


# --- the paper's method --------------------------------------------------------------------------


def _paper(table: StopTable, g: float, g_source: str, opts: Options) -> Calibration:
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
    doubts = fit_doubts(None, float(max(sig[0], sig[1])), None if table.cov_s is not None else 3 * len(table) - 4)
    notes += [d + "; the result is not confident" for d in doubts]
    notes.append(
        "the paper's method reports the statistical σ only: the sensor's systematic part (scale, cross-axis, bias the "
        f"stops cannot see) is propagated by {option('method', 'full')}"
    )
    if est.slope_rad is None:
        notes.append(
            f"step 2 failed: cos α = {est.cos_slope:.6f} > 1 from the opposite-heading pairs (a vertical bias, scale "
            "error or wrong g); slope not determined. The full estimator takes α from the circle's radius instead."
        )
    return Calibration(
        method="paper",
        model=BASE,
        rot_vs=est.rot_vs,
        **Calibration.angle_fields(
            Angles(
                roll_deg=roll,
                roll_sigma_deg=float(sig[0]),
                pitch_deg=pitch,
                pitch_sigma_deg=float(sig[1]),
                yaw_deg=None if yaw_reason else yaw,
                yaw_sigma_deg=None if yaw_reason else float(sig[2]),
                yaw_reason=yaw_reason,
                slope_deg=slope,
                slope_sigma_deg=None if slope is None else float(sig[3]),
            )
        ),
        rotation_sigma_deg=(None, None, None),
        bias_mps2=None,
        bias_sigma_mps2=None,
        gravity_mps2=g,
        gravity_source=g_source,
        residual_rms_mps2=float(np.sqrt(np.mean(residual**2))),
        residual_s=residual,
        fit=FitQuality(
            noise="per-stop covariance from the table" if table.cov_s is not None else "common σ from residuals",
            headings=table.headings,
            noise_scale_mps2=None if table.cov_s is not None else noise_scale,
            pairs=est.n_pairs,
            cos_slope=est.cos_slope,
            uncertainty="first-order propagation of the stop noise through the paper's steps",
        ),
        observability=None,
        model_selection=ModelSelection(mode="fixed", chosen=BASE),
        provenance=fit_provenance(table, "paper", BASE),
        notes=tuple(notes),
        confident=not doubts,
    )


# --- shared ------------------------------------------------------------------------------------


def _check_geometry(table: StopTable) -> None:
    check_count(len(table), table.source)
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


def _not_converged(table: StopTable, fixed: tuple[str, ...] | None, err: str) -> str:
    """Why the fit of these stops did not converge, and what to change: the values against the parameters."""
    terms = fixed or BASE
    n = len(table)
    free = table.beta_rad is None or table.headings == "none"
    params = len(full.StaticModel(table, terms, G_N).names)
    why = (
        f"{n} stops give {3 * n} values for the model's {params} parameters"
        + (" (each stop's heading is a free parameter: the table gives none)" if free else "")
        + f"; {max(3 * n - params, 0)} are left to fix the rest, too few to guide the search"
        if 3 * n - params < 6
        else "the model's terms leave some direction of the parameters nearly undetermined by these stops"
    )
    fixes = [f"fit fewer terms ({option('model', 'rotation,slope')})"] if fixed not in (None, BASE) else []
    if free:
        given = option("headings", "uphill")
        fixes.insert(0, f"give the stops' headings (a beta_deg column read with {given} or 'relative')")
    fixes.append("add stops at other headings")
    return f"{table.source}: the fit did not converge ({err}): {why}. To fix it: {'; or '.join(fixes)}."
