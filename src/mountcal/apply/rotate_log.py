"""Whole logs into the vehicle frame, streamed; and the notebook API around it.

:func:`rotate_log` reads a log in bounded chunks (:func:`~mountcal.io.logs.iter_log`), applies a calibration
to each (:mod:`mountcal.apply.rotate`: bias removed, then ``acc_v = R_vs · (acc_s − b)``; rates only rotated)
and writes the vehicle-frame samples with their timestamps to Parquet (default), CSV or MCAP. The output appears
only when complete, never over an input; every sample read is written; what a reader dropped is counted.

An MCAP input rotated to MCAP keeps every record byte for byte and gains a channel ``<topic>/vehicle``: one
vehicle-frame ``sensor_msgs/msg/Imu`` per IMU message (same stamps; ``frame_id`` ``base_link``, REP 103: x forward,
y left, z up; orientation, when known, ``R_wv = R_ws · R_vsᵀ``, and all three covariances, the orientation's
about the IMU's own axes as imu_transformer and robot_localization read it, turned to the vehicle's: ``R C Rᵀ``).

Notebook use — read a log into a table, load a calibration, apply it:

>>> import tempfile, pathlib
>>> from mountcal import Calibration, calibrate, frame_to_vehicle, simulate_preset
>>> from mountcal.io.logs import read_log
>>> from mountcal.apply.rotate_log import rotate_log, to_frame
>>> from mountcal.simulate.drive import simulate_drive
>>> folder = pathlib.Path(tempfile.mkdtemp())
>>> drive = simulate_drive(duration_s=60.0, seed=1)
>>> to_frame(drive.to_samples()).to_csv(folder / "drive.csv", index=False)
>>> df = to_frame(read_log(folder / "drive.csv"))
>>> list(df.columns)
['t_s', 'ax', 'ay', 'az', 'gx', 'gy', 'gz', 'speed_mps']
>>> calibrate(simulate_preset("zhang2011", seed=0)[0]).save(folder / "result.json")
>>> cal = Calibration.load(folder / "result.json")
>>> df_v = frame_to_vehicle(df, cal, gyro_columns=("gx", "gy", "gz"))
>>> round(float(df_v["az"].median()), 1)  # gravity is now on the vehicle's z axis
9.8
>>> report = rotate_log([folder / "drive.csv"], cal, folder / "drive_v.parquet")
>>> report.samples_out == len(df)
True
"""

from __future__ import annotations

import json
import os
from collections import Counter
from collections.abc import Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor, wait
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from mountcal.apply.rotate import (
    acc_to_vehicle,
    check_applicable,
    rate_to_vehicle,
    refuse_gravity_free,
    refuse_rotated,
)
from mountcal.apply.rotate_report import RotateReport
from mountcal.core.atomic import atomic_output
from mountcal.core.conventions import CONVENTIONS, FloatArray
from mountcal.core.errors import InputError
from mountcal.core.option_names import option
from mountcal.core.output_suffix import check_output_suffix
from mountcal.core.ranges import check
from mountcal.core.result import Calibration
from mountcal.core.threads import helpers_allowed
from mountcal.core.version import software_version
from mountcal.estimate import effects
from mountcal.io.frame import CALIBRATION_KEY, FRAME_KEY, PREFIX, frame_word
from mountcal.io.input_conventions import AxisMap, check_same_axes, parse_axes
from mountcal.io.logs import iter_log
from mountcal.io.mcap.chunks import open_log
from mountcal.io.mcap.copy import copy_mcap_with_imu
from mountcal.io.mcap.read import has_odometry
from mountcal.io.mcap.write import McapImuSamples
from mountcal.io.reader import CHUNK_SAMPLES, LogOptions
from mountcal.io.registry import reader_for
from mountcal.io.ros2.imu import ImuMessages
from mountcal.io.samples import Samples
from mountcal.io.sensor_frame import refuse_several
from mountcal.io.sensor_logger import sign_for_calibration
from mountcal.io.table.write import CsvSamples, ParquetSamples
from mountcal.io.whole import Cut, reading
from mountcal.loop.crosscheck import TurnWatch
from mountcal.stops.detect import GyroUnitWatch

FORMATS = {".parquet": "parquet", ".pq": "parquet", ".csv": "csv", ".mcap": "mcap"}
VEHICLE_FRAME_ID = "base_link"  # REP 103's body frame: x forward, y left, z up = ISO 8855
LEVELLED_FRAME_ID = "mountcal_levelled"  # z up, heading the sensor's own: not REP 103's base_link


