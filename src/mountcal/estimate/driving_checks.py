"""Residual tests of yaw from driving: independent cues and parts of the drive against each other.

Yaw from driving rests on one cue — the direction in which the levelled IMU follows the speed changes on
straight road (:mod:`mountcal.estimate.driving`). What the driving model lacks shows up as two estimates of
one quantity that disagree beyond their σ:

- **Cues.** The *lateral* cue: on every interval at speed, turns included, the direction in which the IMU
  follows the centripetal acceleration ``v·ω`` is the vehicle's y axis; yaw solves
  ``Σ v·ω · ((Rz(yaw)·u)_x − s·a) = 0`` (``s`` the longitudinal scale, ``a`` the speed change), the mirror of the
  longitudinal equation. In a right-handed sensor with orthogonal axes the two directions are 90° apart in the
  vehicle's horizontal plane; a horizontal scale or cross-axis error turns them apart (by up to the difference
  of the axes' scales, or twice the cross-axis coupling), a lever arm or the body rolling under load moves the
  lateral one.
- **Halves and parts** of the drive, in time: yaw (and the tilt from the mean gravity, and the speed's clock
  offset) of the first half against the second; yaw of up to ``PARTS`` consecutive parts against their mean
  (χ²). A remount, a bracket that slips, a temperature trend, a clock that drifts.
- **Left against right turns** (the lateral cue from each): a lever arm or sideslip (the sensor ahead of or
  behind the point whose speed is measured adds ``−ω²·r`` along x in both turns).
- **Accelerating against braking** (the longitudinal cue from each): an effect that follows |a| — brake pull,
  a nonlinear axis.
- **Speed scale**, errors in variables: the IMU's longitudinal specific force against d(speed)/dt with both
  noises counted (Deming's regression; the speed channel's noise from its own second differences, the IMU's
  from the lateral residual of straight driving); its note only beyond ``SCALE_Z`` σ, and only when both
  ordinary regressions (between which the truth lies, whatever the noises) are on the same side of 1.

Each σ is a jackknife over blocks of consecutive straight segments (a block keeps the correlation of neighbouring
segments: the same hill, the same road; a short drive's segments are cut into pieces first, :func:`units`),
scaled up to the whole drive's σ where that is larger (its Newey–West part sees the correlation of neighbouring
intervals the blocks do not); a test needs ``MIN_BLOCKS`` blocks per side. The family's p-values go through
Holm's procedure at :data:`FAMILY_ALPHA`; what it rejects is a finding: the result is not confident, and the
σ of what the finding concerns is widened by a model-error term — half the disagreement (both estimates then
lie within 1σ of their mean) — stated in the result. The reported yaw rests on the longitudinal cue, the one
that defines the vehicle's x axis. Its σ also holds what the accelerometer's horizontal scale and cross-axis
errors may leave (the sensor class's limits, ±3 % and ±2 % by default, as for the stops' systematic part),
narrowed by the cues: such an error turns the two cues by half their difference each, in opposite directions,
so the lateral cue measures it when the drive turns enough (:func:`_axes`).

**Effects of the body and the road**, each taken only when the data choose it, with the value before and after:

- ``lateral_scale``: the IMU's lateral specific force against ``v·ω``. The body rolling on its suspension
  under lateral load adds ``g·k·v·ω`` (the gyro removes it; without a gyro it stays), and the longitudinal
  equation subtracts ``v·ω``: beyond ``EFFECT_Z`` σ from 1 it is fitted, and yaw refitted with it.
- ``body_pitch``, ``body_roll``: the body's pitch per longitudinal and roll per lateral acceleration, from the
  gyro's attitude (which the fit already removes from the horizontal): reported when beyond ``EFFECT_Z`` σ.
- ``grade``: the route's mean grade from the altitude channel and the distance driven; it tilts the mean gravity
  about the vehicle's y axis, and replaces the assumed grade's σ when it is known better.
- ``crown``: the mean cross slope cannot be told from a roll of the mounting while driving — declined, with the
  reason (parked stops on a slope can).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial.transform import Rotation

from mountcal.core.angles import Angles
from mountcal.core.conventions import FloatArray
from mountcal.core.driving_document import (
    Comparison,
    Cues,
    DrivingConsistency,
    DrivingEffect,
    Estimate,
    Halves,
    ModelError,
    Parts,
    SpeedScale,
)
from mountcal.core.findings import Finding
from mountcal.core.option_names import option
from mountcal.core.pvalues import unexplained
from mountcal.estimate.driving_blocks import (
    MIN_BLOCKS,
    Sums,
    compare,
    comparison_finding,
    estimate,
    half_mask,
    jackknife,
    lateral,
    longitudinal,
    mean_times,
    part_yaws,
    parts_finding,
    sum_units,
    time_blocks,
    units,
    widened,
)
from mountcal.estimate.driving_intervals import (
    IntArray,
    Intervals,
    Layout,
    OffsetSearch,
    SegmentLines,
    turned_share,
    turned_tilt_removed,
)
from mountcal.estimate.speed_unit import scale_note, speed_factor
from mountcal.io.samples import Channel

if TYPE_CHECKING:
    from mountcal.estimate.driving_options import DrivingOptions

FAMILY_ALPHA = 0.01  # all tests together flag a drive the model explains with at most this probability
SCALE_Z = 3.0  # the speed-scale note beyond this many σ from 1
LAMBDA_FACTOR = 3.0  # the ratio of the IMU's to the speed's noise is known to within this factor
EFFECT_Z = 3.0  # an effect of the body or road is taken beyond this many σ
TURN_RATE_DEG_S = 45.0  # the lateral cue keeps turns up to this yaw rate
TURNING_MPS2 = 0.3  # |v·ω| beyond this: a left or a right turn
SPEEDING_MPS2 = 0.3  # |d(speed)/dt| beyond this: accelerating or braking
MIRRORED_DEG = 90.0  # cues further apart than this: a mirror image (the model's effects turn them a few degrees)
G = 9.80665
YAW_TESTS = (
    "driving_cues",
    "driving_halves_yaw",
    "driving_parts",
    "driving_left_right",
    "driving_accelerating_braking",
)
CAUSES = {
    "driving_cues": "a horizontal scale or cross-axis error of the accelerometer (its axes are not 90° apart), "
    "the body rolling under lateral load, a lever arm, or a speed channel not along the vehicle's x axis",
    "driving_halves_yaw": "a remount or a bracket that slipped during the drive, or a drift with temperature",
    "driving_parts": "a remount or a bracket that slipped during the drive, or a drift with temperature",
    "driving_halves_roll": "a remount, or the body's load (passengers, cargo) changing during the drive",
    "driving_halves_pitch": "a remount, the body's load changing during the drive, or the route's grade differing "
    "between the halves",
    "driving_halves_clock": "the speed's clock drifting against the IMU's (separate loggers)",
    "driving_left_right": "a lever arm or sideslip (the sensor ahead of or behind the point whose speed is measured)",
    "driving_accelerating_braking": "an effect that follows the acceleration's size: brake pull, a nonlinear axis",
}


@dataclass(frozen=True)
class Inputs:
    """What the checks need from the fit: the straight intervals and their centred values as the fit used them,
    its yaw and scales, the layout (to gate the intervals otherwise), the channels and the options."""

    iv: Intervals
    u: FloatArray  # centred levelled horizontal specific force, turning's share of the road tilt removed
    a: FloatArray  # centred speed change rate
    lat: FloatArray  # centred v·ω
    yaw_rad: float
    scale: float  # the fit's longitudinal scale (speed regressed on the IMU)
    lateral_scale: float  # the IMU's lateral specific force per v·ω the fit used (1 unless the data chose it)
    sigma_rad: float  # the fit's statistical σ of yaw (Newey–West or jackknife, the larger)
    layout: Layout
    speed: Channel
    rot_tilt: Rotation
    offset_s: float
    offset_search: OffsetSearch | None
    altitude: Channel | None
    opts: DrivingOptions
    straightness_known: bool  # a gyro or a heading channel gives the yaw rate (so v·ω)
    gyro: bool


@dataclass(frozen=True)
class Checks:
    """What the residual tests found, and what follows from it for the fit."""

    document: DrivingConsistency
    findings: tuple[Finding, ...]
    notes: tuple[str, ...]
    lateral_scale: float | None  # the data chose to fit it (refit yaw with it)
    grade: Estimate | None  # the route's mean grade from the altitude, when the data chose it (deg)


# --------------------------------------------------------------------------- units, sums and their σ


# --------------------------------------------------------------------------- the checks


def run(inp: Inputs) -> Checks:
    """Every test the drive allows, the findings (Holm), the model-error terms and the effects the data choose."""
    iv = inp.iv
    unit = units(iv)
    c = inp.lateral_scale * inp.lat
    s_long = Sums.of(unit, iv.t_mid_s, inp.a, inp.u[:, 0], inp.u[:, 1], c)
    # The blocks see the correlation of neighbouring units, the fit's Newey–West that of neighbouring intervals:
    # a part's σ is scaled up to the whole drive's, where that is larger.
    whole = estimate(s_long, s_long.every(), longitudinal)
    inflate = 1.0
    if whole is not None and whole.sigma:
        inflate = max(1.0, float(np.degrees(inp.sigma_rad)) / whole.sigma)
    whole = estimate(s_long, s_long.every(), longitudinal, inflate)

    first = half_mask(s_long)
    scale = _speed_scale(inp, unit)
    # the distance the altitude's grade divides by, in metres: a unit slip the scale names is taken out of it
    factor = speed_factor(scale.value, scale.sigma) if scale.noted else 1.0
    tilt = _tilt_halves(inp, unit, first, factor)
    halves = Halves(
        compare(
            "driving_halves_yaw",
            "yaw of the first half of the drive against the second",
            estimate(s_long, first, longitudinal, inflate),
            estimate(s_long, ~first, longitudinal, inflate),
        ),
        *tilt,
        _clock_halves(inp),
    )
    parts = part_yaws(s_long, inflate)
    acc = Sums.of(unit, iv.t_mid_s, np.where(iv.a_ref > SPEEDING_MPS2, inp.a, 0.0), inp.u[:, 0], inp.u[:, 1], c)
    brk = Sums.of(unit, iv.t_mid_s, np.where(iv.a_ref < -SPEEDING_MPS2, inp.a, 0.0), inp.u[:, 0], inp.u[:, 1], c)
    accelerating_braking = compare(
        "driving_accelerating_braking",
        "yaw from accelerating against yaw from braking",
        estimate(acc, acc.every(), longitudinal, inflate),
        estimate(brk, brk.every(), longitudinal, inflate),
    )
    wide = _wide(inp)
    cues, left_right = _cues(whole, wide)
    comparisons = [halves.yaw, halves.roll_about_vehicle_x, halves.pitch_about_vehicle_y, halves.clock_offset]
    comparisons += [accelerating_braking, cues.comparison, left_right]
    tests = (
        [comparison_finding(x) for x in comparisons[:4]]
        + [parts_finding(parts)]
        + [comparison_finding(x) for x in comparisons[4:]]
    )
    findings = tuple(unexplained(tests, FAMILY_ALPHA))
    model_error = _model_error(findings, comparisons, parts, cues, inp.opts.horizontal_axes_sigma_deg)
    notes = [_note(f, cues.comparison) for f in findings]
    if scale.noted and scale.value is not None and scale.sigma is not None:
        notes.append(scale_note(scale.value, scale.sigma, scale.z or 0.0, inp.gyro))
    grade = _grade(inp, unit, factor)
    effects = _effects(inp, wide, grade)
    document = DrivingConsistency(
        FAMILY_ALPHA,
        halves,
        parts,
        cues,
        left_right,
        accelerating_braking,
        scale,
        effects,
        tuple(tests),
        tuple(f.test for f in findings),
        model_error,
    )
    chosen = {e.name for e in effects if e.chosen}
    return Checks(
        document,
        findings,
        tuple(notes),
        wide.ratio.value if "lateral_scale" in chosen and wide is not None and wide.ratio is not None else None,
        grade if "grade" in chosen else None,
    )


def changed(checks: Checks, name: str, quantity: str, before: float, after: float) -> Checks:
    """``checks`` with the effect ``name`` recorded as taken, changing ``quantity`` from ``before`` to ``after``."""
    effects = tuple(
        replace(e, chosen=True, changes=quantity, before=float(before), after=float(after)) if e.name == name else e
        for e in checks.document.effects
    )
    return replace(checks, document=replace(checks.document, effects=effects))


def _note(f: Finding, cues: Comparison) -> str:
    cause = CAUSES.get(f.test, "an effect the model lacks")
    if f.test == "driving_cues" and abs(cues.difference or 0.0) > MIRRORED_DEG:
        cause = (
            f"a mirrored sensor (one axis reversed: a left-handed triad; state its axes with {option('axes')}) or a "
            "yaw rate or lateral acceleration with the wrong sign at its source: no scale or cross-axis error, body "
            "roll or lever arm turns the cues this far apart"
        )
    return f"{f.what}: they DISAGREE beyond their σ ({f.size}; p = {f.p_value:.2g}); likely {cause}"


def _model_error(
    findings: tuple[Finding, ...], comparisons: list[Comparison], parts: Parts, cues: Cues, prior_deg: float
) -> ModelError:
    """Half the largest disagreement each finding shows, per what it concerns; for yaw at least what the horizontal
    axes' scale and cross-axis errors may leave, given the cues (:func:`_axes`)."""
    size = {c.test: abs(c.difference or 0.0) / 2.0 for c in comparisons}
    size["driving_parts"] = (parts.spread_deg or 0.0) / 2.0
    named = {f.test for f in findings}
    yaw = max((size[t] for t in named & set(YAW_TESTS)), default=0.0)
    axes = _axes(cues.comparison, prior_deg)
    return ModelError(
        max(yaw, axes),
        size["driving_halves_roll"] if "driving_halves_roll" in named else 0.0,
        size["driving_halves_pitch"] if "driving_halves_pitch" in named else 0.0,
        axes,
        prior_deg,
    )


