"""Results that survive a kill: content hashes, one atomic part file per finished log, atomic tables.

A log's result is keyed by the hash of its files' bytes (XXH3-128) and of every option that changes
the answer (SHA-256 of them all, :func:`job_hash`), so a re-run skips what is done however the
files were renamed or moved.
Each finished log is written to ``<output>.parts/<hash>.json`` atomically (temporary file, then
rename): a kill at any moment leaves whole part files only, and a re-run reads them back. The final
tables are consolidated from the parts and written atomically too.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Mapping
from dataclasses import asdict
from pathlib import Path
from typing import Any

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import xxhash

from mountcal.core.angles import YAW_REASON, Angles
from mountcal.core.atomic import atomic_path
from mountcal.core.errors import InputError
from mountcal.core.paths import special_kind
from mountcal.core.version import software_version  # part of every key: another version may answer differently
from mountcal.fleet.inputs import FleetJob
from mountcal.io.frame import FLEET_MARK

PART_FORMAT = "mountcal.fleet.part"
PART_VERSION = 2  # 2: a log without yaw stores the levelling rotation (1 stored an invented yaw)
TABLE_MARK = FLEET_MARK  # Parquet metadata key of the tables written here (io.frame knows it too)


HASH_BLOCK = 1 << 18  # bytes read at a time by file_digest: within the core's L2 cache
DIGEST = "xxh3-128"  # named in every digest: a key made by another hash can never match


def file_digest(path: str | Path, where: str | None = None) -> str:
    """XXH3-128 of a file's bytes, as ``xxh3-128:<hex>``, read in blocks (bounded memory; 20 % less CPU
    than through a memory map here, whose page faults cost more than the copies).

    The key only has to tell logs apart, and the command hashes every local log of a fleet while the
    workers calibrate: XXH3 costs 0.02-0.03 s of CPU per GB here against 0.16-0.18 s for BLAKE3 (and
    about 0.9 s for SHA-256), leaving the ~0.1 s per GB of reading the file. 128 bits make an accidental
    collision negligible (about 10^-27 among a million logs); a deliberate one is possible, as with any
    non-cryptographic hash, but only someone who can put logs into the fleet could use it, and they
    could as well put in a wrong log.

    Raises
    ------
    InputError
        The file cannot be read; ``where`` names the setting that points at it.
    """
    if Path(path).is_dir():  # a log that is a folder (a Sensor Logger recording, a ROS 2 bag, a comma2k19 segment)
        return _folder_digest(Path(path), where)
    kind = special_kind(path)
    if kind is not None:  # a FIFO or a device would block the hashing, or never end
        raise InputError(
            where or str(path),
            "a regular file",
            kind if where else f"{kind} ({path})",
            "Point the manifest or option at the file itself; the other logs are calibrated regardless.",
        )
    try:
        digest = xxhash.xxh3_128()
        block = bytearray(HASH_BLOCK)
        view = memoryview(block)
        with open(path, "rb", buffering=0) as f:
            while size := f.readinto(block):
                digest.update(view[:size])
    except OSError as err:
        raise InputError(
            where or str(path),
            "a readable file",
            f"{err.strerror or err or type(err).__name__}" + ("" if where else f" ({path})"),
            "Check the path; the other logs are calibrated regardless.",
        ) from err
    return f"{DIGEST}:{digest.hexdigest()}"


def _folder_digest(folder: Path, where: str | None) -> str:
    """XXH3-128 of a folder's files: each one's path inside it and its digest, in sorted order (hidden files and
    folders, which no reader reads, left out)."""
    digest = xxhash.xxh3_128()
    for root, dirs, files in os.walk(folder):
        dirs[:] = sorted(d for d in dirs if not d.startswith("."))
        for name in sorted(f for f in files if not f.startswith(".")):
            file = Path(root) / name
            inner = file.relative_to(folder).as_posix()
            digest.update(f"{inner}\0{file_digest(file, where and f'{where}: {inner}')}\0".encode())
    return f"{DIGEST}:{digest.hexdigest()}"


def job_hash(job: FleetJob) -> str:
    """The key of a log's result: its files' bytes plus every setting that changes the answer.

    Paths and the vehicle id are not part of it (a renamed or moved log is the same log); the file
    suffixes (they choose the reader), the contents of the DBC, mapping and protocol sheet are, as
    is the mountcal version. An object in storage counts by its listed stamp (ETag, size, time), not
    its bytes (a prefix that is one log: its objects' paths and stamps): a resumed run reads no object twice.
    """
    lj = job.job
    stamps = job.stamps or (None,) * len(lj.paths)
    log = asdict(lj.log)
    for key in ("dbc", "mapping"):
        if log[key] is not None:
            log[key] = file_digest(log[key], where=f"{job.log}: {key} {log[key]}")
    spec = {
        "key": PART_FORMAT,
        "version": PART_VERSION,
        "mountcal": software_version(),
        "files": [  # the suffix chooses the reader
            (Path(p).suffix.lower(), stamp or file_digest(p, where=shown))
            for p, shown, stamp in zip(lj.paths, job.shown or lj.paths, stamps, strict=True)
        ],
        "log": log,
        "protocol": None if lj.protocol is None else file_digest(lj.protocol, where=f"{job.log}: protocol sheet"),
        "detection": asdict(lj.detection),
        "uphill_azimuth_deg": lj.uphill_azimuth_deg,
        "options": asdict(lj.options),
        "use": lj.use,
        "driving": None if lj.driving is None else asdict(lj.driving),
        "headings": job.headings,
    }
    return hashlib.sha256(json.dumps(spec, sort_keys=True, default=str).encode()).hexdigest()


class PartStore:
    """The folder of finished logs' results: ``<hash>.json``, each written atomically."""

    def __init__(self, folder: str | Path) -> None:
        self.folder = Path(folder)

    def path(self, key: str) -> Path:
        return self.folder / f"{key}.json"

    def remove_temporaries(self) -> int:
        """Delete temporary files a killed run left behind; returns how many."""
        if not self.folder.is_dir():
            return 0
        stale = list(self.folder.glob(".*.part"))
        for tmp in stale:
            tmp.unlink(missing_ok=True)
        return len(stale)

    def load(self) -> tuple[dict[str, dict[str, Any]], int]:
        """The stored results by key, and the number of unreadable part files (they are redone)."""
        records: dict[str, dict[str, Any]] = {}
        bad = 0
        if not self.folder.is_dir():
            return records, bad
        for file in self.folder.glob("*.json"):
            try:
                doc = json.loads(file.read_text(encoding="utf-8"))
                ok = (
                    doc.get("format") == PART_FORMAT
                    and doc.get("format_version") == PART_VERSION
                    and doc.get("key") == file.stem
                    and isinstance(doc.get("record"), dict)
                )
            except (OSError, ValueError, AttributeError):
                ok = False
            if ok:
                records[file.stem] = doc["record"]
            else:
                bad += 1
        return records, bad

    def save(self, key: str, record: dict[str, Any]) -> None:
        """Write one result atomically."""
        doc = {"format": PART_FORMAT, "format_version": PART_VERSION, "key": key, "record": record}
        text = json.dumps(doc, allow_nan=False, default=_plain)
        # not synced: after a power cut a lost or empty part is only a log recalculated (load()
        # counts it unreadable), and a sync per log would stall the run
        with atomic_path(self.path(key), durable=False) as tmp:
            tmp.write_text(text, encoding="utf-8")


def _plain(value: object) -> object:
    if hasattr(value, "tolist"):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def write_table(
    frame: pd.DataFrame, schema: pa.Schema, path: str | Path, metadata: Mapping[str, str] | None = None
) -> None:
    """Write a DataFrame as Parquet with an explicit schema, atomically; ``metadata`` is added to the file's.

    The schema keeps each column's type when every value is null (all logs failed, no yaw).
    """
    table = pa.Table.from_pandas(frame[schema.names], schema=schema, preserve_index=False)
    table = table.replace_schema_metadata(
        {**(table.schema.metadata or {}), **(metadata or {}), TABLE_MARK: schema.metadata[TABLE_MARK]}
    )
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp)