def output_format(path: str | os.PathLike[str], fmt: str | None = None) -> str:
    """``parquet``, ``csv`` or ``mcap``: the one asked for, else from the suffix, else Parquet.

    A name whose suffix says another format (``out.blf``, or ``out.csv`` with ``fmt="parquet"``)
    is refused (:func:`~mountcal.core.output_suffix.check_output_suffix`).
    """
    by_name = FORMATS[check_output_suffix(option("output"), path, tuple(FORMATS))]
    if fmt is None:
        return by_name
    if fmt not in ("parquet", "csv", "mcap"):
        raise InputError(option("format"), "parquet, csv or mcap", repr(fmt), "Choose one of them.")
    suffix = Path(path).suffix.lower()
    if suffix in FORMATS and by_name != fmt:
        raise InputError(
            f"{option('output')} {path}",
            f"a name ending in the suffix of {option('format', fmt)}",
            f"one ending in {suffix} ({by_name})",
            f"Drop {option('format')} to write {by_name}, or name the output {Path(path).with_suffix('.' + fmt).name}.",
        )
    return fmt


def rotate_log(
    paths: str | os.PathLike[str] | Sequence[str | os.PathLike[str]],
    cal: Calibration,
    output: str | os.PathLike[str],
    *,
    fmt: str | None = None,
    options: LogOptions | None = None,
    chunk_samples: int = CHUNK_SAMPLES,
    frame_id: str = VEHICLE_FRAME_ID,
    level_only: bool = False,
    require_confident: bool = False,
    where: str | None = None,
) -> RotateReport:
    """Write a log's samples in the vehicle frame, streaming with bounded memory.

    A calibration without a determined yaw is refused unless ``level_only``: then the output is
    levelled (z up, heading the sensor's own) and its metadata, column descriptions, MCAP topic
    (``…/levelled``) and frame id (``mountcal_levelled``) say so. A result that is not confident is
    applied with a warning (``RotateReport.warnings``, and ``confident: false`` in the metadata), or
    refused with ``require_confident``.

    Parameters
    ----------
    paths : path or sequence of paths
        One log, or the splits of one log (joined in time order).
    cal : Calibration
        The mounting (:meth:`Calibration.load`).
    output : path
        The file to write; never one of the inputs.
    fmt : {"parquet", "csv", "mcap"}, optional
        Default: from the output's suffix, else Parquet.
    options : LogOptions, optional
        DBC, mapping and channel for CAN logs, topic for MCAP.
    chunk_samples : int
        Samples per chunk (per Parquet row group): the memory bound.
    frame_id : str
        ``header.frame_id`` of the vehicle-frame MCAP messages.
    level_only : bool
        Accept a calibration without yaw and write the levelled frame.
    require_confident : bool
        Refuse a calibration that is not confident.
    where : str, optional
        How a refusal names the calibration (default: the input it was made from; the CLI names its file).

    Returns
    -------
    RotateReport

    Raises
    ------
    InputError
        Unreadable input, an output that is an input, data in g instead of m/s², an MCAP output
        from several MCAP files; an undetermined yaw without ``level_only`` (or to CSV, which
        cannot say so), a result that is not confident with ``require_confident``.
    """
    files = [Path(p) for p in ([paths] if isinstance(paths, str | os.PathLike) else paths)]
    opts = options or LogOptions()
    out = Path(output)
    kind = output_format(out, fmt)
    _check_not_an_input(out, files)
    checked = Checked(
        level_only,
        tuple(check_applicable(cal, level_only=level_only, require_confident=require_confident, where=where)),
    )
    axes = None if opts.axes is None else parse_axes(opts.axes, option("axes"))
    check_same_axes(cal.provenance.conventions, axes, " + ".join(map(str, files)))
    if not cal.yaw_determined:  # a CSV says so in its column frame ("levelled"), the others in their metadata
        frame_id = LEVELLED_FRAME_ID if frame_id == VEHICLE_FRAME_ID else frame_id
    check("chunk_samples", chunk_samples, option("chunk"))
    if kind == "mcap" and any(reader_for(f, opts).name == "mcap" for f in files):  # copied through
        if len(files) != 1:
            raise InputError(
                " + ".join(map(str, files)),
                "one MCAP file to copy through with its vehicle-frame topic",
                f"{len(files)} files",
                "Rotate each MCAP file to its own output, or write Parquet/CSV (which joins splits).",
            )
        with reading(opts.allow_truncated) as cuts:
            report = _rotate_mcap_copy(files[0], cal, out, opts.topic, frame_id, cuts, checked, opts, axes)
    else:
        report = _rotate_stream(files, cal, out, kind, opts, chunk_samples, frame_id, checked)
    return replace(report, frame=cal.frame, warnings=report.warnings or checked.warnings)


