"""Per vehicle: a consensus mounting across its logs, the logs that disagree, and remounts.

Each successful log gives a mounting rotation ``R_i`` (``rot_vs``) and the 1σ of the rotation
about the vehicle axes; a log without yaw says nothing about the rotation about vehicle z. All
comparisons are on SO(3), in the tangent space of a reference ``R̄`` about the vehicle axes:
``R_i = exp(δ_i) R̄``. For a log without yaw only its tilt counts: ``δ_i`` is the rotation about a
horizontal axis that takes its "up" (``R_iᵀ e_z`` in sensor coordinates) to the reference's, and
its weight about z is zero.

- **Consensus**: the inverse-covariance weighted mean on SO(3), iterated until the weighted mean
  of the ``δ_i`` vanishes (a Gauss–Newton step of Σ δ_iᵀ W_i δ_i); its covariance is
  ``(Σ W_i)⁻¹``. Yaw is reported only when some log determined it.
- **Disagreement**: each log against the consensus of the others (leave-one-out), χ² on 2 or 3
  dof; below :data:`ALPHA` the log disagrees, and the worst such log is dropped from the consensus
  (one at a time, while more than two remain). When the remaining logs still scatter beyond their
  σ (χ² p < ALPHA) the consensus σ is scaled by √(χ²/dof).
- **Remounts**: the logs in time order are split where the two-segment consensus explains them
  best: for each split k the statistic is the χ² of the difference of the two segments' means,
  ``(m_B − m_A)ᵀ (C_A + C_B)⁻¹ (m_B − m_A)`` (the likelihood-ratio statistic of "one mounting"
  against "two"); the best split's p-value, Bonferroni-corrected for the n − 1 candidates, must be
  below ALPHA. Segments are split again (binary segmentation). A single log between two segments
  that agree with each other is an outlier, not two remounts: the three are merged.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from mountcal.core.conventions import FloatArray, angles_from_rot_vs
from mountcal.core.pvalues import chi2_logsf, chi2_sf

ALPHA = 1e-3  # significance of disagreement and of a remount


MAX_ITERATIONS = 100


STEP_TOL_RAD = 1e-12


E_Z = np.array([0.0, 0.0, 1.0])


def _blocks() -> dict[bytes, tuple[np.ndarray, tuple[np.ndarray, ...]]]:
    """Per pattern of observed axes (the bool mask's bytes): its axes and their ``np.ix_`` block.

    Built once: the χ² loops index a 3×3 block thousands of times per vehicle, and building the
    index arrays cost more than the algebra (the same indexing, so the same numbers).
    """
    table = {}
    for code in range(8):
        mask = np.array([bool(code & 1), bool(code & 2), bool(code & 4)])
        axes = np.flatnonzero(mask)
        block = np.ix_(axes, axes)
        for a in (axes, *block):
            a.setflags(write=False)
        table[mask.tobytes()] = (axes, block)
    return table


_BLOCKS = _blocks()


@dataclass(frozen=True)
class Consensus:
    """The weighted mean mounting of some logs.

    Attributes
    ----------
    rot_vs : Rotation
        The consensus; its yaw is arbitrary when ``observed[2]`` is False.
    cov_rad2 : ndarray, shape (3, 3)
        Covariance of the rotation about the vehicle axes (rad²); NaN on unobserved axes.
    observed : ndarray of bool, shape (3,)
        Axes (vehicle x, y, z) the logs determine; z is yaw.
    chi2 : float
        Σ δ_iᵀ W_i δ_i of the logs about the consensus.
    dof : int
        Its degrees of freedom: Σ rank(W_i) − rank(Σ W_i).
    residual_rad : ndarray, shape (n, 3)
        δ_i of each log about the consensus, vehicle axes (rad).
    """

    rot_vs: Rotation
    cov_rad2: FloatArray
    observed: np.ndarray
    chi2: float
    dof: int
    residual_rad: FloatArray

    @property
    def p_value(self) -> float:
        return float(chi2_sf(self.chi2, self.dof)) if self.dof > 0 else float("nan")


@dataclass(frozen=True)
class ChangePoint:
    """A remount: the mounting changes from log ``index − 1`` to log ``index`` (time order)."""

    index: int
    statistic: float
    dof: int
    p_value: float  # Bonferroni-corrected over the candidate splits of its segment


@dataclass(frozen=True)
class Segment:
    """One mounting period of a vehicle: logs ``start … stop − 1`` in time order."""

    start: int
    stop: int
    consensus: Consensus
    used: np.ndarray  # bool, shape (stop − start,): logs in the consensus
    log_chi2: FloatArray  # shape (stop − start,): each log against the consensus of the others
    log_dof: np.ndarray
    sigma_scale: float
    change: ChangePoint | None  # the remount that starts this segment


def information(sigma_deg: FloatArray, floor_deg: float = 0.0) -> FloatArray:
    """Information matrices (rad⁻²), shape (n, 3, 3), from the 1σ about the vehicle axes.

    Parameters
    ----------
    sigma_deg : ndarray, shape (n, 3)
        1σ of each log's rotation about vehicle x, y, z in degrees; NaN where not determined.
    floor_deg : float
        A mounting scatter added in quadrature to every σ (unmodelled between-log variation).
    """
    sigma = np.radians(np.hypot(np.asarray(sigma_deg, dtype=float), floor_deg))
    weight = np.where(np.isfinite(sigma) & (sigma > 0), 1.0 / np.where(sigma > 0, sigma, 1.0) ** 2, 0.0)
    info = np.zeros((weight.shape[0], 3, 3))
    info[:, [0, 1, 2], [0, 1, 2]] = weight
    return info


def tangent_residuals(rot_vs: Rotation, ref: Rotation, yaw_known: np.ndarray) -> FloatArray:
    """δ_i with ``R_i = exp(δ_i) · ref``, shape (n, 3), rad, about the vehicle axes.

    Where ``yaw_known`` is False only the tilt counts: δ_i is the rotation about a horizontal
    vehicle axis taking ``R_iᵀ e_z`` to ``refᵀ e_z``, with no z part.
    """
    return _tangent_residuals(rot_vs, rot_vs.inv().apply(E_Z), ref, yaw_known)


def _tangent_residuals(rot_vs: Rotation, up_sensor: FloatArray, ref: Rotation, yaw_known: np.ndarray) -> FloatArray:
    """:func:`tangent_residuals` given ``up_sensor = R_iᵀ e_z``, which the consensus iteration keeps."""
    full = (rot_vs * ref.inv()).as_rotvec()
    up = ref.apply(up_sensor)  # the log's "up" in the reference's vehicle frame
    horizontal = np.hypot(up[:, 0], up[:, 1])
    angle = np.arctan2(horizontal, up[:, 2])
    scale = np.where(horizontal > 1e-15, angle / np.where(horizontal > 1e-15, horizontal, 1.0), 1.0)
    tilt = np.column_stack([up[:, 1] * scale, -up[:, 0] * scale, np.zeros_like(scale)])
    return np.where(np.asarray(yaw_known)[:, None], full, tilt)


def consensus(rot_vs: Rotation, info: FloatArray) -> Consensus:
    """Inverse-covariance weighted mean rotation of logs on SO(3).

    Parameters
    ----------
    rot_vs : Rotation, n rotations
    info : ndarray, shape (n, 3, 3)
        Information about the vehicle axes (rad⁻²); zero about z for logs without yaw.
    """
    yaw_known = info[:, 2, 2] > 0
    total = info.sum(axis=0)
    observed = total.diagonal() > 0
    obs, block = _BLOCKS[observed.tobytes()]
    ref = rot_vs[int(np.argmax(np.trace(info, axis1=1, axis2=2)))]
    up_sensor = rot_vs.inv().apply(E_Z)  # the logs' "up" in their sensor frames: the same every iteration
    for _ in range(MAX_ITERATIONS):
        delta = _tangent_residuals(rot_vs, up_sensor, ref, yaw_known)
        gradient = np.einsum("nij,nj->i", info, delta)
        step = np.zeros(3)
        step[obs] = np.linalg.solve(total[block], gradient[obs])
        ref = Rotation.from_rotvec(step) * ref
        if np.linalg.norm(step) < STEP_TOL_RAD:
            break
    delta = _tangent_residuals(rot_vs, up_sensor, ref, yaw_known)
    cov = np.full((3, 3), np.nan)
    cov[block] = np.linalg.inv(total[block])
    ranks = (np.diagonal(info, axis1=1, axis2=2) > 0).sum()
    return Consensus(
        rot_vs=ref,
        cov_rad2=cov,
        observed=observed,
        chi2=float(np.einsum("ni,nij,nj->", delta, info, delta)),
        dof=int(ranks - obs.size),
        residual_rad=delta,
    )


def _mean_and_cov(info_sum: FloatArray, gradient: FloatArray) -> tuple[FloatArray, FloatArray, np.ndarray]:
    """Mean δ and its covariance from summed information and Σ W_i δ_i, on the observed axes."""
    observed = info_sum.diagonal() > 0
    obs, block = _BLOCKS[observed.tobytes()]
    mean, cov = np.full(3, np.nan), np.full((3, 3), np.nan)
    if obs.size:
        cov[block] = np.linalg.inv(info_sum[block])
        mean[obs] = cov[block] @ gradient[obs]
    return mean, cov, observed


def _difference_chi2(
    mean_a: FloatArray, cov_a: FloatArray, mean_b: FloatArray, cov_b: FloatArray, axes: np.ndarray
) -> tuple[float, int]:
    """χ² of ``mean_b − mean_a`` on the axes both sides observe, and its dof."""
    idx, block = _BLOCKS[axes.tobytes()]
    if idx.size == 0:
        return float("nan"), 0
    diff = mean_b[idx] - mean_a[idx]
    cov = cov_a[block] + cov_b[block]
    return float(diff @ np.linalg.solve(cov, diff)), int(idx.size)


def leave_one_out(info: FloatArray, cons: Consensus) -> tuple[FloatArray, np.ndarray]:
    """χ² of each log against the consensus of the others (linearised at ``cons``), and its dof.

    NaN and dof 0 where the others say nothing on the log's axes (a single log).
    """
    n = info.shape[0]
    gradient_all = np.einsum("nij,nj->ni", info, cons.residual_rad)
    total, gradient_sum = info.sum(axis=0), gradient_all.sum(axis=0)
    chi2, dof = np.full(n, np.nan), np.zeros(n, dtype=int)
    for i in range(n):  # one 3×3 solve per log, not per sample
        mean_o, cov_o, obs_o = _mean_and_cov(total - info[i], gradient_sum - gradient_all[i])
        mean_i, cov_i, obs_i = _mean_and_cov(info[i], gradient_all[i])
        chi2[i], dof[i] = _difference_chi2(mean_o, cov_o, mean_i, cov_i, obs_o & obs_i)
    return chi2, dof


def against(rot_vs: Rotation, info: FloatArray, cons: Consensus) -> tuple[FloatArray, np.ndarray]:
    """χ² of logs that are not part of ``cons`` against it, and its dof."""
    yaw_known = info[:, 2, 2] > 0
    delta = tangent_residuals(rot_vs, cons.rot_vs, yaw_known & cons.observed[2])
    n = info.shape[0]
    chi2, dof = np.full(n, np.nan), np.zeros(n, dtype=int)
    for i in range(n):
        mean_i, cov_i, obs_i = _mean_and_cov(info[i], info[i] @ delta[i])
        chi2[i], dof[i] = _difference_chi2(
            np.zeros(3), np.nan_to_num(cons.cov_rad2), mean_i, cov_i, obs_i & cons.observed
        )
    return chi2, dof


def best_split(rot_vs: Rotation, info: FloatArray, cons: Consensus | None = None) -> ChangePoint | None:
    """The most significant single change of mounting in a time-ordered run of logs.

    The statistic of each split is linearised about the run's consensus (``cons``, computed if not
    given); the p-value of the best one is Bonferroni-corrected for the ``n − 1`` candidates. None
    for fewer than two logs.
    """
    n = info.shape[0]
    if n < 2:
        return None
    cons = consensus(rot_vs, info) if cons is None else cons
    gradient = np.einsum("nij,nj->ni", info, cons.residual_rad)
    cum_info, cum_gradient = np.cumsum(info, axis=0), np.cumsum(gradient, axis=0)
    best: tuple[float, float, int, int] | None = None  # (log sf, statistic, dof, k)
    for k in range(1, n):
        mean_a, cov_a, obs_a = _mean_and_cov(cum_info[k - 1], cum_gradient[k - 1])
        mean_b, cov_b, obs_b = _mean_and_cov(cum_info[-1] - cum_info[k - 1], cum_gradient[-1] - cum_gradient[k - 1])
        statistic, dof = _difference_chi2(mean_a, cov_a, mean_b, cov_b, obs_a & obs_b)
        if dof == 0:
            continue
        log_sf = float(chi2_logsf(statistic, dof))
        if best is None or (log_sf, -statistic) < (best[0], -best[1]):
            best = (log_sf, statistic, dof, k)
    if best is None:
        return None
    log_sf, statistic, dof, k = best
    return ChangePoint(k, statistic, dof, float(min(1.0, (n - 1) * np.exp(log_sf))))


def find_change_points(
    rot_vs: Rotation, info: FloatArray, alpha: float = ALPHA, runs: dict[tuple[int, int], Consensus] | None = None
) -> tuple[list[ChangePoint], list[int]]:
    """Remounts in a time-ordered run of logs (binary segmentation), and the single-log outliers.

    ``runs``, if given, receives the consensus of every run of logs ``a … b − 1`` tested for a split,
    by ``(a, b)``: a mounting period's first consensus, which the caller need not compute again.

    Returns
    -------
    change_points : list of ChangePoint, by index
    outliers : list of int
        Logs that stood alone between two segments that agree with each other (merged back).
    """
    n = info.shape[0]
    found: list[ChangePoint] = []
    pending = [(0, n)]
    while pending:
        a, b = pending.pop()
        cp = None
        if b - a >= 2:
            cons = consensus(rot_vs[a:b], info[a:b])
            cp = best_split(rot_vs[a:b], info[a:b], cons)
            if runs is not None:
                runs[a, b] = cons
        if cp is not None and cp.p_value < alpha:
            found.append(ChangePoint(a + cp.index, cp.statistic, cp.dof, cp.p_value))
            pending += [(a, a + cp.index), (a + cp.index, b)]
    found.sort(key=lambda c: c.index)
    outliers: list[int] = []
    merged = True
    while merged:
        merged = False
        edges = [0, *(c.index for c in found), n]
        for s in range(1, len(edges) - 2):
            lo, mid, hi, end = edges[s - 1], edges[s], edges[s + 1], edges[s + 2]
            if hi - mid != 1:
                continue
            keep = np.r_[lo:mid, hi:end]
            cp = _split_at(rot_vs[keep], info[keep], mid - lo)
            if cp is None or cp.p_value >= alpha:
                outliers.append(mid)
                found = [c for c in found if c.index not in (mid, hi)]
                merged = True
                break
    return found, sorted(outliers)


def _split_at(rot_vs: Rotation, info: FloatArray, k: int) -> ChangePoint | None:
    """The statistic of one given split (no multiple-testing correction)."""
    cons = consensus(rot_vs, info)
    gradient = np.einsum("nij,nj->ni", info, cons.residual_rad)
    mean_a, cov_a, obs_a = _mean_and_cov(info[:k].sum(axis=0), gradient[:k].sum(axis=0))
    mean_b, cov_b, obs_b = _mean_and_cov(info[k:].sum(axis=0), gradient[k:].sum(axis=0))
    statistic, dof = _difference_chi2(mean_a, cov_a, mean_b, cov_b, obs_a & obs_b)
    if dof == 0:
        return None
    return ChangePoint(k, statistic, dof, float(chi2_sf(statistic, dof)))


def segment_consensus(
    rot_vs: Rotation, info: FloatArray, alpha: float = ALPHA, of_all: Consensus | None = None
) -> tuple[Consensus, np.ndarray, FloatArray, np.ndarray, float]:
    """Consensus of one mounting period, dropping disagreeing logs one at a time; ``of_all``, if
    known, is the consensus of all its logs (the first one this computes).

    Returns
    -------
    consensus : Consensus
        Of the used logs, its covariance scaled by ``sigma_scale``².
    used : ndarray of bool, shape (n,)
    log_chi2, log_dof : ndarray, shape (n,)
        Each log against the consensus of the others (used logs: leave-one-out; dropped logs:
        against the final consensus).
    sigma_scale : float
    """
    n = info.shape[0]
    used = np.ones(n, dtype=bool)
    while True:
        cons = of_all if of_all is not None and used.all() else consensus(rot_vs[used], info[used])
        chi2_used, dof_used = leave_one_out(info[used], cons)
        if used.sum() <= 2:
            break
        p = np.where(dof_used > 0, chi2_sf(np.nan_to_num(chi2_used), np.maximum(dof_used, 1)), 1.0)
        worst = int(np.argmin(p))
        if p[worst] >= alpha:
            break
        used[np.flatnonzero(used)[worst]] = False
    log_chi2, log_dof = np.full(n, np.nan), np.zeros(n, dtype=int)
    log_chi2[used], log_dof[used] = chi2_used, dof_used
    if (~used).any():
        log_chi2[~used], log_dof[~used] = against(rot_vs[~used], info[~used], cons)
    scale = 1.0
    if cons.dof > 0 and cons.p_value < alpha:
        scale = float(np.sqrt(cons.chi2 / cons.dof))
        cons = Consensus(cons.rot_vs, cons.cov_rad2 * scale**2, cons.observed, cons.chi2, cons.dof, cons.residual_rad)
    return cons, used, log_chi2, log_dof, scale


def analyse_vehicle(rot_vs: Rotation, info: FloatArray, alpha: float = ALPHA) -> tuple[list[Segment], list[int]]:
    """Mounting periods of one vehicle's time-ordered logs, with their consensus; and the outliers."""
    runs: dict[tuple[int, int], Consensus] = {}  # consensus of each run split-tested: not computed twice
    change_points, outliers = find_change_points(rot_vs, info, alpha, runs)
    edges = [0, *(c.index for c in change_points), info.shape[0]]
    segments = []
    for s in range(len(edges) - 1):
        a, b = edges[s], edges[s + 1]
        cons, used, chi2, dof, scale = segment_consensus(rot_vs[a:b], info[a:b], alpha, runs.get((a, b)))
        segments.append(Segment(a, b, cons, used, chi2, dof, scale, change_points[s - 1] if s else None))
    return segments, outliers