def check_overwritable(path: str | Path) -> None:
    """Refuse to replace an existing file that is not a table this module wrote (a log, say).

    Raises
    ------
    InputError
    """
    path = Path(path)
    if not path.exists():
        return
    try:
        mark = (pq.read_schema(path).metadata or {}).get(TABLE_MARK)
    except Exception:  # not Parquet at all
        mark = None
    if mark is None:
        raise InputError(
            str(path),
            "a new output path, or a table an earlier `mountcal fleet` run wrote",
            "an existing file that mountcal did not write",
            "Choose another -o path; mountcal never overwrites its input.",
        )


# --- the tables' columns: name, Arrow type, meaning (docs/fleet.md lists the same) ----------------

_F, _I, _S, _B = pa.float64(), pa.int64(), pa.string(), pa.bool_()
_T = pa.timestamp("us", tz="UTC")
_L = pa.list_(pa.string())


def _angle_columns(meanings: tuple[str, ...], slope: bool = True) -> tuple[tuple[str, pa.DataType, str], ...]:
    """The angle columns (:meth:`Angles.column_names`, the one spelling of them), each with its meaning."""
    names = Angles.column_names(slope=slope)
    assert len(meanings) == len(names)
    return tuple((n, _S if n == YAW_REASON else _F, m) for n, m in zip(names, meanings, strict=True))


