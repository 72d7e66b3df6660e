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

Everything is whole-array numpy: cumulative integrals of the IMU, interpolated at the interval
ends; no per-sample Python.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from mountcal.conventions import FloatArray, angles_from_rot_vs, rot_vs_from_angles, tilt_from_normal
from mountcal.errors import InputError, NotEnoughInformation
from mountcal.result import Calibration
from mountcal.samples import Channel, Samples

IntArray = NDArray[np.int64]
AGREE_Z = 2.0  # |z| above this: the two estimates disagree beyond their uncertainties (≈ 95 %)
DISAGREE_Z = 3.0  # |z| above this (tilt or yaw): a finding; the stops and the drive are not combined
GAP_FACTOR = 3.0  # an IMU step longer than this × the median step is a gap
MIN_INTERVALS = 20


@dataclass(frozen=True)
class DrivingOptions:
    """Gates and settings of the driving estimator (defaults suit cars; units in the names)."""

    min_speed_mps: float = 3.0
    max_yaw_rate_deg_s: float = 3.0
    max_tilt_rate_deg_s: float = 3.0
    max_acc_mps2: float = 4.0
    max_lateral_mps2: float = 0.5  # straightness from the lateral acceleration (no gyro, no heading)
    interval_s: float = 1.0
    segment_s: float = 30.0
    max_segment_turn_deg: float = 5.0
    min_segment_intervals: int = 5
    max_time_offset_s: float = 2.0
    time_offset_step_s: float = 0.01
    time_offset_s: float | None = None  # a known offset (added to the speed times): no search
    road_grade_sigma_deg: float = 0.5
    road_cross_slope_sigma_deg: float = 1.5
    max_yaw_sigma_deg: float = 5.0


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
    the ``moving_s`` driven at speed, passed the gates.
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
    tilt_check: dict[str, Any] | None  # driving's up axis against the given tilt's, when one was given
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

    def to_dict(self) -> dict[str, Any]:
        """Plain types, for the result JSON (``fit["driving"]``)."""
        return {
            "roll_deg": self.roll_deg,
            "pitch_deg": self.pitch_deg,
            "yaw_deg": self.yaw_deg,
            "sigma": {
                "roll_deg": self.roll_sigma_deg,
                "pitch_deg": self.pitch_sigma_deg,
                "yaw_deg": self.yaw_sigma_deg,
                "yaw_newey_west_deg": self.yaw_sigma_hac_deg,
                "yaw_jackknife_deg": self.yaw_sigma_jackknife_deg,
                "rotation_about_vehicle_xyz_deg": list(self.rotation_sigma_deg),
                "level": "1 sigma",
            },
            "yaw_reason": self.yaw_reason,
            "tilt_source": self.tilt_source,
            "up_driving_s": self.up_driving_s.tolist(),
            "tilt_check": self.tilt_check,
            "quaternion_xyzw": self.rot_vs.as_quat().tolist(),
            "time_offset_s": self.time_offset_s,
            "time_offset_sigma_s": self.time_offset_sigma_s,
            "time_offset_meaning": "added to the speed channel's times to put them on the IMU clock",
            "time_offset_searched": self.time_offset_searched,
            "intervals": self.n_intervals,
            "segments": self.n_segments,
            "usable_s": self.usable_s,
            "moving_s": self.moving_s,
            "speed_scale": self.speed_scale,
            "correlation": self.correlation,
            "longitudinal_residual_rms_mps2": self.longitudinal_rms_mps2,
            "lateral_rms_mps2": self.lateral_rms_mps2,
            "straightness_from": self.straightness_source,
            "gates": asdict(self.options),
            "notes": list(self.notes),
        }


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
    speed = _speed_channel(samples)
    t, acc = samples.t_s, samples.acc_s
    gyro = samples.gyro_s
    where = samples.source or "log"
    moving = np.interp(t, speed.t_s + (opts.time_offset_s or 0.0), speed.value) >= opts.min_speed_mps
    moving_s = float(np.sum(np.diff(t)[moving[:-1]])) if t.size > 1 else 0.0
    if moving.sum() < 10:
        raise NotEnoughInformation(
            f"{where}: no driving at ≥ {opts.min_speed_mps:g} m/s in the speed channel; yaw from driving needs a drive"
        )
    if tilt_from is not None:
        up_given = np.asarray(tilt_from.rot_vs.inv().apply([0.0, 0.0, 1.0]), dtype=float)
        up = up_given
        tilt_source = f"static calibration ({tilt_from.method})"
    else:
        up_given = None
        up = _unit(acc[moving].mean(axis=0))
        tilt_source = "mean gravity while driving"
    imu = _Imu.build(t, acc, gyro)
    straight = "gyro" if gyro is not None else ("heading channel" if "heading_deg" in samples.channels else "")
    heading = samples.channels.get("heading_deg") if gyro is None else None
    notes: list[str] = []

    # A second pass refines what the first had to guess: the tilt (from driving) and, without a
    # yaw rate, the vehicle's y axis for the straightness gate.
    rot_tilt = _tilt_rotation(up)
    last = tilt_from is not None and bool(straight)
    layout = _intervals(imu, speed, rot_tilt, heading, opts, None)
    offset, offset_sigma, searched = _time_offset(layout, opts, notes if last else [])
    fit = _fit(layout.at(offset), opts, where)
    if not last:
        rot_tilt = rot_tilt if tilt_from is not None else _tilt_rotation(fit.up_s(rot_tilt))
        layout = _intervals(imu, speed, rot_tilt, heading, opts, None if straight else fit.yaw_rad)
        offset, offset_sigma, searched = _time_offset(layout, opts, notes)
        fit = _fit(layout.at(offset), opts, where)
    if not straight:
        straight = f"lateral acceleration (|a_y| ≤ {opts.max_lateral_mps2:g} m/s² after a first pass)"
    up_driving = fit.up_s(rot_tilt)
    return _result(
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
    )


