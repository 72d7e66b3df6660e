"""Frames, angles, signs and gravity: docs/conventions.md §1–2, written once.

This is the only module that converts between rotations and Euler angles.

- Sensor frame ``s``: the accelerometer axes as the log reports them (right-handed, SI units).
- Vehicle frame ``v`` (ISO 8855): x forward, y left, z up.
- ``rot_vs`` maps sensor to vehicle coordinates: ``acc_v = rot_vs.apply(acc_s)``.
- ``rot_vs = Rz(yaw) · Ry(pitch) · Rx(roll)``, intrinsic z-y'-x'' (the paper's φ, θ, γ).
- An accelerometer at rest reads +g along "up".
- Heading β: from the slope's uphill direction to the vehicle's x axis, counter-clockwise seen
  from above.
"""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:  # scipy.spatial costs a command ~0.2 s to import: only what rotates imports it
    from scipy.spatial.transform import Rotation

FloatArray = NDArray[np.float64]

G_N = 9.80665  # standard gravity, m/s²
EULER_SEQUENCE = "ZYX"  # scipy's intrinsic sequence for Rz(yaw)·Ry(pitch)·Rx(roll)
GIMBAL_LOCK_PITCH_DEG = 89.0  # beyond this |pitch| roll and yaw are not separately meaningful

CONVENTIONS = {
    "sensor_frame": "accelerometer axes as logged, right-handed, SI units",
    "vehicle_frame": "ISO 8855: x forward, y left, z up",
    "rotation": "rot_vs maps sensor to vehicle coordinates: acc_v = rot_vs @ acc_s",
    "euler": "rot_vs = Rz(yaw) Ry(pitch) Rx(roll), intrinsic z-y'-x'' (scipy from_euler('ZYX', [yaw, pitch, roll]))",
    "specific_force": "an accelerometer at rest reads +g along up",
    "heading": "beta: from the uphill direction to the vehicle x axis, counter-clockwise seen from above",
    "units": "angles in degrees, accelerations in m/s^2, temperatures in degrees C, times in s",
}


def rot_vs_from_angles(roll_rad: float, pitch_rad: float, yaw_rad: float) -> Rotation:
    """The mounting rotation from roll γ, pitch θ, yaw φ in radians (docs/conventions.md §1)."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_euler(EULER_SEQUENCE, [yaw_rad, pitch_rad, roll_rad])


def angles_from_rot_vs(rot_vs: Rotation) -> tuple[float, float, float]:
    """Roll γ, pitch θ, yaw φ in radians of a mounting rotation.

    At pitch ±90° the triple is not unique; scipy then sets a convention and so do we: the
    rotation itself stays exact, only its split into roll and yaw is arbitrary.
    """
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Gimbal lock detected")
        yaw, pitch, roll = rot_vs.as_euler(EULER_SEQUENCE)
    return float(roll), float(pitch), float(yaw)


def euler_angles(rot: Rotation, sequence: str) -> tuple[float, float, float]:
    """Another convention's Euler angles of a rotation, in radians, in the order of ``sequence``.

    ``sequence`` is scipy's (upper case: intrinsic). For the exporters, whose vendors each use
    their own sequence; at gimbal lock scipy sets the last angle to 0 and the rotation stays exact.
    """
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Gimbal lock detected")
        a, b, c = rot.as_euler(sequence)
    return float(a), float(b), float(c)


def levelled(rot_vs: Rotation) -> Rotation:
    """The mounting rotation with yaw 0: the vehicle's up axis kept, its x axis the sensor's x on the horizontal.

    What a calibration holds when yaw is not determined: it levels (z up) but leaves the heading
    the sensor's own instead of inventing one. Built from the up axis, so it is exact even at pitch ±90°.
    """
    roll, pitch = tilt_from_normal(np.asarray(rot_vs.inv().apply([0.0, 0.0, 1.0]), dtype=float))
    return rot_vs_from_angles(roll, pitch, 0.0)


def specific_force_v(slope_rad: float, beta_rad: ArrayLike, g: float = G_N) -> FloatArray:
    """Static specific force in the vehicle frame, parked at heading β on slope α (docs/conventions.md §2).

    Returns
    -------
    ndarray, shape (n, 3)
        ``g · (sin α cos β, −sin α sin β, cos α)`` in m/s².
    """
    beta = np.atleast_1d(np.asarray(beta_rad, dtype=float))
    sa, ca = np.sin(slope_rad), np.cos(slope_rad)
    return g * np.column_stack([sa * np.cos(beta), -sa * np.sin(beta), np.full_like(beta, ca)])


def tilt_from_normal(normal_s: FloatArray) -> tuple[float, float]:
    """Roll γ and pitch θ in radians from the vehicle's z axis in sensor coordinates (docs/conventions.md §3.3)."""
    n = normal_s / np.linalg.norm(normal_s)
    return float(np.arctan2(n[1], n[2])), float(-np.arcsin(np.clip(n[0], -1.0, 1.0)))


def normal_gravity(lat_deg: float, alt_m: float = 0.0) -> float:
    """WGS 84 normal gravity in m/s² at geodetic latitude and height above the ellipsoid.

    Somigliana's closed formula with the second-order free-air correction (NIMA TR8350.2, eqs. 4-1
    and 4-3). Good to about 1e-6 relative near the surface.
    """
    a, f = 6378137.0, 1.0 / 298.257223563
    gamma_e, k, e2, m = 9.7803253359, 0.00193185265241, 0.00669437999013, 0.00344978650684
    s2 = np.sin(np.radians(lat_deg)) ** 2
    gamma = gamma_e * (1.0 + k * s2) / np.sqrt(1.0 - e2 * s2)
    h = alt_m
    return float(gamma * (1.0 - 2.0 / a * (1.0 + f + m - 2.0 * f * s2) * h + 3.0 * h**2 / a**2))


def skew(v: FloatArray) -> FloatArray:
    """Cross-product matrices ``[v]×`` of vectors v, shape (..., 3) → (..., 3, 3)."""
    z = np.zeros(v.shape[:-1])
    x, y, w = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([np.stack([z, -w, y], -1), np.stack([w, z, -x], -1), np.stack([-y, x, z], -1)], -2)