LOG_COLUMNS: tuple[tuple[str, pa.DataType, str], ...] = (
    ("vehicle_id", _S, "vehicle (manifest, or the log's parent folder name)"),
    ("log", _S, "the log as found: a file, split files joined with ' + ', or a CANedge session folder"),
    ("session", _S, "the CANedge session (folder name); null in the other layouts"),
    ("n_splits", _I, "files joined into this log (a CANedge session's splits)"),
    ("split_gaps", _I, "gaps between consecutive splits: more than 1 s without a sample"),
    ("split_gap_s", _F, "the gaps' total duration (s)"),
    ("split_overlaps", _I, "splits starting before the previous one ends (the log then fails: not one recording)"),
    ("status", _S, "ok or failed"),
    ("start_time", _T, "start of the log (manifest, or the log's clock when it is Unix time)"),
    ("start_time_source", _S, "manifest, log clock, or null"),
    ("input_kind", _S, "log or stop table"),
    ("calibrated_from", _S, "stops, driving or stops + driving (logs); null for a stop table"),
    *_angle_columns(
        (
            "roll γ (deg)",
            "1σ of roll (deg)",
            "pitch θ (deg)",
            "1σ of pitch (deg)",
            "yaw φ (deg); null when not determined",
            "1σ of yaw (deg); null when not determined",
            "why yaw is not determined; null when it is",
            "slope α of the parking plane (deg)",
            "1σ of the slope (deg)",
        )
    ),
    ("rot_sigma_x_deg", _F, "1σ of the rotation about the vehicle x axis (deg; statistical part)"),
    ("rot_sigma_y_deg", _F, "1σ of the rotation about the vehicle y axis (deg; statistical part)"),
    ("rot_sigma_z_deg", _F, "1σ of the rotation about the vehicle z axis (deg; statistical part); null without yaw"),
    ("rot_sys_sigma_x_deg", _F, "systematic part (sensor spec or triad) of that σ about x (deg), common to the sensor"),
    ("rot_sys_sigma_y_deg", _F, ""),
    ("rot_sys_sigma_z_deg", _F, ""),
    ("quat_x", _F, "rot_vs as a quaternion (x, y, z, w)"),
    ("quat_y", _F, ""),
    ("quat_z", _F, ""),
    ("quat_w", _F, ""),
    ("method", _S, "full or paper"),
    ("model", _S, "fitted terms, e.g. rotation,slope,bias"),
    ("bias_x_mps2", _F, "fitted accelerometer bias, sensor x (m/s²); null when no bias was fitted"),
    ("bias_y_mps2", _F, ""),
    ("bias_z_mps2", _F, ""),
    ("bias_sigma_x_mps2", _F, "1σ of the bias (m/s²)"),
    ("bias_sigma_y_mps2", _F, ""),
    ("bias_sigma_z_mps2", _F, ""),
    ("residual_rms_mps2", _F, "RMS of the stop residuals (m/s²)"),
    ("chi2", _F, "χ² of the fit"),
    ("dof", _I, "its degrees of freedom"),
    ("fit_p_value", _F, "P(χ² ≥ chi2) when the stop covariances are known"),
    ("n_stops", _I, "stops used"),
    ("headings", _S, "uphill, relative or none"),
    ("heading_source", _S, "where the headings came from (logs)"),
    ("n_samples", _I, "samples read (logs)"),
    ("dropped", _S, "samples or frames the reader discarded, by reason"),
    ("confident", _B, "whether the calibration is confident (false: flag not_confident); null for a failed log"),
    ("flags", _L, "see docs/fleet.md"),
    ("notes", _S, "the calibration's notes, joined with ' | '"),
    ("error", _S, "why the log failed: the message (file, expected, found, what to do)"),
    ("error_type", _S, "the exception type of a failure (VersionMismatch: computed by another mountcal)"),
    ("segment", _I, "index of the vehicle's mounting period this log belongs to"),
    ("in_consensus", _B, "whether the log entered its segment's consensus"),
    ("consensus_chi2", _F, "χ² of this log against the consensus of the segment's other logs"),
    ("consensus_dof", _I, "its degrees of freedom (2 without yaw, 3 with)"),
    ("consensus_p_value", _F, "P(χ² ≥ consensus_chi2); below 0.001 the log disagrees"),
    ("content_hash", _S, "SHA-256 of the log's XXH3-128 content hash and the options (the resume key)"),
    ("mountcal_version", _S, "software that computed the row"),
    ("elapsed_s", _F, "wall time of the calibration on its worker (s)"),
)