def _speed_channel(samples: Samples) -> Channel:
    where = samples.source or "log"
    ch = samples.channels.get("speed_mps")
    if ch is None or ch.t_s.size < 3:
        raise NotEnoughInformation(
            f"{where}: no vehicle speed channel (speed_mps); yaw from driving needs the speed (CAN/OBD, "
            'wheel speed, GNSS or odometry). Map one (`speed = "MSG.SIGNAL"` in the CAN mapping, an '
            "odometry topic in MCAP, a speed_mps column in a table)."
        )
    ok = np.isfinite(ch.t_s) & np.isfinite(ch.value)
    order = np.argsort(ch.t_s[ok], kind="stable")
    t_v, v = ch.t_s[ok][order], ch.value[ok][order]
    keep = np.concatenate([[True], np.diff(t_v) > 0])  # one value per time
    return Channel(t_v[keep], v[keep])


def _unit(v: FloatArray) -> FloatArray:
    n = float(np.linalg.norm(v))
    if not np.isfinite(n) or n == 0.0:
        raise InputError("acc_s", "finite, non-zero specific force", f"a mean of {v}", "Check the accelerometer data.")
    return np.asarray(v / n, dtype=float)


def _tilt_rotation(up_s: FloatArray) -> Rotation:
    """``Ry(pitch) · Rx(roll)``: the tilt that maps the up axis ``up_s`` (sensor frame) onto z."""
    roll, pitch = tilt_from_normal(up_s)
    return rot_vs_from_angles(roll, pitch, 0.0)


# --------------------------------------------------------------------------- the IMU as integrals


@dataclass(frozen=True)
class _Imu:
    """Cumulative integrals of the IMU on its clock, to average any quantity over any interval."""

    t_s: FloatArray
    acc_s: FloatArray
    gyro_s: FloatArray | None
    gaps: IntArray  # cumulative count of gaps up to each sample

    @classmethod
    def build(cls, t: FloatArray, acc: FloatArray, gyro: FloatArray | None) -> _Imu:
        if t.size < 10:
            raise NotEnoughInformation("too few IMU samples for yaw from driving")
        step = np.diff(t)
        gap = step > GAP_FACTOR * float(np.median(step))
        return cls(t, acc, gyro, np.concatenate([[0], np.cumsum(gap)]).astype(np.int64))

    def integral(self, values: FloatArray) -> FloatArray:
        """Trapezoid cumulative integral of ``values`` (n, k) over time, shape (n, k)."""
        mid = 0.5 * (values[1:] + values[:-1]) * np.diff(self.t_s)[:, None]
        return np.concatenate([np.zeros((1, values.shape[1])), np.cumsum(mid, axis=0)])


def _interp_columns(x: FloatArray, xp: FloatArray, fp: FloatArray) -> FloatArray:
    """``np.interp`` of every column of ``fp`` (n, k) at ``x`` (any shape) → shape (*x.shape, k)."""
    return np.stack([np.interp(x, xp, fp[:, j]) for j in range(fp.shape[1])], axis=-1)