def _axes(cue: Comparison, prior_deg: float) -> float:
    """What the horizontal axes' scale and cross-axis errors may leave in yaw, given the cues (deg, 1σ).

    Such an error turns each cue by ε, in opposite directions: the cues' difference Δ measures 2ε with the noise
    σ_Δ. With the sensor class's ε ~ N(0, prior²), ε given Δ has mean ``m = (Δ/2)·p/(p + s)`` and variance
    ``v = p·s/(p + s)`` (p = prior², s = (σ_Δ/2)²); yaw rests on the longitudinal cue uncorrected, so its error
    from this source has the second moment ``m² + v``. An uninformative lateral cue (few turns) leaves the prior, an
    informative one what it shows.
    """
    p = prior_deg**2
    if cue.difference is None or not cue.z or p == 0:
        return prior_deg
    s = (cue.difference / cue.z / 2.0) ** 2
    m = cue.difference / 2.0 * p / (p + s)
    return float(np.sqrt(m * m + p * s / (p + s)))


def _clock_halves(inp: Inputs) -> Comparison:
    what = "the speed's clock offset, first half against second"
    search = inp.offset_search
    if search is None:
        why = "no test: the clock offset was given, not found"
        return Comparison("driving_halves_clock", what, "s", None, None, None, None, None, why)
    early = search.segment_t_s < float(np.median(inp.iv.t_mid_s))
    return compare("driving_halves_clock", what, _offset(search, early), _offset(search, ~early), "s")


