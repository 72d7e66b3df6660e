"""What mountcal's outputs look like, the one place that knows it: the frame a file says its samples are in.

``mountcal rotate`` (:mod:`mountcal.apply.rotate_log`) writes the frame and the calibration it applied
into its output — a Parquet file's key-value metadata (``mountcal.frame``, ``mountcal.calibration``), an
MCAP output channel's metadata (``frame``, ``calibration``) — and the readers recognise them here by that
metadata, never by a name, into :class:`Rotated` (``Samples.rotated``): such samples are already in the
vehicle (or levelled) frame, so applying a calibration again is refused and calibrating them is said to
measure the rotation left over. A CSV has no metadata: a table says its frame in a column ``frame``
(:data:`FRAME_COLUMN`) — a rotated CSV's (the frame's first word in every row: :func:`table_column_rotated`
reads it over the whole file) and a stop table's (its whole text) — by one rule (:func:`column_text`).

:func:`written_by_mountcal` also knows mountcal's other outputs (a fleet table: any ``mountcal.*`` key).
"""

from __future__ import annotations

import io
import json
import re
from collections.abc import Generator, Mapping, Sequence
from contextlib import closing
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mountcal.core.angles import ANGLE_NAMES, Angles
from mountcal.core.errors import InputError
from mountcal.core.option_names import option
from mountcal.core.paths import special_kind
from mountcal.core.result import Convention

PREFIX = "mountcal."  # a Parquet output's keys; an MCAP channel's keys go without it
FRAME_KEY = "frame"
CALIBRATION_KEY = "calibration"
FRAME_CONVENTION = "frame"  # the name of the Convention saying the samples' frame (frame_convention)
FRAME_NAMES = ("vehicle", "levelled")  # the first word of the frame mountcal writes (core.result's frames)
SENSOR = "sensor"  # a table's frame column for the sensor's own axes (what no column means too)
FRAME_COLUMN = "frame"  # a table's column saying its samples' frame (a CSV has no metadata to say it)


@dataclass(frozen=True)
class Rotated:
    """Samples a file says mountcal already rotated: into which frame, by what calibration, and where it says so.

    ``frame`` is ``"vehicle"`` or ``"levelled"``; ``calibration`` what the file records of the calibration
    applied (its input and angles, "" when it records none); ``by`` the metadata that says it.
    """

    frame: str
    calibration: str
    by: str

    def sentence(self) -> str:
        """``samples mountcal rotate already put in the vehicle frame (calibration from …, roll … pitch … yaw …)``."""
        said = f" ({self.calibration})" if self.calibration else ""
        return f"samples mountcal rotate already put in the {self.frame} frame{said}"


def rotated_by(metadata: Mapping[str, str], by: str, prefix: str = "") -> Rotated | None:
    """What ``metadata`` (keys after ``prefix``) says of a rotation mountcal applied, or None (sensor frame)."""
    frame = metadata.get(prefix + FRAME_KEY)
    if frame is None:
        return None
    word = frame_word(frame)
    return Rotated(word if word in FRAME_NAMES else frame, _calibration(metadata.get(prefix + CALIBRATION_KEY)), by)


def frame_word(frame: str) -> str:
    """The first word of a frame's text (``vehicle``, ``levelled``, ``sensor``): what a rotated CSV's column holds."""
    return frame.strip().split(" ", 1)[0]


def _calibration(text: str | None) -> str:
    """The input and angles of the calibration JSON rotate stored (:func:`mountcal.apply.rotate_log`)."""
    try:
        doc = json.loads(text) if text else None
    except ValueError:
        return ""
    if not isinstance(doc, dict):
        return ""
    angles = [
        f"{name} {value:.2f}°"
        for name in ANGLE_NAMES[:3]
        if isinstance(value := doc.get(Angles.value_column(name)), int | float)
    ]
    source = f"from {doc['input']}" if isinstance(doc.get("input"), str) and doc["input"] else ""
    return "calibration " + ", ".join(filter(None, [source, " ".join(angles)])) if source or angles else ""


def parquet_rotated(path: Path) -> Rotated | None:
    """What a Parquet file's key-value metadata says of its samples' frame (None: sensor frame)."""
    import pyarrow.parquet as pq

    raw = pq.read_schema(path).metadata or {}
    metadata = {k.decode(errors="replace"): v.decode(errors="replace") for k, v in raw.items()}
    return rotated_by(metadata, f"the file's Parquet metadata ({PREFIX}{FRAME_KEY})", PREFIX)


