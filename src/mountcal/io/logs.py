"""One entry point for every log format: the reader is picked by :mod:`mountcal.io.registry`.

Built in: MCAP (ROS 2 Imu, CDR or JSON), CAN logs (``.blf .asc .log .trc .mf4 .mdf``, and ``.csv``
when a DBC is given) decoded with the DBC, CSV/Parquet sample tables (``t_s, ax, ay, az`` and
optionally ``gx, gy, gz`` in rad/s and the channels of :data:`mountcal.io.table.read.TABLE_CHANNELS`),
comma2k19 segment folders; and the formats of installed plugins (entry points ``mountcal.readers``).

A log split over several files (a logger's 10-minute MF4 splits) is read file by file and joined
in time order. Files whose clocks overlap are not splits of one log (two loggers, or one session
given twice): joining them would interleave two recordings, so they are refused.

The conventions every reader shares are applied here, once, whatever the format
(:mod:`mountcal.io.input_conventions`): the axis map ``axes`` (after a reader's own map: a CAN mapping's
``axes``, a format's documented frame) to the accelerometer and the gyro, and the unit of the heading
channel (stated by ``heading_unit``, or checked: radians are refused); and the frame a file states its
samples are in when mountcal rotated them (:mod:`mountcal.io.frame`), or else the name a ROS log gives
the sensor frame (:mod:`mountcal.io.sensor_frame`). ``Samples.conventions`` says how each was known.

Each file is read under the completeness policy of :mod:`mountcal.io.whole`: a file cut short is
refused, or with ``LogOptions.allow_truncated`` read to its last whole record and named in
``Samples.incomplete`` (``LogSummary.incomplete`` for a listing).
"""

from __future__ import annotations

import os
from collections import Counter
from collections.abc import Iterator, Sequence
from dataclasses import replace
from itertools import pairwise
from pathlib import Path
from typing import TYPE_CHECKING

from mountcal.core.budget import scoped, scoped_iter
from mountcal.core.errors import InputError
from mountcal.io.reader import CHUNK_SAMPLES, LogOptions
from mountcal.io.registry import reader_for
from mountcal.io.whole import Cut, read_under, reading

if TYPE_CHECKING:  # numpy and the readers load when a log is read: `mountcal --help` needs neither
    from mountcal.io.input_conventions import AxisMap
    from mountcal.io.reader import LogReader
    from mountcal.io.samples import LogSummary, Samples


# options only some formats read: given for another, they would be silently ignored
_READ_BY = {"field": ("mcap", "bag"), "columns": ("table",), "unit": ("table",)}


def _reader(path: Path, opts: LogOptions) -> LogReader:
    """The reader of ``path``, refusing an option that its format does not read."""
    from mountcal.core.option_names import option

    reader = reader_for(path, opts)
    for name, formats in _READ_BY.items():
        if getattr(opts, name) is not None and reader.name not in formats:
            raise InputError(
                str(path),
                f"a {' or '.join(formats)} log for {option(name)}",
                f"a {reader.name} log, which {option(name)} does not apply to",
                f"Drop {option(name)}.",
            )
    if reader.name == "table" and opts.columns is None and opts.mapping is None:
        _not_a_stop_table(path)
    return reader


def _not_a_stop_table(path: Path) -> None:
    """Refuse a stop table read as a log — ``rotate``, ``stops``, ``inspect``, ``plan --from-log``, the library
    alike: its rows (one per parked stop, minutes apart) would be taken for a few samples, rotated or searched
    for stops. Told by the stop table's own columns (:data:`mountcal.io.kind.STOP_COLUMNS`) without a sample
    table's, as the one decision of what an input is (:mod:`mountcal.io.kind`) tells it; a column map
    (``--columns``) says the table is samples and reads it so."""
    from mountcal.core.option_names import option
    from mountcal.io.kind import SAMPLE_COLUMNS, STOP_COLUMNS, table_columns

    try:
        columns = table_columns(path)
    except InputError:  # a table cut short or unreadable: its reader says so (and reads the part when allowed)
        return
    stop = sorted(columns & STOP_COLUMNS)
    if not stop or columns & SAMPLE_COLUMNS:
        return
    raise InputError(
        str(path),
        "a log: samples in time (t_s, ax, ay, az at the sensor's rate)",
        f"a stop table (by its columns {', '.join(stop)}): one row per parked stop, not samples",
        "A stop table is fitted as it is: mountcal calibrate (or triad; report --stops) takes it. Here, give the "
        f"log the stops were found in; if these rows are samples, name the columns with {option('columns')}.",
    )