@dataclass(frozen=True)
class Checked:
    """What :func:`~mountcal.apply.rotate.check_applicable` decided, once per run: ``level_only`` and the
    warnings, passed as a value to every rotation and into the output's metadata (never decided again)."""

    level_only: bool
    warnings: tuple[str, ...]


def _check_not_an_input(out: Path, files: Sequence[Path]) -> None:
    for f in files:
        same = out.resolve() == f.resolve() or (out.exists() and f.exists() and os.path.samefile(out, f))
        if same:
            raise InputError(
                str(out),
                "an output path other than the input",
                "the input file itself",
                "Choose another -o path; mountcal never overwrites its input.",
            )


def _metadata(
    cal: Calibration, files: Sequence[Path], checked: Checked, incomplete: Sequence[str] = ()
) -> dict[str, str]:
    version = software_version()
    return {
        PREFIX + FRAME_KEY: cal.frame,  # what the readers recognise (mountcal.io.frame)
        "mountcal.units": "t_s s; ax, ay, az m/s^2 (specific force, bias removed); gx, gy, gz rad/s",
        "mountcal.yaw": "vehicle" if cal.yaw_determined else "sensor's own (not determined)",
        "mountcal.confident": json.dumps(cal.confident),
        "mountcal.warnings": json.dumps(list(checked.warnings)),
        "mountcal.core.conventions": json.dumps(CONVENTIONS),
        PREFIX + CALIBRATION_KEY: json.dumps(
            {
                "quaternion_vs_xyzw": cal.rot_vs.as_quat().tolist(),
                **cal.angles.columns(slope=False),  # each angle with its σ (and why a yaw is undetermined)
                "bias_mps2": _offset(cal),
                "method": cal.method,
                "input": cal.provenance.input,
            }
        ),
        "mountcal.inputs": json.dumps([str(f) for f in files]),
        "mountcal.incomplete_inputs": json.dumps(list(incomplete)),  # cut short, read in part
        "mountcal.software": f"mountcal {version}",
    }


# --------------------------------------------------------------------------- Parquet, CSV, MCAP from a stream


def _rotate_stream(
    files: Sequence[Path],
    cal: Calibration,
    out: Path,
    kind: str,
    opts: LogOptions,
    chunk_samples: int,
    frame_id: str,
    checked: Checked,
) -> RotateReport:
    chunks = iter_log(files, opts, chunk_samples)
    first = next(chunks, None)
    if first is None:
        raise InputError(" + ".join(map(str, files)), "IMU samples", "none", "Check the log and the topic/DBC.")
    refuse_gravity_free(first)
    acc_to_vehicle(first.acc_s, cal, check_units=True, level_only=checked.level_only)  # g units refused before output
    flip, said = sign_for_calibration(first, cal.provenance.conventions)  # a phone app's sign (Sensor Logger)
    checked = replace(checked, warnings=(*checked.warnings, said)) if said else checked
    tally = _Tally(gyro=first.gyro_s is not None, several=len(files) > 1, flip_sign=flip, turns=TurnWatch.of(cal))
    with atomic_output(out) as f, ThreadPoolExecutor(max_workers=1) as encoder:
        writer = _writer(f, kind, tally.gyro, cal, files, frame_id, first.incomplete, checked)
        # Encoding and compressing chunk k (pyarrow releases the GIL) overlaps reading chunk k + 1;
        # one chunk in flight keeps memory bounded.
        overlap = helpers_allowed()
        pending: Future[None] | None = None
        frames: Counter[str] = Counter()  # the IMU messages' frame names so far: one calibration, one frame
        try:
            for chunk in _chain(first, chunks):
                if chunk.frame_ids is not None:
                    frames.update(dict(chunk.frame_ids.counts))
                    refuse_several(frames, chunk.frame_ids.topic, chunk.source)
                rows = tally.rotate(chunk, cal, checked.level_only)
                if pending is not None:
                    pending.result()
                    pending = None
                if rows is not None and overlap:
                    pending = encoder.submit(writer.write, *rows)
                elif rows is not None:
                    writer.write(*rows)
            if pending is not None:
                pending.result()
        finally:
            if pending is not None:
                wait([pending])  # after an error: no write still running when the file is dropped
            writer.close()  # after an error this only completes the unnamed file, which is dropped
    return RotateReport(
        output=str(out),
        format=kind,
        inputs=tuple(map(str, files)),
        samples_in=tally.samples,
        samples_out=tally.samples,
        dropped={k: v for k, v in tally.dropped.items() if v},
        chunks=tally.chunks,
        largest_chunk=tally.largest,
        gyro=tally.gyro,
        topic=_topic("/imu", cal) if kind == "mcap" else None,
        incomplete=tuple(tally.incomplete),
        warnings=checked.warnings,
        turns=tally.turns.lines() if tally.turns else (),
    )