def _offset(search: OffsetSearch, mask: np.ndarray) -> Estimate | None:
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        return None
    value = search.offset(idx)
    blocks = time_blocks(idx, search.segment_t_s)
    if len(blocks) < MIN_BLOCKS:
        return Estimate(value, None, len(blocks))
    loo = np.array([search.offset(np.setdiff1d(idx, b)) for b in blocks])
    k = len(blocks)
    return Estimate(value, float(np.sqrt((k - 1) / k * np.sum((loo - loo.mean()) ** 2))), k)


def _tilt_halves(inp: Inputs, unit: IntArray, first: np.ndarray, factor: float = 1.0) -> tuple[Comparison, Comparison]:
    """The tilt from the mean gravity of each half, as small rotations about the vehicle x and y axes (deg).

    The route's grade over half a drive is measured when the altitude is logged (and taken out), else assumed as
    the drive's (the scatter within a half cannot show a hill as long as the half); its cross slope varies little.
    """
    iv = inp.iv
    n = int(unit.max()) + 1
    scale = inp.scale if np.isfinite(inp.scale) else 1.0
    rot = Rotation.from_euler("z", inp.yaw_rad) * inp.rot_tilt  # sensor → vehicle
    f_v = rot.apply(iv.acc_s) - scale * iv.a_ref[:, None] * np.array([1.0, 0.0, 0.0])
    about = {"x": np.degrees(np.arctan2(-f_v[:, 1], f_v[:, 2])), "y": np.degrees(np.arctan2(f_v[:, 0], f_v[:, 2]))}
    w = sum_units(unit, iv.width_s, n)
    t = mean_times(unit, iv.t_mid_s, n)
    grades = _grades(inp, unit, factor)
    out = []
    for axis, name in (("x", "roll"), ("y", "pitch")):
        per = sum_units(unit, iv.width_s * about[axis], n) / np.maximum(w, 1e-300)
        prior = inp.opts.road_grade_sigma_deg if axis == "y" else 0.0
        if axis == "y" and grades is not None:
            per, prior = per - grades, 0.0
        one, two = (widened(jackknife(per, w, t, m), prior) for m in (first, ~first))
        what = f"the tilt about the vehicle {axis} axis ({name}) from the mean gravity, first half against second"
        out.append(compare(f"driving_halves_{name}", what, one, two))
    return out[0], out[1]


