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

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from mountcal.core.conventions import FloatArray, angles_from_rot_vs, levelled
from mountcal.core.pvalues import chi2_logsf, chi2_sf
from mountcal.fleet.inputs import natural_key

ALPHA = 1e-3  # significance of disagreement and of a remount
MAX_ITERATIONS = 100
STEP_TOL_RAD = 1e-12
E_Z = np.array([0.0, 0.0, 1.0])


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
    full = (rot_vs * ref.inv()).as_rotvec()
    up = ref.apply(rot_vs.inv().apply(E_Z))  # the log's "up" in the reference's vehicle frame
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
    observed = np.diag(total) > 0
    obs = np.flatnonzero(observed)
    block = np.ix_(obs, obs)
    ref = rot_vs[int(np.argmax(np.trace(info, axis1=1, axis2=2)))]
    for _ in range(MAX_ITERATIONS):
        delta = tangent_residuals(rot_vs, ref, yaw_known)
        gradient = np.einsum("nij,nj->i", info, delta)
        step = np.zeros(3)
        step[obs] = np.linalg.solve(total[block], gradient[obs])
        ref = Rotation.from_rotvec(step) * ref
        if np.linalg.norm(step) < STEP_TOL_RAD:
            break
    delta = tangent_residuals(rot_vs, ref, yaw_known)
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
    observed = np.diag(info_sum) > 0
    obs = np.flatnonzero(observed)
    mean, cov = np.full(3, np.nan), np.full((3, 3), np.nan)
    if obs.size:
        cov[np.ix_(obs, obs)] = np.linalg.inv(info_sum[np.ix_(obs, obs)])
        mean[obs] = cov[np.ix_(obs, obs)] @ gradient[obs]
    return mean, cov, observed


def _difference_chi2(
    mean_a: FloatArray, cov_a: FloatArray, mean_b: FloatArray, cov_b: FloatArray, axes: np.ndarray
) -> tuple[float, int]:
    """χ² of ``mean_b − mean_a`` on the axes both sides observe, and its dof."""
    idx = np.flatnonzero(axes)
    if idx.size == 0:
        return float("nan"), 0
    diff = mean_b[idx] - mean_a[idx]
    cov = cov_a[np.ix_(idx, idx)] + cov_b[np.ix_(idx, idx)]
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


def best_split(rot_vs: Rotation, info: FloatArray) -> ChangePoint | None:
    """The most significant single change of mounting in a time-ordered run of logs.

    The statistic of each split is linearised about the run's consensus; the p-value of the best
    one is Bonferroni-corrected for the ``n − 1`` candidates. None for fewer than two logs.
    """
    n = info.shape[0]
    if n < 2:
        return None
    cons = consensus(rot_vs, info)
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


def find_change_points(rot_vs: Rotation, info: FloatArray, alpha: float = ALPHA) -> tuple[list[ChangePoint], list[int]]:
    """Remounts in a time-ordered run of logs (binary segmentation), and the single-log outliers.

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
        cp = best_split(rot_vs[a:b], info[a:b]) if b - a >= 2 else None
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
    rot_vs: Rotation, info: FloatArray, alpha: float = ALPHA
) -> tuple[Consensus, np.ndarray, FloatArray, np.ndarray, float]:
    """Consensus of one mounting period, dropping disagreeing logs one at a time.

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
        cons = consensus(rot_vs[used], info[used])
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
    change_points, outliers = find_change_points(rot_vs, info, alpha)
    edges = [0, *(c.index for c in change_points), info.shape[0]]
    segments = []
    for s in range(len(edges) - 1):
        a, b = edges[s], edges[s + 1]
        cons, used, chi2, dof, scale = segment_consensus(rot_vs[a:b], info[a:b], alpha)
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


# --- tables -------------------------------------------------------------------------------------