@dataclass
class _Tally:
    """Rotates and writes chunk after chunk, counting what went through."""

    gyro: bool
    several: bool
    flip_sign: bool = False  # the acceleration read with the other sign than the calibration found
    samples: int = 0
    chunks: int = 0
    largest: int = 0
    dropped: Counter[str] = field(default_factory=Counter)
    incomplete: list[str] = field(default_factory=list)
    gyro_unit: GyroUnitWatch = field(default_factory=GyroUnitWatch)  # deg/s read as rad/s: refused, not written
    turns: TurnWatch | None = None  # the gyro's scale and the turns' sense against the calibration

    def rotate(
        self, chunk: Samples, cal: Calibration, level_only: bool
    ) -> tuple[FloatArray, FloatArray, FloatArray | None] | None:
        """The chunk's rows to write, in the vehicle frame (None for an empty chunk), counted."""
        self.dropped.update(chunk.dropped)
        self.incomplete += chunk.incomplete
        refuse_rotated(chunk.rotated, chunk.source)  # any split: the output is dropped (atomic_output)
        n = len(chunk)
        if n == 0:
            return None
        if (chunk.gyro_s is not None) != self.gyro:
            raise InputError(
                chunk.source,
                "the same channels in every file of the log" if self.several else "a gyro in every chunk",
                "a file without the gyro" if self.gyro else "a gyro in only some files",
                "Rotate the files separately.",
            )
        self.gyro_unit.look(chunk)
        # Units checked on the first chunk; yaw by rotate_log (level_only: its decision, passed on).
        acc_s = -chunk.acc_s if self.flip_sign else chunk.acc_s
        if self.turns is not None:
            self.turns.look(replace(chunk, acc_s=acc_s) if self.flip_sign else chunk)
        acc_v = acc_to_vehicle(acc_s, cal, check_units=False, level_only=level_only)
        gyro_v = rate_to_vehicle(chunk.gyro_s, cal, level_only=level_only) if chunk.gyro_s is not None else None
        self.samples, self.chunks, self.largest = self.samples + n, self.chunks + 1, max(self.largest, n)
        return chunk.t_s, acc_v, gyro_v


def _chain(first: Samples, rest: Iterator[Samples]) -> Iterator[Samples]:
    # No read-ahead thread: the MCAP and BLF readers already decompress on a background thread,
    # and on two cores a third thread measured slower, not faster.
    yield first
    yield from rest


def _writer(
    f: BinaryIO,
    kind: str,
    gyro: bool,
    cal: Calibration,
    files: Sequence[Path],
    frame_id: str,
    incomplete: Sequence[str],
    checked: Checked,
) -> ParquetSamples | CsvSamples | McapImuSamples:
    meta = _metadata(cal, files, checked, incomplete)
    if kind == "parquet":
        return ParquetSamples(f, gyro, meta, descriptions=_descriptions(cal))
    if kind == "csv":
        return CsvSamples(f, gyro, frame_word(cal.frame))  # a CSV has no metadata: the frame in a column
    return McapImuSamples(f, _topic("/imu", cal), frame_id, {k.removeprefix(PREFIX): v for k, v in meta.items()})


def _topic(base: str, cal: Calibration) -> str:
    return base + ("/vehicle" if cal.yaw_determined else "/levelled")


def _descriptions(cal: Calibration) -> dict[str, str]:
    """Each written column's meaning, stored with the column (Parquet field metadata)."""
    axes = (
        "vehicle frame (ISO 8855)"
        if cal.yaw_determined
        else "levelled frame: z up, x and y about the sensor's own heading (yaw not determined)"
    )
    out = {"t_s": "time, s (the log's clock)"}
    for n, what in zip(("ax", "ay", "az"), ("x", "y", "z"), strict=True):
        out[n] = f"specific force along {what}, m/s^2, bias removed; {axes}"
    for n, what in zip(("gx", "gy", "gz"), ("x", "y", "z"), strict=True):
        out[n] = f"angular rate about {what}, rad/s; {axes}"
    return out


