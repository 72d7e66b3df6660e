"""Yaw from driving — and roll and pitch from the mean gravity while driving, as a check.

While the vehicle drives straight, its specific force along the vehicle x axis is the rate of
change of its speed (plus the grade's share of gravity); sideways it is nearly nothing. So the
horizontal specific force the IMU sees (after levelling it with roll and pitch) points along the
vehicle's x axis exactly as much as the speed changes. The estimator:

1. **Levels** the accelerometer with the tilt of a static calibration when one is given, else with
   the mean gravity direction while moving; yaw is the rotation about the vehicle's z axis after
   that tilt, ``R_vs = Rz(yaw) · R_tilt`` (docs/conventions.md §1), so it is insensitive to small tilt errors
   (they shift the horizontal components by constants, which step 3 removes).
2. **Cuts the drive into intervals** between speed samples about ``interval_s`` apart. Over each,
   the speed change ``Δv/T`` and the mean levelled horizontal specific force ``ΔU/T`` (the exact
   integral of the IMU over the same interval — a matched filter, whatever the two rates) are
   compared. Intervals are **gated** on speed (≥ ``min_speed_mps``; reversing and creeping are
   excluded), straightness (mean |yaw rate| from the gyro, else from a heading channel, else from
   the lateral acceleration of a first pass), grade changes and bumps (mean levelled pitch/roll
   rate) and the acceleration magnitude (wheel slip).
3. Consecutive accepted intervals form **segments** of at most ``segment_s``; each segment's
   means are removed, which absorbs a constant grade, a bias and a residual tilt.
4. The **time offset** between the speed and IMU clocks maximises the length of the cross
   covariance ``c(τ) = Σ (ΔU/T)(τ) · Δv/T`` over a grid of lags, refined by a parabola.
5. **Yaw** is the direction of ``c``: ``yaw = atan2(−c_y, c_x)``. The lateral acceleration and
   the IMU noise are uncorrelated with the speed change, so they add scatter but no bias, and a
   wrong speed scale (tyre radius) changes only the length of ``c``.
6. **σ** of yaw: the perpendicular component of ``c`` is a sum of the interval products
   ``e_i = ΔU⊥_i/T · Δv_i/T``; its variance is estimated with a Newey–West (Bartlett) long-run
   variance inside each segment, which accounts for the autocorrelation of neighbouring intervals;
   a jackknife over segments gives a second estimate and the larger is reported.
7. **Roll and pitch check**: the mean specific force over the accepted intervals, less the mean
   longitudinal acceleration along the estimated x axis, points up. The unknown mean road grade
   and cross slope (crown) along the route and an accelerometer bias enter it directly, so its σ
   includes ``road_grade_sigma_deg`` and ``road_cross_slope_sigma_deg``; parked stops are better.

Everything is whole-array numpy (cumulative integrals of the IMU at the interval ends); no per-sample Python.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace

import numpy as np
from scipy.spatial.transform import Rotation

from mountcal.core.conventions import FloatArray, angles_from_rot_vs
from mountcal.core.driving_document import DrivingConsistency, DrivingDocument, DrivingGates, DrivingSigma, TiltCheck
from mountcal.core.errors import NotEnoughInformation
from mountcal.core.findings import Finding
from mountcal.core.option_names import option
from mountcal.core.result import Angles, Calibration
from mountcal.estimate import driving_checks as checks
from mountcal.estimate.driving_intervals import (
    MIN_INTERVALS,
    Imu,
    IntArray,
    Intervals,
    layout_intervals,
    speed_channel,
    speed_intervals,
    tilt_rotation,
    time_offset,
    turned_tilt_removed,
    unit_vector,
    yaw_from_sums,
)
from mountcal.estimate.driving_options import DrivingOptions
from mountcal.io.samples import Samples
from mountcal.stops.detect import checked_gyro

AGREE_Z = 2.0  # |z| above this: the two estimates disagree beyond their uncertainties (≈ 95 %)
DISAGREE_Z = 3.0  # |z| above this (tilt or yaw): a finding; the stops and the drive are not combined


@dataclass(frozen=True)
class DrivingFit:
    """The mounting from driving, with σ and what it rests on.

    Angles in degrees, σ 1σ. ``yaw_deg`` is None (with ``yaw_reason``) when the drive does not
    determine it to ``max_yaw_sigma_deg``. ``rot_vs`` maps sensor to vehicle coordinates; its yaw
    is 0 when yaw is not determined. ``rotation_sigma_deg`` is the σ of small rotations about the
    vehicle x, y, z axes: z is what the drive measures (Newey–West or jackknife, the larger:
    ``yaw_sigma_hac_deg``, ``yaw_sigma_jackknife_deg``); x and y are the tilt's (the road's mean
    cross slope and grade, or the static calibration's). ``yaw_sigma_deg`` is the Euler yaw's σ
    from all three, so it grows near pitch ±90°. ``time_offset_s`` is added to the speed channel's
    times to put them on the IMU clock. ``speed_scale`` is the IMU's longitudinal specific force
    over d(speed)/dt (1 for a true speed; the speed regressed on the IMU, so the noise of a
    differentiated speed does not pull it towards 0); ``correlation`` is theirs. ``n_intervals``
    intervals of about ``interval_s`` in ``n_segments`` straight segments, ``usable_s`` seconds of
    the ``moving_s`` driven at speed, passed the gates; ``segments_s`` holds each segment's start
    and end on the IMU clock (what the report marks).
    """

    rot_vs: Rotation
    roll_deg: float
    pitch_deg: float
    yaw_deg: float | None
    roll_sigma_deg: float
    pitch_sigma_deg: float
    yaw_sigma_deg: float | None
    yaw_reason: str | None
    tilt_source: str
    rotation_sigma_deg: tuple[float, float, float | None]
    up_driving_s: FloatArray  # shape (3,), the up axis from the mean gravity while driving
    tilt_check: TiltCheck | None  # driving's up axis against the given tilt's, when one was given
    time_offset_s: float
    time_offset_sigma_s: float | None
    time_offset_searched: bool
    n_intervals: int
    n_segments: int
    usable_s: float
    moving_s: float
    speed_scale: float
    correlation: float
    longitudinal_rms_mps2: float
    lateral_rms_mps2: float
    yaw_sigma_hac_deg: float | None
    yaw_sigma_jackknife_deg: float | None
    straightness_source: str
    options: DrivingOptions
    notes: tuple[str, ...] = field(default=())
    segments_s: FloatArray = field(default_factory=lambda: np.empty((0, 2)))
    consistency: DrivingConsistency | None = None  # the residual tests (:mod:`mountcal.estimate.driving_checks`)
    findings: tuple[Finding, ...] = ()  # those the family's test rejects: the model lacks an effect
    # ``rot_vs`` with the longitudinal cue's yaw whenever its noise alone determines it, a model-error term aside
    # (what the turns' handedness check levels the lateral acceleration with); None: the noise does not
    rot_vs_longitudinal: Rotation | None = None

    @property
    def yaw_model_error_deg(self) -> float:
        """The model-error term in the σ about the vehicle z axis (0 when the tests found nothing)."""
        return 0.0 if self.consistency is None else self.consistency.model_error.yaw_about_vehicle_z_deg

    @property
    def angles(self) -> Angles:
        """Roll, pitch and yaw with their σ (no slope: a drive has none)."""
        return Angles(
            self.roll_deg,
            self.roll_sigma_deg,
            self.pitch_deg,
            self.pitch_sigma_deg,
            self.yaw_deg,
            self.yaw_sigma_deg,
            self.yaw_reason,
            None,
            None,
        )

    def document(self) -> DrivingDocument:
        """The fit as the result file keeps it (``fit.driving``)."""
        finite = bool(np.isfinite(self.speed_scale))
        return DrivingDocument(
            roll_deg=self.roll_deg,
            pitch_deg=self.pitch_deg,
            yaw_deg=self.yaw_deg,
            sigma=DrivingSigma(
                roll_deg=self.roll_sigma_deg,
                pitch_deg=self.pitch_sigma_deg,
                yaw_deg=self.yaw_sigma_deg,
                yaw_newey_west_deg=self.yaw_sigma_hac_deg,
                yaw_jackknife_deg=self.yaw_sigma_jackknife_deg,
                yaw_model_error_deg=self.yaw_model_error_deg,
                rotation_about_vehicle_xyz_deg=self.rotation_sigma_deg,
            ),
            yaw_reason=self.yaw_reason,
            tilt_source=self.tilt_source,
            up_driving_s=(float(self.up_driving_s[0]), float(self.up_driving_s[1]), float(self.up_driving_s[2])),
            tilt_check=self.tilt_check,
            quaternion_xyzw=tuple(float(q) for q in self.rot_vs.as_quat()),  # type: ignore[arg-type]
            time_offset_s=self.time_offset_s,
            time_offset_sigma_s=self.time_offset_sigma_s,
            time_offset_meaning="added to the speed channel's times to put them on the IMU clock",
            time_offset_searched=self.time_offset_searched,
            intervals=self.n_intervals,
            segments=self.n_segments,
            usable_s=self.usable_s,
            moving_s=self.moving_s,
            speed_scale=float(self.speed_scale) if finite else None,
            correlation=self.correlation,
            longitudinal_residual_rms_mps2=self.longitudinal_rms_mps2,
            lateral_rms_mps2=self.lateral_rms_mps2,
            straightness_from=self.straightness_source,
            gates=DrivingGates(**asdict(self.options)),
            notes=self.notes,
            consistency=self.consistency,
        )


# --------------------------------------------------------------------------- the estimator


def estimate_driving(
    samples: Samples, options: DrivingOptions | None = None, *, tilt_from: Calibration | None = None
) -> DrivingFit:
    """Yaw (and a roll/pitch check) of the mounting from a drive with a speed channel.

    Parameters
    ----------
    samples : Samples
        ``acc_s`` (n, 3) m/s² in the sensor frame, ``gyro_s`` (n, 3) rad/s when logged, and a
        ``speed_mps`` channel (CAN/OBD speed, wheel speed, GNSS or odometry, m/s) on its own clock;
        a ``heading_deg`` channel serves for straightness when there is no gyro.
    options : DrivingOptions, optional
    tilt_from : Calibration, optional
        A (static) calibration whose roll and pitch level the data; yaw is then relative to that
        tilt, so the two can be combined (:func:`combine`). Without it the mean gravity while
        driving levels the data.

    Returns
    -------
    DrivingFit

    Raises
    ------
    NotEnoughInformation
        No speed channel, or too few usable straight intervals at speed.
    """
    opts = options or DrivingOptions()
    speed = speed_channel(samples)
    t, acc = samples.t_s, samples.acc_s
    gyro = samples.gyro_s if tilt_from is not None else checked_gyro(samples)  # deg/s: refused; stops: checked
    where = samples.source or "log"
    moving = np.interp(t, speed.t_s + (opts.time_offset_s or 0.0), speed.value) >= opts.min_speed_mps
    moving_s = float(np.sum(np.diff(t)[moving[:-1]])) if t.size > 1 else 0.0
    if moving.sum() < 10:
        raise NotEnoughInformation(
            f"{where}: no driving at ≥ {opts.min_speed_mps:g} m/s in the speed channel; yaw from driving needs a drive"
        )
    at_speed = int(speed_intervals(speed, opts)[2].sum())
    if at_speed < MIN_INTERVALS:  # decided by the speed alone: the IMU's integrals would be built for nothing
        raise NotEnoughInformation(
            f"{where}: only {at_speed} intervals at ≥ {opts.min_speed_mps:g} m/s, straight or not (need "
            f"{MIN_INTERVALS}); yaw from driving needs more straight driving with speed changes (accelerating and "
            f"braking), or stops on a slope with headings ({option('protocol')})"
        )
    if tilt_from is not None:
        up_given = np.asarray(tilt_from.rot_vs.inv().apply([0.0, 0.0, 1.0]), dtype=float)
        up = up_given
        tilt_source = f"static calibration ({tilt_from.method})"
    else:
        up_given = None
        up = unit_vector(acc[moving].mean(axis=0))
        tilt_source = "mean gravity while driving"
    imu = Imu.build(t, acc, gyro)
    straight = "gyro" if gyro is not None else ("heading channel" if "heading_deg" in samples.channels else "")
    heading = samples.channels.get("heading_deg") if gyro is None else None
    notes: list[str] = []

    # A second pass refines what the first had to guess: the tilt (from driving) and, without a
    # yaw rate, the vehicle's y axis for the straightness gate.
    rot_tilt = tilt_rotation(up)
    last = tilt_from is not None and bool(straight)
    layout = layout_intervals(imu, speed, rot_tilt, heading, opts, None)
    offset, offset_sigma, searched, search = time_offset(layout, opts, notes if last else [])
    fit = _fit(layout.at(offset), opts, where)
    if not last:
        rot_tilt = rot_tilt if tilt_from is not None else tilt_rotation(fit.up_s(rot_tilt))
        layout = layout_intervals(imu, speed, rot_tilt, heading, opts, None if straight else fit.yaw_rad)
        offset, offset_sigma, searched, search = time_offset(layout, opts, notes)
        fit = _fit(layout.at(offset), opts, where)
    iv = used = layout.at(offset)
    inputs = checks.Inputs(
        iv,
        *_centred(iv, fit.yaw_rad),
        fit.yaw_rad,
        fit.scale,
        1.0,
        max(fit.sigma_hac_rad, fit.sigma_jack_rad or 0.0),
        layout,
        speed,
        rot_tilt,
        offset,
        search,
        samples.channels.get("alt_m"),
        opts,
        bool(straight),
        gyro is not None,
    )
    found = checks.run(inputs)
    if found.lateral_scale is not None:  # the data chose it: refit yaw with the lateral acceleration it measured
        before = fit
        fit = _fit(iv, opts, where, found.lateral_scale)
        sigma = max(fit.sigma_hac_rad, fit.sigma_jack_rad or 0.0)
        u = _centred(iv, fit.yaw_rad)[0]
        found = checks.run(
            replace(inputs, u=u, yaw_rad=fit.yaw_rad, lateral_scale=found.lateral_scale, sigma_rad=sigma)
        )
        found = checks.changed(
            found, "lateral_scale", Angles.value_column("yaw"), np.degrees(before.yaw_rad), np.degrees(fit.yaw_rad)
        )
    if not straight:
        straight = f"lateral acceleration (|a_y| ≤ {opts.max_lateral_mps2:g} m/s² after a first pass)"
    up_driving = fit.up_s(rot_tilt)
    result = _result(
        fit,
        rot_tilt,
        up_driving,
        up_given,
        tilt_source,
        tilt_from,
        offset,
        offset_sigma,
        searched,
        moving_s,
        straight,
        opts,
        notes,
        found,
    )
    return replace(result, segments_s=used.segment_spans())


def _centred(iv: Intervals, yaw: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``u``, ``a_ref`` and ``a_lat`` as the fit uses them: detrended per segment, turning's share of the road tilt
    out of ``u``."""
    u, a, lat = iv.centred()
    if np.any(iv.turned_rad):
        u = turned_tilt_removed(iv, yaw)
    return u, a, lat