@dataclass(frozen=True)
class WideCue:
    """The lateral cue on every interval at speed, turns included."""

    iv: Intervals
    lat: FloatArray  # centred v·ω
    sums: Sums  # of the lateral equation
    left: Sums  # … over left turns only
    right: Sums  # … over right turns only
    ratio: Estimate | None  # the IMU's lateral specific force per v·ω
    rms: float  # of the centred v·ω, m/s²


def _wide(inp: Inputs) -> WideCue | None:
    """The lateral cue's sums (all, left turns, right turns) and the IMU's lateral specific force per v·ω; None
    without a yaw rate or with too few intervals."""
    if not inp.straightness_known:
        return None
    opts = replace(inp.opts, max_yaw_rate_deg_s=TURN_RATE_DEG_S, max_segment_turn_deg=1e9)
    wide = replace(inp.layout, opts=opts, lateral_yaw_rad=None).at(inp.offset_s)  # the same integrals, wider gates
    if wide.a_ref.size < 2 * MIN_BLOCKS:
        return None
    u, a, lat = wide.centred()
    if np.any(wide.turned_rad):
        u = turned_tilt_removed(wide, inp.yaw_rad)
    s = inp.scale if np.isfinite(inp.scale) and inp.scale > 0 else 1.0
    unit, t = units(wide), wide.t_mid_s
    sums = Sums.of(unit, t, lat, u[:, 0], u[:, 1], s * a)
    left = Sums.of(unit, t, np.where(wide.a_lat > TURNING_MPS2, lat, 0.0), u[:, 0], u[:, 1], s * a)
    right = Sums.of(unit, t, np.where(wide.a_lat < -TURNING_MPS2, lat, 0.0), u[:, 0], u[:, 1], s * a)
    across = np.sin(inp.yaw_rad) * u[:, 0] + np.cos(inp.yaw_rad) * u[:, 1]
    n = sums.count.size
    ll, ly = sum_units(unit, lat * lat, n), sum_units(unit, lat * across, n)
    ratio = jackknife(ly / np.maximum(ll, 1e-300), ll, sums.t_s, ll > 0)
    return WideCue(wide, lat, sums, left, right, ratio, float(np.sqrt(np.mean(lat**2))))


