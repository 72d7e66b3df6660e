"""From log files to a calibration: the one pipeline of ``mountcal calibrate``, ``mountcal fleet`` and the API.

:func:`calibrate_log` reads the log once, tries its parked stops (stops → headings → fit,
:func:`mountcal.calibration.fit.calibrate`) and yaw from driving (:mod:`mountcal.estimate.driving`), and
returns the stops' result, the driving result, or the stops' result with the driving's yaw folded
in (:func:`mountcal.calibration.with_driving.combine`), saying which and why the others were not used.
"""

from __future__ import annotations

import hashlib
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from mountcal.calibration.fit import calibrate
from mountcal.calibration.job import LogJob as LogJob  # defined apart: the fleet command needs it, not the fit
from mountcal.calibration.job import not_from_driving
from mountcal.calibration.options import DEFAULT_USE, Options, Use
from mountcal.calibration.record import local_gravity
from mountcal.calibration.with_driving import combine, driving_calibration, not_combined
from mountcal.core.driving_document import Comparison, DrivingConsistency
from mountcal.core.errors import NotEnoughInformation
from mountcal.core.option_names import option
from mountcal.core.paths import special_kind
from mountcal.core.result import Calibration, Convention, Provenance
from mountcal.core.version import software_version
from mountcal.estimate import effects
from mountcal.estimate.driving import DrivingFit, estimate_driving
from mountcal.estimate.driving_options import DrivingOptions, horizontal_axes_sigma_deg
from mountcal.io.frame import with_frame_note
from mountcal.io.input_conventions import merged, parse_axes
from mountcal.io.kind import Declared, InputKind, kind_of_input
from mountcal.io.logs import read_log, stated
from mountcal.io.reader import LogOptions
from mountcal.io.samples import Samples, with_gravity
from mountcal.io.sensor_frame import sensor_frame_note
from mountcal.io.sensor_logger import other_sign
from mountcal.io.timestamps import increasing_times
from mountcal.io.whole import reading
from mountcal.loop import crosscheck, plausibility
from mountcal.loop.sign import turned_once
from mountcal.stops.detect import StopDetection
from mountcal.stops.headings import StopTableFromLog, near_miss_advice, read_protocol, tabulate
from mountcal.stops.table import Headings, StopTable, Unit, read_stop_table

if TYPE_CHECKING:  # the sheet a live session passes in hand; pandas is loaded by the readers anyway
    import pandas as pd


@dataclass(frozen=True)
class LogResult:
    """A log's calibration, what it was made from, and what was left out and why.

    ``used`` is ``"stops"``, ``"driving"`` or ``"stops + driving"``; ``skipped`` maps a source that
    was not used to the reason. ``stops`` is what stop detection found, also when no fit used it
    (``table``, the table the result was fitted to, is then None).
    """

    calibration: Calibration
    samples: Samples
    used: str
    static: Calibration | None = None
    driving: DrivingFit | None = None
    stops: StopTableFromLog | None = None
    table: StopTable | None = None
    skipped: dict[str, str] = field(default_factory=dict)


def calibrate_log(
    paths: str | Path | Sequence[str | Path],
    *,
    log: LogOptions | None = None,
    detection: StopDetection | None = None,
    protocol: str | Path | None = None,
    uphill_azimuth_deg: float | None = None,
    options: Options | None = None,
    use: Use = DEFAULT_USE,
    driving: DrivingOptions | None = None,
) -> LogResult:
    """Calibrate one log (a file, or the splits of one recording) from its parked stops, its driving, or both.

    This is what ``mountcal calibrate LOG`` and ``mountcal fleet`` do with each log.

    Parameters
    ----------
    paths : path or sequence of paths
        The log; splits of one recording are joined in the order given.
    log : LogOptions, optional
        How to read it (DBC, mapping, channel, topic).
    detection : StopDetection, optional
        Thresholds of stop detection.
    protocol : path, optional
        Protocol sheet (``t_start_s, t_end_s, beta_deg``) giving the stops' headings.
    uphill_azimuth_deg : float, optional
        Compass azimuth of the slope's uphill direction, with a heading signal in the log.
    options : Options, optional
        Method, model, gravity and yaw threshold of the fit.
    use : {"auto", "stops", "driving"}
        ``"auto"`` uses whatever the log supports; the others insist on one source.
    driving : DrivingOptions, optional
        Gates and settings of yaw from driving.

    Raises
    ------
    NotEnoughInformation
        When the log supports neither source (the message gives both reasons).
    """
    given = [paths] if isinstance(paths, str | Path) else list(paths)
    job = LogJob(
        paths=tuple(str(p) for p in given),
        log=log or LogOptions(),
        detection=detection or StopDetection(),
        protocol=None if protocol is None else str(protocol),
        uphill_azimuth_deg=uphill_azimuth_deg,
        options=options or Options(),
        use=use,
        driving=driving,
    )
    return calibrate_job(job)