@dataclass(frozen=True)
class _Layout:
    """Candidate intervals between speed samples and the integrals to evaluate them at any lag."""

    t_a: FloatArray  # interval start and end on the speed clock, shape (m,)
    t_b: FloatArray
    v_a: FloatArray  # speed at the start and the end, m/s
    v_b: FloatArray
    base_ok: NDArray[np.bool_]  # gates that do not depend on the lag (speed, no speed gap)
    imu_t: FloatArray
    cum: FloatArray  # (n, 12) cumulative integrals: levelled horizontal (2), raw acc (3), gates (3), yaw rate,
    # attitude change about the levelled x and y axes (2), heading change (1)
    g_mps2: float
    gaps: IntArray
    index: IntArray  # position of each interval in the sequence (consecutive ones differ by 1)
    opts: DrivingOptions
    heading: Channel | None
    lateral_yaw_rad: float | None
    turn_known: bool  # the yaw rate comes from a gyro or a heading channel

    def at(self, offset_s: float) -> _Intervals:
        """The accepted intervals with the speed clock moved by ``offset_s``."""
        a, b = self.t_a + offset_s, self.t_b + offset_s
        ok = self.base_ok & (a >= self.imu_t[0]) & (b <= self.imu_t[-1])
        ia = np.searchsorted(self.imu_t, a, side="left")
        ib = np.searchsorted(self.imu_t, b, side="right")
        ok &= self.gaps[np.clip(ib - 1, 0, None)] == self.gaps[np.clip(ia, 0, self.gaps.size - 1)]
        width = self.t_b - self.t_a
        mean = (_interp_columns(b, self.imu_t, self.cum) - _interp_columns(a, self.imu_t, self.cum)) / width[:, None]
        u, acc3, gate = mean[:, :2], mean[:, 2:5], mean[:, 5:8]
        yaw_rate = mean[:, 8]  # rad/s, counter-clockwise about the vehicle's up axis
        # Gravity leaks into the horizontal as the body rolls and pitches (bank, grade, suspension):
        # a small attitude change δ gives f ≈ f₀ − δ × (0, 0, g), so remove (−g·δ_y, g·δ_x).
        attitude = mean[:, 9:11]
        u_raw = u
        u = u + self.g_mps2 * np.column_stack([attitude[:, 1], -attitude[:, 0]])
        turned = mean[:, 11]  # heading change since the log's start (gyro), rad
        o = self.opts
        ok &= gate[:, 0] <= o.max_acc_mps2
        ok &= gate[:, 1] <= np.radians(o.max_yaw_rate_deg_s)
        ok &= gate[:, 2] <= np.radians(o.max_tilt_rate_deg_s)
        if self.heading is not None:  # compass heading: clockwise, so the counter-clockwise rate is −dψ/dt
            psi = np.unwrap(np.radians(self.heading.value))
            yaw_rate = -(np.interp(b, self.heading.t_s, psi) - np.interp(a, self.heading.t_s, psi)) / width
            ok &= np.abs(yaw_rate) <= np.radians(o.max_yaw_rate_deg_s)
        if self.lateral_yaw_rad is not None:
            c, s = np.cos(self.lateral_yaw_rad), np.sin(self.lateral_yaw_rad)
            lateral = s * u[:, 0] + c * u[:, 1]
            ok &= np.abs(lateral - np.median(lateral[ok])) <= o.max_lateral_mps2 if ok.any() else ok
        turn = (yaw_rate * width)[ok] if self.turn_known else None
        segment = _segments(self.index[ok], width[ok], turn, o)
        keep = segment >= 0
        sel = np.flatnonzero(ok)[keep]
        return _Intervals(
            index=sel,
            u=u[sel],
            u_raw=u_raw[sel],
            acc_s=acc3[sel],
            a_ref=(self.v_b[sel] - self.v_a[sel]) / width[sel],
            a_lat=0.5 * (self.v_a[sel] + self.v_b[sel]) * yaw_rate[sel],
            turned_rad=turned[sel],
            width_s=width[sel],
            segment=segment[keep],
            t_mid_s=0.5 * (a[sel] + b[sel]),
        )


def _intervals(
    imu: _Imu,
    speed: Channel,
    rot_tilt: Rotation,
    heading: Channel | None,
    opts: DrivingOptions,
    lateral_yaw_rad: float | None,
) -> _Layout:
    """Intervals of about ``interval_s`` between speed samples, and the IMU integrals to judge them."""
    t_v, v = speed.t_s, speed.value
    step = float(np.median(np.diff(t_v)))
    stride = max(1, round(opts.interval_s / step))
    start = np.arange(0, t_v.size - stride, stride)
    end = start + stride
    width = t_v[end] - t_v[start]
    base_ok = (v[start] >= opts.min_speed_mps) & (v[end] >= opts.min_speed_mps) & (width <= 1.5 * stride * step)
    levelled = rot_tilt.apply(imu.acc_s)
    gate_cols = [np.linalg.norm(levelled[:, :2], axis=1)]
    if imu.gyro_s is not None:
        w = rot_tilt.apply(imu.gyro_s)
        # Attitude change from the levelled roll and pitch rates. A gyro bias (or a levelling error
        # tipping the yaw rate into them) makes it drift about linearly within a straight segment,
        # which the per-segment detrending removes.
        attitude = imu.integral(w[:, :2])
        turned = imu.integral(w[:, 2:3])[:, 0]
        gate_cols += [
            np.abs(w[:, 2]),
            np.linalg.norm(w[:, :2], axis=1),
            w[:, 2],
            attitude[:, 0],
            attitude[:, 1],
            turned,
        ]
    else:
        gate_cols += [np.zeros(imu.t_s.size)] * 6
    values = np.column_stack([levelled[:, :2], imu.acc_s, *gate_cols])
    return _Layout(
        t_a=t_v[start],
        t_b=t_v[end],
        v_a=v[start],
        v_b=v[end],
        base_ok=base_ok,
        imu_t=imu.t_s,
        cum=imu.integral(values),
        g_mps2=float(np.median(np.linalg.norm(imu.acc_s, axis=1))),
        gaps=imu.gaps,
        index=np.arange(start.size, dtype=np.int64),
        opts=opts,
        heading=heading,
        lateral_yaw_rad=lateral_yaw_rad,
        turn_known=imu.gyro_s is not None or heading is not None,
    )


