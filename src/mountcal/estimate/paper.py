"""The paper's method (Zhang, Chai, Luo, Liu 2011), faithfully, in docs/conventions.md's conventions (§3).

1. Algebraic least-squares plane ``A x + B y + C z = 1`` through the stop means → normal n_s.
2. Slope from pairs of opposite headings: ``cos α = |a(β) + a(β+180°)| / (2g)``, averaged.
3. Roll and pitch from n_s; yaw from the in-plane phase against the known β.

The paper gives no uncertainties; :func:`paper_method` propagates the stop noise through these
steps to first order (the delta method), so its answers carry a σ like every other.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from mountcal.core.conventions import FloatArray, angles_from_rot_vs, specific_force_v
from mountcal.core.errors import NotEnoughInformation
from mountcal.core.option_names import option
from mountcal.estimate.geometry import level_rotation, phase_yaw, plane_normal, with_yaw
from mountcal.stops.table import StopTable

OPPOSITE_TOL_DEG = 1.0  # two headings are "opposite" within this


@dataclass(frozen=True)
class PaperEstimate:
    """Angles in radians; ``slope_rad`` is None when step 2 fails (cos α > 1)."""

    rot_vs: Rotation
    slope_rad: float | None
    cos_slope: float
    n_pairs: int


def opposite_pairs(beta_rad: FloatArray) -> list[tuple[int, int]]:
    """Index pairs (i, j), i < j, whose headings differ by 180° (each stop used once)."""
    deg = np.degrees(beta_rad) % 360.0
    used: set[int] = set()
    pairs = []
    for i in range(deg.size):
        if i in used:
            continue
        diff = np.abs((deg - deg[i] - 180.0 + 180.0) % 360.0 - 180.0)
        for j in np.flatnonzero(diff < OPPOSITE_TOL_DEG):
            if j > i and j not in used:
                pairs.append((i, int(j)))
                used.update((i, int(j)))
                break
    return pairs


def paper_angles(acc_s: FloatArray, beta_rad: FloatArray, pairs: list[tuple[int, int]], g_mps2: float) -> PaperEstimate:
    """Steps 1–3 on stop means ``acc_s`` (n, 3) in m/s² with headings ``beta_rad`` (n,)."""
    normal = plane_normal(acc_s)
    rot_level = level_rotation(normal)
    rot = with_yaw(rot_level, phase_yaw(acc_s, beta_rad, rot_level))
    i, j = np.array(pairs).T
    cos_a = float(np.mean(np.linalg.norm(acc_s[i] + acc_s[j], axis=1) / (2.0 * g_mps2)))
    slope = float(np.arccos(cos_a)) if cos_a <= 1.0 else None
    return PaperEstimate(rot, slope, cos_a, len(pairs))


def paper_method(table: StopTable, g_mps2: float) -> tuple[PaperEstimate, FloatArray, float, FloatArray]:
    """The paper's estimate with a delta-method covariance.

    Returns
    -------
    estimate : PaperEstimate
    cov : ndarray, shape (4, 4)
        Covariance of (roll, pitch, yaw, slope) in rad²; NaN rows where undefined.
    noise_scale : float
        1 when the stop covariances are known, else σ̂ in m/s² from the residuals.
    residual_s : ndarray, shape (n, 3)
    """
    if table.beta_rad is None or table.headings == "none":
        raise NotEnoughInformation(
            f"{table.source}: the paper's method needs the heading β of every stop, found none. "
            f"Add a beta_deg column, or use {option('method', 'full')}, which estimates roll, pitch and slope "
            "without headings."
        )
    beta = table.beta_rad
    pairs = opposite_pairs(beta)
    if not pairs:
        raise NotEnoughInformation(
            f"{table.source}: the paper's slope step needs pairs of opposite headings (β and β+180°), "
            f"found none. Use {option('method', 'full')}, which needs no pairs."
        )
    est = paper_angles(table.acc_s, beta, pairs, g_mps2)

    def outputs(acc: FloatArray) -> FloatArray:
        e = paper_angles(acc, beta, pairs, g_mps2)
        roll, pitch, yaw = angles_from_rot_vs(e.rot_vs)
        return np.array([roll, pitch, yaw, np.arccos(min(e.cos_slope, 1.0))])

    h = 1e-6 * g_mps2
    n = len(table)
    jac = np.empty((4, 3 * n))
    for k in range(3 * n):  # central differences over the 3n inputs: cheap for tens of stops
        d = np.zeros(3 * n)
        d[k] = h
        up, down = outputs(table.acc_s + d.reshape(n, 3)), outputs(table.acc_s - d.reshape(n, 3))
        diff = up - down
        diff[:3] = np.angle(np.exp(1j * diff[:3]))  # angles wrap at ±π
        jac[:, k] = diff / (2 * h)

    slope_for_residual = est.slope_rad if est.slope_rad is not None else 0.0
    residual = table.acc_s - est.rot_vs.inv().apply(specific_force_v(slope_for_residual, beta, g_mps2))
    if table.cov_s is not None:
        cov_in = np.zeros((3 * n, 3 * n))
        for s in range(n):
            cov_in[3 * s : 3 * s + 3, 3 * s : 3 * s + 3] = table.cov_s[s]
        noise_scale = 1.0
    else:
        dof = 3 * n - 4
        noise_scale = float(np.sqrt(np.sum(residual**2) / dof)) if dof > 0 else np.nan
        cov_in = np.eye(3 * n) * noise_scale**2
    cov = jac @ cov_in @ jac.T
    if est.slope_rad is None:
        cov[3, :] = cov[:, 3] = np.nan
    return est, cov, noise_scale, residual