def _cues(longitudinal_cue: Estimate | None, wide: WideCue | None) -> tuple[Cues, Comparison]:
    what = "the vehicle's x axis from speed changes (longitudinal cue) and from v·ω in turns (lateral cue, less 90°)"
    what_lr = "yaw from left turns against yaw from right turns (lateral cue)"
    rests = "longitudinal: the speed changes on straight road"
    if wide is None:
        why = "no test: no yaw rate (gyro or heading channel) for v·ω, or too few intervals at speed"
        cue = Comparison("driving_cues", what, "deg", longitudinal_cue, None, None, None, None, why)
        return Cues(cue, None, None, rests), Comparison(
            "driving_left_right", what_lr, "deg", None, None, None, None, None, why
        )
    lateral_cue = estimate(wide.sums, wide.sums.every(), lateral)
    cue = compare("driving_cues", what, longitudinal_cue, lateral_cue)
    angle = None if cue.difference is None else 90.0 + cue.difference
    left_right = compare(
        "driving_left_right",
        what_lr,
        estimate(wide.left, wide.left.every(), lateral),
        estimate(wide.right, wide.right.every(), lateral),
    )
    return Cues(cue, angle, wide.rms, rests), left_right


def _speed_scale(inp: Inputs, unit: IntArray) -> SpeedScale:
    """The IMU's longitudinal specific force over d(speed)/dt with errors in both (Deming's regression).

    The noise of each interval's speed change is ``2 σ_v² / T²`` with σ_v the speed channel's white noise, from its
    second differences at lags 1 and 2 (a smooth signal grows 16-fold between them, white noise not at all); the
    IMU's is the variance of its lateral residual on the same straight intervals. Neither is known well, so σ
    holds what their ratio changes over a factor ``LAMBDA_FACTOR`` either way beside the jackknife's part.
    """
    iv = inp.iv
    along = np.cos(inp.yaw_rad) * inp.u[:, 0] - np.sin(inp.yaw_rad) * inp.u[:, 1]
    across = np.sin(inp.yaw_rad) * inp.u[:, 0] + np.cos(inp.yaw_rad) * inp.u[:, 1] - inp.lateral_scale * inp.lat
    v = inp.speed.value
    var_v = 0.0
    if v.size > 8:
        d1, d2 = v[2:] - 2.0 * v[1:-1] + v[:-2], v[4:] - 2.0 * v[2:-2] + v[:-4]
        var_v = max((16.0 * float(np.var(d1)) - float(np.var(d2))) / 90.0, 0.0)
    var_d = 2.0 * var_v * float(np.mean(1.0 / iv.width_s**2))
    var_e = float(np.var(across))
    ratio = var_e / var_d if var_d > 0 else np.inf

    def deming(sxx: float, syy: float, sxy: float, lam: float = ratio) -> float:
        if sxy <= 0 or sxx <= 0:
            return float("nan")
        if not np.isfinite(lam):
            return sxy / sxx  # no noise in the speed: the IMU regressed on it
        d = syy - lam * sxx
        return (d + float(np.sqrt(d * d + 4.0 * lam * sxy * sxy))) / (2.0 * sxy)

    n = int(unit.max()) + 1
    sxx, syy, sxy = (sum_units(unit, p, n) for p in (inp.a * inp.a, along * along, inp.a * along))
    total = (float(sxx.sum()), float(syy.sum()), float(sxy.sum()))
    value = deming(*total)
    blocks = time_blocks(np.arange(n), mean_times(unit, iv.t_mid_s, n))
    sigma = None
    if len(blocks) >= MIN_BLOCKS and np.isfinite(value):
        loo = np.array([deming(*(float(x.sum() - x[b].sum()) for x in (sxx, syy, sxy))) for b in blocks])
        if np.all(np.isfinite(loo)):
            k = len(blocks)
            # The noises' ratio is itself estimated (a speed's noise from its differences, the IMU's from its lateral
            # residual, which need not be its longitudinal one): what a factor LAMBDA_FACTOR either way changes counts.
            spread = [deming(*total, lam=ratio * f) for f in (LAMBDA_FACTOR, 1.0 / LAMBDA_FACTOR)]
            systematic = 0.5 * abs(spread[0] - spread[1]) if all(np.isfinite(spread)) else 0.0
            sigma = float(np.hypot(np.sqrt((k - 1) / k * np.sum((loo - loo.mean()) ** 2)), systematic))
    z = (value - 1.0) / sigma if sigma and np.isfinite(value) else None
    low = total[2] / total[0] if total[0] > 0 else None  # attenuated by the speed's noise
    high = total[1] / total[2] if total[2] > 0 else None  # inflated by the IMU's
    # Whatever the noises, the scale lies between the two regressions: a note needs both on one side of 1.
    outside = low is not None and high is not None and (min(low, high) > 1.0 or max(low, high) < 1.0)
    return SpeedScale(
        value if np.isfinite(value) else None,
        sigma,
        z,
        low,
        high,
        float(np.sqrt(var_v)),
        float(np.sqrt(var_e)),
        z is not None and abs(z) > SCALE_Z and outside,
    )


