"""Closed-form geometry of the stop circle (docs/conventions.md §2–3): plane normal, tilt, in-plane phase.

Used by the paper's method and to start the maximum-likelihood fit.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from mountcal.core.conventions import FloatArray, rot_vs_from_angles, tilt_from_normal


def plane_normal(acc_s: FloatArray) -> FloatArray:
    """Unit normal of the algebraic least-squares plane ``A x + B y + C z = 1`` (paper, step 1).

    The normal points from the origin towards the plane, i.e. along the vehicle's up axis.
    """
    coef, *_ = np.linalg.lstsq(acc_s, np.ones(acc_s.shape[0]), rcond=None)
    return coef / np.linalg.norm(coef)


def level_rotation(normal_s: FloatArray) -> Rotation:
    """The rotation with yaw 0 whose vehicle z axis is ``normal_s`` in sensor coordinates."""
    roll, pitch = tilt_from_normal(normal_s)
    return rot_vs_from_angles(roll, pitch, 0.0)


def in_plane_azimuth(acc_s: FloatArray, rot_level: Rotation) -> FloatArray:
    """Azimuth ψ_i in radians of each stop's horizontal part after removing roll and pitch."""
    h = np.asarray(rot_level.apply(acc_s), dtype=np.float64)  # scipy ships no types
    return np.arctan2(h[:, 1], h[:, 0])


def phase_yaw(acc_s: FloatArray, beta_rad: FloatArray, rot_level: Rotation) -> float:
    """Yaw φ from the in-plane phase against the known β (paper, step 3): ψ_i = −(β_i + φ).

    A radius-weighted circular mean of ``−ψ_i − β_i``.
    """
    h = rot_level.apply(acc_s)
    z = (h[:, 0] - 1j * h[:, 1]) * np.exp(-1j * beta_rad)
    return float(np.angle(z.sum()))


def with_yaw(rot_level: Rotation, yaw_rad: float) -> Rotation:
    """``Rz(φ) · rot_level``: add a yaw to a level rotation."""
    return Rotation.from_euler("z", yaw_rad) * rot_level


def span_ratio(acc_s: FloatArray) -> float:
    """Second over first singular value of the centred stop means: ~0 when they lie on a line."""
    s = np.linalg.svd(acc_s - acc_s.mean(axis=0), compute_uv=False)
    return float(s[1] / s[0]) if s[0] > 0 else 0.0