def channel_rotated(metadata: Mapping[str, str], topic: str) -> Rotated | None:
    """What an MCAP channel's metadata says of its samples' frame (None: sensor frame)."""
    return rotated_by(metadata, f"the metadata of the MCAP channel {topic!r} ({FRAME_KEY})")


def topic_label(topic: str, metadata: Mapping[str, str]) -> str:
    """``'/imu/data/vehicle' (mountcal rotate's vehicle-frame output)`` for a listing of topics."""
    rotated = channel_rotated(metadata, topic)
    return repr(topic) + (f" (mountcal rotate's {rotated.frame}-frame output)" if rotated else "")


def frame_convention(rotated: Rotated) -> Convention:
    """The samples' frame as a convention of the input (``provenance.conventions``)."""
    said = f"; {rotated.calibration}" if rotated.calibration else ""
    return Convention(FRAME_CONVENTION, f"{rotated.frame} (mountcal rotate's output{said})", "stated", rotated.by)


_FRAME_VALUE = re.compile(r"(?P<frame>\S+) \(mountcal rotate's output(?:; (?P<calibration>.*))?\)", re.S)


def rotated_of(conventions: Sequence[Convention]) -> Rotated | None:
    """The :class:`Rotated` a ``frame`` convention states (:func:`frame_convention`, or a stop table's
    ``frame`` column), or None: the samples are in the sensor's frame."""
    c = next((c for c in conventions if c.name == FRAME_CONVENTION), None)
    if c is None:
        return None
    found = _FRAME_VALUE.fullmatch(c.value)
    if found is None:
        return Rotated(frame_word(c.value), "", c.by)
    return Rotated(found["frame"], found["calibration"] or "", c.by)


def column_frame(values: Sequence[object], where: str, column: str) -> list[Convention]:
    """The frame a stop table's column ``frame`` says its accelerations are in: the sensor's (no convention),
    or mountcal's vehicle or levelled frame, as :func:`frame_convention` wrote it (:func:`column_text`'s rule)."""
    text = column_text(values, where, column)
    return [] if text is None else [Convention(FRAME_CONVENTION, text, "stated", f"{where}: column {column}")]


def column_rotated(values: Sequence[object], where: str, column: str = FRAME_COLUMN) -> Rotated | None:
    """What a sample table's column ``frame`` says (``values``: the column's distinct values over the whole
    file): None for the sensor's frame, else the :class:`Rotated` of mountcal rotate's CSV output (the word
    its rows hold; a column records no calibration). The rule is :func:`column_text`'s."""
    text = column_text(values, where, column)
    return None if text is None else Rotated(frame_word(text), "", f"the column {column} of {where}")


def column_text(values: Sequence[object], where: str, column: str) -> str | None:
    """The one frame a table's column holds in every row (None: ``sensor``, the sensor's own axes).

    Raises
    ------
    InputError
        Not one value in every row, or a first word other than ``sensor``, ``vehicle``, ``levelled``:
        naming the file, the column and the values found (a column of that name holding something else
        is taken for mountcal's mark by its name, so it is to be renamed).
    """
    texts = {_text(v) for v in values}
    words = (SENSOR, *FRAME_NAMES)
    if len(texts) != 1 or not {frame_word(t) for t in texts} <= set(words):
        shown = sorted(repr(t) for t in texts)
        raise InputError(
            where,
            f"one frame in every row of the column {column}, its first word {', '.join(words)}",
            f"{len(texts)} value(s) in the column {column}: {', '.join(shown)}"
            if len(shown) <= _SHOWN
            else f"more than {_SHOWN} values in the column {column}, among them {', '.join(shown[:_SHOWN])}",
            f"Give every row the frame of its samples ({SENSOR}: the sensor's own axes; vehicle or levelled: "
            f"mountcal rotate's output), one file per frame; a column {column} holding anything else: rename it.",
        )
    text = texts.pop()
    return None if frame_word(text) == SENSOR else text


_SHOWN = 6  # the values a refusal lists


def _text(value: object) -> str:
    """A cell as text: empty for a missing one (None, NaN), bytes decoded."""
    if value is None or (isinstance(value, float) and value != value):
        return ""
    return (value.decode(errors="replace") if isinstance(value, bytes) else str(value)).strip()


