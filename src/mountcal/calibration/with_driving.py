"""Yaw from driving as a calibration, and combined with the stops' (:mod:`mountcal.estimate.driving`).

A drive alone gives a :class:`~mountcal.core.result.Calibration` with roll and pitch from the mean gravity
(:func:`driving_calibration`); with a static calibration, the two are compared (:func:`disagreement`)
and combined — the stops' tilt with the drive's yaw (:func:`combine`) — or kept apart with the
reason (:func:`not_combined`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation

from mountcal.core.conventions import angles_from_rot_vs
from mountcal.core.driving_document import Combination
from mountcal.core.findings import Finding
from mountcal.core.result import Calibration, FitQuality, ModelSelection, Provenance
from mountcal.estimate.driving import AGREE_Z, DISAGREE_Z, DrivingFit, euler_sigma
from mountcal.estimate.driving_checks import YAW_TESTS
from mountcal.estimate.driving_intervals import tilt_rotation

# --------------------------------------------------------------------------- as a calibration, and combined


def driving_calibration(
    fit: DrivingFit, *, gravity_mps2: float, gravity_source: str, provenance: Provenance
) -> Calibration:
    """A :class:`~mountcal.core.result.Calibration` from driving alone (no parked stops).

    Roll and pitch come from the mean gravity while driving (σ include the unknown mean road grade
    and cross slope), yaw from the speed changes; slope and bias are not applicable (no stops) and
    the result says so. The full driving fit is in ``fit.driving``.
    """
    grade = None if fit.consistency is None else fit.consistency.effect("grade")
    road = (
        f"the route's mean grade is {grade.value:+.2f}° ± {grade.sigma:.2f}° (from the altitude, taken out) and its "
        f"cross slope 0 ± {fit.options.road_cross_slope_sigma_deg:g}°"
        if grade is not None and grade.chosen and grade.value is not None and grade.sigma is not None
        else f"the route's mean grade and cross slope are 0 ± {fit.options.road_grade_sigma_deg:g}° and 0 ± "
        f"{fit.options.road_cross_slope_sigma_deg:g}°"
    )
    notes = [
        f"from driving only: no parked stops; roll and pitch are the mean gravity direction while driving, whose σ "
        f"assume {road}",
        "an accelerometer bias b tilts the mean gravity by b/g (20 mg → 1.1°) and cannot be told from a tilt "
        "while driving; parked stops on a slope can (docs/conventions.md §4)",
        "slope: not applicable (no parked stops)",
        *fit.notes,
    ]
    return Calibration(
        method="driving",
        model=("rotation",),
        rot_vs=fit.rot_vs,
        **Calibration.angle_fields(fit.angles),  # no slope: a drive has none
        rotation_sigma_deg=fit.rotation_sigma_deg,
        bias_mps2=None,
        bias_sigma_mps2=None,
        gravity_mps2=gravity_mps2,
        gravity_source=gravity_source,
        residual_rms_mps2=fit.longitudinal_rms_mps2,
        residual_s=np.zeros((0, 3)),
        fit=FitQuality(calibrated_from="driving", driving=fit.document()),
        observability=None,
        model_selection=ModelSelection(mode="driving", chosen=("rotation",)),
        provenance=provenance,
        notes=tuple(notes),
        unexplained=fit.findings,
        confident=not fit.findings,
    )


def disagreement(static: Calibration, fit: DrivingFit) -> Finding | None:
    """The stops against the drive, beyond ``DISAGREE_Z`` σ in tilt or yaw: an ``unexplained`` entry, else None.

    Tilt: the drive's mean gravity against the stops' up axis (``fit.tilt_check``), about the
    vehicle x and y axes. Yaw: the two yaws about the vehicle z axis, when both determine one.
    """
    parts: list[str] = []
    z_max = 0.0
    check = fit.tilt_check
    if check is not None:
        z_tilt = check.z_max
        if z_tilt > DISAGREE_Z or not np.isfinite(z_tilt):
            zx, zy = (f"{z:+.1f}" if z is not None else "∞" for z in (check.z_about_vehicle_x, check.z_about_vehicle_y))
            parts.append(f"tilt by {check.angle_deg:.1f}° (z = {zx} about x, {zy} about y)")
            z_max = max(z_max, z_tilt)
    s_drive, s_static = fit.rotation_sigma_deg[2], static.rotation_sigma_deg[2] or static.yaw_sigma_deg
    if fit.yaw_deg is not None and static.yaw_deg is not None and s_drive is not None and s_static is not None:
        diff = float((fit.yaw_deg - static.yaw_deg + 180.0) % 360.0 - 180.0)
        z_yaw = diff / float(np.hypot(s_drive, s_static))
        if abs(z_yaw) > DISAGREE_Z:
            parts.append(
                f"yaw by {diff:+.1f}° (z = {z_yaw:+.1f}): {fit.yaw_deg:.2f}° from driving, "
                f"{static.yaw_deg:.2f}° from the stops"
            )
            z_max = max(z_max, abs(z_yaw))
    if not parts:
        return None
    return Finding(
        test="stops_vs_driving",
        what="the parked stops and the drive disagree beyond their uncertainties (not combined)",
        size="; ".join(parts),
        statistic=float(z_max) if np.isfinite(z_max) else None,
        dof=None,
        p_value=None,
        log10_p=None,
        z_limit=DISAGREE_Z,
    )


def not_combined(static: Calibration, fit: DrivingFit, found: Finding) -> Calibration:
    """The stops' calibration, not confident, with the disagreement with the drive as a finding."""
    words = (
        f"stops and driving DISAGREE: {found.size}, beyond {DISAGREE_Z:g}σ; they are not combined and the "
        "result is not confident. One of them misses an effect (a remount between the stops and the drive, "
        "a wrong protocol heading or uphill azimuth (or one from another north than the heading channel's: the "
        "declination), a speed channel not along the vehicle x axis, the stops' "
        "mirror solution)"
    )
    return replace(
        static,
        fit=replace(
            static.fit,
            calibrated_from="stops (driving disagrees: not combined)",
            driving=fit.document(),
            combination=Combination(
                used="none: disagreement", agree=False, disagreement=found, tilt_check=fit.tilt_check
            ),
        ),
        notes=(*static.notes, words),
        unexplained=(*static.unexplained, found),
        confident=False,
    )