# --------------------------------------------------------------------------- MCAP copied through


def _rotate_mcap_copy(
    src: Path,
    cal: Calibration,
    out: Path,
    topic: str | None,
    frame_id: str,
    cuts: Sequence[Cut],
    checked: Checked,
    opts: LogOptions,
    axes: AxisMap | None = None,
) -> RotateReport:
    open_log(src, discover=False).file.close()  # a cut file is refused, or its cut recorded in `cuts`, before writing
    chunks = iter_log([src], opts, CHUNK_SAMPLES)  # a topic mountcal rotated, a gyro in deg/s: refused before writing
    gyro_unit, turns = GyroUnitWatch(), TurnWatch.of(cal)
    if not has_odometry(src):  # no speed, no heading: the turns cannot decide, and the log is not read through
        turns = replace(turns, unable="the log holds no odometry topic (no speed, no heading)")
    try:
        first = chunk = next(chunks, None)
        refuse_rotated(None if first is None else first.rotated, str(src))
        if first is not None:
            refuse_gravity_free(first)
        while chunk is not None and not (gyro_unit.done and turns.done):  # a log without turns is read through
            gyro_unit.look(chunk)
            turns.look(chunk)
            chunk = next(chunks, None)
    finally:
        getattr(chunks, "close", lambda: None)()
    incomplete = tuple(c.sentence for c in cuts)
    meta = {k.removeprefix(PREFIX): v for k, v in _metadata(cal, [src], checked, incomplete).items()}
    units_checked = False

    def transform(msgs: ImuMessages) -> tuple[ImuMessages, int]:
        nonlocal units_checked
        mapped = msgs if axes is None or axes.identity else _mapped(msgs, axes)
        rotated = _to_vehicle(mapped, cal, not units_checked, checked.level_only)
        units_checked = units_checked or len(msgs) >= 10
        return rotated

    with atomic_output(out) as g:
        stats = copy_mcap_with_imu(
            src, g, transform, topic=topic, suffix=_topic("", cal), frame_id=frame_id, metadata=meta
        )
    return RotateReport(
        output=str(out),
        format="mcap",
        inputs=(str(src),),
        samples_in=stats.imu_messages,
        samples_out=stats.imu_messages,
        dropped={},
        chunks=stats.imu_chunks,
        largest_chunk=stats.largest_chunk,
        gyro=True,
        topic=stats.topic,
        copied_messages=stats.copied_messages,
        copied_channels=stats.copied_channels,
        nonfinite=stats.nonfinite,
        incomplete=tuple(c.sentence for c in cuts),
        turns=turns.lines(),
    )


def _to_vehicle(msgs: ImuMessages, cal: Calibration, check_units: bool, level_only: bool) -> tuple[ImuMessages, int]:
    """The messages in the vehicle frame, and how many hold a non-finite value."""
    acc, gyro = msgs.linear_acceleration, msgs.angular_velocity
    finite = np.isfinite(acc).all(axis=1) & np.isfinite(gyro).all(axis=1)
    if check_units and finite.sum() >= 10:
        acc_to_vehicle(acc[finite], cal, check_units=True, level_only=level_only)  # refuses g units
    rot = cal.rot_vs.as_matrix()
    orientation = msgs.orientation.copy()
    known = (msgs.orientation_covariance[:, 0] != -1.0) & (np.linalg.norm(orientation, axis=1) > 0.5)
    known &= np.isfinite(orientation).all(axis=1)
    if known.any():  # the vehicle's orientation: R_wv = R_ws · R_vsᵀ
        orientation[known] = (Rotation.from_quat(orientation[known]) * cal.rot_vs.inv()).as_quat()
    return (
        ImuMessages(
            sec=msgs.sec,
            nanosec=msgs.nanosec,
            orientation=orientation,
            # about the IMU's own axes (as ROS's consumers read it: imu_transformer, robot_localization)
            orientation_covariance=_rotate_covariance(msgs.orientation_covariance, rot),
            angular_velocity=rate_to_vehicle(gyro, cal, level_only=level_only),
            angular_velocity_covariance=_rotate_covariance(msgs.angular_velocity_covariance, rot),
            linear_acceleration=acc_to_vehicle(acc, cal, check_units=False, level_only=level_only),
            linear_acceleration_covariance=_rotate_covariance(msgs.linear_acceleration_covariance, rot),
        ),
        int((~finite).sum()),
    )


