"""What a worker does with one log: calibrate it and return a plain record, never raise.

The record holds only plain types (it travels between processes and into JSON). A log that fails
is a record too, with the message of the :class:`~mountcal.core.errors.MountcalError` (file, expected,
found, what to do) or, for anything unexpected, the exception's type and text — in the user's
terms: the files as they named them (not the absolute paths or scratch copies the worker read) and,
for a command-line run, the options as flags. Workers need nothing but the installed package;
paths in the job are absolute, or URLs whose objects the worker fetches itself
(:func:`mountcal.fleet.storage.local_copies`; a prefix that is one log: :func:`~mountcal.fleet.storage.local_folder`).

The splits of one log are read one by one and joined in time order; the gaps between them (more
than :data:`GAP_S` without a sample) and their overlaps are counted in the record.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import time
from collections.abc import Iterator, Sequence
from dataclasses import replace
from datetime import UTC, datetime
from itertools import pairwise
from pathlib import Path
from typing import Any

import numpy as np

from mountcal.calibration.pipeline import calibrate_input
from mountcal.core import budget
from mountcal.core.angles import ANGLE_NAMES
from mountcal.core.conventions import GIMBAL_LOCK_PITCH_DEG
from mountcal.core.errors import MountcalError
from mountcal.core.findings import STRUCTURE_P
from mountcal.core.option_names import as_flags
from mountcal.core.result import Calibration, Systematic
from mountcal.core.version import software_version
from mountcal.estimate import effects as registry
from mountcal.fleet.inputs import COMPUTED_BY, FleetJob
from mountcal.fleet.storage import is_url, local_copies, local_folder
from mountcal.io.logs import join, read_file
from mountcal.io.samples import Samples
from mountcal.io.whole import is_cut

UNIX_TIME_S = (1.0e9, 4.1e9)  # a log clock in this range is Unix time (2001 … 2099)
GAP_S = 1.0  # more than this without a sample between two splits is a gap


def run_job(job: FleetJob) -> dict[str, Any]:
    """Calibrate one log and return its record (status ``ok`` or ``failed``); never raises."""
    started = time.perf_counter()
    record: dict[str, Any] = {
        "status": "failed",
        "session": job.session,
        "n_splits": len(job.job.paths),
        "split_gaps": 0,
        "split_gap_s": 0.0,
        "split_overlaps": 0,
    }
    local: Sequence[str] = job.job.paths
    try:
        # each log its own totals of the budget
        with as_flags() if job.flags else contextlib.nullcontext(), budget.scope(), _fetched(job) as local:
            record.update(_calibrate(replace(job, job=replace(job.job, paths=tuple(local))), record))
        record["status"] = "ok"
    except MountcalError as err:
        record.update(error=_in_user_terms(str(err), job, local), error_type=type(err).__name__)
    except Exception as err:  # a bug or a library failure on one log must not stop the batch
        kind = f"{type(err).__module__}.{type(err).__qualname__}"
        record.update(error=_in_user_terms(f"unexpected {kind}: {err}", job, local), error_type=kind)
    record["elapsed_s"] = time.perf_counter() - started
    record[COMPUTED_BY] = software_version()  # the command stores only what its own version computed
    return record


def run_batch(jobs: Sequence[FleetJob]) -> list[dict[str, Any]]:
    """:func:`run_job` of several logs, in order (one task of a Dask cluster), with a heap made for
    them (:func:`heap_for_logs`)."""
    with heap_for_logs():
        return [run_job(job) for job in jobs]


M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3  # glibc's mallopt parameters
HEAP_MMAP_THRESHOLD = 32 << 20  # arrays below this are recycled within the heap (glibc's largest)
DEFAULT_MMAP_THRESHOLD = 128 << 10  # glibc's default, restored after a batch


@contextlib.contextmanager
def heap_for_logs() -> Iterator[None]:
    """Let glibc recycle a log's arrays instead of mapping fresh pages for each (restored after).

    A Dask nanny starts its workers with ``MALLOC_TRIM_THRESHOLD_`` set (to hand memory back to the
    system), which also turns off glibc's adaptive mmap threshold: every array above 128 KiB is then
    mmap-ed and unmapped, and its pages faulted in again, for every log — measured 25–35 % more CPU
    per log than in a worker without it. Elsewhere (not glibc) this does nothing.
    """
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        yield
        return
    mallopt(M_MMAP_THRESHOLD, HEAP_MMAP_THRESHOLD)
    mallopt(M_TRIM_THRESHOLD, 2 * HEAP_MMAP_THRESHOLD)
    try:
        yield
    finally:
        mallopt(M_MMAP_THRESHOLD, _env_bytes("MALLOC_MMAP_THRESHOLD_", DEFAULT_MMAP_THRESHOLD))
        mallopt(M_TRIM_THRESHOLD, _env_bytes("MALLOC_TRIM_THRESHOLD_", DEFAULT_MMAP_THRESHOLD))
        with contextlib.suppress(AttributeError):
            ctypes.CDLL(None).malloc_trim(0)  # hand the batch's memory back, as the worker's setting wants


def _env_bytes(name: str, default: int) -> int:
    try:
        return int(os.environ.get(name, default))
    except ValueError:
        return default


@contextlib.contextmanager
def _fetched(job: FleetJob) -> Iterator[Sequence[str]]:
    """The job's files as local paths: objects in storage fetched to scratch files for the block (a log that
    is a prefix: its objects into one folder)."""
    paths = job.job.paths
    if job.folder_objects:
        with local_folder(paths[0], job.folder_objects, dict(job.storage)) as folder:
            yield (folder,)
        return
    if not any(is_url(p) for p in paths):
        yield paths
        return
    stamps = job.stamps or (None,) * len(paths)
    with local_copies(paths, dict(job.storage), stamps) as copies:
        yield copies


def _in_user_terms(message: str, job: FleetJob, local: Sequence[str]) -> str:
    """The message with the files named as the user sees them (longest paths first, so that a
    folder never replaces part of a file's path)."""
    shown = job.shown or job.job.paths
    pairs = [*zip(local, shown, strict=False), *zip(job.job.paths, shown, strict=False)]
    for path, name in sorted(set(pairs), key=lambda pair: -len(pair[0])):
        if path != name:
            message = message.replace(path, name)
    return message


def _read_splits(job: FleetJob, record: dict[str, Any]) -> Samples:
    """The log's files read one by one and joined in time order; gaps and overlaps counted in ``record``."""
    paths = [Path(p) for p in job.job.paths]
    parts = [read_file(p, job.job.log) for p in paths]  # each under the completeness policy
    if len(parts) == 1:
        return parts[0]
    spans = sorted((float(s.t_s[0]), float(s.t_s[-1])) for s in parts if len(s))
    steps = np.array([after[0] - before[1] for before, after in pairwise(spans)])
    record.update(
        split_gaps=int((steps > GAP_S).sum()),
        split_gap_s=float(steps[steps > GAP_S].sum()) if steps.size else 0.0,
        split_overlaps=int((steps < 0).sum()),
    )
    return join(parts)  # refuses overlapping splits: they are not one recording


def _calibrate(job: FleetJob, record: dict[str, Any]) -> dict[str, Any]:
    splits = record  # a log's split gaps are counted into the run's record as its files are read
    # what `mountcal calibrate` does with an input: a stop table fitted, or the log's stops, driving or both
    result = calibrate_input(  # the fleet's --uphill-azimuth-deg is for its logs: a stop table keeps its β
        job.job,
        headings=job.headings,
        read=lambda _: _read_splits(job, splits),
        table_azimuth=False,
        hash_files=False,  # its key is the command's digest of the files; a record keeps no provenance hashes
    )
    record = calibration_record(result.calibration)
    ends = result.calibration.provenance.incomplete_inputs
    if any(is_cut(e) for e in ends):
        record["flags"].append("input_incomplete")  # cut short, read in part (--allow-truncated)
    elif ends:
        record["flags"].append("input_end_unverified")  # an unfinalised MF4: a cut between records is invisible
    if result.log is None:
        table = result.table
        assert table is not None
        record.update(input_kind="stop table", n_stops=len(table), headings=table.headings)
        if table.t_s is not None and table.t_s.size:
            record["log_start_time"] = _unix_time(float(np.min(table.t_s)))
        return record
    done = result.log
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
        rot_sigma = [cal.angles.sigmas[a] for a in ANGLE_NAMES[:3]]
        flags.append("axis_sigma_from_angles")
    sys_sigma: list[float | None] = [None] * 3
    if cal.systematic is not None and rot_sigma[0] is not None:
        # the logs of one sensor share its systematic error: they are compared, and averaged, on the statistical
        # part; the vehicle's consensus adds the systematic part once (fleet.vehicles)
        rot_sigma = list(Systematic.rotation_of(cal.systematic.statistical))
        sys_sigma = list(Systematic.rotation_of(cal.systematic.systematic))
    if cal.yaw_deg is None:
        flags.append("yaw_not_determined")
        rot_sigma[2] = sys_sigma[2] = None
    if cal.slope_deg is None:
        flags.append("slope_not_determined")
    offset = registry.offset()
    if offset.name in cal.model:
        flags.append(f"{offset.name}_fitted")
    chi2, dof = cal.fit.chi2, cal.fit.dof
    p_fit = cal.fit.p_value  # None when the stop noise was estimated from the residuals
    if p_fit is not None and p_fit < STRUCTURE_P:
        flags.append("model_misfit")
    if not cal.confident:
        flags.append("not_confident")  # the flag users filter on; the bool column ``confident`` is what mountcal reads
    if abs(cal.pitch_deg) > GIMBAL_LOCK_PITCH_DEG:
        flags.append("near_gimbal_lock")
    fitted = registry.offset_of(cal)  # the fleet table's bias columns are the offset's (a published format)
    bias = [None] * 3 if fitted is None else list(fitted.value)
    bias_sigma = [None] * 3 if fitted is None else list(fitted.sigma)
    return {
        **cal.angles.columns(),  # the table's angle columns, spelled by the type
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
        "confident": bool(cal.confident),
        "flags": flags,
        "notes": " | ".join(cal.notes) or None,
    }