@scoped
def read_log(paths: str | Path | Sequence[str | Path], options: LogOptions | None = None) -> Samples:
    """Samples of one log (one file, or several splits joined in time order)."""
    opts = options or LogOptions()
    files = [Path(p) for p in ([paths] if isinstance(paths, str | Path) else paths)]
    if not files:
        raise InputError("LOG", "at least one log file", "none", "Name the log file(s).")
    axes = _axes(opts)  # a bad map is refused before any file is read
    parts = [read_file(f, opts) for f in files]
    return stated(parts[0] if len(parts) == 1 else join(parts), opts, axes)


def _axes(opts: LogOptions) -> AxisMap | None:
    from mountcal.core.option_names import option
    from mountcal.io.input_conventions import parse_axes

    return None if opts.axes is None else parse_axes(opts.axes, option("axes"))


def stated(samples: Samples, opts: LogOptions, axes: AxisMap | None = None, check: bool = True) -> Samples:
    """The samples with the log conventions of ``opts`` applied and recorded (see the module's docstring);
    samples that carry them already are returned as they are.

    ``check``: infer the heading channel's unit from the whole log (a chunk of a stream cannot).
    """
    from dataclasses import replace

    import numpy as np

    from mountcal.io.frame import frame_convention
    from mountcal.io.input_conventions import axes_convention, heading_channel_unit
    from mountcal.io.samples import Channel, marked_gravity_free
    from mountcal.io.sensor_frame import sensor_frame_convention

    samples = marked_gravity_free(samples)  # every reader's: an acceleration without gravity reads, not calibrates
    if any(c.name == "axes" for c in samples.conventions):
        return samples
    axes = _axes(opts) if axes is None else axes
    reader_map = samples.axis_map
    conventions = [axes_convention(axes, reader_map, f"the reader ({samples.axis_map})")]
    if samples.rotated is not None:  # the frame the file states: said in every result made of these samples
        conventions.append(frame_convention(samples.rotated))
    elif samples.frame_ids is not None:  # the sensor frame's name (a rotated log's names mountcal's output frame)
        named = sensor_frame_convention(samples.frame_ids)
        conventions += [] if named is None else [named]
    if axes is not None and not axes.identity:
        samples = replace(
            samples,
            acc_s=axes.apply(samples.acc_s),
            gyro_s=None if samples.gyro_s is None else axes.apply(samples.gyro_s),
            axis_map=conventions[0].value if reader_map == "x,y,z" else f"{reader_map}, then {conventions[0].value}",
        )
    heading = samples.channels.get("heading_deg")
    if heading is not None and (check or opts.heading_unit is not None):
        turned = None
        if check and samples.gyro_s is not None and len(samples) > 1:
            up = samples.acc_s.mean(axis=0)
            rate = samples.gyro_s @ (up / max(float(np.linalg.norm(up)), 1e-12))
            yaw = np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(samples.t_s))])
            turned = float(np.degrees(np.ptp(yaw)))
        factor, unit = heading_channel_unit(heading.t_s, heading.value, turned, opts.heading_unit, samples.source)
        conventions.append(unit)
        if factor != 1.0:
            channels = dict(samples.channels) | {"heading_deg": Channel(heading.t_s, (heading.value * factor) % 360.0)}
            samples = replace(samples, channels=channels)
    return replace(samples, conventions=(*samples.conventions, *conventions))


def read_file(path: Path, opts: LogOptions) -> Samples:
    """One file's samples, read under the completeness policy (:mod:`mountcal.io.whole`): refused when
    cut short, or read in part and named in ``incomplete`` with ``opts.allow_truncated``."""
    with reading(opts.allow_truncated) as cuts:
        samples = _reader(path, opts).read(path, opts)
    return _marked(samples, cuts)


def _marked(samples: Samples, cuts: Sequence[Cut]) -> Samples:
    """``samples`` naming the files that were read although cut short."""
    if not cuts:
        return samples
    return replace(samples, incomplete=(*samples.incomplete, *(c.sentence for c in cuts)))


@scoped
def inspect_log(path: str | Path, options: LogOptions | None = None) -> LogSummary:
    """What a log holds: topics or messages, signals, rates, duration (a CAN log without a DBC too:
    ids per channel with counts, rates and DLCs)."""
    opts = options or LogOptions()
    path = Path(path)
    with reading(opts.allow_truncated) as cuts:
        info = _reader(path, opts).inspect(path, opts)
    return replace(info, incomplete=(*info.incomplete, *(c.sentence for c in cuts))) if cuts else info