def table_column_rotated(path: Path, names: Sequence[str], sep: str = ",") -> Rotated | None:
    """What a table's column ``frame`` says over the whole file (:func:`column_rotated`); None without one.

    ``names`` are the table's columns (its header), ``sep`` a CSV's delimiter. The column is read alone,
    before any sample is used — a file read in chunks is judged as a whole one — and only its distinct
    values reach Python (pyarrow's ``unique`` a batch; a CSV by position, as bytes, its whole lines when
    it was cut and that is allowed, a row with too few or too many fields skipped: it holds no sample).

    Raises
    ------
    InputError
        The column's values (:func:`column_text`), or a CSV that does not parse.
    """
    import pyarrow as pa
    import pyarrow.compute as pc

    if FRAME_COLUMN not in names:
        return None
    found: set[object] = set()
    batches = _parquet_column(path) if path.suffix.lower() in (".parquet", ".pq") else _csv_column(path, names, sep)
    with closing(batches):
        try:
            for column in batches:
                found.update(pc.unique(column).to_pylist())
                if len(found) > _SHOWN:  # refused whatever follows: reading on would only list more
                    break
        except (pa.ArrowInvalid, OSError) as err:
            raise InputError(
                str(path), "a sample table", f"a file that does not parse ({err})", "Check the file."
            ) from err
    return column_rotated(sorted(found, key=str), str(path))


def _parquet_column(path: Path) -> Generator[Any, None, None]:
    import pyarrow.parquet as pq

    for batch in pq.ParquetFile(path).iter_batches(batch_size=1 << 20, columns=[FRAME_COLUMN]):
        yield batch.column(0)


def _csv_column(path: Path, names: Sequence[str], sep: str) -> Generator[Any, None, None]:
    import pyarrow as pa
    import pyarrow.csv as pa_csv

    from mountcal.io.inputs import comment_lines
    from mountcal.io.whole import text_source

    ours = f"c{list(names).index(FRAME_COLUMN)}"  # by position: the caller has read (and stripped) the names
    above = comment_lines(path)  # '#' lines above the header (mountcal.io.table.mapped.dialect reads past them)
    source = text_source(path)
    try:
        reader = pa_csv.open_csv(
            source,
            read_options=pa_csv.ReadOptions(
                skip_rows=above + 1, column_names=[f"c{i}" for i in range(len(names))], block_size=1 << 22
            ),
            parse_options=pa_csv.ParseOptions(delimiter=sep, invalid_row_handler=lambda _: "skip"),
            convert_options=pa_csv.ConvertOptions(include_columns=[ours], column_types={ours: pa.binary()}),
        )
        for batch in reader:
            yield batch.column(0)
    finally:
        if isinstance(source, io.IOBase):  # a cut file's whole lines (mountcal.io.whole)
            source.close()


def refuse_rotated(rotated: Rotated | None, where: str, because: str, todo: str) -> None:
    """Refuse samples mountcal already rotated (``rotated`` not None) where the sensor's own frame is
    needed: applying the mounting again, or fitting or applying a triad calibration (the sensor's axes).

    Raises
    ------
    InputError
        Naming what the file states (the frame, the calibration applied), ``because`` and ``todo``.
    """
    if rotated is not None:
        raise InputError(where, "samples in the sensor's frame", f"{rotated.sentence()}: {because}", todo)


def refuse_leftover(conventions: Sequence[Convention], where: str, to: str) -> None:
    """Refuse to use as a mounting a calibration made of samples mountcal had already rotated: its angles
    are the rotation left over in mountcal's frame, not the sensor's mounting (``to``: what it was asked for).

    Raises
    ------
    InputError
        ``conventions`` (the calibration's provenance) state a ``frame`` (:func:`frame_convention`).
    """
    rotated = rotated_of(conventions)
    if rotated is not None:
        raise InputError(
            where,
            f"a calibration of a log in the sensor's own frame, to {to}",
            f"a calibration of {rotated.sentence()}: its angles are the rotation left over, not the sensor's mounting",
            "Use the calibration that rotation applied, or calibrate the original log.",
        )


def frame_note(rotated: Rotated) -> str:
    """What a calibration of such samples measures."""
    return (
        f"the samples are already in mountcal's {rotated.frame} frame, as {rotated.by} says: the angles are "
        f"relative to that frame, the rotation left over (≈ 0 when the rotation applied was right)"
    )


