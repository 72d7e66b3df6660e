"""A log's calibration from whatever it supports: parked stops, driving, or both.

:func:`calibrate_any` reads the log once, tries the parked stops (:mod:`mountcal.pipeline`'s
path: stops → headings → fit) and yaw from driving (:mod:`mountcal.estimate.driving`), and
returns the stops' result, the driving result, or the stops' result with the driving's yaw folded
in (:func:`mountcal.estimate.driving.combine`), saying which and why the others were not used.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Literal

import numpy as np

from mountcal.calibrate import calibrate
from mountcal.conventions import G_N, normal_gravity
from mountcal.errors import NotEnoughInformation
from mountcal.estimate.driving import (
    DrivingFit,
    DrivingOptions,
    combine,
    driving_calibration,
    estimate_driving,
    not_combined,
)
from mountcal.io.logs import read_log
from mountcal.io.timestamps import increasing_times
from mountcal.pipeline import LogJob
from mountcal.result import Calibration
from mountcal.samples import Samples
from mountcal.stops import StopTableFromLog, read_protocol, tabulate
from mountcal.stoptable import StopTable, stop_table_from_frame
from mountcal.version import software_version

Use = Literal["auto", "stops", "driving"]


@dataclass(frozen=True)
class LogResult:
    """A log's calibration, what it was made from, and what was left out and why.

    ``used`` is ``"stops"``, ``"driving"`` or ``"stops + driving"``; ``skipped`` maps a source that
    was not used to the reason.
    """

    calibration: Calibration
    samples: Samples
    used: str
    static: Calibration | None = None
    driving: DrivingFit | None = None
    stops: StopTableFromLog | None = None
    table: StopTable | None = None
    skipped: dict[str, str] = field(default_factory=dict)


def calibrate_any(job: LogJob, use: Use = "auto", driving: DrivingOptions | None = None) -> LogResult:
    """Calibrate one log from its parked stops, its driving, or both.

    Parameters
    ----------
    job : LogJob
        The log and the stop-table settings (as for :func:`mountcal.pipeline.calibrate_log`).
    use : {"auto", "stops", "driving"}
        ``"auto"`` uses whatever the log supports; the others insist on one source (and fail
        with the reason when the log does not support it).
    driving : DrivingOptions, optional
        Gates and settings of yaw from driving.

    Raises
    ------
    NotEnoughInformation
        When the log supports neither source (the message gives both reasons).
    """
    samples = read_log(list(job.paths), job.log)
    source = " + ".join(str(Path(p)) for p in job.paths)
    skipped: dict[str, str] = {}
    static = found = table = None
    if use in ("auto", "stops"):
        try:
            protocol = read_protocol(job.protocol) if job.protocol else None
            found = tabulate(samples, job.detection, protocol, job.uphill_azimuth_deg)
            table = stop_table_from_frame(found.frame, headings=found.headings, source=source)  # type: ignore[arg-type]
            static = calibrate(table, job.options)
        except NotEnoughInformation as err:
            if use == "stops":
                raise
            skipped["stops"] = str(err)
    fit = None
    if use in ("auto", "driving"):
        try:
            fit = estimate_driving(increasing_times(samples), driving, tilt_from=static)  # duplicate stamps merged
        except NotEnoughInformation as err:
            if use == "driving":
                raise
            if static is None:
                raise NotEnoughInformation(
                    f"{source}: the log supports neither a calibration from parked stops ({skipped.get('stops')}) "
                    f"nor one from driving ({err})"
                ) from err
            skipped["driving"] = str(err)
    if static is not None and fit is not None:
        cal = stops_with_drive(static, table, fit, samples, job, driving)
        if cal.fit.get("combination", {}).get("disagreement") is not None:
            skipped["combination"] = "the stops and the drive disagree beyond 3σ (see the notes)"
        return LogResult(cal, samples, str(cal.fit["calibrated_from"]), static, fit, found, table, skipped)
    if static is not None:
        return LogResult(static, samples, "stops", static, None, found, table, skipped)
    assert fit is not None
    g, g_source = _gravity(samples, job.options.gravity_mps2)
    cal = driving_calibration(fit, gravity_mps2=g, gravity_source=g_source, provenance=_provenance(job.paths))
    return LogResult(cal, increasing_times(samples), "driving", None, fit, None, None, skipped)  # counts merged stamps


def stops_with_drive(
    static: Calibration,
    table: StopTable | None,
    fit: DrivingFit,
    samples: Samples,
    job: LogJob,
    driving: DrivingOptions | None = None,
) -> Calibration:
    """The stops' calibration with the drive's yaw folded in, or — when they disagree — not combined.

    ``fit`` is the drive levelled with ``static``. On a disagreement beyond 3σ the result is not
    confident and carries the finding; it is the stops' result when their rotation puts the
    stops' specific force +g up, else (their mirror solution) the drive's own, levelled by its
    mean gravity: either way the result is on the physical branch.
    """
    cal = combine(static, fit)
    found = cal.fit.get("combination", {}).get("disagreement")
    if found is None or _up_is_up(static, table):
        return cal
    alone = estimate_driving(samples, driving)  # levelled by its own mean gravity: +g up by construction
    g, g_source = _gravity(samples, job.options.gravity_mps2)
    cal = not_combined(
        driving_calibration(alone, gravity_mps2=g, gravity_source=g_source, provenance=_provenance(job.paths)),
        fit,
        found,
    )
    return replace(
        cal,
        fit={
            **cal.fit,
            "calibrated_from": "driving (the stops disagree and put −g up)",
            "driving": alone.to_dict(),  # the fit used; the one levelled with the stops shows the disagreement
            "driving_levelled_with_stops": fit.to_dict(),
        },
    )


def describe_any(result: LogResult, n_files: int) -> Sequence[str]:
    """Lines for the user: what was read and dropped, which sources were used, and why not the others."""
    s = result.samples
    dropped = ", ".join(f"{k}: {v}" for k, v in s.dropped.items())
    lines = [f"read {len(s)} samples from {n_files} file(s)" + (f"; dropped {dropped}" if dropped else "")]
    if result.stops is not None:
        found = result.stops
        lines.append(
            f"found {len(found.frame)} stops; headings: {found.heading_source}"
            + (
                f"; {found.unmatched_protocol_rows} protocol rows without a stop"
                if found.unmatched_protocol_rows
                else ""
            )
        )
        lines += found.notes
    if result.driving is not None:
        d = result.driving
        offset = f"{d.time_offset_s:+.3f} s" + (
            f" ± {d.time_offset_sigma_s:.3f} s" if d.time_offset_sigma_s is not None else ""
        )
        lines.append(
            f"driving: {d.usable_s:.0f} s usable of {d.moving_s:.0f} s moving, in {d.n_segments} straight segments; "
            f"speed clock offset {offset} ({'found' if d.time_offset_searched else 'given'}); "
            f"straightness from the {d.straightness_source}"
        )
    lines.append(f"calibrated from: {result.used}")
    lines += [f"not used: {k} — {v}" for k, v in result.skipped.items()]
    return lines


def _up_is_up(cal: Calibration, table: StopTable | None) -> bool:
    """Whether the calibration rotates the parked stops' specific force to +g up (the physical branch)."""
    if table is None:
        return cal.slope_deg is None or cal.slope_deg < 90.0
    acc = table.acc_s - (cal.bias_mps2 if cal.bias_mps2 is not None else 0.0)
    return bool(np.median(cal.rot_vs.apply(acc)[:, 2]) > 0.0)


def _gravity(samples: Samples, given: float | None) -> tuple[float, str]:
    if given is not None:
        return float(given), "given"
    lat, alt = samples.channels.get("lat_deg"), samples.channels.get("alt_m")
    if lat is not None and lat.value.size and np.all(np.isfinite(lat.value)):
        lat_deg = float(np.mean(lat.value))
        alt_m = float(np.mean(alt.value)) if alt is not None and alt.value.size else 0.0
        return normal_gravity(lat_deg, alt_m), f"WGS 84 normal gravity at latitude {lat_deg:.4f}°, height {alt_m:.0f} m"
    return G_N, "assumed standard gravity 9.80665 m/s² (no position known); local gravity differs by up to ±0.27 %"


def _provenance(paths: Sequence[str]) -> dict[str, Any]:
    version = software_version()
    return {
        "input": " + ".join(str(Path(p)) for p in paths),
        "input_sha256": [_sha256(Path(p)) for p in paths],
        "software": f"mountcal {version}",
        "method": "driving",
        "model": ["rotation"],
        "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
    }


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()