def _grades(inp: Inputs, unit: IntArray, factor: float = 1.0) -> FloatArray | None:
    """The grade (deg, uphill positive) of each unit of the straight intervals, from the altitude and the distance
    driven: the altitude's change over the unit (its intervals follow each other) over the distance, so that the
    altitude's noise enters once per unit, not once per interval. None without an altitude channel. ``factor``: m/s
    per unit of the speed as read (:func:`~mountcal.estimate.speed_unit.speed_factor`; km/h read as m/s: 1/3.6)."""
    alt = inp.altitude
    if alt is None or alt.t_s.size < 3:
        return None
    iv = inp.iv
    n = int(unit.max()) + 1
    start, end = np.full(n, np.inf), np.full(n, -np.inf)
    np.minimum.at(start, unit, iv.t_mid_s - 0.5 * iv.width_s)
    np.maximum.at(end, unit, iv.t_mid_s + 0.5 * iv.width_s)
    dh = np.interp(end, alt.t_s, alt.value) - np.interp(start, alt.t_s, alt.value)
    v = np.interp(iv.t_mid_s, inp.speed.t_s + inp.offset_s, inp.speed.value)
    distance = np.maximum(sum_units(unit, factor * v * iv.width_s, n), 1e-3)
    return np.asarray(np.degrees(np.arcsin(np.clip(dh / distance, -1.0, 1.0))), dtype=float)


