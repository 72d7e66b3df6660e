"""The fleet's tables: per vehicle its logs, mountings (consensus segments), remounts and the logs that
disagree (:func:`analyse_fleet`), and one row per vehicle (:func:`vehicle_table`); the statistics are
:mod:`mountcal.fleet.agreement`'s."""

from __future__ import annotations

from collections import Counter
from dataclasses import replace
from functools import cached_property
from typing import Any

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from mountcal.core.angles import YAW_REASON, Angles
from mountcal.core.conventions import FloatArray, levelled
from mountcal.core.pvalues import chi2_sf
from mountcal.fleet.agreement import ALPHA, Segment, analyse_vehicle, angles_with_sigma, information, tangent_residuals
from mountcal.fleet.layout import natural_key

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
    labels, logs = logs.index, logs.reset_index(drop=True)  # a copy, by positions; the labels go back at the end
    out = _PerLog(len(logs), logs["flags"])
    cells = _LogCells(logs)
    rows: list[dict[str, Any]] = []
    # one grouping, not a scan of the whole table per vehicle: a fleet of 10⁴ vehicles × 10² logs
    groups = logs.groupby("vehicle_id", sort=False).indices
    for vehicle in sorted(groups, key=natural_key):
        rows += _vehicle_rows(cells, groups[vehicle], vehicle, out, alpha, floor_deg)
    out.fill(logs)
    logs.index = labels
    return logs, pd.DataFrame(rows)


class _PerLog:
    """The per-log columns analyse_fleet fills, as arrays written by position and set once."""

    def __init__(self, n: int, flags: pd.Series) -> None:
        self.flags = [list(f) if isinstance(f, list | tuple | np.ndarray) else [] for f in flags]
        self.segment = np.full(n, -1)
        self.in_consensus = np.full(n, -1, dtype=np.int8)  # -1: not in any consensus (no usable result)
        self.chi2 = np.full(n, np.nan)
        self.dof = np.zeros(n, dtype=int)  # 0: no degrees of freedom (alone in its period)
        self.p_value = np.full(n, np.nan)

    def fill(self, logs: pd.DataFrame) -> None:
        logs["flags"] = self.flags
        logs["segment"] = pd.arrays.IntegerArray(self.segment, self.segment < 0)
        logs["in_consensus"] = pd.arrays.BooleanArray(self.in_consensus == 1, self.in_consensus < 0)
        logs["consensus_chi2"] = self.chi2
        logs["consensus_dof"] = pd.arrays.IntegerArray(self.dof, self.dof == 0)
        logs["consensus_p_value"] = self.p_value


class _LogCells:
    """The per-log values the analysis and the vehicle table read, taken out of the table once as
    arrays and lists (by position), each when first read: per-vehicle DataFrame slices and row
    iteration cost more than the statistics."""

    def __init__(self, logs: pd.DataFrame) -> None:
        self.logs = logs
        self.ok = (logs["status"] == "ok").to_numpy(dtype=bool)
        self.failed = ~self.ok

    @cached_property
    def usable(self) -> np.ndarray:
        """Calibrated with an uncertainty."""
        needed = self.logs[["quat_w", "rot_sigma_x_deg", "rot_sigma_y_deg"]].to_numpy(dtype=float)
        usable: np.ndarray = self.ok & np.isfinite(needed).all(axis=1)
        return usable

    @cached_property
    def start_known(self) -> np.ndarray:
        known: np.ndarray = self.logs["start_time"].notna().to_numpy(dtype=bool)
        return known

    @cached_property
    def start(self) -> list[Any]:
        return list(self.logs["start_time"].tolist())  # the scalars .iloc gives: Timestamp / NaT

    @cached_property
    def log(self) -> list[Any]:
        return list(self.logs["log"].tolist())

    @cached_property
    def quat(self) -> FloatArray:
        quat: FloatArray = self.logs[["quat_x", "quat_y", "quat_z", "quat_w"]].to_numpy(dtype=float)
        return quat

    @cached_property
    def sigma(self) -> FloatArray:
        sigma: FloatArray = self.logs[["rot_sigma_x_deg", "rot_sigma_y_deg", "rot_sigma_z_deg"]].to_numpy(dtype=float)
        return sigma

    @cached_property
    def sys(self) -> FloatArray | None:
        """The sensor's systematic σ per log, where the table has it."""
        columns = [f"rot_sys_sigma_{a}_deg" for a in "xyz"]
        sys: FloatArray | None = self.logs[columns].to_numpy(float) if columns[0] in self.logs else None
        return sys

    @cached_property
    def yaw_reason(self) -> np.ndarray:
        reasons: np.ndarray = self.logs[YAW_REASON].to_numpy(dtype=object)
        return reasons

    @cached_property
    def segment(self) -> FloatArray:  # the analysis's columns, read by the vehicle table
        segment: FloatArray = self.logs["segment"].to_numpy(dtype=float, na_value=np.nan)
        return segment

    @cached_property
    def in_consensus(self) -> np.ndarray:
        used: np.ndarray = self.logs["in_consensus"].fillna(False).astype(bool).to_numpy(dtype=bool)
        return used

    @cached_property
    def doubtful(self) -> np.ndarray:
        """Flagged not confident (a missing flag or column is not doubt)."""
        logs = self.logs
        sure = logs["confident"] if "confident" in logs.columns else pd.Series(True, index=logs.index)
        return np.array([not pd.isna(c) and not bool(c) for c in sure], dtype=bool)

    def in_period(self, mine: np.ndarray, segment: Any) -> np.ndarray:
        """Those of ``mine`` in this mounting period (none for a missing segment, as NA == x is)."""
        return mine[self.segment[mine] == segment] if not pd.isna(segment) else mine[:0]

    def starts(self, mine: np.ndarray) -> list[Any]:
        """Start times of the successful logs of ``mine`` that have one."""
        return [self.start[i] for i in mine[(self.ok & self.start_known)[mine]]]