def _segments(index: IntArray, width: FloatArray, turn_rad: FloatArray | None, opts: DrivingOptions) -> IntArray:
    """Segment label of each accepted interval (−1: in a piece too short to use).

    A segment is a run of consecutive intervals whose heading stays within ``max_segment_turn_deg``
    (when the heading change ``turn_rad`` of each interval is known) and that lasts at most
    ``segment_s`` (longer runs are cut into equal pieces). Within a straight segment the tilt the
    road gives the body stays put in the body frame, so its gravity share is one constant.
    """
    if index.size == 0:
        return np.empty(0, np.int64)
    new = np.concatenate([[True], np.diff(index) != 1])
    if turn_rad is not None:
        heading_bin = np.floor(np.cumsum(turn_rad) / np.radians(opts.max_segment_turn_deg))
        new |= np.concatenate([[True], np.diff(heading_bin) != 0])
    run = np.cumsum(new) - 1
    per = max(1, round(opts.segment_s / float(np.median(width))))
    run_start = np.flatnonzero(new)
    run_len = np.diff(np.concatenate([run_start, [index.size]]))
    pieces = np.maximum(1, np.ceil(run_len / per)).astype(np.int64)
    pos = np.arange(index.size) - run_start[run]
    label = np.concatenate([[0], np.cumsum(pieces)[:-1]])[run] + (pos * pieces[run]) // run_len[run]
    size = np.bincount(label)
    usable = size >= opts.min_segment_intervals
    remap = np.where(usable, np.cumsum(usable) - 1, -1)
    return remap[label]