def _mapped(msgs: ImuMessages, axes: AxisMap) -> ImuMessages:
    """The messages in the sensor frame of the axis map (as the log readers apply it). An orientation
    turns with a proper map; under a reflection (no rotation) it is marked unknown, as ROS does."""
    p = axes.matrix
    orientation, orientation_cov = msgs.orientation.copy(), msgs.orientation_covariance.copy()
    if axes.reflection:
        orientation_cov[:, 0] = -1.0
    else:  # R_w,sensor = R_w,device · Pᵀ; its covariance, about the device's axes, turned to the sensor's
        known = np.isfinite(orientation).all(axis=1) & (np.linalg.norm(orientation, axis=1) > 0.5)
        orientation[known] = (Rotation.from_quat(orientation[known]) * Rotation.from_matrix(p).inv()).as_quat()
        orientation_cov = _rotate_covariance(orientation_cov, p)
    return replace(
        msgs,
        orientation=orientation,
        orientation_covariance=orientation_cov,
        angular_velocity=axes.apply(msgs.angular_velocity),
        angular_velocity_covariance=_rotate_covariance(msgs.angular_velocity_covariance, p),
        linear_acceleration=axes.apply(msgs.linear_acceleration),
        linear_acceleration_covariance=_rotate_covariance(msgs.linear_acceleration_covariance, p),
    )


def _rotate_covariance(cov: FloatArray, rot: FloatArray) -> FloatArray:
    """``R · C · Rᵀ`` for each row-major 3×3 covariance (rows marked unknown, ``C[0] = −1``, kept)."""
    c = cov.reshape(-1, 3, 3)
    out = np.einsum("ij,njk,lk->nil", rot, c, rot).reshape(-1, 9)
    return np.where((cov[:, 0] == -1.0)[:, None], cov, out)


# --------------------------------------------------------------------------- tables for notebooks


def to_frame(samples: Samples) -> pd.DataFrame:
    """Samples as a DataFrame: ``t_s, ax, ay, az`` (and ``gx, gy, gz``), plus each channel held.

    Parameters
    ----------
    samples : Samples
        From :func:`mountcal.io.logs.read_log` (sensor frame, SI units).

    Returns
    -------
    pandas.DataFrame
        One row per IMU sample: ``t_s`` (s), ``ax, ay, az`` (m/s²), ``gx, gy, gz`` (rad/s) when
        logged, and each auxiliary channel (``speed_mps``, ``heading_deg``, …) at its latest
        value at or before the row's time (NaN before its first sample; channels keep their own
        clock, so this is a sample-and-hold, not an interpolation). ``attrs`` records the frame
        (``"sensor"``, or ``"vehicle"``/``"levelled"`` where the file says mountcal rotated it), the source,
        the axis mapping and the reader's drop counts.
    """
    data: dict[str, Any] = {"t_s": samples.t_s}
    for j, name in enumerate(("ax", "ay", "az")):
        data[name] = samples.acc_s[:, j]
    if samples.gyro_s is not None:
        for j, name in enumerate(("gx", "gy", "gz")):
            data[name] = samples.gyro_s[:, j]
    for key, ch in samples.channels.items():
        order = np.argsort(ch.t_s, kind="stable")
        t_ch, v_ch = ch.t_s[order], ch.value[order]
        idx = np.searchsorted(t_ch, samples.t_s, side="right") - 1
        data[key] = np.where(idx >= 0, v_ch[np.clip(idx, 0, None)], np.nan) if t_ch.size else np.nan
    # One block per column (pandas ≥ 3 hands out read-only views of a shared block, which
    # scipy's Rotation.apply refuses; see the report of issue 5).
    df = pd.DataFrame({"t_s": data.pop("t_s")})
    for name, column in data.items():
        df[name] = column
    frame = "sensor" if samples.rotated is None else samples.rotated.frame  # frame_to_vehicle refuses a rotated one
    df.attrs.update(frame=frame, source=samples.source, axis_map=samples.axis_map, dropped=dict(samples.dropped))
    return df


def _offset(cal: Calibration) -> list[float] | None:
    """The metadata's copy of the result's ``bias_mps2`` (the offset effect's values)."""
    off = effects.offset_of(cal)
    return None if off is None else list(off.value)
