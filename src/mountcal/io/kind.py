"""What kind of input a path is: the one decision every command makes before it reads one.

An input is a **stop table** (CSV or Parquet, one row per parked stop: the fit's input) or a
**log**: a sample table (CSV or Parquet of time-stamped samples), a CAN log (BLF, ASC, candump
``.log``, TRC, MF4; a CSV read with a DBC), an MCAP, a comma2k19 segment folder, or the format of
a reader plugin (:mod:`mountcal.io.registry`).

The name decides where it can (a suffix, ``--dbc`` given for a CSV, a folder's layout), and so
does a column map (``--columns``, a mapping's ``[columns]``: a sample table). A CSV or Parquet table
is told apart by its content: by its columns first (a stop table's headings, noise and per-stop
columns; a sample table's gyro or speed; a known export's columns, :mod:`mountcal.io.table.layout`),
then by its rows — stops lie seconds to minutes apart, samples a fraction of a second. A table that
neither settles is refused with the option and the columns that would (:data:`KIND_OPTION`). Every
command says which kind it took and why (:attr:`InputKind.sentence`): in its log, and in a result's
provenance.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np

from mountcal.core.errors import InputError
from mountcal.io.frame import not_samples
from mountcal.io.magic import check_named_for_content

if TYPE_CHECKING:
    from mountcal.io.reader import LogOptions

Declared = Literal["auto", "stop-table", "log"]
KIND_OPTION = "--input-kind"
TABLE_SUFFIXES = (".csv", ".parquet", ".pq")
# columns only a stop table has (written by `mountcal stops`, or by hand: one value per stop)
STOP_COLUMNS = frozenset(
    {"beta_deg", "heading_ref", "n", "sx", "sy", "sz", "sx_mean", "sy_mean", "sz_mean", "rxy", "rxz", "ryz"}
    | {"duration_s", "site"}
)
SAMPLE_COLUMNS = frozenset({"gx", "gy", "gz", "speed_mps"})  # only a sample table has these
STOP_SPACING_S = 2.0  # rows at least this far apart (median) are stops: a stop lasts longer
SAMPLE_SPACING_S = 0.5  # rows at most this far apart (median) are samples, from ...
SAMPLE_MIN_ROWS = 20  # ... this many rows on
_SETTLE = (
    f"Say which: {KIND_OPTION} stop-table or {KIND_OPTION} log; or add the columns that settle it: "
    "beta_deg, or sx, sy, sz and n (a stop table), or gx, gy, gz (a sample table)."
)


@dataclass(frozen=True)
class InputKind:
    """The kind of an input, and how it was decided.

    Attributes
    ----------
    stop_table : bool
        A stop table (fitted as it is); otherwise a log (read, its stops and driving found).
    what : str
        ``"a stop table (CSV)"``, ``"a sample table (Parquet)"``, ``"a CAN log (BLF)"``, ...
    why : str
        ``"by its columns beta_deg, sx"``, ``"by its suffix"``, ``"by its rows: 12, 60 s apart"``, ...
    """

    stop_table: bool
    what: str
    why: str

    @property
    def sentence(self) -> str:
        """The kind in one phrase, as summaries and provenance say it."""
        return f"{self.what}, {self.why}"


def input_kind(
    paths: Sequence[str | Path], *, dbc: bool = False, columns: bool = False, declared: Declared = "auto"
) -> InputKind:
    """The kind of the input named by ``paths`` (one stop table, or the files of one log).

    Parameters
    ----------
    paths : sequence of paths
        ``["-"]`` is a CSV stop table on stdin; several paths are the splits of one log.
    dbc : bool
        A DBC was given: a CSV is a CAN log.
    columns : bool
        A column map was given (``--columns``, a mapping's ``[columns]``): a table is a sample table.
    declared : {"auto", "stop-table", "log"}
        What the user said (:data:`KIND_OPTION`); ``"auto"`` decides from the name and content.

    Raises
    ------
    InputError
        A table whose kind its columns and rows do not settle; a stop table among several files;
        a file no reader takes.
    """
    names = [str(p) for p in paths]
    if names == ["-"]:
        if declared == "log":
            raise InputError("-", "a log file", "stdin", "Name the log file; stdin takes a CSV stop table.")
        return InputKind(True, "a stop table (CSV on stdin)", "from stdin")
    if not names:
        raise InputError("INPUT", "a stop table or log file(s)", "none", "Name the input.")
    kinds = [_kind_of(Path(p), dbc, columns, declared) for p in names]
    if len(kinds) == 1:
        return kinds[0]
    tables = [p for p, k in zip(names, kinds, strict=True) if k.stop_table]
    if tables:
        raise InputError(
            " + ".join(names),
            "one stop table, or the files of one log",
            f"a stop table ({tables[0]}: {kinds[names.index(tables[0])].why}) among {len(names)} files",
            "Give the stop table alone, or only the log files.",
        )
    return InputKind(False, f"{len(names)} files of one log ({kinds[0].what[2:]})", kinds[0].why)


def kind_of_input(paths: Sequence[str | Path], log: LogOptions, declared: Declared = "auto") -> InputKind:
    """:func:`input_kind` of ``paths`` read as ``log`` says: the one place that tells, for every command
    (``calibrate``, ``triad``, every fleet worker), whether its input is a stop table or a log. A DBC makes a
    CSV a CAN log; a column map (``columns``, or a ``mapping`` without a DBC: its ``[columns]``) makes a
    table a sample table."""
    mapped = log.columns is not None or (log.mapping is not None and log.dbc is None)
    return input_kind(paths, dbc=log.dbc is not None, columns=mapped, declared=declared)


def _kind_of(path: Path, dbc: bool, columns: bool, declared: Declared) -> InputKind:
    from mountcal.core.paths import special_kind

    suffix = path.suffix.lower()
    table = suffix in TABLE_SUFFIXES and not (dbc and suffix == ".csv" and not _stop_columns_given_dbc(path))
    form = "CSV" if suffix == ".csv" else "Parquet"
    special = None if path.is_dir() else special_kind(path)  # a folder may be a log (a comma2k19 segment)
    if special is not None:  # refused by the reader, without opening it
        return InputKind(declared != "log", special, "not a regular file")
    check_named_for_content(path)  # a Parquet file named .csv, an MCAP named .csv: said, not misread
    if (held := not_samples(path)) is not None:  # mountcal's own answer given back as its input
        raise InputError(str(path), "a log or a stop table", held[0], held[1])
    if declared == "stop-table":
        if not table:
            raise InputError(
                str(path),
                f"a CSV or Parquet stop table ({KIND_OPTION} stop-table)",
                f"a file ending in {path.suffix or '(nothing)'}" if not path.is_dir() else "a folder",
                f"Pass the stop table, or drop {KIND_OPTION} to read the log.",
            )
        return InputKind(True, f"a stop table ({form})", f"as {KIND_OPTION} says")
    if table and declared == "log":
        return InputKind(False, f"a sample table ({form})", f"as {KIND_OPTION} says")
    if table and columns:
        return InputKind(False, f"a sample table ({form})", "read with a column map")
    if table:
        return _table_kind(path, form)
    from mountcal.io.reader import LogOptions
    from mountcal.io.registry import reader_for

    reader = reader_for(path, LogOptions(dbc="given" if dbc else None))  # raises for a file no reader takes
    if reader.name == "can":
        how = "a CSV read with a DBC" if suffix == ".csv" else f"by its suffix {suffix}"
        return InputKind(False, f"a CAN log ({suffix.lstrip('.').upper()})", how)
    if reader.name == "mcap":
        return InputKind(False, "an MCAP log", f"by its suffix {suffix}")
    if path.is_dir():
        return InputKind(False, f"a {reader.description or reader.name}", "by the folder's layout")
    return InputKind(False, f"a log ({reader.description or reader.name})", f"by its suffix {suffix}")


def _stop_columns_given_dbc(path: Path) -> bool:
    """With a DBC a CSV is a CAN log, unless its header holds a stop table's columns (a fleet folder
    of CAN logs and the stop tables beside them): python-can's CSV columns are never those."""
    try:
        return bool(table_columns(path) & STOP_COLUMNS)
    except InputError:
        return False  # the CAN reader says what is wrong with it