@dataclass(frozen=True)
class _Intervals:
    """The accepted intervals: means over each (m/s²) and its segment."""

    index: IntArray  # position in the layout's arrays
    u: FloatArray  # (m, 2) levelled horizontal specific force, less the gravity the attitude change adds
    u_raw: FloatArray  # (m, 2) levelled horizontal specific force as measured
    acc_s: FloatArray  # (m, 3) raw specific force, sensor frame
    a_ref: FloatArray  # (m,) speed change / duration
    a_lat: FloatArray  # (m,) centripetal acceleration v·ω predicted from the speed and yaw rate (0 without)
    turned_rad: FloatArray  # (m,) mean heading change since the log's start (gyro; 0 without)
    width_s: FloatArray
    segment: IntArray
    t_mid_s: FloatArray

    def centred(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``u``, ``a_ref`` and ``a_lat`` less a straight line in time fitted per segment."""
        fit = _SegmentLines(self.segment, self.t_mid_s)
        return (
            np.column_stack([fit.residual(self.u[:, 0]), fit.residual(self.u[:, 1])]),
            fit.residual(self.a_ref),
            fit.residual(self.a_lat),
        )


@dataclass(frozen=True)
class _SegmentLines:
    """Least-squares lines ``x ≈ α_k + β_k·t`` per segment k, to detrend anything on the intervals.

    A segment's mean absorbs the road's constant tilt and a bias; its slope absorbs slow drifts: a
    gyro bias integrated into the attitude, a levelling error tipping a gentle curve's yaw rate.
    """

    segment: IntArray
    t_s: FloatArray

    def _sums(self, x: FloatArray) -> FloatArray:
        return np.bincount(self.segment, x, int(self.segment.max()) + 1).astype(np.float64)

    def residual(self, x: FloatArray) -> FloatArray:
        seg = self.segment
        count = self._sums(np.ones_like(x))
        t = self.t_s - (self._sums(self.t_s) / count)[seg]
        x_c = x - (self._sums(x) / count)[seg]
        stt = self._sums(t * t)
        slope = np.divide(self._sums(t * x_c), stt, out=np.zeros_like(stt), where=stt > 0)
        return x_c - slope[seg] * t

    def mean(self, x: FloatArray) -> FloatArray:
        return self._sums(x) / self._sums(np.ones_like(x))


# --------------------------------------------------------------------------- time offset and fit


def _time_offset(layout: _Layout, opts: DrivingOptions, notes: list[str]) -> tuple[float, float | None, bool]:
    """The lag that best aligns the IMU with the speed change (jackknife σ over segments), or the given one.

    The IMU's longitudinal specific force (along the direction of the cross covariance at lag 0,
    so lateral accelerations that follow speed changes cannot pull the peak) is correlated with
    d(speed)/dt, both detrended per segment; the lag of the largest correlation coefficient (not of
    the largest covariance: the IMU's energy inside the fixed intervals changes with the lag) is
    found on a coarse grid over ±``max_time_offset_s`` and refined on a fine one. The accepted
    intervals are those of lag 0, so every lag is judged on the same intervals.
    """
    if opts.time_offset_s is not None:
        return float(opts.time_offset_s), None, False
    base = layout.at(0.0)
    if base.a_ref.size < MIN_INTERVALS:
        return 0.0, None, False
    lines = _SegmentLines(base.segment, base.t_mid_s)
    _, a_ref, _ = base.centred()
    t_a, t_b = layout.t_a[base.index], layout.t_b[base.index]
    cols = layout.cum[:, :2] + layout.g_mps2 * np.column_stack([layout.cum[:, 10], -layout.cum[:, 9]])
    n_seg = int(base.segment.max()) + 1
    u0 = (_interp_columns(t_b, layout.imu_t, cols) - _interp_columns(t_a, layout.imu_t, cols)) / (t_b - t_a)[:, None]
    c0 = u0.T @ a_ref
    direction = c0 / max(float(np.linalg.norm(c0)), 1e-300)

    def sums(lags: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Per segment Σ along·a_ref and Σ along², along detrended; shape (lags, segments) each."""
        along = _interp_columns(t_b[None, :] + lags[:, None], layout.imu_t, cols)
        along -= _interp_columns(t_a[None, :] + lags[:, None], layout.imu_t, cols)
        along = (along[..., 0] * direction[0] + along[..., 1] * direction[1]) / (t_b - t_a)[None, :]
        cross, energy = np.empty((lags.size, n_seg)), np.empty((lags.size, n_seg))
        for k in range(lags.size):
            x = lines.residual(along[k])
            cross[k] = np.bincount(base.segment, x * a_ref, n_seg)
            energy[k] = np.bincount(base.segment, x * x, n_seg)
        return cross, energy

    def correlation(cross: FloatArray, energy: FloatArray) -> FloatArray:
        return cross / np.sqrt(np.maximum(energy, 1e-300))

    limit, step = opts.max_time_offset_s, opts.time_offset_step_s
    coarse: FloatArray = np.arange(-limit, limit + 0.5 * step * 5, step * 5, dtype=np.float64)
    cross, energy = sums(coarse)
    best = _peak(coarse, correlation(cross.sum(axis=1), energy.sum(axis=1)))
    fine: FloatArray = best + np.arange(-10, 11, dtype=np.float64) * step
    cross, energy = sums(fine)
    best = _peak(fine, correlation(cross.sum(axis=1), energy.sum(axis=1)))
    if abs(best) >= limit - step:
        notes.append(
            f"the time offset between the speed and IMU clocks is at the search limit ({best:+.2f} s): "
            "it may be larger; widen max_time_offset_s"
        )
    sigma = None
    if n_seg >= 3:
        c_all, e_all = cross.sum(axis=1), energy.sum(axis=1)
        loo = np.array([_peak(fine, correlation(c_all - cross[:, k], e_all - energy[:, k])) for k in range(n_seg)])
        sigma = float(np.sqrt((n_seg - 1) / n_seg * np.sum((loo - loo.mean()) ** 2)))
    return best, sigma, True


def _peak(x: FloatArray, y: FloatArray) -> float:
    """Location of the maximum of ``y(x)``, refined by a parabola through its neighbours."""
    k = int(np.argmax(y))
    if 0 < k < y.size - 1:
        den = y[k - 1] - 2 * y[k] + y[k + 1]
        if den < 0:
            return float(x[k] + 0.5 * (y[k - 1] - y[k + 1]) / den * (x[1] - x[0]))
    return float(x[k])


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
        return _unit(self.mean_acc_s - self.mean_a_ref * scale * np.asarray(x_s))


def _fit(iv: _Intervals, opts: DrivingOptions, where: str) -> _Fit:
    """Yaw from the intervals: the direction in which the levelled IMU follows the speed change.

    With ``A, B = Σ a·u_x, Σ a·u_y`` and ``C = Σ a·a_lat`` (segment-centred; ``a`` the speed
    change rate, ``a_lat`` the predicted centripetal acceleration) yaw solves
    ``Σ a · ((Rz(yaw)·u)_y − a_lat) = 0``, i.e. ``sin(yaw + β) = C / hypot(A, B)``, β = atan2(B, A).
    """
    if iv.a_ref.size < MIN_INTERVALS:
        raise NotEnoughInformation(
            f"{where}: only {iv.a_ref.size} usable straight intervals at ≥ {opts.min_speed_mps:g} m/s "
            f"(need {MIN_INTERVALS}); yaw from driving needs more straight driving with speed changes "
            "(accelerating and braking), or stops on a slope with headings (--protocol)"
        )
    u, a, lat = iv.centred()
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
    yaw, slope = _yaw_from_sums(float(u[:, 0] @ a), float(u[:, 1] @ a), float(lat @ a))
    if np.any(iv.turned_rad):
        # The road's tilt of the body at a segment's start, h₀ (its horizontal gravity share), turns
        # with the heading: f ≈ f₀ − δ × f₀ adds (δ_z·h₀_y, −δ_z·h₀_x). h₀ is the segment's mean
        # levelled horizontal specific force less its mean kinematic acceleration.
        u = _turned_tilt_removed(iv, yaw)
        yaw, slope = _yaw_from_sums(float(u[:, 0] @ a), float(u[:, 1] @ a), float(lat @ a))
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
        yaw_loo = np.array([_yaw_from_sums(loo[0][k], loo[1][k], loo[2][k])[0] for k in range(n_seg)])
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


def _turned_tilt_removed(iv: _Intervals, yaw: float) -> FloatArray:
    """Detrended ``u`` less the share of the body's road tilt that turning rotates into it."""
    lines = _SegmentLines(iv.segment, iv.t_mid_s)
    seg = iv.segment
    x_l = np.array([np.cos(yaw), -np.sin(yaw)])  # vehicle x and y in levelled coordinates
    y_l = np.array([np.sin(yaw), np.cos(yaw)])
    h0 = np.column_stack([lines.mean(iv.u_raw[:, j]) for j in range(2)])
    h0 -= np.outer(lines.mean(iv.a_ref), x_l) + np.outer(lines.mean(iv.a_lat), y_l)
    u = iv.u - iv.turned_rad[:, None] * np.column_stack([h0[seg, 1], -h0[seg, 0]])
    return np.column_stack([lines.residual(u[:, 0]), lines.residual(u[:, 1])])


def _yaw_from_sums(a_x: float, a_y: float, a_lat: float) -> tuple[float, float]:
    """Yaw solving ``sin(yaw)·a_x + cos(yaw)·a_y = a_lat`` near ``atan2(−a_y, a_x)``, and the slope there."""
    r = float(np.hypot(a_x, a_y))
    beta = float(np.arctan2(a_y, a_x))
    phase = float(np.arcsin(np.clip(a_lat / r, -1.0, 1.0))) if r > 0 else 0.0
    yaw = float(np.angle(np.exp(1j * (phase - beta))))
    return yaw, max(r * np.cos(phase), 1e-300)


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
) -> DrivingFit:
    sigma_z = float(np.degrees(max(fit.sigma_hac_rad, fit.sigma_jack_rad or 0.0)))  # about the vehicle z axis
    yaw_reason = None
    if sigma_z > opts.max_yaw_sigma_deg:
        yaw_reason = (
            f"the drive determines yaw only to {sigma_z:.3g}° (limit {opts.max_yaw_sigma_deg:g}°): too few "
            "speed changes on straight road; drive with more accelerating and braking"
        )
    yaw_rad = fit.yaw_rad if yaw_reason is None else 0.0
    rot_vs = Rotation.from_euler("z", yaw_rad) * rot_tilt
    # Tilt σ about the vehicle x (cross slope) and y (grade) axes: the unknown mean road attitude
    # dominates the scatter of the mean; tilt from a static calibration keeps that one's σ.
    stat = np.degrees(fit.longitudinal_rms / 9.8 / np.sqrt(max(fit.n, 1)))
    road = (float(np.hypot(stat, opts.road_cross_slope_sigma_deg)), float(np.hypot(stat, opts.road_grade_sigma_deg)))
    if tilt_from is not None:
        sx = tilt_from.rotation_sigma_deg[0] or tilt_from.roll_sigma_deg
        sy = tilt_from.rotation_sigma_deg[1] or tilt_from.pitch_sigma_deg
    else:
        sx, sy = road
    r, p, _ = angles_from_rot_vs(rot_vs)
    roll, pitch = float(np.degrees(r)), float(np.degrees(p))
    roll_sigma, pitch_sigma, yaw_sigma = _euler_sigma(rot_vs, (sx, sy, 0.0 if yaw_reason else sigma_z))
    if tilt_from is not None:  # the static fit's own marginals know its correlations
        roll_sigma, pitch_sigma = tilt_from.roll_sigma_deg, tilt_from.pitch_sigma_deg
    rot_sigma = (float(sx), float(sy))
    tilt_check = None
    if up_given is not None:
        tilt_check = _tilt_check(rot_vs, up_given, up_driving, road, tilt_from)
        if not tilt_check["agree"]:
            notes.append(
                "the mean gravity while driving tilts from the given calibration's up axis by "
                f"{tilt_check['angle_deg']:.2f}° (z = {tilt_check['z_about_vehicle_x']:+.1f} about x, "
                f"{tilt_check['z_about_vehicle_y']:+.1f} about y): more than the road's grade and cross slope explain"
            )
    if abs(pitch) > 60.0:
        notes.append(
            f"pitch {pitch:.1f}° is near ±90°: roll and yaw then trade off (gimbal lock), so compare rotations, "
            "not Euler angles; the rotation about the vehicle z axis is what the drive measures"
        )
    if np.isfinite(fit.scale) and abs(fit.scale - 1.0) > 0.1:
        notes.append(
            f"the IMU's longitudinal acceleration is {fit.scale:.3f} × d(speed)/dt: a speed scale error, "
            "an accelerometer scale error or a strongly graded route"
        )
    return DrivingFit(
        rot_vs=rot_vs,
        roll_deg=float(roll),
        pitch_deg=float(pitch),
        yaw_deg=None if yaw_reason else float(np.degrees(yaw_rad)),
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
        speed_scale=fit.scale,
        correlation=fit.correlation,
        longitudinal_rms_mps2=fit.longitudinal_rms,
        lateral_rms_mps2=fit.lateral_rms,
        yaw_sigma_hac_deg=float(np.degrees(fit.sigma_hac_rad)),
        yaw_sigma_jackknife_deg=None if fit.sigma_jack_rad is None else float(np.degrees(fit.sigma_jack_rad)),
        straightness_source=straight,
        options=opts,
        notes=tuple(notes),
    )