def angles_with_sigma(cons: Consensus, h: float = 1e-7) -> tuple[list[float], list[float | None]]:
    """Roll, pitch, yaw (deg) of a consensus and their 1σ (deg; None on what is not observed)."""
    angles = np.array(angles_from_rot_vs(cons.rot_vs))
    jac = np.zeros((3, 3))  # ∂(roll, pitch, yaw)/∂δ about the vehicle axes
    for j in range(3):
        d = np.zeros(3)
        d[j] = h
        up = np.array(angles_from_rot_vs(Rotation.from_rotvec(d) * cons.rot_vs))
        down = np.array(angles_from_rot_vs(Rotation.from_rotvec(-d) * cons.rot_vs))
        jac[:, j] = np.angle(np.exp(1j * (up - down))) / (2 * h)
    obs = np.flatnonzero(cons.observed)
    cov = jac[:, obs] @ cons.cov_rad2[np.ix_(obs, obs)] @ jac[:, obs].T
    sigma: list[float | None] = [float(np.degrees(np.sqrt(max(cov[k, k], 0.0)))) for k in range(3)]
    if not cons.observed[2]:
        sigma[2] = None
    return [float(a) for a in np.degrees(angles)], sigma


__all__ = [
    "ALPHA",
    "E_Z",
    "MAX_ITERATIONS",
    "STEP_TOL_RAD",
    "ChangePoint",
    "Consensus",
    "Segment",
    "against",
    "analyse_vehicle",
    "angles_with_sigma",
    "best_split",
    "consensus",
    "find_change_points",
    "information",
    "leave_one_out",
    "segment_consensus",
    "tangent_residuals",
]