MOUNTING_COLUMNS: tuple[tuple[str, pa.DataType, str], ...] = (  # FleetResult.mountings: per mounting period
    ("vehicle_id", _S, "vehicle"),
    ("segment", _I, "mounting period, 0 = the first; a new one starts at each remount"),
    ("n_segments", _I, "mounting periods of the vehicle"),
    ("latest", _B, "whether this is the vehicle's current mounting"),
    ("status", _S, "ok, or no calibration (no log of the vehicle succeeded)"),
    ("reason", _S, "why there is no calibration"),
    ("order", _S, "how the logs were put in time order: start_time or log name"),
    ("n_logs", _I, "successful logs in the segment"),
    ("n_used", _I, "of those, logs in the consensus"),
    ("n_disagreeing", _I, "logs that disagree with the consensus (χ² test at 0.1 %)"),
    ("disagreeing_logs", _L, "those logs"),
    ("n_failed_vehicle", _I, "failed logs of the whole vehicle"),
    ("first_log", _S, "first log of the segment"),
    ("last_log", _S, "last log of the segment"),
    ("first_start_time", _T, ""),
    ("last_start_time", _T, ""),
    *_angle_columns(
        (
            "consensus roll (deg)",
            "its 1σ (deg)",
            "consensus pitch (deg)",
            "its 1σ (deg)",
            "consensus yaw (deg); null when no log determined it",
            "its 1σ (deg)",
            "why yaw is not determined",
        ),
        slope=False,
    ),
    ("rot_sigma_x_deg", _F, "1σ of the consensus rotation about vehicle x (deg)"),
    ("rot_sigma_y_deg", _F, ""),
    ("rot_sigma_z_deg", _F, ""),
    ("quat_x", _F, "consensus rot_vs as a quaternion (x, y, z, w)"),
    ("quat_y", _F, ""),
    ("quat_z", _F, ""),
    ("quat_w", _F, ""),
    ("chi2", _F, "χ² of the used logs about the consensus"),
    ("dof", _I, "its degrees of freedom"),
    ("p_value", _F, "P(χ² ≥ chi2)"),
    ("sigma_scale", _F, "factor applied to the consensus σ: √(χ²/dof) when the logs scatter beyond their σ, else 1"),
    ("remount", _B, "a remount was detected at the start of this segment"),
    ("remount_log", _S, "the first log after the remount"),
    ("remount_change_deg", _F, "angle of the change of mounting (deg)"),
    ("remount_change_sigma_deg", _F, "its 1σ (deg)"),
    ("remount_change_x_deg", _F, "the change as a rotation about vehicle x (deg)"),
    ("remount_change_y_deg", _F, "… about vehicle y (deg)"),
    ("remount_change_z_deg", _F, "… about vehicle z (deg); null when yaw is not determined on both sides"),
    ("remount_statistic", _F, "χ² of the change against the two-segment consensus"),
    ("remount_dof", _I, "its degrees of freedom"),
    ("remount_p_value", _F, "Bonferroni-corrected p-value of the change point (flagged below 0.001)"),
)