def _euler_sigma(rot_vs: Rotation, sigma_xyz_deg: tuple[float, float, float]) -> tuple[float, float, float]:
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
) -> dict[str, Any]:
    """Driving's up axis against the given one, as small rotations about the vehicle x and y axes."""
    d_v = np.asarray(rot_vs.apply(up_driving_s), dtype=float)  # the given up is exactly +z here
    about_x, about_y = float(np.degrees(np.arctan2(-d_v[1], d_v[2]))), float(np.degrees(np.arctan2(d_v[0], d_v[2])))
    gx = given.rotation_sigma_deg[0] if given is not None and given.rotation_sigma_deg[0] is not None else 0.0
    gy = given.rotation_sigma_deg[1] if given is not None and given.rotation_sigma_deg[1] is not None else 0.0
    zx = about_x / float(np.hypot(sigma_driving[0], gx))
    zy = about_y / float(np.hypot(sigma_driving[1], gy))
    return {
        "angle_deg": float(np.degrees(np.arccos(np.clip(up_given_s @ up_driving_s, -1.0, 1.0)))),
        "about_vehicle_x_deg": about_x,
        "about_vehicle_y_deg": about_y,
        "z_about_vehicle_x": zx,
        "z_about_vehicle_y": zy,
        "agree": bool(abs(zx) <= AGREE_Z and abs(zy) <= AGREE_Z),
    }