def analyse_fleet(
    logs: pd.DataFrame, alpha: float = ALPHA, floor_deg: float = 0.0
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Annotate the per-log table and build the per-vehicle table.

    Parameters
    ----------
    logs : DataFrame
        One row per log with the columns of :data:`mountcal.fleet.store.LOG_COLUMNS` (at least
        vehicle_id, log, status, start_time, quat_*, rot_sigma_*_deg, yaw_reason, flags).
    alpha : float
        Significance of disagreement and remounts.
    floor_deg : float
        Mounting scatter between logs added in quadrature to every log's σ.

    Returns
    -------
    logs : DataFrame
        The input with ``segment``, ``in_consensus``, ``consensus_chi2``, ``consensus_dof``,
        ``consensus_p_value`` filled and the flags ``disagrees_with_consensus``, ``remount`` added.
    vehicles : DataFrame
        One row per vehicle and mounting period (:data:`mountcal.fleet.store.VEHICLE_COLUMNS`).
    """
    logs = logs.copy()
    logs["flags"] = [list(f) if isinstance(f, list | tuple | np.ndarray) else [] for f in logs["flags"]]
    for col, value in (
        ("segment", pd.NA),
        ("in_consensus", pd.NA),
        ("consensus_chi2", np.nan),
        ("consensus_dof", pd.NA),
        ("consensus_p_value", np.nan),
    ):
        logs[col] = value
    logs["segment"] = logs["segment"].astype("Int64")
    logs["consensus_dof"] = logs["consensus_dof"].astype("Int64")
    logs["in_consensus"] = logs["in_consensus"].astype("boolean")
    rows: list[dict[str, Any]] = []
    for vehicle in sorted(logs["vehicle_id"].unique(), key=natural_key):
        rows += _vehicle_rows(logs, vehicle, alpha, floor_deg)
    return logs, pd.DataFrame(rows)


def _vehicle_rows(logs: pd.DataFrame, vehicle: str, alpha: float, floor_deg: float) -> list[dict[str, Any]]:
    mine = logs[logs["vehicle_id"] == vehicle]
    ok = mine[(mine["status"] == "ok")]
    usable = ok[np.isfinite(ok[["quat_w", "rot_sigma_x_deg", "rot_sigma_y_deg"]].to_numpy(dtype=float)).all(axis=1)]
    for idx in ok.index.difference(usable.index):
        logs.at[idx, "flags"] = [*logs.at[idx, "flags"], "no_uncertainty"]
    n_failed = int((mine["status"] != "ok").sum())
    base = {"vehicle_id": vehicle, "n_failed_vehicle": n_failed}
    if usable.empty:
        reason = f"all {len(mine)} logs failed" if ok.empty else "no successful log carries an uncertainty"
        return [
            {
                **base,
                "segment": 0,
                "n_segments": 0,
                "latest": True,
                "status": "no calibration",
                "reason": reason,
                "n_logs": 0,
                "n_used": 0,
                "n_disagreeing": 0,
                "disagreeing_logs": [],
                "remount": False,
            }
        ]
    order = "start_time" if usable["start_time"].notna().all() else "log name"
    keys = [
        (row.start_time if order == "start_time" else pd.Timestamp(0, tz="UTC"), natural_key(row.log))
        for row in usable.itertuples()
    ]
    usable = usable.iloc[sorted(range(len(usable)), key=lambda i: keys[i])]
    rot = Rotation.from_quat(usable[["quat_x", "quat_y", "quat_z", "quat_w"]].to_numpy(dtype=float))
    sigma = usable[["rot_sigma_x_deg", "rot_sigma_y_deg", "rot_sigma_z_deg"]].to_numpy(dtype=float)
    info = information(sigma, floor_deg)
    segments, _ = analyse_vehicle(rot, info, alpha)
    rows = []
    for s, seg in enumerate(segments):
        index = usable.index[seg.start : seg.stop]
        p = np.where(seg.log_dof > 0, chi2_sf(np.nan_to_num(seg.log_chi2), np.maximum(seg.log_dof, 1)), np.nan)
        disagree = (p < alpha) | ~seg.used
        for j, idx in enumerate(index):
            logs.at[idx, "segment"] = s
            logs.at[idx, "in_consensus"] = bool(seg.used[j])
            logs.at[idx, "consensus_chi2"] = seg.log_chi2[j]
            logs.at[idx, "consensus_dof"] = int(seg.log_dof[j]) if seg.log_dof[j] else pd.NA
            logs.at[idx, "consensus_p_value"] = p[j]
            extra = (["disagrees_with_consensus"] if disagree[j] else []) + (
                ["remount"] if j == 0 and seg.change is not None else []
            )
            logs.at[idx, "flags"] = [*logs.at[idx, "flags"], *extra]
        rows.append({**base, **_segment_row(seg, s, len(segments), usable, index, disagree, order)})
        if seg.change is not None:
            rows[-1].update(_change_row(segments[s - 1], seg))
    return rows


def _segment_row(
    seg: Segment, s: int, n_segments: int, usable: pd.DataFrame, index: pd.Index, disagree: np.ndarray, order: str
) -> dict[str, Any]:
    cons = seg.consensus
    part = usable.loc[index]
    if "rot_sys_sigma_x_deg" in part:  # the sensor's systematic part, common to its logs: added once
        cols = part[[f"rot_sys_sigma_{a}_deg" for a in "xyz"]].to_numpy(float).T
        sys = np.array([np.median(c[np.isfinite(c)]) if np.isfinite(c).any() else 0.0 for c in cols])
        cons = replace(cons, cov_rad2=cons.cov_rad2 + np.diag(np.radians(sys) ** 2))
    angles, sigma = angles_with_sigma(cons)
    # Without yaw the consensus stores the levelling rotation: its yaw was arbitrary, never invented.
    quat = (cons.rot_vs if cons.observed[2] else levelled(cons.rot_vs)).as_quat()
    rot_sigma = np.degrees(np.sqrt(np.clip(np.diagonal(cons.cov_rad2), 0.0, None)))
    yaw_reason = None
    if not cons.observed[2]:
        reasons = part["yaw_reason"].dropna()
        common = reasons.mode().iloc[0] if not reasons.empty else "no log determined yaw"
        yaw_reason = f"no log of this mounting period determined yaw (e.g. {common})"
    return {
        "segment": s,
        "n_segments": n_segments,
        "latest": s == n_segments - 1,
        "status": "ok",
        "reason": None,
        "order": order,
        "n_logs": len(index),
        "n_used": int(seg.used.sum()),
        "n_disagreeing": int(disagree.sum()),
        "disagreeing_logs": [str(x) for x in part["log"][disagree]],
        "first_log": str(part["log"].iloc[0]),
        "last_log": str(part["log"].iloc[-1]),
        "first_start_time": part["start_time"].iloc[0],
        "last_start_time": part["start_time"].iloc[-1],
        "roll_deg": angles[0],
        "roll_sigma_deg": sigma[0],
        "pitch_deg": angles[1],
        "pitch_sigma_deg": sigma[1],
        "yaw_deg": angles[2] if cons.observed[2] else None,
        "yaw_sigma_deg": sigma[2],
        "yaw_reason": yaw_reason,
        "rot_sigma_x_deg": float(rot_sigma[0]),
        "rot_sigma_y_deg": float(rot_sigma[1]),
        "rot_sigma_z_deg": float(rot_sigma[2]) if cons.observed[2] else None,
        "quat_x": float(quat[0]),
        "quat_y": float(quat[1]),
        "quat_z": float(quat[2]),
        "quat_w": float(quat[3]),
        "chi2": cons.chi2,
        "dof": cons.dof,
        "p_value": cons.p_value,
        "sigma_scale": seg.sigma_scale,
        "remount": seg.change is not None,
        "remount_log": str(part["log"].iloc[0]) if seg.change is not None else None,
    }


def _change_row(before: Segment, after: Segment) -> dict[str, Any]:
    """The change of mounting between two consecutive periods: angle ± σ and its components."""
    a, b = before.consensus, after.consensus
    both = a.observed & b.observed
    delta = tangent_residuals(Rotation.concatenate([b.rot_vs]), a.rot_vs, np.array([bool(both[2])]))[0]
    idx = np.flatnonzero(both)
    cov = np.nan_to_num(a.cov_rad2)[np.ix_(idx, idx)] + np.nan_to_num(b.cov_rad2)[np.ix_(idx, idx)]
    angle = float(np.linalg.norm(delta[idx]))
    direction = delta[idx] / angle if angle > 0 else np.zeros(idx.size)
    sigma = float(np.sqrt(max(direction @ cov @ direction, 0.0))) if angle > 0 else float(np.sqrt(np.trace(cov)))
    change = after.change
    assert change is not None
    return {
        "remount_change_deg": float(np.degrees(angle)),
        "remount_change_sigma_deg": float(np.degrees(sigma)),
        "remount_change_x_deg": float(np.degrees(delta[0])),
        "remount_change_y_deg": float(np.degrees(delta[1])),
        "remount_change_z_deg": float(np.degrees(delta[2])) if both[2] else None,
        "remount_statistic": change.statistic,
        "remount_dof": change.dof,
        "remount_p_value": change.p_value,
    }


# --- one row per vehicle ------------------------------------------------------------------------

MOUNTING_KEYS = (
    "segment",
    "first_log",
    "last_log",
    "first_start_time",
    "last_start_time",
    "n_logs",
    "n_used",
    "roll_deg",
    "roll_sigma_deg",
    "pitch_deg",
    "pitch_sigma_deg",
    "yaw_deg",
    "yaw_sigma_deg",
    "sigma_scale",
)
LATEST_KEYS = (
    "roll_deg",
    "roll_sigma_deg",
    "pitch_deg",
    "pitch_sigma_deg",
    "yaw_deg",
    "yaw_sigma_deg",
    "yaw_reason",
    "rot_sigma_x_deg",
    "rot_sigma_y_deg",
    "rot_sigma_z_deg",
    "quat_x",
    "quat_y",
    "quat_z",
    "quat_w",
    "n_used",
    "n_disagreeing",
    "disagreeing_logs",
    "chi2",
    "dof",
    "p_value",
    "sigma_scale",
)


def vehicle_table(mountings: pd.DataFrame, logs: pd.DataFrame) -> pd.DataFrame:
    """One row per vehicle from :func:`analyse_fleet`'s tables: the current mounting ± σ, whether it
    is confident (and why not), its remounts (time, log, size ± σ) and every mounting period in time
    order (``mountings``: a list of records, the vehicle's mounting over time)."""
    rows = []
    for vehicle, periods in mountings.groupby("vehicle_id", sort=False):
        periods = periods.sort_values("segment")
        mine = logs[logs["vehicle_id"] == vehicle]
        latest = periods.iloc[-1]
        ok = latest["status"] == "ok"
        confident, note = _confidence(latest, mine[mine["segment"] == latest["segment"]]) if ok else (False, None)
        starts = mine.loc[mine["status"] == "ok", "start_time"].dropna()
        rows.append(
            {
                "vehicle_id": vehicle,
                "status": latest["status"],
                "reason": latest.get("reason"),
                "order": latest.get("order") if ok else None,
                "n_logs": int((mine["status"] == "ok").sum()),
                "n_failed": int((mine["status"] != "ok").sum()),
                "n_mountings": len(periods) if ok else 0,
                "first_start_time": starts.min() if not starts.empty else None,
                "last_start_time": starts.max() if not starts.empty else None,
                **({k: _plain(latest.get(k)) for k in LATEST_KEYS} if ok else {"disagreeing_logs": []}),
                "since_log": latest.get("first_log") if ok else None,
                "since_time": latest.get("first_start_time") if ok else None,
                "latest_confident": confident,
                "confidence_note": note if ok else latest.get("reason"),
                "n_remounts": int(periods["remount"].fillna(False).astype(bool).sum()),
                "remounts": [_remount(p) for _, p in periods.iterrows() if bool(p.get("remount"))],
                "mountings": [{k: _plain(p.get(k)) for k in MOUNTING_KEYS} for _, p in periods.iterrows()]
                if ok
                else [],
            }
        )
    return pd.DataFrame(rows)


def _confidence(latest: pd.Series, period_logs: pd.DataFrame) -> tuple[bool, str | None]:
    """Whether the current mounting can be trusted as stated, and if not why (for fleet people)."""
    reasons = []
    used = period_logs[period_logs["in_consensus"].fillna(False).astype(bool)]
    doubtful = int(used["flags"].map(lambda f: "not_confident" in list(f)).sum())
    if len(used) and doubtful == len(used):
        reasons.append(f"its {doubtful} log(s) are not confident (flag not_confident)")
    scale = latest.get("sigma_scale")
    if scale is not None and np.isfinite(scale) and scale > 1.0:
        reasons.append(
            f"its logs scatter beyond their σ (σ scaled by {scale:.2g}: an effect the model lacks, or a loose mount)"
        )
    return not reasons, "; ".join(reasons) or None


def _remount(period: pd.Series) -> dict[str, Any]:
    return {
        "time": period.get("first_start_time"),
        "log": period.get("remount_log"),
        "change_deg": _plain(period.get("remount_change_deg")),
        "change_sigma_deg": _plain(period.get("remount_change_sigma_deg")),
        "change_x_deg": _plain(period.get("remount_change_x_deg")),
        "change_y_deg": _plain(period.get("remount_change_y_deg")),
        "change_z_deg": _plain(period.get("remount_change_z_deg")),
        "p_value": _plain(period.get("remount_p_value")),
    }


def _plain(value: Any) -> Any:
    """None for a missing number (a struct field in Parquet is null, not NaN), else the value."""
    if value is None or value is pd.NA or value is pd.NaT:
        return None
    if isinstance(value, float | np.floating) and not np.isfinite(value):
        return None
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return value
