"""From log files to a calibration: read → stops → headings → fit. The CLI and the fleet runner share it."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from mountcal.calibrate import Options, calibrate
from mountcal.io.logs import LogOptions, read_log
from mountcal.result import Calibration
from mountcal.samples import Samples
from mountcal.stops import StopDetection, StopTableFromLog, read_protocol, tabulate
from mountcal.stoptable import StopTable, stop_table_from_frame


@dataclass(frozen=True)
class LogJob:
    """Everything needed to calibrate one log (one file or several splits)."""

    paths: tuple[str, ...]
    log: LogOptions = field(default_factory=LogOptions)
    detection: StopDetection = field(default_factory=StopDetection)
    protocol: str | None = None
    uphill_azimuth_deg: float | None = None
    options: Options = field(default_factory=Options)


@dataclass(frozen=True)
class LogCalibration:
    """A log's calibration with what led to it."""

    calibration: Calibration
    stops: StopTableFromLog
    table: StopTable
    samples: Samples


def stops_of_log(job: LogJob) -> tuple[Samples, StopTableFromLog]:
    """Read the log and tabulate its stops with their headings."""
    samples = read_log(list(job.paths), job.log)
    protocol = read_protocol(job.protocol) if job.protocol else None
    return samples, tabulate(samples, job.detection, protocol, job.uphill_azimuth_deg)


def calibrate_log(job: LogJob) -> LogCalibration:
    """Calibrate one log from its parked stops."""
    samples, found = stops_of_log(job)
    source = " + ".join(str(Path(p)) for p in job.paths)
    table = stop_table_from_frame(found.frame, headings=found.headings, source=source)  # type: ignore[arg-type]
    return LogCalibration(calibrate(table, job.options), found, table, samples)


def describe(samples: Samples, found: StopTableFromLog, n_files: int) -> Sequence[str]:
    """Lines for the user: what was read, dropped and found."""
    dropped = ", ".join(f"{k}: {v}" for k, v in samples.dropped.items())
    return [
        f"read {len(samples)} samples from {n_files} file(s)" + (f"; dropped {dropped}" if dropped else ""),
        f"found {len(found.frame)} stops; headings: {found.heading_source}"
        + (f"; {found.unmatched_protocol_rows} protocol rows without a stop" if found.unmatched_protocol_rows else ""),
        *found.notes,
    ]