def _table_kind(path: Path, form: str) -> InputKind:
    """A stop table or a sample table, by the columns, else by the spacing of ``t_s``."""
    columns = table_columns(path)
    stop, sample = sorted(columns & STOP_COLUMNS), sorted(columns & SAMPLE_COLUMNS)
    if stop and sample:
        raise InputError(
            str(path),
            "the columns of a stop table or of a sample table",
            f"both: {', '.join(stop)} (a stop table's) and {', '.join(sample)} (a sample table's)",
            _SETTLE,
        )
    if stop:
        return InputKind(True, f"a stop table ({form})", f"by its columns {', '.join(stop)}")
    if sample:
        return InputKind(False, f"a sample table ({form})", f"by its columns {', '.join(sample)}")
    if "t_s" not in columns:
        from mountcal.io.table.layout import detect, suggested_map
        from mountcal.io.table.mapped import header

        export = detect(header(path)[0] if form == "CSV" else sorted(columns), path)
        if export is not None:  # a phone's or imucal's export holds samples, under its own names
            return InputKind(False, f"a sample table ({form})", f"by its columns: {export.name}")
        if not {"ax", "ay", "az"} <= columns and suggested_map(sorted(columns)) is not None:
            # no stop table (it names ax, ay, az so), but a time and an accelerometer named as a logger names
            # them ('time (s)', 'ax [g]'): samples, whose reader names the column map they say
            return InputKind(False, f"a sample table ({form})", "by its columns: a time and an acceleration")
        return InputKind(True, f"a stop table ({form})", "by its columns: no t_s, so not samples in time")
    from mountcal.io.table.time_unit import ROWS_LOOKED_AT, median_step  # the rows _times reads (a look)

    t_s = _times(path, form)
    spacing = median_step(t_s)  # NaN without two distinct times
    spaced = bool(np.isfinite(spacing))
    rows = int(t_s.shape[0])
    if spaced and spacing >= STOP_SPACING_S and rows >= ROWS_LOOKED_AT:
        _refuse_stops_or_samples(path, rows, spacing)
    if spaced and spacing >= STOP_SPACING_S:
        return InputKind(True, f"a stop table ({form})", f"by its rows: {rows}, a median {spacing:.3g} s apart")
    if rows >= SAMPLE_MIN_ROWS and spaced and spacing <= SAMPLE_SPACING_S:
        more = "+" if rows >= ROWS_LOOKED_AT else ""
        return InputKind(False, f"a sample table ({form})", f"by its rows: {rows}{more}, {1 / spacing:.3g} per second")
    found = f"{rows} rows" + (f" a median {spacing:.3g} s apart" if spaced else " without distinct times")
    raise InputError(
        str(path),
        f"a stop table (rows ≥ {STOP_SPACING_S:g} s apart) or a sample table "
        f"(≥ {SAMPLE_MIN_ROWS} rows ≤ {SAMPLE_SPACING_S:g} s apart), told by its columns or rows",
        f"columns {', '.join(sorted(columns))} and {found}",
        _SETTLE,
    )