@dataclass(frozen=True)
class InputResult:
    """The calibration of an input, what kind of input it was, and the stop table or log result behind it."""

    kind: InputKind
    calibration: Calibration
    table: StopTable | None  # the stop table fitted (None: calibrated from driving alone)
    log: LogResult | None  # how a log was used (None for a stop table)


def calibrate_input(
    job: LogJob,
    *,
    unit: Unit | None = None,
    headings: Headings | None = None,
    declared: Declared = "auto",
    read: Callable[[LogJob], Samples] | None = None,
    table_azimuth: bool = True,
    hash_files: bool = True,
) -> InputResult:
    """Calibrate whatever the job's paths are: a stop table fitted as it is, or a log
    (:func:`calibrate_job`), as :func:`mountcal.io.kind.kind_of_input` decides; the result's provenance
    says which kind it was taken for and why. ``unit`` and ``headings`` are a stop table's (a log
    finds its own; the job's axis map, heading unit and uphill azimuth apply to both); ``declared`` is
    what the user said the input is (``--input-kind``); ``read`` reads
    a log's files (default :func:`~mountcal.io.logs.read_log`; the fleet reads splits itself);
    ``table_azimuth``: a stop table's β come from its compass column ``heading_deg`` and the job's
    uphill azimuth (off for a fleet, whose azimuth is for its logs' heading channels);
    ``hash_files``: a log's files' SHA-256 in its provenance (off for a fleet, which keys its
    results by its own digest of the files and keeps no provenance hashes).

    What ``mountcal calibrate`` and every fleet worker do with an input.
    """
    kind = kind_of_input(job.paths, job.log, declared)
    table: StopTable | None
    if kind.stop_table:
        with reading(job.log.allow_truncated):  # a cut CSV: refused, or its whole rows read and said
            table = read_stop_table(
                job.paths[0],
                unit=unit,
                headings=headings,
                heading_unit=job.log.heading_unit,
                axes=None if job.log.axes is None else parse_axes(job.log.axes, option("axes")),
                uphill_azimuth_deg=job.uphill_azimuth_deg if table_azimuth else None,
            )
        cal, done = calibrate(table, job.options), None
        cal = replace(cal, notes=(*cal.notes, *table.notes))  # what the table held that was not read
    else:
        done = calibrate_job(job, None if read is None else read(job), hash_files=hash_files)
        cal, table = done.calibration, done.table
    cal = replace(cal, provenance=replace(cal.provenance, input_kind=kind.sentence))
    return InputResult(kind, cal, table, done)


def calibrate_job(job: LogJob, samples: Samples | None = None, *, hash_files: bool = True) -> LogResult:
    """:func:`calibrate_log` of a prepared job (the fleet's and the command line's form); ``samples``
    are the job's files already read (the fleet reads a log's splits itself to count their gaps).

    Besides the fit: each file's SHA-256 (hashed beside the reading; not with ``hash_files=False``),
    the log's conventions, the cross-checks between its cues (:mod:`mountcal.loop.crosscheck`: turns,
    the stops' yaw against the drive's) and the answer's plausibility (:mod:`mountcal.loop.plausibility`)
    go into the result.
    """
    stop = threading.Event()  # a failed read ends the hashing too
    with ThreadPoolExecutor(max_workers=1) as pool:  # no thread starts until something is submitted
        hashes = pool.submit(lambda: tuple(_sha256(Path(p), stop) for p in job.paths)) if hash_files else None
        try:
            done, cal = _signed(job, samples, None)
            hashed = () if hashes is None else hashes.result()
            return replace(done, calibration=replace(cal, provenance=replace(cal.provenance, input_sha256=hashed)))
        finally:
            stop.set()


def calibrate_samples(job: LogJob, samples: Samples, protocol: pd.DataFrame | None = None) -> LogResult:
    """:func:`calibrate_job` of samples in hand with a protocol sheet in hand (``protocol``, as
    :func:`~mountcal.stops.headings.protocol_sheet` checks it; else the job's file, if any), without the files'
    hashes: a live session's final answer, the same fit, cross-checks, conventions and notes as ``calibrate``
    gives on its recording and sheet."""
    done, cal = _signed(job, samples, protocol)
    return replace(done, calibration=cal)