# --------------------------------------------------------------------------- as a calibration, and combined


def driving_calibration(
    fit: DrivingFit, *, gravity_mps2: float, gravity_source: str, provenance: dict[str, Any]
) -> Calibration:
    """A :class:`~mountcal.result.Calibration` from driving alone (no parked stops).

    Roll and pitch come from the mean gravity while driving (σ include the unknown mean road grade
    and cross slope), yaw from the speed changes; slope and bias are not applicable (no stops) and
    the result says so. The full driving fit is in ``fit["driving"]``.
    """
    notes = [
        "from driving only: no parked stops; roll and pitch are the mean gravity direction while driving, "
        "whose σ assume the route's mean grade and cross slope are 0 ± "
        f"{fit.options.road_grade_sigma_deg:g}° and 0 ± {fit.options.road_cross_slope_sigma_deg:g}°",
        "an accelerometer bias b tilts the mean gravity by b/g (20 mg → 1.1°) and cannot be told from a tilt "
        "while driving; parked stops on a slope can (docs/conventions.md §4)",
        "slope: not applicable (no parked stops)",
        *fit.notes,
    ]
    return Calibration(
        method="driving",
        model=("rotation",),
        rot_vs=fit.rot_vs,
        roll_deg=fit.roll_deg,
        pitch_deg=fit.pitch_deg,
        yaw_deg=fit.yaw_deg,
        roll_sigma_deg=fit.roll_sigma_deg,
        pitch_sigma_deg=fit.pitch_sigma_deg,
        yaw_sigma_deg=fit.yaw_sigma_deg,
        yaw_reason=fit.yaw_reason,
        slope_deg=None,
        slope_sigma_deg=None,
        rotation_sigma_deg=fit.rotation_sigma_deg,
        bias_mps2=None,
        bias_sigma_mps2=None,
        gravity_mps2=gravity_mps2,
        gravity_source=gravity_source,
        residual_rms_mps2=fit.longitudinal_rms_mps2,
        residual_s=np.zeros((0, 3)),
        fit={"calibrated_from": "driving", "driving": fit.to_dict()},
        observability={},
        model_selection={"mode": "driving", "chosen": ["rotation"]},
        provenance=provenance,
        notes=tuple(notes),
    )