def combine(static: Calibration, fit: DrivingFit) -> Calibration:
    """The static calibration with the yaw from driving folded in.

    ``fit`` must have been levelled with ``static`` (``estimate_driving(..., tilt_from=static)``) so
    both yaws are about the same axis. When the static result has no yaw, yaw comes from driving;
    when both have one, they are combined by inverse variance (of the rotation about the vehicle z
    axis) and their difference is reported as a z-score, with a note when ``|z| > 2``: then they
    disagree beyond their uncertainties and one of them misses an effect. Roll and pitch stay the
    static ones; the driving's mean gravity is reported as a check (``tilt_check``). Beyond
    ``DISAGREE_Z`` σ in tilt or yaw they are not combined (:func:`not_combined`): the stops'
    result comes back not confident, the disagreement in its notes and ``unexplained``.
    """
    if not fit.tilt_source.startswith("static"):
        raise ValueError("combine() needs a driving fit levelled with the static calibration (tilt_from=static)")
    found = disagreement(static, fit)
    if found is not None:
        return not_combined(static, fit, found)
    notes = list(static.notes)
    combination = Combination(used="static", static_yaw_deg=static.yaw_deg, driving_yaw_deg=fit.yaw_deg)
    s_drive = fit.rotation_sigma_deg[2]
    if fit.yaw_deg is None or s_drive is None:
        notes.append(f"yaw from driving not determined: {fit.yaw_reason}")
        return replace(
            static,
            fit=replace(
                static.fit, calibrated_from="stops (driving checked)", driving=fit.document(), combination=combination
            ),
            notes=tuple(notes),
        )
    sx = static.rotation_sigma_deg[0] or static.roll_sigma_deg
    sy = static.rotation_sigma_deg[1] or static.pitch_sigma_deg
    if static.yaw_deg is None or static.yaw_sigma_deg is None:
        yaw, s_z = fit.yaw_deg, s_drive
        combination = replace(
            combination, used="driving (the stops do not determine yaw)", static_yaw_reason=static.yaw_reason
        )
        notes.append(f"yaw from driving; the stops alone could not give it ({static.yaw_reason})")
    else:
        s_static = static.rotation_sigma_deg[2] or static.yaw_sigma_deg
        diff = float((fit.yaw_deg - static.yaw_deg + 180.0) % 360.0 - 180.0)
        w_d, w_s = 1.0 / s_drive**2, 1.0 / s_static**2
        yaw = float(static.yaw_deg + diff * w_d / (w_d + w_s))
        s_z = float(1.0 / np.sqrt(w_d + w_s))
        z = diff / float(np.hypot(s_drive, s_static))
        agree = abs(z) <= AGREE_Z
        words = (
            f"driving and stops agree on yaw: {fit.yaw_deg:.3f}° ± {s_drive:.3f}° against {static.yaw_deg:.3f}° ± "
            f"{s_static:.3f}° (z = {z:+.2f})"
            if agree
            else f"driving and stops DISAGREE on yaw beyond their uncertainties: {fit.yaw_deg:.3f}° ± {s_drive:.3f}° "
            f"against {static.yaw_deg:.3f}° ± {s_static:.3f}° (z = {z:+.2f}); one of them misses an effect (a wrong "
            "uphill azimuth or protocol heading, a speed channel that is not along the vehicle x axis), so the "
            "combined yaw is not trustworthy"
        )
        combination = replace(
            combination, used="inverse-variance combination", difference_deg=diff, z=z, agree=agree, words=words
        )
        notes.append(words)
    rot_vs = Rotation.from_euler("z", np.radians(yaw)) * tilt_rotation(
        np.asarray(static.rot_vs.inv().apply([0.0, 0.0, 1.0]), dtype=float)
    )
    roll, pitch, yaw_e = (float(np.degrees(a)) for a in angles_from_rot_vs(rot_vs))
    yaw_sigma = euler_sigma(rot_vs, (sx, sy, s_z))[2]
    # the stops' tilt σ and slope, the new rotation's angles, the yaw determined (its reason gone)
    angles = replace(
        static.angles, roll_deg=roll, pitch_deg=pitch, yaw_deg=yaw_e, yaw_sigma_deg=yaw_sigma, yaw_reason=None
    )
    combination = replace(combination, yaw_deg=yaw_e, yaw_sigma_about_vehicle_z_deg=s_z, tilt_check=fit.tilt_check)
    doubts = tuple(f for f in fit.findings if f.test in YAW_TESTS)  # what the drive's own tests say of its yaw
    return replace(
        static.with_angles(angles),
        rot_vs=rot_vs,
        rotation_sigma_deg=(static.rotation_sigma_deg[0], static.rotation_sigma_deg[1], s_z),
        fit=replace(static.fit, calibrated_from="stops + driving", driving=fit.document(), combination=combination),
        notes=tuple(notes),
        unexplained=(*static.unexplained, *doubts),
        confident=static.confident and not doubts,
    )