def _signed(job: LogJob, samples: Samples | None, protocol: pd.DataFrame | None) -> tuple[LogResult, Calibration]:
    """The log's result and its checked calibration; where a handedness check finds the data mirrored and the
    acceleration's sign was only a default (an iOS Sensor Logger recording), the other sign, inferred and said
    (:func:`mountcal.io.sensor_logger.other_sign`). A mirror the sign cannot explain is refused as found, with
    what the sign rests on.

    Raises
    ------
    InputError
        The data are mirrored with either sign, or with a sign that was stated or inferred.
    """
    samples = with_gravity(read_log(list(job.paths), job.log) if samples is None else stated(samples, job.log))
    sheet = protocol is not None or job.protocol is not None

    def run(read: Samples) -> tuple[LogResult, Calibration]:
        done = _calibrate_job(job, read, protocol)
        return done, checked(done, job.uphill_azimuth_deg, sheet)

    return turned_once(run, samples, other_sign, _conventions)


def _conventions(samples: Samples) -> tuple[Convention, ...]:
    return samples.conventions


def _calibrate_job(job: LogJob, samples: Samples | None, protocol: pd.DataFrame | None = None) -> LogResult:
    # samples read elsewhere get the log conventions here (idempotent: read_log's are kept)
    samples = with_gravity(read_log(list(job.paths), job.log) if samples is None else stated(samples, job.log))
    source = _source(job.paths)
    skipped: dict[str, str] = {}
    static = found = table = None
    if job.use in ("auto", "stops"):
        try:
            found = _tabulate(samples, job, protocol)
            table = replace(found.table, source=source, incomplete=samples.incomplete)
            static = calibrate(table, job.options, sign_by_caller=True)  # the sign: on the samples (_signed)
        except NotEnoughInformation as err:
            missed = near_miss_advice(found.near_misses) if found is not None else ""
            if found is not None and found.gyro_rejection:  # the gyro, not the parking, left too few stops
                missed = f" But the log is not short of parked periods: {found.gyro_rejection}{missed}"
            refusal = NotEnoughInformation(str(err) + missed) if missed else err  # the stops a driver made, dropped
            if job.use == "stops":
                raise refusal from err
            skipped["stops"] = str(refusal)
    fit = None
    if job.use in ("auto", "driving"):
        try:
            fit = estimate_driving(increasing_times(samples), _driving_options(job), tilt_from=static)  # stamps merged
        except NotEnoughInformation as err:
            if job.use == "driving":
                raise
            if static is None:
                raise NotEnoughInformation(
                    f"{source}: the log supports neither a calibration from parked stops ({skipped.get('stops')}) "
                    f"nor one from driving ({err})"
                ) from err
            skipped["driving"] = str(err)
    if static is not None and fit is not None:
        cal = stops_with_drive(static, table, fit, samples, job)
        if cal.fit.combination is not None and cal.fit.combination.disagreement is not None:
            skipped["combination"] = "the stops and the drive disagree beyond 3σ (see the notes)"
        return LogResult(cal, samples, str(cal.fit.calibrated_from), static, fit, found, table, skipped)
    if static is not None:
        return LogResult(static, samples, "stops", static, None, found, table, skipped)
    assert fit is not None
    cal = _driving_alone(fit, samples, job)
    return LogResult(cal, increasing_times(samples), "driving", None, fit, found, None, skipped)  # counts merged stamps


