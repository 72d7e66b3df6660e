"""The fit of yaw from driving as the result file keeps it (``fit.driving``, its residual tests ``.consistency``)
and how it was combined with the stops (``fit.combination``).

Typed records, so that the published JSON Schema describes them (:func:`mountcal.core.result.schema_defs`) and a
reader can rely on their keys; :mod:`mountcal.estimate.driving_checks` fills them. Angles in degrees, clock
offsets in seconds, σ 1σ; a value is None where the drive does not allow it, with the reason.
"""

from __future__ import annotations

from dataclasses import dataclass

from mountcal.core.angles import Angles
from mountcal.core.findings import Finding


@dataclass(frozen=True)
class Estimate:
    """One estimate from a part of the drive or one cue: value, σ (a jackknife over blocks of consecutive straight
    segments; None with fewer blocks than a test needs) and the number of blocks."""

    value: float
    sigma: float | None
    blocks: int


@dataclass(frozen=True)
class Comparison:
    """Two estimates of one quantity from different parts or cues of a drive, and the z-test of their difference
    (``one − two``); ``reason`` says why there is no test."""

    test: str
    what: str
    unit: str  # "deg" or "s"
    one: Estimate | None
    two: Estimate | None
    difference: float | None
    z: float | None
    p_value: float | None
    reason: str | None = None


@dataclass(frozen=True)
class Halves:
    """The first half of the drive (half its straight intervals) against the second."""

    yaw: Comparison
    roll_about_vehicle_x: Comparison
    pitch_about_vehicle_y: Comparison
    clock_offset: Comparison


@dataclass(frozen=True)
class Parts:
    """Yaw of consecutive parts of the drive against their weighted mean: χ²(parts with a σ − 1)."""

    yaw: tuple[Estimate | None, ...]
    chi2: float | None
    dof: int | None
    p_value: float | None
    spread_deg: float | None
    reason: str | None = None


@dataclass(frozen=True)
class Cues:
    """The vehicle's x axis from the speed changes (longitudinal) and from v·ω in turns (lateral, less 90°): in a
    right-handed sensor with orthogonal axes, 90° apart in the vehicle's horizontal plane."""

    comparison: Comparison
    axes_angle_deg: float | None  # the angle between the two directions (90 when they agree)
    rms_lateral_mps2: float | None  # how much turning there was to measure the lateral cue with
    rests_on: str  # which cue the reported yaw rests on


@dataclass(frozen=True)
class SpeedScale:
    """The IMU's longitudinal specific force over d(speed)/dt, errors in both counted (Deming's regression);
    ``imu_on_speed`` and ``speed_on_imu`` are the two ordinary regressions, between which it lies."""

    value: float | None
    sigma: float | None
    z: float | None  # (value − 1)/σ
    imu_on_speed: float | None
    speed_on_imu: float | None
    speed_noise_mps: float
    imu_noise_mps2: float
    noted: bool  # beyond its σ: the result's notes say so


@dataclass(frozen=True)
class DrivingEffect:
    """An effect of the body or the road the driving model may take: its value ± σ, whether the data chose it and
    why, and what it changes (``changes``: the quantity, ``before`` and ``after`` its value without and with it)."""

    name: str
    meaning: str
    unit: str
    value: float | None
    sigma: float | None
    chosen: bool
    why: str
    changes: str | None = None
    before: float | None = None
    after: float | None = None


@dataclass(frozen=True)
class ModelError:
    """The model-error terms added in quadrature to the σ (deg): half the largest disagreement a finding shows, and
    for yaw at least what the horizontal axes' scale and cross-axis errors may leave, given the cues."""

    yaw_about_vehicle_z_deg: float
    about_vehicle_x_deg: float
    about_vehicle_y_deg: float
    horizontal_axes_deg: float  # the horizontal axes' share of yaw, narrowed by the cues (1σ)
    horizontal_axes_prior_deg: float  # … before the cues narrowed it: the sensor class's limits


@dataclass(frozen=True)
class DrivingConsistency:
    """The residual tests of yaw from driving: halves, parts, cues, left and right turns, accelerating and braking,
    the speed's scale and clock, the effects of the body and the road, and what the family's test found."""

    family_alpha: float  # Holm's procedure over ``tests`` flags a drive the model explains with at most this
    halves: Halves
    parts: Parts
    cues: Cues
    left_right: Comparison
    accelerating_braking: Comparison
    speed_scale: SpeedScale
    effects: tuple[DrivingEffect, ...]
    tests: tuple[Finding, ...]
    findings: tuple[str, ...]  # the tests the family's test rejects: the driving model lacks an effect
    model_error: ModelError

    def effect(self, name: str) -> DrivingEffect | None:
        return next((e for e in self.effects if e.name == name), None)