def with_frame_note(notes: tuple[str, ...], conventions: Sequence[Convention]) -> tuple[str, ...]:
    """``notes`` with what a calibration of rotated samples measures, once, when ``conventions`` say
    the samples were rotated (from a log's metadata or a stop table's ``frame`` column)."""
    rotated = rotated_of(conventions)
    if rotated is None or (note := frame_note(rotated)) in notes:
        return notes
    return (*notes, note)


FLEET_MARK = b"mountcal.fleet"  # a fleet table's Parquet key (mountcal.fleet.store writes it)
_JSON_LOOK = 1 << 20  # bytes of a JSON file read to see whether mountcal wrote it (its "format" comes first)


def not_samples(path: Path) -> tuple[str, str] | None:
    """What an output of mountcal holds when it is not samples — a fleet table, a calibration result, a triad
    calibration — and what to do with it; None for anything else (a rotated log holds samples).

    A file given where a log or a stop table is expected, recognised by its content, never by its name.
    """
    suffix = path.suffix.lower()
    if special_kind(path) is not None or not path.is_file():
        return None
    try:
        if suffix in (".parquet", ".pq"):
            import pyarrow.parquet as pq

            if FLEET_MARK in (pq.read_schema(path).metadata or {}):
                return (
                    "a table mountcal fleet wrote (its Parquet metadata mountcal.fleet): results per log, not samples",
                    "Calibrate the logs it lists (its column log), or read it with pandas.",
                )
        if suffix == ".json":
            with path.open("rb") as f:
                found = re.search(rb'"format"\s*:\s*"(mountcal\.[a-z_.]+)"', f.read(_JSON_LOOK))
            if found is not None:
                what = found[1].decode()
                use = f"pass it with {option('triad')}" if what.endswith("triad") else "rotate or export with it"
                return (
                    f"a {what} JSON mountcal wrote: an answer, not a log",
                    f"Calibrate the log it came from; {use}.",
                )
    except Exception:  # unreadable: not recognisably ours; the reader will say what is wrong with it
        return None
    return None


def written_by_mountcal(path: Path) -> bool:
    """Whether mountcal wrote this file (recognised by its metadata, not its name).

    A fleet table or a rotated log in Parquet carries ``mountcal.*`` file metadata; a rotated MCAP
    has a channel whose metadata holds the frame and the calibration applied; a rotated CSV says
    ``vehicle`` or ``levelled`` in its column ``frame``. Such a file is an output, never a log to
    calibrate (a rotated log would calibrate to the identity).
    """
    suffix = path.suffix.lower()
    if special_kind(path) is not None:  # a FIFO would block the look inside; its reader refuses it
        return False
    try:
        if suffix in (".parquet", ".pq"):
            import pyarrow.parquet as pq

            keys = (pq.read_schema(path).metadata or {}).keys()
            return any(k.startswith(PREFIX.encode()) for k in keys)
        if suffix == ".mcap":
            from mcap.reader import make_reader

            with path.open("rb") as f:
                summary = make_reader(f).get_summary()
            channels = summary.channels.values() if summary is not None else ()
            return any({FRAME_KEY, CALIBRATION_KEY} <= c.metadata.keys() for c in channels)
        if suffix == ".csv":  # as mountcal rotate writes it: comma-separated, its column frame named exactly
            with path.open("rb") as f:  # the header line alone: a fleet's listing looks at every CSV (0.1 ms each)
                header = f.readline(1 << 16).decode("utf-8", errors="replace").lstrip("\ufeff").rstrip("\r\n")
            names = [name.strip().strip('"') for name in header.split(",")]
            return FRAME_COLUMN in names and table_column_rotated(path, names) is not None
    except Exception:  # unreadable: not recognisably ours; the log reader will say what is wrong with it
        return False
    return False


__all__ = [
    "FRAME_COLUMN",
    "FRAME_CONVENTION",
    "Rotated",
    "channel_rotated",
    "column_frame",
    "column_rotated",
    "column_text",
    "frame_convention",
    "frame_note",
    "frame_word",
    "not_samples",
    "parquet_rotated",
    "refuse_leftover",
    "refuse_rotated",
    "rotated_by",
    "rotated_of",
    "table_column_rotated",
    "topic_label",
    "with_frame_note",
    "written_by_mountcal",
]