def checked(done: LogResult, uphill_azimuth_deg: float | None, protocol: bool) -> Calibration:
    """The log's calibration with its samples' conventions, the cross-checks of its cues (``protocol``: the
    stops' headings came from a protocol sheet), the answer's plausibility and the notes on its frame: what
    every log's result carries, whether its samples were read from files or decoded live.

    Raises
    ------
    InputError
        The gyro, the heading and the lateral acceleration turn opposite ways (a mirrored sensor).
    """
    cal = done.calibration
    stated = merged(done.samples.conventions, cal.provenance.conventions)
    checks = []
    disagree = any(u.test == "stops_vs_driving" for u in cal.unexplained)
    if done.static is not None and done.driving is not None:
        check, found = crosscheck.half_turn(done.static.yaw_deg, done.driving.yaw_deg, uphill_azimuth_deg, protocol)
        checks.append(check)
        if check.passed is not None:  # the drive told the sensor's direction: the stops' doubt about it is settled
            cal = replace(cal, notes=tuple(n for n in cal.notes if not n.startswith(plausibility.BACKWARD)))
        if found is not None:
            cal = replace(cal, unexplained=(*cal.unexplained, found), confident=False)
    # the lateral cue needs a yaw both sources agree on; the yaw rate needs only the up axis
    yaw_known = cal.yaw_deg is not None and not disagree
    rot_vs = cal.rot_vs
    if not yaw_known and not disagree and done.driving is not None and done.driving.rot_vs_longitudinal is not None:
        # yaw left undetermined by the drive's residual tests (a mirrored sensor turns its longitudinal and lateral
        # cues half a turn apart, and the model-error term that follows exceeds the limit): the longitudinal cue's
        # yaw still tells left from right, so the turns are compared and the mirror is named, not passed over
        rot_vs, yaw_known = done.driving.rot_vs_longitudinal, True
    cues = crosscheck.turn_cues(done.samples, rot_vs, yaw_known)
    checks += [crosscheck.turn_handedness(done.samples, rot_vs, cues), crosscheck.gyro_scale(done.samples, cues)]
    if cal.method == "driving":
        checks += plausibility.answer_checks(cal)
    sign = plausibility.sign_check(stated, (*cal.checks, *checks))  # a sign only assumed: confirmed or not
    if sign is not None:
        checks.append(sign[0])
        stated = merged(stated, (sign[1],))
    axes = plausibility.axes_check(stated, (*cal.checks, *checks))  # axes only assumed: could anything test them?
    if axes is not None:
        checks.append(axes)
    cal = replace(cal, provenance=replace(cal.provenance, conventions=stated))
    if done.samples.rotated is not None:  # legitimate (checking a rotation), but the angles mean something else
        cal = replace(cal, notes=with_frame_note(cal.notes, stated))
    elif (named := sensor_frame_note(done.samples.frame_ids)) is not None:  # several frames: none is picked
        cal = replace(cal, notes=(*cal.notes, named))
    return plausibility.with_checks(cal, checks)


def stops_of_log(job: LogJob) -> tuple[Samples, StopTableFromLog]:
    """Read the log and tabulate its stops with their headings (``mountcal stops``)."""
    samples = with_gravity(read_log(list(job.paths), job.log))
    return samples, _tabulate(samples, job)


def stops_with_drive(
    static: Calibration, table: StopTable | None, fit: DrivingFit, samples: Samples, job: LogJob
) -> Calibration:
    """The stops' calibration with the drive's yaw folded in, or — when they disagree — not combined.

    ``fit`` is the drive levelled with ``static``. On a disagreement beyond 3σ the result is not
    confident and carries the finding; it is the stops' result when their rotation puts the
    stops' specific force +g up, else (their mirror solution) the drive's own, levelled by its
    mean gravity: either way the result is on the physical branch.
    """
    cal = combine(static, fit)
    found = next((u for u in cal.unexplained if u.test == "stops_vs_driving"), None)
    if found is None or _up_is_up(static, table):
        return cal
    alone = estimate_driving(samples, _driving_options(job))  # levelled by its own mean gravity: +g up by construction
    cal = not_combined(_driving_alone(alone, samples, job), fit, found)
    return replace(
        cal,
        fit=replace(
            cal.fit,
            calibrated_from="driving (the stops disagree and put −g up)",
            driving=alone.document(),  # the fit used; the one levelled with the stops shows the disagreement
            driving_levelled_with_stops=fit.document(),
        ),
    )


def describe(result: LogResult | tuple[Samples, StopTableFromLog], n_files: int) -> Sequence[str]:
    """Lines for the user: what was read and dropped, the stops found, which sources were used and why not others."""
    done = None if isinstance(result, tuple) else result
    samples = result[0] if isinstance(result, tuple) else result.samples
    found = result[1] if isinstance(result, tuple) else result.stops
    dropped = ", ".join(f"{k}: {v}" for k, v in samples.dropped.items())
    lines = [f"read {len(samples)} samples from {n_files} file(s)" + (f"; dropped {dropped}" if dropped else "")]
    lines += samples.notes
    lines += [f"input file: {line}" for line in samples.incomplete]
    if found is not None:
        unmatched = found.unmatched_protocol_rows
        lines.append(
            f"found {len(found.table)} stops; headings: {found.heading_source}"
            + (f"; {unmatched} protocol rows without a stop" if unmatched else "")
        )
        lines += found.notes
    if done is None:  # a result says the frame in its conventions and notes; a stop table has no place for it
        rotated = samples.rotated
        return lines + ([] if rotated is None else [f"input frame: {rotated.sentence()}, as {rotated.by} says"])
    if done.driving is not None:
        d = done.driving
        offset = f"{d.time_offset_s:+.3f} s" + (
            f" ± {d.time_offset_sigma_s:.3f} s" if d.time_offset_sigma_s is not None else ""
        )
        lines.append(
            f"driving: {d.usable_s:.0f} s usable of {d.moving_s:.0f} s moving, in {d.n_segments} straight segments; "
            f"speed clock offset {offset} ({'found' if d.time_offset_searched else 'given'}); "
            f"straightness from the {d.straightness_source}"
        )
        if d.consistency is not None:
            lines.append(_driving_tests(d.consistency))
    lines.append(f"calibrated from: {done.used}")
    lines += [f"not used: {k} — {v}" for k, v in done.skipped.items()]
    return lines