def _vehicle_rows(
    cells: _LogCells, mine: np.ndarray, vehicle: str, out: _PerLog, alpha: float, floor_deg: float
) -> list[dict[str, Any]]:
    """One vehicle's mounting periods (``mine``: its logs' positions); its logs' columns written into ``out``."""
    ok = mine[cells.ok[mine]]
    usable = ok[cells.usable[ok]]
    for idx in ok[~cells.usable[ok]]:
        out.flags[idx].append("no_uncertainty")
    n_failed = int(cells.failed[mine].sum())
    base = {"vehicle_id": vehicle, "n_failed_vehicle": n_failed}
    if usable.size == 0:
        reason = f"all {len(mine)} logs failed" if ok.size == 0 else "no successful log carries an uncertainty"
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
    order = "start_time" if cells.start_known[usable].all() else "log name"
    if order == "start_time":
        keys: list[Any] = [(cells.start[i], natural_key(cells.log[i])) for i in usable]
    else:  # the same order as keying every log with one and the same time
        keys = [natural_key(cells.log[i]) for i in usable]
    usable = usable[sorted(range(len(usable)), key=keys.__getitem__)]
    rot = Rotation.from_quat(cells.quat[usable])
    info = information(cells.sigma[usable], floor_deg)
    segments, _ = analyse_vehicle(rot, info, alpha)
    rows = []
    for s, seg in enumerate(segments):
        at = usable[seg.start : seg.stop]
        p = np.where(seg.log_dof > 0, chi2_sf(np.nan_to_num(seg.log_chi2), np.maximum(seg.log_dof, 1)), np.nan)
        disagree = (p < alpha) | ~seg.used
        out.segment[at] = s
        out.in_consensus[at] = seg.used
        out.chi2[at] = seg.log_chi2
        out.dof[at] = seg.log_dof
        out.p_value[at] = p
        for j, idx in enumerate(at):
            out.flags[idx] += (["disagrees_with_consensus"] if disagree[j] else []) + (
                ["remount"] if j == 0 and seg.change is not None else []
            )
        rows.append({**base, **_segment_row(seg, s, len(segments), cells, at, disagree, order)})
        if seg.change is not None:
            rows[-1].update(_change_row(segments[s - 1], seg))
    return rows


def _segment_row(
    seg: Segment, s: int, n_segments: int, cells: _LogCells, at: np.ndarray, disagree: np.ndarray, order: str
) -> dict[str, Any]:
    cons = seg.consensus
    if cells.sys is not None:  # the sensor's systematic part, common to its logs: added once
        cols = cells.sys[at].T
        sys = np.array([np.median(c[np.isfinite(c)]) if np.isfinite(c).any() else 0.0 for c in cols])
        cons = replace(cons, cov_rad2=cons.cov_rad2 + np.diag(np.radians(sys) ** 2))
    angles, sigma = angles_with_sigma(cons)
    # Without yaw the consensus stores the levelling rotation: its yaw was arbitrary, never invented.
    quat = (cons.rot_vs if cons.observed[2] else levelled(cons.rot_vs)).as_quat()
    rot_sigma = np.degrees(np.sqrt(np.clip(np.diagonal(cons.cov_rad2), 0.0, None)))
    yaw_reason = None
    if not cons.observed[2]:
        reasons = [r for r in cells.yaw_reason[at] if not pd.isna(r)]
        common = _most_common(reasons) if reasons else "no log determined yaw"
        yaw_reason = f"no log of this mounting period determined yaw (e.g. {common})"
    yaw = angles[2] if cons.observed[2] else None
    consensus = Angles(angles[0], sigma[0], angles[1], sigma[1], yaw, sigma[2], yaw_reason, None, None)
    return {
        "segment": s,
        "n_segments": n_segments,
        "latest": s == n_segments - 1,
        "status": "ok",
        "reason": None,
        "order": order,
        "n_logs": len(at),
        "n_used": int(seg.used.sum()),
        "n_disagreeing": int(disagree.sum()),
        "disagreeing_logs": [str(cells.log[i]) for i in at[disagree]],
        "first_log": str(cells.log[at[0]]),
        "last_log": str(cells.log[at[-1]]),
        "first_start_time": cells.start[at[0]],
        "last_start_time": cells.start[at[-1]],
        **consensus.columns(slope=False),  # the table's angle columns, spelled by the type
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
        "remount_log": str(cells.log[at[0]]) if seg.change is not None else None,
    }