def _refuse_stops_or_samples(path: Path, rows: int, spacing: float) -> None:
    """Thousands of rows seconds apart: a stop table of more stops than a parking session makes, or samples
    whose ``t_s`` is in another unit (a logger's ms under mountcal's name). Refused naming both readings
    where another unit gives an IMU's rate (:mod:`mountcal.io.table.time_unit`)."""
    from mountcal.core.option_names import option
    from mountcal.io.table.layout import TIME_UNITS
    from mountcal.io.table.time_unit import fits

    units = [u for u in ("ms", "us", "ns") if fits(spacing, TIME_UNITS[u])]
    if not units:
        return
    unit = units[0]
    raise InputError(
        str(path),
        f"a stop table (rows ≥ {STOP_SPACING_S:g} s apart, one per stop) or a sample table with t_s in seconds",
        f"{rows}+ rows a median {spacing:.6g} apart: {rows}+ stops, or samples at "
        f"{1.0 / (spacing * TIME_UNITS[unit]):.4g} Hz with t_s in {unit}",
        f"If t_s is in {unit}: {option('columns', f'time=t_s:{unit},ax=ax,ay=ay,az=az')}; if these are stops: "
        f"{KIND_OPTION} stop-table.",
    )


def table_columns(path: Path) -> frozenset[str]:
    """The column names of a CSV or Parquet table, read as every reader of a table reads its header."""
    return frozenset(_header(path)[0])


def _header(path: Path) -> tuple[list[str], dict[str, str]]:
    """The table's column names and how to read it as CSV (:func:`mountcal.io.table.mapped.dialect`: the
    delimiter, a decimal comma, comment lines above the header), as every reader of a table takes them."""
    if path.suffix.lower() == ".csv" and path.is_file():  # a million columns: refused before pandas reads them
        from mountcal.io.inputs import csv_columns

        csv_columns(path, str(path), charge=False)
    try:
        if path.suffix.lower() == ".csv":
            from mountcal.io.table.mapped import csv_header

            names, read_as = csv_header(path)
            if not names:
                raise ValueError("no header line")
            return names, read_as
        import pyarrow.parquet as pq

        return [str(c).strip() for c in pq.read_schema(path).names], {}
    except InputError:
        raise
    except FileNotFoundError:
        found = "no such file"
    except OSError as err:
        found = f"a file that cannot be read ({err.strerror or err})"
    except Exception as err:  # pandas and pyarrow raise many types for malformed files
        found = f"a file that does not parse ({type(err).__name__}: {err})"
    if found.startswith("a file that does not parse") and path.stat().st_size == 0:
        found = "an empty file (0 bytes)"
    raise InputError(
        str(path),
        "a CSV or Parquet stop table (beta_deg, ax, ay, az) or sample table (t_s, ax, ay, az)",
        found,
        "Check the path, or replace the file.",
    )


def _times(path: Path, form: str) -> np.ndarray:
    """The first rows' ``t_s`` in seconds (a bounded look; a timestamp type or date-time text as such)."""
    from mountcal.io.table.time_unit import first_seconds

    return first_seconds(path, "t_s", _header(path)[1] if form == "CSV" else None)


__all__ = ["KIND_OPTION", "SAMPLE_COLUMNS", "STOP_COLUMNS", "Declared", "InputKind", "input_kind", "table_columns"]