def _driving_options(job: LogJob) -> DrivingOptions:
    """The job's driving options, the sensor's horizontal axes from its spec (the default class without one)."""
    opts = job.driving or DrivingOptions()
    spec = job.options.spec
    if spec.is_default:
        return opts
    return replace(opts, horizontal_axes_sigma_deg=horizontal_axes_sigma_deg(spec.scale, spec.cross_axis))


def _driving_tests(c: DrivingConsistency) -> str:
    """One line of the drive's residual tests: the split-half z-scores, the cues, what the family found."""

    def z(x: Comparison) -> str:
        return "—" if x.z is None else f"{x.z:+.1f}"

    cue = c.cues.comparison
    cues = "no test" if cue.difference is None else f"{cue.difference:+.2f}° apart (z {z(cue)})"
    return (
        f"driving tests: halves z yaw {z(c.halves.yaw)}, roll {z(c.halves.roll_about_vehicle_x)}, pitch "
        f"{z(c.halves.pitch_about_vehicle_y)}, clock {z(c.halves.clock_offset)}; longitudinal and lateral cues {cues}; "
        f"findings: {', '.join(c.findings) or 'none'}"
    )


def _tabulate(samples: Samples, job: LogJob, protocol: pd.DataFrame | None = None) -> StopTableFromLog:
    if protocol is None and job.protocol:
        protocol = read_protocol(job.protocol, job.log.heading_unit)
    return tabulate(samples, job.detection, protocol, job.uphill_azimuth_deg)


def _driving_alone(fit: DrivingFit, samples: Samples, job: LogJob) -> Calibration:
    lat, alt = samples.channels.get("lat_deg"), samples.channels.get("alt_m")
    g, g_source = local_gravity(
        None if lat is None else lat.value, None if alt is None else alt.value, job.options.gravity_mps2
    )
    provenance = replace(_provenance(job.paths), incomplete_inputs=samples.incomplete)
    cal = driving_calibration(fit, gravity_mps2=g, gravity_source=g_source, provenance=provenance)
    unused = []
    if job.options.slope_reference is not None:
        unused.append(
            f"{option('slope_reference')} was not checked: this result is from driving, which measures no slope"
        )
    beyond = not_from_driving(job.options)
    if beyond:
        unused.append(
            f"{option('model', job.options.model)} was not applied: this result is from driving, which estimates the "
            f"rotation only ({', '.join(beyond)} need parked stops)"
        )
    return replace(cal, notes=(*cal.notes, *unused)) if unused else cal


def _up_is_up(cal: Calibration, table: StopTable | None) -> bool:
    """Whether the calibration rotates the parked stops' specific force to +g up (the physical branch)."""
    if table is None:
        return cal.slope_deg is None or cal.slope_deg < 90.0
    offset = effects.offset_of(cal)
    acc = table.acc_s - (np.array(offset.value) if offset is not None else 0.0)
    return bool(np.median(cal.rot_vs.apply(acc)[:, 2]) > 0.0)


def _source(paths: Sequence[str]) -> str:
    return " + ".join(str(Path(p)) for p in paths)


def _provenance(paths: Sequence[str]) -> Provenance:
    return Provenance(
        input=_source(paths),
        software=f"mountcal {software_version()}",
        method="driving",
        model=("rotation",),
        created_utc=datetime.now(UTC).isoformat(timespec="seconds"),
    )  # the files' hashes: calibrate_job, hashed beside the reading


def _sha256(path: Path, stop: threading.Event | None = None) -> str:
    """The SHA-256 of a file, streamed in 1 MiB blocks; of a folder (a comma2k19 segment), the SHA-256 of
    its files' relative paths and hashes, in sorted order. A FIFO or device is not opened (its reader
    refuses it); ``stop`` ends the hashing early (the result is then not used)."""
    if path.is_dir():
        digest = hashlib.sha256()
        for item in sorted(p for p in path.rglob("*") if p.is_file()):
            digest.update(f"{item.relative_to(path).as_posix()}\0{_sha256(item, stop)}\n".encode())
        return digest.hexdigest()
    if special_kind(path) is not None:
        return ""
    digest = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            if stop is not None and stop.is_set():
                return ""
            digest.update(block)
    return digest.hexdigest()