@dataclass(frozen=True)
class _Fit:
    """The fit at one time offset."""

    yaw_rad: float
    sigma_hac_rad: float
    sigma_jack_rad: float | None
    n: int
    n_segments: int
    usable_s: float
    scale: float
    correlation: float
    longitudinal_rms: float
    lateral_rms: float
    mean_acc_s: FloatArray  # (3,) mean specific force over the accepted intervals, sensor frame
    mean_a_ref: float

    def up_s(self, rot_tilt: Rotation) -> FloatArray:
        """The up axis from the mean specific force less the mean longitudinal acceleration."""
        x_s = rot_tilt.inv().apply([np.cos(self.yaw_rad), -np.sin(self.yaw_rad), 0.0])
        scale = self.scale if np.isfinite(self.scale) else 1.0
        return unit_vector(self.mean_acc_s - self.mean_a_ref * scale * np.asarray(x_s))


def _fit(iv: Intervals, opts: DrivingOptions, where: str, lateral_scale: float = 1.0) -> _Fit:
    """Yaw from the intervals: the direction in which the levelled IMU follows the speed change.

    With ``A, B = Σ a·u_x, Σ a·u_y`` and ``C = Σ a·a_lat`` (segment-centred; ``a`` the speed
    change rate, ``a_lat`` the predicted centripetal acceleration) yaw solves
    ``Σ a · ((Rz(yaw)·u)_y − a_lat) = 0``, i.e. ``sin(yaw + β) = C / hypot(A, B)``, β = atan2(B, A).
    """
    if iv.a_ref.size < MIN_INTERVALS:
        raise NotEnoughInformation(
            f"{where}: only {iv.a_ref.size} usable straight intervals at ≥ {opts.min_speed_mps:g} m/s "
            f"(need {MIN_INTERVALS}); yaw from driving needs more straight driving with speed changes "
            f"(accelerating and braking), or stops on a slope with headings ({option('protocol')})"
        )
    u, a, lat = iv.centred()
    lat = lateral_scale * lat  # the IMU's lateral specific force per v·ω, when the data chose to fit it
    saa = float(a @ a)
    if saa <= 1e-12 * a.size:  # the speed never changes: nothing points along the vehicle's x axis
        rms = float(np.sqrt(np.mean(u**2)))
        mean_acc = iv.width_s @ iv.acc_s / iv.width_s.sum()
        return _Fit(
            0.0,
            np.inf,
            None,
            int(a.size),
            int(iv.segment.max()) + 1,
            float(iv.width_s.sum()),
            float("nan"),
            0.0,
            rms,
            rms,
            mean_acc,
            0.0,
        )
    yaw, slope = yaw_from_sums(float(u[:, 0] @ a), float(u[:, 1] @ a), float(lat @ a))
    if np.any(iv.turned_rad):
        # The road's tilt of the body at a segment's start, h₀ (its horizontal gravity share), turns
        # with the heading: f ≈ f₀ − δ × f₀ adds (δ_z·h₀_y, −δ_z·h₀_x). h₀ is the segment's mean
        # levelled horizontal specific force less its mean kinematic acceleration.
        u = turned_tilt_removed(iv, yaw)
        yaw, slope = yaw_from_sums(float(u[:, 0] @ a), float(u[:, 1] @ a), float(lat @ a))
    along = np.cos(yaw) * u[:, 0] - np.sin(yaw) * u[:, 1]  # vehicle x
    across = np.sin(yaw) * u[:, 0] + np.cos(yaw) * u[:, 1] - lat  # vehicle y, less the centripetal part
    n_seg = int(iv.segment.max()) + 1
    dof = max(iv.a_ref.size - 2 * n_seg - 1, 1)
    e = across * a  # the estimating equation, interval by interval
    sigma_hac = np.sqrt(_long_run_variance(e, iv.segment) * iv.a_ref.size / dof) / slope
    sigma_jack = None
    if n_seg >= 3:
        sums = [np.bincount(iv.segment, x * a, n_seg) for x in (u[:, 0], u[:, 1], lat)]
        loo = [float(x.sum()) - x for x in sums]
        yaw_loo = np.array([yaw_from_sums(loo[0][k], loo[1][k], loo[2][k])[0] for k in range(n_seg)])
        d = np.angle(np.exp(1j * (yaw_loo - yaw)))
        sigma_jack = float(np.sqrt((n_seg - 1) / n_seg * np.sum((d - d.mean()) ** 2)))
    # IMU longitudinal / d(speed)/dt, from regressing the speed change on the IMU: the noise of a
    # differentiated speed (GNSS especially) would attenuate the other regression towards 0.
    sxa = float(along @ a)
    scale = float(along @ along) / sxa if sxa > 0 else float("nan")
    weights = iv.width_s / iv.width_s.sum()
    return _Fit(
        yaw_rad=yaw,
        sigma_hac_rad=float(sigma_hac),
        sigma_jack_rad=sigma_jack,
        n=int(iv.a_ref.size),
        n_segments=n_seg,
        usable_s=float(iv.width_s.sum()),
        scale=scale,
        correlation=float(along @ a / np.sqrt(max(float(along @ along) * saa, 1e-300))),
        longitudinal_rms=float(np.sqrt(np.mean((along - sxa / saa * a) ** 2))),
        lateral_rms=float(np.sqrt(np.mean(across**2))),
        mean_acc_s=weights @ iv.acc_s,
        mean_a_ref=float(weights @ iv.a_ref),
    )