@dataclass(frozen=True)
class TiltCheck:
    """The drive's up axis (its mean gravity) against a given calibration's, as small rotations about the vehicle x and
    y axes (deg), each as a z-score against both σ; a z is None where it is not finite (a σ of 0)."""

    angle_deg: float
    about_vehicle_x_deg: float
    about_vehicle_y_deg: float
    z_about_vehicle_x: float | None
    z_about_vehicle_y: float | None
    agree: bool

    @property
    def z_max(self) -> float:
        """The larger |z| of the two axes (infinite where a z is not finite)."""
        zs = (self.z_about_vehicle_x, self.z_about_vehicle_y)
        return max(float("inf") if z is None else abs(z) for z in zs)


@dataclass(frozen=True)
class DrivingSigma:
    """The 1σ of the drive's angles (deg): the Euler angles', the parts of yaw's, and about the vehicle x, y, z axes.
    ``yaw_model_error_deg`` is None in files written before the drive's residual tests."""

    roll_deg: float
    pitch_deg: float
    yaw_deg: float | None
    yaw_newey_west_deg: float | None
    yaw_jackknife_deg: float | None
    rotation_about_vehicle_xyz_deg: tuple[float, float, float | None]
    level: str = "1 sigma"
    yaw_model_error_deg: float | None = None


@dataclass(frozen=True)
class DrivingGates:
    """The driving estimator's gates and settings of the fit (:class:`mountcal.estimate.driving_options.DrivingOptions`,
    field for field); None where a file written by an earlier version does not record one."""

    min_speed_mps: float | None = None
    max_yaw_rate_deg_s: float | None = None
    max_tilt_rate_deg_s: float | None = None
    max_acc_mps2: float | None = None
    max_lateral_mps2: float | None = None
    interval_s: float | None = None
    segment_s: float | None = None
    max_segment_turn_deg: float | None = None
    min_segment_intervals: int | None = None
    max_time_offset_s: float | None = None
    time_offset_step_s: float | None = None
    time_offset_s: float | None = None
    road_grade_sigma_deg: float | None = None
    road_cross_slope_sigma_deg: float | None = None
    max_yaw_sigma_deg: float | None = None
    horizontal_axes_sigma_deg: float | None = None


@dataclass(frozen=True)
class DrivingDocument:
    """The fit of the mounting from a drive as the result file keeps it (``fit.driving``): angles ± σ, the tilt it
    rests on, the speed clock's offset, how much of the drive passed the gates, and its residual tests.

    ``speed_scale`` is None where it is not finite (the speed never changed); ``consistency`` is None in files written
    before the residual tests existed."""

    roll_deg: float
    pitch_deg: float
    yaw_deg: float | None
    sigma: DrivingSigma
    yaw_reason: str | None
    tilt_source: str
    up_driving_s: tuple[float, float, float]
    tilt_check: TiltCheck | None
    quaternion_xyzw: tuple[float, float, float, float]
    time_offset_s: float
    time_offset_sigma_s: float | None
    time_offset_meaning: str
    time_offset_searched: bool
    intervals: int
    segments: int
    usable_s: float
    moving_s: float
    speed_scale: float | None
    correlation: float
    longitudinal_residual_rms_mps2: float
    lateral_rms_mps2: float
    straightness_from: str
    gates: DrivingGates
    notes: tuple[str, ...] = ()
    consistency: DrivingConsistency | None = None

    @property
    def angles(self) -> Angles:
        """Roll, pitch and yaw with their σ as the file keeps them (no slope: a drive has none)."""
        s = self.sigma
        return Angles(
            self.roll_deg, s.roll_deg, self.pitch_deg, s.pitch_deg, self.yaw_deg, s.yaw_deg, self.yaw_reason, None, None
        )


@dataclass(frozen=True)
class Combination:
    """How the stops and the drive were combined (``fit.combination``): ``used`` says which yaw the result holds —
    ``"inverse-variance combination"``, ``"driving (the stops do not determine yaw)"``, ``"static"`` (the drive did not
    determine yaw) or ``"none: disagreement"`` (beyond 3σ: not combined, ``disagreement`` the finding); the other
    fields are None where that way of combining has none."""

    used: str
    static_yaw_deg: float | None = None
    driving_yaw_deg: float | None = None
    static_yaw_reason: str | None = None
    difference_deg: float | None = None  # driving − stops, wrapped to ±180°
    z: float | None = None
    agree: bool | None = None
    words: str | None = None
    yaw_deg: float | None = None  # the combined Euler yaw
    yaw_sigma_about_vehicle_z_deg: float | None = None
    tilt_check: TiltCheck | None = None
    disagreement: Finding | None = None