_MOUNTING = pa.struct(
    [
        ("segment", _I),
        ("first_log", _S),
        ("last_log", _S),
        ("first_start_time", _T),
        ("last_start_time", _T),
        ("n_logs", _I),
        ("n_used", _I),
        *((name, _F) for name in Angles.column_names(slope=False, reason=False)),
        ("sigma_scale", _F),
    ]
)
_REMOUNT = pa.struct(
    [
        ("time", _T),
        ("log", _S),
        ("change_deg", _F),
        ("change_sigma_deg", _F),
        ("change_x_deg", _F),
        ("change_y_deg", _F),
        ("change_z_deg", _F),
        ("p_value", _F),
    ]
)

VEHICLE_COLUMNS: tuple[tuple[str, pa.DataType, str], ...] = (  # fleet_vehicles.parquet: one row per vehicle
    ("vehicle_id", _S, "vehicle"),
    ("status", _S, "ok, or no calibration (no log of the vehicle succeeded)"),
    ("reason", _S, "why there is no calibration"),
    ("order", _S, "how the logs were put in time order: start_time or log name"),
    ("n_logs", _I, "successful logs of the vehicle"),
    ("n_failed", _I, "failed logs of the vehicle"),
    ("n_mountings", _I, "mounting periods (1 + remounts)"),
    ("first_start_time", _T, "start of the vehicle's first successful log"),
    ("last_start_time", _T, "start of its last"),
    *_angle_columns(
        (
            "current mounting: consensus roll (deg)",
            "its 1σ (deg)",
            "current mounting: consensus pitch (deg)",
            "its 1σ (deg)",
            "current mounting: consensus yaw (deg); null when no log of the period determined it",
            "its 1σ (deg)",
            "why yaw is not determined",
        ),
        slope=False,
    ),
    ("rot_sigma_x_deg", _F, "1σ of the current mounting about vehicle x (deg)"),
    ("rot_sigma_y_deg", _F, ""),
    ("rot_sigma_z_deg", _F, ""),
    ("quat_x", _F, "current mounting, rot_vs as a quaternion (x, y, z, w)"),
    ("quat_y", _F, ""),
    ("quat_z", _F, ""),
    ("quat_w", _F, ""),
    ("n_used", _I, "logs in the current mounting's consensus"),
    ("n_disagreeing", _I, "logs of the current mounting that disagree with its consensus"),
    ("disagreeing_logs", _L, "those logs"),
    ("chi2", _F, "χ² of the used logs about the current consensus"),
    ("dof", _I, "its degrees of freedom"),
    ("p_value", _F, "P(χ² ≥ chi2)"),
    ("sigma_scale", _F, "factor applied to the current σ: √(χ²/dof) when the logs scatter beyond their σ, else 1"),
    ("since_log", _S, "first log of the current mounting"),
    ("since_time", _T, "its start"),
    ("latest_confident", _B, "whether the current mounting is confident (see confidence_note)"),
    ("confidence_note", _S, "why it is not: its logs are not confident, or they scatter beyond their σ"),
    ("n_remounts", _I, "remounts found"),
    ("remounts", pa.list_(_REMOUNT), "each remount: time and log where the new mounting starts, change ± σ, p"),
    ("mountings", pa.list_(_MOUNTING), "the mounting over time: each period's extent and angles ± σ"),
)


def schema(columns: tuple[tuple[str, pa.DataType, str], ...], kind: str) -> pa.Schema:
    """The Arrow schema of a table (``kind`` "logs" or "vehicles"), each column's meaning as metadata."""
    fields = [pa.field(n, t, metadata={"description": d} if d else None) for n, t, d in columns]
    return pa.schema(fields, metadata={TABLE_MARK: f"{kind} {PART_VERSION}"})