def _long_run_variance(e: FloatArray, segment: IntArray) -> float:
    """Newey–West variance of ``Σ e`` with Bartlett weights, lags only within a segment."""
    n = e.size
    lag_max = int(np.ceil(4.0 * (n / 100.0) ** (2.0 / 9.0)))
    total = float(e @ e)
    for lag in range(1, lag_max + 1):
        same = segment[lag:] == segment[:-lag]
        total += 2.0 * (1.0 - lag / (lag_max + 1.0)) * float(np.sum(e[lag:] * e[:-lag] * same))
    return max(total, float(e @ e) / max(n, 1))


# --------------------------------------------------------------------------- the result


def _result(
    fit: _Fit,
    rot_tilt: Rotation,
    up_driving: FloatArray,
    up_given: FloatArray | None,
    tilt_source: str,
    tilt_from: Calibration | None,
    offset: float,
    offset_sigma: float | None,
    searched: bool,
    moving_s: float,
    straight: str,
    opts: DrivingOptions,
    notes: list[str],
    found: checks.Checks,
) -> DrivingFit:
    sigma_stat = float(np.degrees(max(fit.sigma_hac_rad, fit.sigma_jack_rad or 0.0)))  # about the vehicle z axis
    model_error = found.document.model_error
    sigma_z = float(np.hypot(sigma_stat, model_error.yaw_about_vehicle_z_deg))  # the model-error term, stated
    yaw_reason = None
    if sigma_z > opts.max_yaw_sigma_deg:
        yaw_reason = (
            f"the drive determines yaw only to {sigma_z:.3g}° (limit {opts.max_yaw_sigma_deg:g}°): too few "
            "speed changes on straight road; drive with more accelerating and braking"
        )
    yaw_rad = fit.yaw_rad if yaw_reason is None else 0.0
    rot_vs = Rotation.from_euler("z", yaw_rad) * rot_tilt
    # The longitudinal cue's yaw wherever its noise alone determines it: a finding's model-error term (the cues half
    # a turn apart: a mirrored sensor) may leave yaw undetermined, yet the vehicle's axes are known well enough for the
    # sign of its turns (:func:`mountcal.loop.crosscheck.turn_handedness`).
    longitudinal = Rotation.from_euler("z", fit.yaw_rad) * rot_tilt if sigma_stat <= opts.max_yaw_sigma_deg else None
    # Tilt σ about the vehicle x (cross slope) and y (grade) axes: the unknown mean road attitude
    # dominates the scatter of the mean; tilt from a static calibration keeps that one's σ.
    stat = np.degrees(fit.longitudinal_rms / 9.8 / np.sqrt(max(fit.n, 1)))
    grade_sigma = opts.road_grade_sigma_deg
    if found.grade is not None and tilt_from is None and found.grade.sigma is not None:
        # The route's mean grade from the altitude: the mean gravity leans by it about the vehicle's y axis
        # (nose up on an uphill route), so the body's up axis is the mean gravity turned back by it.
        before = float(np.degrees(angles_from_rot_vs(rot_vs)[1]))
        grade = Rotation.from_euler("y", np.radians(found.grade.value))
        rot_vs = grade * rot_vs
        longitudinal = None if longitudinal is None else grade * longitudinal
        grade_sigma = found.grade.sigma
        found = checks.changed(
            found, "grade", Angles.value_column("pitch"), before, np.degrees(angles_from_rot_vs(rot_vs)[1])
        )
    road = (float(np.hypot(stat, opts.road_cross_slope_sigma_deg)), float(np.hypot(stat, grade_sigma)))
    if tilt_from is not None:
        sx = tilt_from.rotation_sigma_deg[0] or tilt_from.roll_sigma_deg
        sy = tilt_from.rotation_sigma_deg[1] or tilt_from.pitch_sigma_deg
    else:
        errors = (model_error.about_vehicle_x_deg, model_error.about_vehicle_y_deg)
        sx, sy = (float(np.hypot(r, e)) for r, e in zip(road, errors, strict=True))
    r, p, y = angles_from_rot_vs(rot_vs)  # after the grade: it turns the Euler yaw too where the sensor is rolled
    roll, pitch = float(np.degrees(r)), float(np.degrees(p))
    roll_sigma, pitch_sigma, yaw_sigma = euler_sigma(rot_vs, (sx, sy, 0.0 if yaw_reason else sigma_z))
    if tilt_from is not None:  # the static fit's own marginals know its correlations
        roll_sigma, pitch_sigma = tilt_from.roll_sigma_deg, tilt_from.pitch_sigma_deg
    rot_sigma = (float(sx), float(sy))
    tilt_check = None
    if up_given is not None:
        tilt_check = _tilt_check(rot_vs, up_given, up_driving, road, tilt_from)
        if not tilt_check.agree:
            notes.append(
                "the mean gravity while driving tilts from the given calibration's up axis by "
                f"{tilt_check.angle_deg:.2f}° (z = {_z(tilt_check.z_about_vehicle_x)} about x, "
                f"{_z(tilt_check.z_about_vehicle_y)} about y): more than the road's grade and cross slope explain"
            )
    if abs(pitch) > 60.0:
        notes.append(
            f"pitch {pitch:.1f}° is near ±90°: roll and yaw then trade off (gimbal lock), so compare rotations, "
            "not Euler angles; the rotation about the vehicle z axis is what the drive measures"
        )
    notes += found.notes
    if yaw_reason is None and model_error.yaw_about_vehicle_z_deg > 0:
        found_part = model_error.yaw_about_vehicle_z_deg > model_error.horizontal_axes_deg
        notes.append(
            f"yaw rests on the longitudinal cue (speed changes on straight road); its σ about the vehicle z axis, "
            f"{sigma_z:.3g}°, holds {sigma_stat:.3g}° of noise and "
            + (
                f"a model-error term of {model_error.yaw_about_vehicle_z_deg:.3g}° (half the disagreement a finding "
                "shows)"
                if found_part
                else f"{model_error.horizontal_axes_deg:.3g}° for what the accelerometer's horizontal scale and "
                f"cross-axis errors may leave (±{model_error.horizontal_axes_prior_deg:.2g}° for the sensor class, "
                "narrowed by the turns' cue; a sensor spec, --sensor-spec, narrows it)"
            )
        )
    return DrivingFit(
        rot_vs=rot_vs,
        roll_deg=float(roll),
        pitch_deg=float(pitch),
        yaw_deg=None if yaw_reason else float(np.degrees(y)),
        roll_sigma_deg=float(roll_sigma),
        pitch_sigma_deg=float(pitch_sigma),
        yaw_sigma_deg=None if yaw_reason else yaw_sigma,
        yaw_reason=yaw_reason,
        tilt_source=tilt_source,
        rotation_sigma_deg=(rot_sigma[0], rot_sigma[1], None if yaw_reason else sigma_z),
        up_driving_s=up_driving,
        tilt_check=tilt_check,
        time_offset_s=float(offset),
        time_offset_sigma_s=offset_sigma,
        time_offset_searched=searched,
        n_intervals=fit.n,
        n_segments=fit.n_segments,
        usable_s=fit.usable_s,
        moving_s=moving_s,
        speed_scale=float(found.document.speed_scale.value or fit.scale),
        correlation=fit.correlation,
        longitudinal_rms_mps2=fit.longitudinal_rms,
        lateral_rms_mps2=fit.lateral_rms,
        yaw_sigma_hac_deg=float(np.degrees(fit.sigma_hac_rad)),
        yaw_sigma_jackknife_deg=None if fit.sigma_jack_rad is None else float(np.degrees(fit.sigma_jack_rad)),
        straightness_source=straight,
        options=opts,
        notes=tuple(notes),
        consistency=found.document,
        findings=found.findings,
        rot_vs_longitudinal=longitudinal,
    )