@scoped_iter
def iter_log(
    paths: str | os.PathLike[str] | Sequence[str | os.PathLike[str]],
    options: LogOptions | None = None,
    max_samples: int = CHUNK_SAMPLES,
) -> Iterator[Samples]:
    """The samples of a log in chunks of at most ``max_samples``, files in time order.

    Each file through its reader's :meth:`~mountcal.io.reader.LogReader.iter_chunks` (MCAP, CAN
    and tables stream in bounded memory). Each chunk's ``dropped`` counts what its reader
    discarded. Splits of one log are ordered by their first sample; overlapping ones are refused.
    """
    opts = options or LogOptions()
    files = [Path(p) for p in ([paths] if isinstance(paths, str | os.PathLike) else paths)]
    if not files:
        raise InputError("LOG", "at least one log file", "none", "Name the log file(s).")
    if len(files) > 1:
        files = sorted(files, key=lambda f: _first_time(f, opts))
    axes = _axes(opts)
    previous: tuple[str, float] | None = None  # the file before and its last time
    for f in files:
        first = True
        cuts: list[Cut] = []
        told = 0
        for chunk in _chunks(f, opts, max_samples, cuts):
            if len(cuts) > told:  # a cut goes with the first chunk read after it was found
                chunk, told = _marked(chunk, cuts[told:]), len(cuts)
            if len(chunk):
                if first and previous is not None and float(chunk.t_s[0]) < previous[1]:
                    raise overlap_error(previous[0], previous[1], str(f), float(chunk.t_s[0]))
                first, previous = False, (str(f), float(chunk.t_s[-1]))
            yield stated(chunk, opts, axes, check=False)
        if len(cuts) > told:  # found after the last chunk: carried by an empty one
            yield stated(_marked(_empty(str(f)), cuts[told:]), opts, axes, check=False)


def _empty(source: str) -> Samples:
    import numpy as np

    from mountcal.io.samples import Samples

    return Samples(np.empty(0), np.empty((0, 3)), source=source)


def _chunks(path: Path, opts: LogOptions, max_samples: int, cuts: list[Cut]) -> Iterator[Samples]:
    """A file's chunks read under the completeness policy (a reader may check the file before its
    generator starts); the cuts found are added to ``cuts``."""
    with reading(opts.allow_truncated, cuts):
        chunks = _reader(path, opts).iter_chunks(path, opts, max_samples)
    return read_under(chunks, opts.allow_truncated, cuts)


def _first_time(path: Path, opts: LogOptions) -> float:
    chunks = _chunks(path, opts, 1, [])
    try:
        for chunk in chunks:
            if len(chunk):
                return float(chunk.t_s[0])
        return float("inf")
    finally:
        close = getattr(chunks, "close", None)
        if close is not None:
            close()


def join(parts: Sequence[Samples]) -> Samples:
    """Samples of several files in time order, with channels and drop counts merged.

    Raises
    ------
    InputError
        When two files' clocks overlap: they are not consecutive splits of one log.
    """
    import numpy as np

    from mountcal.io.samples import Channel, Samples
    from mountcal.io.sensor_frame import joined

    parts = sorted(parts, key=lambda s: float(s.t_s[0]) if len(s) else np.inf)
    _check_consecutive([p for p in parts if len(p)])
    gyro = None
    if all(p.gyro_s is not None for p in parts):
        gyro = np.concatenate([p.gyro_s for p in parts if p.gyro_s is not None])
    channels = {}
    for key in {k for p in parts for k in p.channels}:
        chs = [p.channels[key] for p in parts if key in p.channels]
        channels[key] = Channel(np.concatenate([c.t_s for c in chs]), np.concatenate([c.value for c in chs]))
    dropped: Counter[str] = Counter()
    for p in parts:
        dropped.update(p.dropped)
    return Samples(
        np.concatenate([p.t_s for p in parts]),
        np.concatenate([p.acc_s for p in parts]),
        gyro,
        channels,
        source=" + ".join(p.source for p in parts),
        axis_map=parts[0].axis_map,
        dropped=dict(dropped),
        notes=tuple(dict.fromkeys(n for p in parts for n in p.notes)),
        gravity_free=next((p.gravity_free for p in parts if p.gravity_free), ""),
        rotated=next((p.rotated for p in parts if p.rotated is not None), None),
        incomplete=tuple(line for p in parts for line in p.incomplete),
        conventions=tuple(dict.fromkeys(c for p in parts for c in p.conventions)),  # each file's, once
        frame_ids=joined([p.frame_ids for p in parts]),
    )


def _check_consecutive(parts: Sequence[Samples]) -> None:
    """Refuse files (sorted by their first sample) whose time spans overlap."""
    for before, after in pairwise(parts):
        end, start = float(before.t_s[-1]), float(after.t_s[0])
        if start < end:
            raise overlap_error(before.source, end, after.source, start)


def overlap_error(before: str, end: float, after: str, start: float) -> InputError:
    """The refusal of two files whose clocks overlap: ``after`` starts before ``before`` ends."""
    return InputError(
        f"{before} + {after}",
        "splits of one log, each starting after the previous one ends",
        f"overlapping clocks: {after} starts at t = {start:.3f} s, {end - start:.3f} s before {before} ends "
        f"(t = {end:.3f} s)",
        "Give the files of one recording session at a time (two loggers, or a file given twice, "
        "cannot be joined into one log).",
    )