def _grade(inp: Inputs, unit: IntArray, factor: float = 1.0) -> Estimate | None:
    """The route's mean grade (deg, uphill positive) over the straight intervals, from the altitude channel."""
    per = _grades(inp, unit, factor)
    if per is None:
        return None
    w = sum_units(unit, inp.iv.width_s, per.size)
    return jackknife(per, w, mean_times(unit, inp.iv.t_mid_s, per.size), w > 0)


# --------------------------------------------------------------------------- effects of the body and the road


def _effects(inp: Inputs, wide: WideCue | None, grade: Estimate | None) -> tuple[DrivingEffect, ...]:
    """Each effect of the body and the road: its value ± σ, whether the data chose it, and why (not)."""
    ratio = None if wide is None else wide.ratio
    meaning = (
        "the IMU's lateral specific force per v·ω: the body rolling under lateral load (without a gyro), a lateral "
        "scale error"
    )
    if ratio is None or not ratio.sigma:
        lateral_scale = DrivingEffect(
            "lateral_scale", meaning, "", None, None, False, "no test: too few turns, or no yaw rate, to measure it"
        )
    else:
        z = (ratio.value - 1.0) / ratio.sigma
        chosen = abs(z) > EFFECT_Z
        why = f"{ratio.value:.3f} ± {ratio.sigma:.3f} × v·ω, {abs(z):.1f}σ from 1: " + (
            "fitted, so that v·ω does not leak into yaw" if chosen else f"within {EFFECT_Z:g}σ, not fitted"
        )
        lateral_scale = DrivingEffect("lateral_scale", meaning, "", ratio.value, ratio.sigma, chosen, why)
    prior = inp.opts.road_grade_sigma_deg
    grade_meaning = "the route's mean grade (uphill positive) from the altitude channel and the distance driven"
    if grade is None or grade.sigma is None:
        why = "no altitude channel (alt_m), or too little driving to judge it"
        grade_effect = DrivingEffect("grade", grade_meaning, "deg", None, None, False, why)
    else:
        chosen = grade.sigma < prior
        why = f"{grade.value:+.3f}° ± {grade.sigma:.3f}°, " + (
            f"better known than the {prior:g}° assumed: the tilt about the vehicle's y axis is corrected by it"
            if chosen
            else f"no better known than the {prior:g}° assumed: not used"
        )
        grade_effect = DrivingEffect(
            "grade", grade_meaning, "deg", grade.value, grade.sigma, chosen, why, Angles.value_column("pitch")
        )
    crown = DrivingEffect(
        "crown",
        "the route's mean cross slope (a crowned road), a roll of the body",
        "deg",
        None,
        None,
        False,
        "no horizontal cue of driving tells a constant roll of the body from a roll of the mounting: its σ stays the "
        f"assumed {inp.opts.road_cross_slope_sigma_deg:g}° (parked stops on a slope at opposite headings separate it)",
    )
    return (lateral_scale, *_body(inp, wide), grade_effect, crown)


