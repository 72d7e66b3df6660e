"""What a worker does with one log: calibrate it and return a plain record, never raise.

The record holds only plain types (it travels between processes and into JSON). A log that fails
is a record too, with the message of the :class:`~mountcal.errors.MountcalError` (file, expected,
found, what to do) or, for anything unexpected, the exception's type and text. Workers need
nothing but the installed package; paths in the job are absolute.
"""

from __future__ import annotations

import time
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from mountcal.calibrate import calibrate
from mountcal.conventions import GIMBAL_LOCK_PITCH_DEG
from mountcal.errors import MountcalError
from mountcal.fleet.inputs import FleetJob
from mountcal.pipeline import calibrate_job, is_stop_table
from mountcal.result import STRUCTURE_P, Calibration
from mountcal.stoptable import read_stop_table

UNIX_TIME_S = (1.0e9, 4.1e9)  # a log clock in this range is Unix time (2001 … 2099)


def run_job(job: FleetJob) -> dict[str, Any]:
    """Calibrate one log and return its record (status ``ok`` or ``failed``); never raises."""
    started = time.perf_counter()
    record: dict[str, Any] = {"status": "failed"}
    try:
        record.update(_calibrate(job))
        record["status"] = "ok"
    except MountcalError as err:
        record.update(error=str(err), error_type=type(err).__name__)
    except Exception as err:  # a bug or a library failure on one log must not stop the batch
        kind = f"{type(err).__module__}.{type(err).__qualname__}"
        record.update(error=f"unexpected {kind}: {err}", error_type=kind)
    record["elapsed_s"] = time.perf_counter() - started
    return record


def _calibrate(job: FleetJob) -> dict[str, Any]:
    lj = job.job
    if len(lj.paths) == 1 and is_stop_table(Path(lj.paths[0]), lj.log.dbc is not None, lj.log.columns is not None):
        table = read_stop_table(lj.paths[0], headings=job.headings)
        cal = calibrate(table, lj.options)
        record = calibration_record(cal)
        record.update(input_kind="stop table", n_stops=len(table), headings=table.headings)
        if table.t_s is not None and table.t_s.size:
            record["log_start_time"] = _unix_time(float(np.min(table.t_s)))
        return record
    done = calibrate_job(lj)  # the pipeline of `mountcal calibrate LOG`: stops, driving, or both
    record = calibration_record(done.calibration)
    samples = done.samples
    record.update(
        input_kind="log",
        calibrated_from=done.used,
        n_stops=0 if done.table is None else len(done.table),
        headings=None if done.table is None else done.table.headings,
        heading_source=None if done.stops is None else done.stops.heading_source,
        n_samples=len(samples),
        dropped="; ".join(f"{k}: {v}" for k, v in samples.dropped.items()) or None,
        log_start_time=_unix_time(float(samples.t_s[0])) if len(samples) else None,
    )
    if samples.dropped:
        record["flags"].append("samples_dropped")
    if done.stops is not None and done.stops.unmatched_protocol_rows:
        record["flags"].append("protocol_rows_without_stop")
    return record


def _unix_time(t_s: float) -> str | None:
    if not UNIX_TIME_S[0] < t_s < UNIX_TIME_S[1]:
        return None
    return datetime.fromtimestamp(t_s, tz=UTC).isoformat()


def calibration_record(cal: Calibration) -> dict[str, Any]:
    """The per-log columns of a calibration (plain types; None where not determined)."""
    quat = cal.rot_vs.as_quat()
    rot_sigma = list(cal.rotation_sigma_deg)
    flags: list[str] = []
    if rot_sigma[0] is None or rot_sigma[1] is None:
        # the paper's method gives σ of the angles only; near level they are the σ about the axes
        rot_sigma = [cal.roll_sigma_deg, cal.pitch_sigma_deg, cal.yaw_sigma_deg]
        flags.append("axis_sigma_from_angles")
    sys_sigma: list[float | None] = [None] * 3
    if cal.systematic is not None and rot_sigma[0] is not None:
        # the logs of one sensor share its systematic error: they are compared, and averaged, on the statistical
        # part; the vehicle's consensus adds the systematic part once (fleet.vehicles)
        rot_sigma = [cal.systematic.statistical[f"rotation_{a}_deg"] for a in "xyz"]
        sys_sigma = [cal.systematic.systematic[f"rotation_{a}_deg"] for a in "xyz"]
    if cal.yaw_deg is None:
        flags.append("yaw_not_determined")
        rot_sigma[2] = sys_sigma[2] = None
    if cal.slope_deg is None:
        flags.append("slope_not_determined")
    if "bias" in cal.model:
        flags.append("bias_fitted")
    chi2, dof = cal.fit.chi2, cal.fit.dof
    p_fit = cal.fit.p_value  # None when the stop noise was estimated from the residuals
    if p_fit is not None and p_fit < STRUCTURE_P:
        flags.append("model_misfit")
    if not getattr(cal, "confident", True):
        flags.append("not_confident")
    if abs(cal.pitch_deg) > GIMBAL_LOCK_PITCH_DEG:
        flags.append("near_gimbal_lock")
    bias = [None] * 3 if cal.bias_mps2 is None else [float(v) for v in cal.bias_mps2]
    bias_sigma = [None] * 3 if cal.bias_sigma_mps2 is None else [float(v) for v in cal.bias_sigma_mps2]
    return {
        "roll_deg": cal.roll_deg,
        "roll_sigma_deg": cal.roll_sigma_deg,
        "pitch_deg": cal.pitch_deg,
        "pitch_sigma_deg": cal.pitch_sigma_deg,
        "yaw_deg": cal.yaw_deg,
        "yaw_sigma_deg": cal.yaw_sigma_deg,
        "yaw_reason": cal.yaw_reason,
        "slope_deg": cal.slope_deg,
        "slope_sigma_deg": cal.slope_sigma_deg,
        "rot_sigma_x_deg": rot_sigma[0],
        "rot_sigma_y_deg": rot_sigma[1],
        "rot_sigma_z_deg": rot_sigma[2],
        "rot_sys_sigma_x_deg": sys_sigma[0],
        "rot_sys_sigma_y_deg": sys_sigma[1],
        "rot_sys_sigma_z_deg": sys_sigma[2],
        "quat_x": float(quat[0]),
        "quat_y": float(quat[1]),
        "quat_z": float(quat[2]),
        "quat_w": float(quat[3]),
        "method": cal.method,
        "model": ",".join(cal.model),
        "bias_x_mps2": bias[0],
        "bias_y_mps2": bias[1],
        "bias_z_mps2": bias[2],
        "bias_sigma_x_mps2": bias_sigma[0],
        "bias_sigma_y_mps2": bias_sigma[1],
        "bias_sigma_z_mps2": bias_sigma[2],
        "residual_rms_mps2": cal.residual_rms_mps2,
        "chi2": None if chi2 is None else float(chi2),
        "dof": None if dof is None else int(dof),
        "fit_p_value": p_fit,
        "flags": flags,
        "notes": " | ".join(cal.notes) or None,
    }
