"""The driving estimator's gates and settings (:class:`DrivingOptions`), read by each of its parts."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def horizontal_axes_sigma_deg(scale: float, cross_axis: float) -> float:
    """The 1σ turn of the longitudinal cue by the horizontal axes' scale and cross-axis errors within ± limits.

    A symmetric distortion of the horizontal axes turns a direction ψ by ``(s_y − s_x)/2·sin 2ψ + c·cos 2ψ``
    (and the perpendicular one by the opposite); with the limits read as rectangular distributions and ψ
    anywhere, its variance is ``(scale²/6 + cross_axis²/3)/2``.
    """
    return float(np.degrees(np.sqrt((scale**2 / 6.0 + cross_axis**2 / 3.0) / 2.0)))


HORIZONTAL_AXES_SIGMA_DEG = horizontal_axes_sigma_deg(0.03, 0.02)  # the default sensor class (mountcal.io.sensor_spec)


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
    # How far the accelerometer's horizontal scale and cross-axis errors may turn the longitudinal cue (1σ, before the
    # cues narrow it): the default sensor class's ±3 % and ±2 % (mountcal.io.sensor_spec), see
    # horizontal_axes_sigma_deg.
    horizontal_axes_sigma_deg: float = HORIZONTAL_AXES_SIGMA_DEG


__all__ = ["HORIZONTAL_AXES_SIGMA_DEG", "DrivingOptions", "horizontal_axes_sigma_deg"]