def _body(inp: Inputs, wide: WideCue | None) -> tuple[DrivingEffect, DrivingEffect]:
    """The body's pitch per longitudinal and roll per lateral acceleration from the gyro's attitude (deg per g):
    pitch on the straight intervals, roll on those with turns."""
    cases = (
        ("body_pitch", "the body's pitch (nose up) per g of longitudinal acceleration", inp.iv, inp.a, 0),
        (
            "body_roll",
            "the body's roll (right side down, outward) per g of lateral acceleration to the left",
            None if wide is None else wide.iv,
            None if wide is None else wide.lat,
            1,
        ),
    )
    out = []
    for name, meaning, iv, load, column in cases:
        if not inp.gyro:
            why = "no gyro: the body's attitude under load cannot be told from the accelerometer's scale"
            out.append(DrivingEffect(name, meaning, "deg/g", None, None, False, why))
            continue
        if iv is None or load is None:
            out.append(DrivingEffect(name, meaning, "deg/g", None, None, False, "no test: no turns at speed"))
            continue
        rot = np.array([[np.cos(inp.yaw_rad), -np.sin(inp.yaw_rad)], [np.sin(inp.yaw_rad), np.cos(inp.yaw_rad)]])
        # g·(δ_y, −δ_x) in vehicle axes: the attitude change the gyro measured, turning's share of the road tilt out
        leak = (iv.u - turned_share(iv, inp.yaw_rad) - iv.u_raw) @ rot.T / G
        attitude = SegmentLines(iv.segment, iv.t_mid_s).residual(-leak[:, column])  # nose up −δ_y, right down +δ_x
        unit = units(iv)
        n = int(unit.max()) + 1
        xx, xy = sum_units(unit, load * load, n), sum_units(unit, load * attitude, n)
        k = jackknife(np.degrees(xy / np.maximum(xx, 1e-300)) * G, xx, mean_times(unit, iv.t_mid_s, n), xx > 0)
        if k is None or not k.sigma:
            out.append(DrivingEffect(name, meaning, "deg/g", None, None, False, "no test: too little load to judge it"))
            continue
        z = k.value / k.sigma
        chosen = bool(abs(z) > EFFECT_Z)
        why = f"{k.value:+.2f} ± {k.sigma:.2f}°/g, {abs(z):.1f}σ from none: " + (
            "measured by the gyro, whose attitude the fit removes from the horizontal specific force"
            if chosen
            else "not significant"
        )
        out.append(DrivingEffect(name, meaning, "deg/g", k.value, k.sigma, chosen, why))
    return out[0], out[1]
