"""Yaw from driving, the data side: the speed channel, the IMU as cumulative integrals, the gated
intervals and their segments, and the time offset between the two clocks (:mod:`mountcal.estimate.driving`
steps 2–4).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from mountcal.core.conventions import FloatArray, rot_vs_from_angles, tilt_from_normal
from mountcal.core.errors import InputError, NotEnoughInformation
from mountcal.io.samples import Channel, Samples

if TYPE_CHECKING:
    from mountcal.estimate.driving_options import DrivingOptions

IntArray = NDArray[np.int64]
GAP_FACTOR = 3.0  # an IMU step longer than this × the median step is a gap
MIN_INTERVALS = 20
# Where the best lag lies at the edge of ±max_time_offset_s, the search is widened to ±WIDE_OFFSET_S on a grid
# WIDE_STEP_S apart: a GNSS receiver's clock (GPS time) runs 18 s ahead of UTC, a gateway or a logger's clock may be
# seconds off. Without the wider search such a lag sat at the edge, and the drive's tilt came out 14° wrong, confident.
WIDE_OFFSET_S = 30.0
WIDE_STEP_S = 0.25
WIDE_GAIN = 2.0  # the wider search's lag is taken where it explains twice the share the nearer one does


def speed_channel(samples: Samples) -> Channel:
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


def unit_vector(v: FloatArray) -> FloatArray:
    n = float(np.linalg.norm(v))
    if not np.isfinite(n) or n == 0.0:
        raise InputError("acc_s", "finite, non-zero specific force", f"a mean of {v}", "Check the accelerometer data.")
    return np.asarray(v / n, dtype=float)


def tilt_rotation(up_s: FloatArray) -> Rotation:
    """``Ry(pitch) · Rx(roll)``: the tilt that maps the up axis ``up_s`` (sensor frame) onto z."""
    roll, pitch = tilt_from_normal(up_s)
    return rot_vs_from_angles(roll, pitch, 0.0)


# --------------------------------------------------------------------------- the IMU as integrals


@dataclass(frozen=True)
class Imu:
    """Cumulative integrals of the IMU on its clock, to average any quantity over any interval."""

    t_s: FloatArray
    acc_s: FloatArray
    gyro_s: FloatArray | None
    gaps: IntArray  # cumulative count of gaps up to each sample

    @classmethod
    def build(cls, t: FloatArray, acc: FloatArray, gyro: FloatArray | None) -> Imu:
        if t.size < 10:
            raise NotEnoughInformation("too few IMU samples for yaw from driving")
        step = np.diff(t)
        gap = step > GAP_FACTOR * float(np.median(step))
        return cls(t, acc, gyro, np.concatenate([[0], np.cumsum(gap)]).astype(np.int64))

    def integral(self, values: FloatArray) -> FloatArray:
        """Trapezoid cumulative integral of ``values`` (n, k) over time, shape (n, k)."""
        mid = 0.5 * (values[1:] + values[:-1]) * np.diff(self.t_s)[:, None]
        return np.concatenate([np.zeros((1, values.shape[1])), np.cumsum(mid, axis=0)])


def interp_columns(x: FloatArray, xp: FloatArray, fp: FloatArray) -> FloatArray:
    """``np.interp`` of every column of ``fp`` (n, k) at ``x`` (any shape) → shape (*x.shape, k)."""
    return np.stack([np.interp(x, xp, fp[:, j]) for j in range(fp.shape[1])], axis=-1)


@dataclass(frozen=True)
class Layout:
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

    def at(self, offset_s: float) -> Intervals:
        """The accepted intervals with the speed clock moved by ``offset_s``."""
        a, b = self.t_a + offset_s, self.t_b + offset_s
        ok = self.base_ok & (a >= self.imu_t[0]) & (b <= self.imu_t[-1])
        ia = np.searchsorted(self.imu_t, a, side="left")
        ib = np.searchsorted(self.imu_t, b, side="right")
        ok &= self.gaps[np.clip(ib - 1, 0, None)] == self.gaps[np.clip(ia, 0, self.gaps.size - 1)]
        width = self.t_b - self.t_a
        mean = (interp_columns(b, self.imu_t, self.cum) - interp_columns(a, self.imu_t, self.cum)) / width[:, None]
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
        segment = segments_of(self.index[ok], width[ok], turn, o)
        keep = segment >= 0
        sel = np.flatnonzero(ok)[keep]
        return Intervals(
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


def speed_intervals(speed: Channel, opts: DrivingOptions) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Start and end indices (into the speed samples) of intervals of about ``interval_s``, and which of them
    start and end at speed without a gap: the most that can be used, decided by the speed alone."""
    t_v, v = speed.t_s, speed.value
    step = float(np.median(np.diff(t_v))) if t_v.size > 1 else np.inf
    stride = max(1, round(opts.interval_s / step)) if np.isfinite(step) and step > 0 else 1
    start = np.arange(0, t_v.size - stride, stride)
    end = start + stride
    width = t_v[end] - t_v[start]
    ok = (v[start] >= opts.min_speed_mps) & (v[end] >= opts.min_speed_mps) & (width <= 1.5 * stride * step)
    return start, end, ok