def euler_sigma(rot_vs: Rotation, sigma_xyz_deg: tuple[float, float, float]) -> tuple[float, float, float]:
    """σ of roll, pitch, yaw from independent small rotations about the vehicle x, y, z axes (1σ, deg).

    Near pitch ±90° roll and yaw trade off, and their σ grow accordingly while the rotation stays
    as well determined as ``sigma_xyz_deg`` says.
    """
    var = np.zeros(3)
    for k, s in enumerate(sigma_xyz_deg):
        if not s:
            continue
        d = np.zeros(3)
        d[k] = np.radians(s)
        up = np.array(angles_from_rot_vs(Rotation.from_rotvec(d) * rot_vs))
        down = np.array(angles_from_rot_vs(Rotation.from_rotvec(-d) * rot_vs))
        var += (np.angle(np.exp(1j * (up - down))) / 2.0) ** 2
    return tuple(float(x) for x in np.degrees(np.sqrt(var)))  # type: ignore[return-value]


def _tilt_check(
    rot_vs: Rotation,
    up_given_s: FloatArray,
    up_driving_s: FloatArray,
    sigma_driving: tuple[float, float],
    given: Calibration | None,
) -> TiltCheck:
    """Driving's up axis against the given one, as small rotations about the vehicle x and y axes."""
    d_v = np.asarray(rot_vs.apply(up_driving_s), dtype=float)  # the given up is exactly +z here
    about_x, about_y = float(np.degrees(np.arctan2(-d_v[1], d_v[2]))), float(np.degrees(np.arctan2(d_v[0], d_v[2])))
    gx = given.rotation_sigma_deg[0] if given is not None and given.rotation_sigma_deg[0] is not None else 0.0
    gy = given.rotation_sigma_deg[1] if given is not None and given.rotation_sigma_deg[1] is not None else 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        zx = float(np.float64(about_x) / np.hypot(sigma_driving[0], gx))
        zy = float(np.float64(about_y) / np.hypot(sigma_driving[1], gy))
    return TiltCheck(
        angle_deg=float(np.degrees(np.arccos(np.clip(up_given_s @ up_driving_s, -1.0, 1.0)))),
        about_vehicle_x_deg=about_x,
        about_vehicle_y_deg=about_y,
        z_about_vehicle_x=zx if np.isfinite(zx) else None,
        z_about_vehicle_y=zy if np.isfinite(zy) else None,
        agree=bool(abs(zx) <= AGREE_Z and abs(zy) <= AGREE_Z),
    )


def _z(z: float | None) -> str:
    return "∞" if z is None else f"{z:+.1f}"