def disagreement(static: Calibration, fit: DrivingFit) -> dict[str, Any] | None:
    """The stops against the drive, beyond ``DISAGREE_Z`` σ in tilt or yaw: an ``unexplained`` entry, else None.

    Tilt: the drive's mean gravity against the stops' up axis (``fit.tilt_check``), about the
    vehicle x and y axes. Yaw: the two yaws about the vehicle z axis, when both determine one.
    """
    parts: list[str] = []
    z_max = 0.0
    check = fit.tilt_check
    if check is not None:
        z_tilt = max(abs(check["z_about_vehicle_x"]), abs(check["z_about_vehicle_y"]))
        if z_tilt > DISAGREE_Z or not np.isfinite(z_tilt):
            parts.append(
                f"tilt by {check['angle_deg']:.1f}° (z = {check['z_about_vehicle_x']:+.1f} about x, "
                f"{check['z_about_vehicle_y']:+.1f} about y)"
            )
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
    return {
        "test": "stops_vs_driving",
        "what": "the parked stops and the drive disagree beyond their uncertainties (not combined)",
        "size": "; ".join(parts),
        "statistic": float(z_max) if np.isfinite(z_max) else None,
        "z_limit": DISAGREE_Z,
        "p_value": None,
    }


def not_combined(static: Calibration, fit: DrivingFit, found: dict[str, Any]) -> Calibration:
    """The stops' calibration, not confident, with the disagreement with the drive as a finding."""
    words = (
        f"stops and driving DISAGREE: {found['size']}, beyond {DISAGREE_Z:g}σ; they are not combined and the "
        "result is not confident. One of them misses an effect (a remount between the stops and the drive, "
        "a wrong protocol heading or uphill azimuth, a speed channel not along the vehicle x axis, the stops' "
        "mirror solution)"
    )
    return replace(
        static,
        fit={
            **static.fit,
            "calibrated_from": "stops (driving disagrees: not combined)",
            "driving": fit.to_dict(),
            "combination": {
                "used": "none: disagreement",
                "agree": False,
                "disagreement": found,
                "tilt_check": fit.tilt_check,
            },
        },
        notes=(*static.notes, words),
        unexplained=[*static.unexplained, found],
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
    combination: dict[str, Any] = {"static_yaw_deg": static.yaw_deg, "driving_yaw_deg": fit.yaw_deg}
    s_drive = fit.rotation_sigma_deg[2]
    if fit.yaw_deg is None or s_drive is None:
        notes.append(f"yaw from driving not determined: {fit.yaw_reason}")
        combination["used"] = "static"
        return replace(
            static,
            fit={
                **static.fit,
                "calibrated_from": "stops (driving checked)",
                "driving": fit.to_dict(),
                "combination": combination,
            },
            notes=tuple(notes),
        )
    sx = static.rotation_sigma_deg[0] or static.roll_sigma_deg
    sy = static.rotation_sigma_deg[1] or static.pitch_sigma_deg
    if static.yaw_deg is None or static.yaw_sigma_deg is None:
        yaw, s_z = fit.yaw_deg, s_drive
        combination.update(used="driving (the stops do not determine yaw)", static_yaw_reason=static.yaw_reason)
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
        combination.update(used="inverse-variance combination", difference_deg=diff, z=z, agree=agree, words=words)
        notes.append(words)
    rot_vs = Rotation.from_euler("z", np.radians(yaw)) * _tilt_rotation(
        np.asarray(static.rot_vs.inv().apply([0.0, 0.0, 1.0]), dtype=float)
    )
    roll, pitch, yaw_e = (float(np.degrees(a)) for a in angles_from_rot_vs(rot_vs))
    yaw_sigma = _euler_sigma(rot_vs, (sx, sy, s_z))[2]
    combination.update(yaw_deg=yaw_e, yaw_sigma_about_vehicle_z_deg=s_z)
    if fit.tilt_check is not None:
        combination["tilt_check"] = fit.tilt_check
    return replace(
        static,
        rot_vs=rot_vs,
        roll_deg=roll,
        pitch_deg=pitch,
        yaw_deg=yaw_e,
        yaw_sigma_deg=yaw_sigma,
        yaw_reason=None,
        rotation_sigma_deg=(static.rotation_sigma_deg[0], static.rotation_sigma_deg[1], s_z),
        fit={**static.fit, "calibrated_from": "stops + driving", "driving": fit.to_dict(), "combination": combination},
        notes=tuple(notes),
    )