def layout_intervals(
    imu: Imu,
    speed: Channel,
    rot_tilt: Rotation,
    heading: Channel | None,
    opts: DrivingOptions,
    lateral_yaw_rad: float | None,
) -> Layout:
    """Intervals of about ``interval_s`` between speed samples, and the IMU integrals to judge them."""
    t_v, v = speed.t_s, speed.value
    start, end, base_ok = speed_intervals(speed, opts)
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
    return Layout(
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


def segments_of(index: IntArray, width: FloatArray, turn_rad: FloatArray | None, opts: DrivingOptions) -> IntArray:
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
    return np.asarray(remap[label], dtype=np.int64)


@dataclass(frozen=True)
class Intervals:
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

    def segment_spans(self) -> FloatArray:
        """Start and end of each segment on the IMU clock, shape (segments, 2), s: its intervals are consecutive."""
        if self.segment.size == 0:
            return np.empty((0, 2))
        half = 0.5 * self.width_s
        n = int(self.segment.max()) + 1
        start = np.full(n, np.inf)
        end = np.full(n, -np.inf)
        np.minimum.at(start, self.segment, self.t_mid_s - half)
        np.maximum.at(end, self.segment, self.t_mid_s + half)
        return np.column_stack([start, end])

    def centred(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``u``, ``a_ref`` and ``a_lat`` less a straight line in time fitted per segment."""
        fit = SegmentLines(self.segment, self.t_mid_s)
        return (
            np.column_stack([fit.residual(self.u[:, 0]), fit.residual(self.u[:, 1])]),
            fit.residual(self.a_ref),
            fit.residual(self.a_lat),
        )


@dataclass(frozen=True)
class SegmentLines:
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


def turned_share(iv: Intervals, yaw: float) -> FloatArray:
    """The share of the body's road tilt that turning rotates into ``u`` (m, 2), levelled coordinates.

    The road's tilt of the body at a segment's start, h₀ (its horizontal gravity share), turns with the heading:
    f ≈ f₀ − δ × f₀ adds (δ_z·h₀_y, −δ_z·h₀_x). h₀ is the segment's mean levelled horizontal specific force less
    its mean kinematic acceleration.
    """
    lines = SegmentLines(iv.segment, iv.t_mid_s)
    x_l = np.array([np.cos(yaw), -np.sin(yaw)])  # vehicle x and y in levelled coordinates
    y_l = np.array([np.sin(yaw), np.cos(yaw)])
    h0 = np.column_stack([lines.mean(iv.u_raw[:, j]) for j in range(2)])
    h0 -= np.outer(lines.mean(iv.a_ref), x_l) + np.outer(lines.mean(iv.a_lat), y_l)
    return np.asarray(iv.turned_rad[:, None] * np.column_stack([h0[iv.segment, 1], -h0[iv.segment, 0]]), dtype=float)


def turned_tilt_removed(iv: Intervals, yaw: float) -> FloatArray:
    """Detrended ``u`` less the share of the body's road tilt that turning rotates into it."""
    lines = SegmentLines(iv.segment, iv.t_mid_s)
    u = iv.u - turned_share(iv, yaw)
    return np.column_stack([lines.residual(u[:, 0]), lines.residual(u[:, 1])])


def yaw_from_sums(a_x: float, a_y: float, a_lat: float) -> tuple[float, float]:
    """Yaw solving ``sin(yaw)·a_x + cos(yaw)·a_y = a_lat`` near ``atan2(−a_y, a_x)``, and the slope there."""
    r = float(np.hypot(a_x, a_y))
    beta = float(np.arctan2(a_y, a_x))
    phase = float(np.arcsin(np.clip(a_lat / r, -1.0, 1.0))) if r > 0 else 0.0
    yaw = float(np.angle(np.exp(1j * (phase - beta))))
    return yaw, max(r * np.cos(phase), 1e-300)


# --------------------------------------------------------------------------- time offset and fit


@dataclass(frozen=True)
class OffsetSearch:
    """The correlation of the fine lags per segment (at lag 0's segments), to find the offset of any segments."""

    lags_s: FloatArray  # (k,)
    cross: FloatArray  # (k, segments) Σ along·a_ref per segment
    energy: FloatArray  # (k, segments) Σ along² per segment
    segment_t_s: FloatArray  # (segments,) mean time of each segment

    def offset(self, segments: np.ndarray) -> float:
        """The lag of the largest correlation over the chosen segments (a boolean mask or indices)."""
        c, e = self.cross[:, segments].sum(axis=1), self.energy[:, segments].sum(axis=1)
        return peak(self.lags_s, c / np.sqrt(np.maximum(e, 1e-300)))


def time_offset(
    layout: Layout, opts: DrivingOptions, notes: list[str]
) -> tuple[float, float | None, bool, OffsetSearch | None]:
    """The lag that best aligns the IMU with the speed change (jackknife σ over segments), or the given one.

    The IMU's longitudinal specific force (along the direction of the cross covariance at lag 0,
    so lateral accelerations that follow speed changes cannot pull the peak) is correlated with
    d(speed)/dt, both detrended per segment; the lag of the largest correlation coefficient (not of
    the largest covariance: the IMU's energy inside the fixed intervals changes with the lag) is
    found on a coarse grid over ±``max_time_offset_s`` and refined on a fine one. The accepted
    intervals are those of lag 0, so every lag is judged on the same intervals.
    """
    if opts.time_offset_s is not None:
        return float(opts.time_offset_s), None, False, None
    base = layout.at(0.0)
    if base.a_ref.size < MIN_INTERVALS:
        return 0.0, None, False, None
    lines = SegmentLines(base.segment, base.t_mid_s)
    _, a_ref, _ = base.centred()
    t_a, t_b = layout.t_a[base.index], layout.t_b[base.index]
    cols = layout.cum[:, :2] + layout.g_mps2 * np.column_stack([layout.cum[:, 10], -layout.cum[:, 9]])
    n_seg = int(base.segment.max()) + 1
    dt = (t_b - t_a)[None, :]

    def rates(lags: FloatArray) -> FloatArray:
        """The IMU's horizontal specific force (two axes) averaged over each interval shifted by each lag."""
        u = interp_columns(t_b[None, :] + lags[:, None], layout.imu_t, cols)
        u -= interp_columns(t_a[None, :] + lags[:, None], layout.imu_t, cols)
        return np.asarray(u / dt[..., None], dtype=np.float64)

    def along_of(c: FloatArray) -> FloatArray:
        return c / max(float(np.linalg.norm(c)), 1e-300)

    direction = along_of(rates(np.zeros(1))[0].T @ a_ref)

    def sums(lags: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Per segment Σ along·a_ref and Σ along², along detrended; shape (lags, segments) each."""
        u = rates(lags)
        along = u[..., 0] * direction[0] + u[..., 1] * direction[1]
        cross, energy = np.empty((lags.size, n_seg)), np.empty((lags.size, n_seg))
        for k in range(lags.size):
            x = lines.residual(along[k])
            cross[k] = np.bincount(base.segment, x * a_ref, n_seg)
            energy[k] = np.bincount(base.segment, x * x, n_seg)
        return cross, energy

    def correlation(cross: FloatArray, energy: FloatArray) -> FloatArray:
        return cross / np.sqrt(np.maximum(energy, 1e-300))

    def coarse_peak(limit: float, spacing: float) -> float:
        coarse: FloatArray = np.arange(-limit, limit + 0.5 * spacing, spacing, dtype=np.float64)
        cross, energy = sums(coarse)
        return peak(coarse, correlation(cross.sum(axis=1), energy.sum(axis=1)))

    def explained(lags: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Per lag, the share of d(speed)/dt both horizontal axes explain (no direction assumed: the one found
        at lag 0 is noise where the clocks are seconds apart), and the direction that explains it."""
        u = rates(lags)
        share, best = np.zeros(lags.size), np.zeros((lags.size, 2))
        total = max(float(a_ref @ a_ref), 1e-300)
        for k in range(lags.size):
            x = np.column_stack([lines.residual(u[k, :, 0]), lines.residual(u[k, :, 1])])
            c, e = x.T @ a_ref, x.T @ x
            if np.linalg.cond(e) < 1e12:
                w = np.asarray(np.linalg.solve(e, c), dtype=np.float64)
                share[k], best[k] = float(c @ w) / total, along_of(w)
        return share, best

    limit, step = opts.max_time_offset_s, opts.time_offset_step_s
    spacing = step * 5
    best = coarse_peak(limit, spacing)
    if WIDE_OFFSET_S > limit:  # clocks further apart than the search: its peak would be a spurious one
        wide: FloatArray = np.arange(-WIDE_OFFSET_S, WIDE_OFFSET_S + 0.5 * WIDE_STEP_S, WIDE_STEP_S)
        share, axes = explained(wide)
        k = int(np.argmax(share))
        near = float(explained(np.array([best]))[0][0])
        if abs(wide[k]) > limit + WIDE_STEP_S and share[k] > WIDE_GAIN * near:
            at_edge = abs(wide[k]) >= WIDE_OFFSET_S - WIDE_STEP_S  # said below as the search's limit
            notes += (
                []
                if at_edge
                else [
                    f"the speed and IMU clocks are {abs(wide[k]):.1f} s apart, beyond the ±{limit:g} s searched first "
                    f"(d(speed)/dt explained {share[k]:.0%} there, {near:.0%} within it): a GNSS clock's 18 leap "
                    "seconds, or a logger's clock off"
                ]
            )
            best, direction, limit, spacing = float(wide[k]), axes[k], WIDE_OFFSET_S, WIDE_STEP_S
    reach = max(10, round(spacing / step))  # the fine grid covers the coarse one's spacing around its peak
    fine: FloatArray = best + np.arange(-reach, reach + 1, dtype=np.float64) * step
    cross, energy = sums(fine)
    best = peak(fine, correlation(cross.sum(axis=1), energy.sum(axis=1)))
    if abs(best) >= limit - step:
        notes.append(
            f"the time offset between the speed and IMU clocks is at the search limit ({best:+.2f} s): "
            "it may be larger; widen max_time_offset_s"
        )
    sigma = None
    if n_seg >= 3:
        c_all, e_all = cross.sum(axis=1), energy.sum(axis=1)
        loo = np.array([peak(fine, correlation(c_all - cross[:, k], e_all - energy[:, k])) for k in range(n_seg)])
        sigma = float(np.sqrt((n_seg - 1) / n_seg * np.sum((loo - loo.mean()) ** 2)))
    times = np.bincount(base.segment, base.t_mid_s, n_seg) / np.bincount(base.segment, minlength=n_seg)
    return best, sigma, True, OffsetSearch(fine, cross, energy, times)


def peak(x: FloatArray, y: FloatArray) -> float:
    """Location of the maximum of ``y(x)``, refined by a parabola through its neighbours."""
    k = int(np.argmax(y))
    if 0 < k < y.size - 1:
        den = y[k - 1] - 2 * y[k] + y[k + 1]
        if den < 0:
            return float(x[k] + 0.5 * (y[k - 1] - y[k + 1]) / den * (x[1] - x[0]))
    return float(x[k])
