"""The residual tests of yaw from driving as the result file keeps them (``fit.driving.consistency``).

Typed records, so that the published JSON Schema describes them (:func:`mountcal.core.result.schema_defs`) and a
reader can rely on their keys; :mod:`mountcal.estimate.driving_checks` fills them. Angles in degrees, clock
offsets in seconds, σ 1σ; a value is None where the drive does not allow it, with the reason.
"""

from __future__ import annotations

from dataclasses import dataclass

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
