"""Plausibility checks of an answer and of the conventions it rests on, named in the result.

Each check is a :class:`~mountcal.core.result.Check` in ``Calibration.checks``: passed, failed (the
result is then not confident, with the reason in its notes), or not tested (with the reason). The
conventions' own checks (a heading's unit, the acceleration unit against |g|, the sensor's
handedness) run where the input is read or cross-checked (:mod:`mountcal.io.input_conventions`,
:mod:`mountcal.loop.crosscheck`) and refuse there; what they found is listed here too. These check the answer:

- ``slope_range``: a vehicle parks on slopes up to :data:`MAX_PARKED_SLOPE_DEG` (the steepest streets
  are 20°); a steeper fitted slope is a unit, an axis map, or a session that is no parking session
  (a multi-position test belongs to ``mountcal triad``).
- ``exact_fit``: real stops carry noise; a fit with no residual (χ² = 0) means copied or simulated data.
- ``noise_scale``: stops that scatter far less than their stated noise (χ²/dof under
  :data:`MIN_CHI2_RATIO`): ``sx, sy, sz`` in another unit than ``ax, ay, az``, or an overstated noise.
- ``gravity``: the gravity used, stated or fitted, within :data:`GRAVITY_TOLERANCE` of gₙ.
- ``acceleration_sign``: an acceleration whose sign only an app's default gave (a Sensor Logger recording
  from iOS, :mod:`mountcal.io.sensor_logger`) must be confirmed by a handedness check (a sign reversed in
  all three axes mirrors the data): failed where none could test it (:func:`sign_check`).
- ``axes``: a log's axes taken as logged (right-handed) by default, where no handedness check could test them
  (no stops with headings, too little turning): failed (:func:`axes_check`), since a mirrored sensor reads as
  well and gives another tilt.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from mountcal.core.conventions import G_N
from mountcal.core.option_names import option
from mountcal.core.pvalues import chi2_sf
from mountcal.core.result import Calibration, Check, Convention
from mountcal.io.heading_frame import heading_frame_check
from mountcal.io.sensor_frame import several_frames_check
from mountcal.io.sensor_logger import SIGN, acceleration_sign

MAX_PARKED_SLOPE_DEG = 30.0
EXACT_RMS_MPS2 = 1e-9 * G_N  # below this residual the stop means sit on the model to rounding
MIN_CHI2_RATIO = 0.05  # χ²/dof under this: the stated noise is over 4.5× the scatter (a unit is 9.8× or 1000×)
LOW_TAIL_P = 1e-3
GRAVITY_TOLERANCE = 0.05  # a gravity beyond ±5 % of gₙ is no gravity on Earth: a unit or a scale error


def answer_checks(cal: Calibration) -> tuple[Check, ...]:
    """The checks of a calibration's answer (see the module's docstring)."""
    out = []
    if cal.slope_deg is None:
        out.append(Check("slope_range", None, "no slope (no stops, or not determined)"))
    else:
        sigma = cal.slope_sigma_deg or 0.0
        steep = cal.slope_deg - 3.0 * sigma > MAX_PARKED_SLOPE_DEG
        out.append(
            Check(
                "slope_range",
                not steep,
                f"slope {cal.slope_deg:.3g}° ± {sigma:.2g}° "
                + (
                    f"is steeper than any vehicle parks on (up to {MAX_PARKED_SLOPE_DEG:g}°): check the units, the "
                    "axis map, and that the stops are a parking session (a multi-position test is `mountcal triad`'s)"
                    if steep
                    else f"is one a vehicle parks on (up to {MAX_PARKED_SLOPE_DEG:g}°)"
                ),
            )
        )
    fit = cal.fit
    stops = cal.residual_s.shape[0]
    if stops == 0:
        out.append(Check("exact_fit", None, "no stops"))
    elif cal.residual_rms_mps2 <= EXACT_RMS_MPS2 or (fit.chi2 is not None and fit.dof and fit.chi2 <= 1e-12 * fit.dof):
        out.append(
            Check(
                "exact_fit",
                False,
                f"the stops fit exactly (residual RMS {cal.residual_rms_mps2:.2g} m/s²): real stops carry noise, so "
                "these were copied, edited or simulated without noise; their σ say nothing about a real sensor",
            )
        )
    else:
        out.append(Check("exact_fit", True, f"residual RMS {cal.residual_rms_mps2:.3g} m/s²: the stops carry noise"))
        if fit.p_value is not None and fit.chi2 is not None and fit.dof:
            ratio = fit.chi2 / fit.dof
            low = 1.0 - float(chi2_sf(fit.chi2, fit.dof))
            too_quiet = ratio < MIN_CHI2_RATIO and low < LOW_TAIL_P
            out.append(
                Check(
                    "noise_scale",
                    not too_quiet,
                    f"χ²/dof = {ratio:.3g}"
                    + (
                        ": the stops scatter far less than their stated noise — sx, sy, sz (or the _mean ones) in "
                        "another unit than ax, ay, az, or an overstated noise; the σ are too large"
                        if too_quiet
                        else ": the stated noise matches the scatter's scale"
                    ),
                )
            )
    g = cal.gravity_mps2
    bad_g = abs(g / G_N - 1.0) > GRAVITY_TOLERANCE
    out.append(
        Check(
            "gravity",
            not bad_g,
            f"gravity {g:.5g} m/s² ({cal.gravity_source})"
            + (
                f" is no gravity on Earth (beyond ±{GRAVITY_TOLERANCE:.0%} of 9.80665): a unit or scale error"
                if bad_g
                else " lies near 9.81 m/s²"
            ),
        )
    )
    return tuple(out)


def convention_checks(conventions: Sequence[Convention]) -> tuple[Check, ...]:
    """The conventions checked where the input was read (a refusal there), listed as passed checks;
    and a heading reference that nothing stated (``heading_reference``), a failed one (so is β from an
    odometry heading in a frame not known to face east: :mod:`mountcal.io.heading_frame`): stops alone
    cannot tell β from uphill, from downhill or with a common offset (each turns the answer about the
    vertical), so a yaw resting on an assumed reference is not a confident one."""
    checked = {"heading_unit", "acceleration_unit"}  # refused where read when they fail
    out = [Check(c.name, True, f"{c.value}: {c.by}") for c in conventions if c.name in checked]
    for c in conventions:
        if c.name == "heading_reference" and c.how == "default" and c.value == "uphill":
            out.append(Check(c.name, False, f"assumed, not stated: {c.by}"))
    frame = heading_frame_check(conventions)  # β from an odometry heading in a frame not known to face east
    sensors = several_frames_check(conventions)  # IMU messages naming several frames: perhaps two sensors
    return (*out, *(c for c in (frame, sensors) if c is not None))


HANDEDNESS = ("handedness_stops", "handedness_turns")


def handedness_passed(checks: Sequence[Check]) -> list[str]:
    """The handedness checks that passed: what confirms a sign or axes that were only assumed (the other would
    have mirrored the data)."""
    return [c.name for c in checks if c.name in HANDEDNESS and c.passed]


def sign_check(conventions: Sequence[Convention], checks: Sequence[Check]) -> tuple[Check, Convention] | None:
    """The check of the acceleration's sign, and its convention as the handedness checks leave it; None where
    the input states no sign. A default is confirmed (now inferred) by a handedness check that passed — the
    other sign would have mirrored the data — and otherwise fails: nothing showed it right."""
    sign = acceleration_sign(conventions)
    if sign is None:
        return None
    if sign.how != "default":
        return Check(SIGN, True, f"{sign.value}: {sign.how} by {sign.by}"), sign
    passed = handedness_passed(checks)
    if passed:
        by = f"{sign.by}, confirmed by {' and '.join(passed)} (the other sign would mirror the data)"
        return Check(SIGN, True, f"{sign.value}: {by}"), replace(sign, how="inferred", by=by)
    reason = (
        f"assumed, not confirmed: {sign.value} is {sign.by}, and no handedness check could test it (no stops with "
        "headings, no turns with a heading or speed): the other sign gives a sensor upside down. Record "
        f"AccelerometerUncalibrated (its unit tells the sign), or give the stops' headings ({option('protocol')})"
    )
    return Check(SIGN, False, reason), sign


AXES = "axes"


def axes_check(conventions: Sequence[Convention], checks: Sequence[Check]) -> Check | None:
    """A failed ``axes`` check where a log's axes were only assumed (the axes as logged, taken as right-handed)
    and no handedness check passed; None where they were stated (``--axes``, a reader's documented map, a CAN
    mapping), where a handedness check confirmed them, or where the input records no axes (a stop table).

    A mirrored sensor (one axis reversed) reads as well as a right-handed one: only the stops' headings or the
    turns tell them apart. Without either, the tilt rests on an assumption — a reversed y reverses roll, a reversed
    x pitch — so the answer is not confident until the axes are stated."""
    axes = next((c for c in conventions if c.name == AXES), None)
    if axes is None or axes.how != "default" or handedness_passed(checks):
        return None
    return Check(
        AXES,
        False,
        f"assumed, not confirmed: {axes.value} is {axes.by}, and no handedness check could test it (no stops with "
        "headings, too little turning): a mirrored sensor reads as well and gives another tilt (a reversed y "
        f"reverses roll, a reversed x pitch). State the axes: {option('axes', 'x,y,z')} where the device is "
        "right-handed as logged, else the map that makes it so",
    )


def with_checks(cal: Calibration, checks: Sequence[Check]) -> Calibration:
    """The calibration with its checks; a failed one makes it not confident and says why in the notes."""
    merged = {c.name: c for c in (*cal.checks, *checks)}
    failed = [c for c in merged.values() if c.passed is False]
    notes = tuple(f"plausibility check {c.name} failed: {c.reason}; the result is not confident" for c in failed)
    known = set(cal.notes)
    return replace(
        cal,
        checks=tuple(merged.values()),
        notes=(*cal.notes, *(n for n in notes if n not in known)),
        confident=cal.confident and not failed,
    )


BACKWARD = "the stops put the sensor's x axis backwards"  # how the note begins (a drive that tests it removes it)


def backward_yaw_note(cal: Calibration, headings: str) -> str | None:
    """A yaw from headings that points the sensor's x axis backwards (within 45° of the vehicle's −x, seen from
    above): the sensor faces backwards, or the headings are a half turn off, and stops alone cannot tell which
    (each turns the answer about the vertical by 180°). Nothing for an x axis that points up, down or sideways."""
    yaw_deg = cal.yaw_deg
    if yaw_deg is None or headings != "uphill":
        return None
    x_v = cal.rot_vs.apply([1.0, 0.0, 0.0])  # the sensor's x axis in the vehicle frame
    if not (x_v[0] < -abs(x_v[1]) and np.hypot(x_v[0], x_v[1]) > 0.5):
        return None
    return (
        f"{BACKWARD} (yaw {yaw_deg:.1f}°). If it faces forwards, the headings are a half turn off and the yaw is "
        f"{(yaw_deg % 360.0) - 180.0:.1f}°: an uphill azimuth that names the downhill direction (a slope's aspect, "
        "as maps give it, is downhill), β measured from downhill, or headings that are courses over ground (the "
        "direction of motion) of a vehicle that reversed into its spots. The stops cannot tell these apart; a "
        "drive in the same log can"
    )