def _most_common(values: list[Any]) -> Any:
    """The most frequent value, the smallest of a tie (what ``Series.mode().iloc[0]`` gives)."""
    counts = Counter(values)
    top = max(counts.values())
    return min(v for v, c in counts.items() if c == top)


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
    *Angles.column_names(slope=False, reason=False),
    "sigma_scale",
)
LATEST_KEYS = (
    *Angles.column_names(slope=False),
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
    by_vehicle = logs.groupby("vehicle_id", sort=False).indices  # one grouping, not a scan per vehicle
    table, mine_logs = _Cells(mountings), _LogCells(logs)
    segment = mountings["segment"].to_numpy(dtype=float, na_value=np.nan)
    remount = mountings["remount"].fillna(False).astype(bool).to_numpy(dtype=bool)
    no_logs = np.zeros(0, dtype=np.intp)
    for vehicle, at in mountings.groupby("vehicle_id", sort=False).indices.items():
        at = at[np.argsort(segment[at], kind="stable")]  # by segment, missing last (as sort_values)
        periods = [_Row(table, i) for i in at]
        mine = by_vehicle.get(vehicle, no_logs)
        latest = periods[-1]
        ok = latest["status"] == "ok"
        period = mine_logs.in_period(mine, latest["segment"]) if ok else no_logs
        confident, note = _confidence(latest, mine_logs, period) if ok else (False, None)
        starts = mine_logs.starts(mine)
        rows.append(
            {
                "vehicle_id": vehicle,
                "status": latest["status"],
                "reason": latest.get("reason"),
                "order": latest.get("order") if ok else None,
                "n_logs": int(mine_logs.ok[mine].sum()),
                "n_failed": int(mine_logs.failed[mine].sum()),
                "n_mountings": len(periods) if ok else 0,
                "first_start_time": min(starts) if starts else None,
                "last_start_time": max(starts) if starts else None,
                **({k: _plain(latest.get(k)) for k in LATEST_KEYS} if ok else {"disagreeing_logs": []}),
                "since_log": latest.get("first_log") if ok else None,
                "since_time": latest.get("first_start_time") if ok else None,
                "latest_confident": confident,
                "confidence_note": note if ok else latest.get("reason"),
                "n_remounts": int(remount[at].sum()),
                "remounts": [_remount(p) for p in periods if bool(p.get("remount"))],
                "mountings": [{k: _plain(p.get(k)) for k in MOUNTING_KEYS} for p in periods] if ok else [],
            }
        )
    return pd.DataFrame(rows)


class _Cells:
    """A table's columns as arrays whose items are the scalars a row (``frame.iloc[i]``) holds:
    reading cells from them costs a fraction of building a row Series per period."""

    def __init__(self, frame: pd.DataFrame) -> None:
        self.columns: dict[Any, Any] = {}
        for name in frame.columns:
            values = frame[name].array
            # numpy columns: their ndarray (numpy scalars, as a row has them); others (str, Int64,
            # datetimes) their extension array, which gives NA / Timestamp as a row does
            self.columns[name] = values.to_numpy() if isinstance(values, pd.arrays.NumpyExtensionArray) else values


class _Row:
    """One row of a :class:`_Cells` table, read like a row Series (``row[k]``, ``row.get(k)``)."""

    __slots__ = ("cells", "i")

    def __init__(self, cells: _Cells, i: int) -> None:
        self.cells, self.i = cells, i

    def __getitem__(self, key: str) -> Any:
        return self.cells.columns[key][self.i]

    def get(self, key: str) -> Any:
        column = self.cells.columns.get(key)
        return None if column is None else column[self.i]


def _confidence(latest: _Row, logs: _LogCells, period: np.ndarray) -> tuple[bool, str | None]:
    """Whether the current mounting can be trusted as stated, and if not why (for fleet people);
    ``period``: the positions in ``logs`` of its mounting period's logs."""
    reasons = []
    used = period[logs.in_consensus[period]]
    doubtful = int(logs.doubtful[used].sum())
    if len(used) and doubtful == len(used):
        reasons.append(f"its {doubtful} log(s) are not confident (flag not_confident)")
    scale = latest.get("sigma_scale")
    if scale is not None and np.isfinite(scale) and scale > 1.0:
        reasons.append(
            f"its logs scatter beyond their σ (σ scaled by {scale:.2g}: an effect the model lacks, or a loose mount)"
        )
    return not reasons, "; ".join(reasons) or None


def _remount(period: _Row) -> dict[str, Any]:
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
