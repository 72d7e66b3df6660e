"""Tables read through a :class:`~mountcal.io.table.layout.Layout`: mapped columns, units converted, exports
recognised. Read whole (:func:`read_mapped`) or in batches of bounded memory (:func:`iter_mapped`).

CSV files are read with their own delimiter (``,``, ``;`` or tab, from the header line) and a decimal
comma where a ``;``-separated file writes one. Rows with a missing or non-numeric value in a sample
column are dropped and counted; so are unreadable times.
"""

from __future__ import annotations

import csv
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from mountcal.core.errors import InputError
from mountcal.core.option_names import option
from mountcal.io.inputs import check_parquet_rows, check_regular_file, comment_lines, max_rows, too_many_rows
from mountcal.io.samples import GRAVITY_BAND_G, Channel, FloatArray, Samples, marked_gravity_free
from mountcal.io.table.layout import ACC, CHANNELS, G_N, GYRO, TIME_UNITS, Layout
from mountcal.io.table.time_unit import TYPED, clock_seconds, iso_seconds, typed_seconds
from mountcal.io.timestamps import REORDERED, table_order
from mountcal.io.whole import parquet_end, text_end, text_source

PARQUET = (".parquet", ".pq")
_COMMA_DECIMAL = re.compile(r"[-+]?\d+,\d+(?:[eE][-+]?\d+)?")
_DOT_DECIMAL = re.compile(r"[-+]?\d*\.\d+(?:[eE][-+]?\d+)?")
_DROPPED = "rows with missing or non-numeric values"


def header(path: Path) -> tuple[list[str], dict[str, str]]:
    """The column names of a CSV or Parquet table, and how to read a CSV (:func:`dialect`)."""
    check_regular_file(path, "sample table")
    where = str(path)
    if path.suffix.lower() in PARQUET:
        import pyarrow.parquet as pq

        parquet_end(path)  # cut short: refused with the byte where it ends (mountcal.io.whole)
        try:
            return [str(n) for n in pq.read_schema(path).names], {}
        except Exception as err:  # pyarrow raises many types for malformed files
            raise InputError(
                where, "a Parquet table", f"a file that does not parse ({err})", "Check the file."
            ) from err
    with path.open("rb") as f:
        check_text(f.read(256), where)  # UTF-16 first: its last line break is two bytes, read as a cut file
    text_end(path)  # a last line without its line break: cut short, refused unless allowed
    return csv_header(path)


def csv_header(path: Path) -> tuple[list[str], dict[str, str]]:
    """:func:`dialect` of a CSV file's first lines: the comment lines above its header (a bounded number),
    the header, a row. A look at its head only (whether the file is whole is its reader's to say)."""
    with path.open("rb") as f:
        lines = [f.readline() for _ in range(comment_lines(path) + 2)]
    return dialect(b"".join(lines), str(path))


_COMMENT = "#"


def check_text(head: bytes, where: str) -> None:
    """Refuse a CSV in UTF-16 or UTF-32 (a spreadsheet's "Unicode text"), told by its first bytes ``head``:
    a byte-order mark, or zero bytes between the characters. Read as UTF-8 it would be noise.

    Raises
    ------
    InputError
        Naming the encoding found and how to save the file as UTF-8.
    """
    head = head[:256]
    if head.startswith((b"\xff\xfe", b"\xfe\xff")) or head.count(0) > len(head) // 4:
        raise InputError(
            where,
            "a CSV in UTF-8 (or ASCII)",
            "UTF-16 or UTF-32 text (a byte-order mark or zero bytes between the characters)",
            'Save it as UTF-8 (a spreadsheet\'s "CSV UTF-8"), e.g. iconv -f UTF-16 -t UTF-8 IN > OUT.csv.',
        )


def dialect(head: bytes, where: str) -> tuple[list[str], dict[str, str]]:
    """The column names of a CSV from its first bytes ``head``, and how to read it (``read_as``, the
    :func:`pandas.read_csv` options every reader of a table passes): its delimiter (``,``, ``;`` or tab, the
    one the header line holds most), a decimal comma where a ``;``-separated file's first row writes one, and
    ``comment`` where lines starting with ``#`` (a logger's preamble) stand above the header.

    Raises
    ------
    InputError
        UTF-16 or UTF-32 text (:func:`check_text`).
    """
    check_text(head, where)
    lines = head.decode("utf-8", errors="replace").removeprefix("\ufeff").splitlines()
    skipped = 0
    while skipped < len(lines) and lines[skipped].lstrip().startswith(_COMMENT):
        skipped += 1
    first = lines[skipped] if skipped < len(lines) else ""
    row = lines[skipped + 1] if skipped + 1 < len(lines) else ""
    sep = max((",", ";", "\t"), key=first.count)
    names = next(csv.reader([first], delimiter=sep)) if first else []
    read_as = {} if sep == "," else {"sep": sep}
    fields = [f.strip() for f in row.split(sep)]
    if sep != "," and sum(bool(_COMMA_DECIMAL.fullmatch(f)) for f in fields) > sum(
        bool(_DOT_DECIMAL.fullmatch(f)) for f in fields
    ):
        read_as["decimal"] = ","
    if skipped:
        read_as["comment"] = _COMMENT
    return [n.strip() for n in names], read_as


def _frames(path: Path, layout: Layout, read_as: dict[str, str], rows: int | None) -> Iterator[pd.DataFrame]:
    """The table's used columns, whole (``rows`` None) or in pieces of ``rows``."""
    used = list(dict.fromkeys(c.name for c in layout.columns.values()))
    where = str(path)
    try:
        if path.suffix.lower() in PARQUET:
            import pyarrow.parquet as pq

            check_parquet_rows(path)
            file = pq.ParquetFile(path)
            for batch in file.iter_batches(batch_size=rows or 1 << 20, columns=used):
                yield batch.to_pandas()
            return
        reader = pd.read_csv(
            text_source(path),  # a cut file read with --allow-truncated: its whole lines
            usecols=lambda c: str(c).strip() in used,
            dtype={layout.time.name: str} if layout.time.unit in ("iso", "clock") else None,
            chunksize=rows,
            skipinitialspace=True,
            encoding="utf-8-sig",
            **read_as,
        )
        if rows is None:
            yield reader.rename(columns=str.strip)
        else:
            with reader:  # closed when the reading stops early too (a refusal after the first chunk)
                for chunk in reader:
                    yield chunk.rename(columns=str.strip)
    except (ValueError, pd.errors.ParserError, UnicodeDecodeError, OSError) as err:
        raise InputError(
            where, "a CSV or Parquet sample table", f"a file that does not parse ({err})", "Check the file."
        ) from err


def _numbers(values: Any) -> FloatArray:
    return np.asarray(pd.to_numeric(values, errors="coerce"), dtype=np.float64)


def _time(values: pd.Series, layout: Layout) -> FloatArray:
    """Seconds (Unix epoch or the table's own zero); NaN where unreadable."""
    column = layout.time
    if column.unit in TYPED:  # a Parquet timestamp or duration (io.table.time_unit)
        typed = typed_seconds(values)
        if typed is not None:
            return typed
    if column.unit == "iso":
        return iso_seconds(values)
    if column.unit == "clock":
        return clock_seconds(values)
    if pd.api.types.is_integer_dtype(values.dtype) and column.scale in TIME_UNITS.values() and column.scale < 1:
        per_second = round(1.0 / column.scale)  # whole ns/us/ms since an epoch: exact seconds, then the fraction
        ints: NDArray[np.int64] = values.to_numpy(dtype=np.int64)
        return (ints // per_second).astype(np.float64) + (ints % per_second) / per_second
    return _numbers(values) * column.scale + column.offset


def _samples(df: pd.DataFrame, layout: Layout, where: str, whole: bool = True) -> Samples:
    """The samples of ``df``: of a ``whole`` table in time order (recordings joined refused, rows put in order
    counted); of a chunk in the file's order, as the chunked native reader keeps it (``rotate`` writes each
    row where it stood; a chunk cannot see the rows it would be sorted among)."""
    cols = layout.columns
    t = _time(df[cols["time"].name], layout)
    acc = np.column_stack([_numbers(df[cols[r].name]) * cols[r].scale + cols[r].offset for r in ACC])
    gyro = None
    if all(r in cols for r in GYRO):
        gyro = np.column_stack([_numbers(df[cols[r].name]) * cols[r].scale + cols[r].offset for r in GYRO])
    ok = np.isfinite(t) & np.isfinite(acc).all(axis=1)
    if gyro is not None:
        ok &= np.isfinite(gyro).all(axis=1)
    channels = {}
    for role, key in CHANNELS.items():
        if role in cols:
            v = _numbers(df[cols[role].name]) * cols[role].scale + cols[role].offset
            good = np.isfinite(v) & np.isfinite(t)
            channels[key] = Channel(t[good], v[good])
    order, reordered = table_order(t[ok], where) if whole else (np.arange(int(ok.sum())), 0)
    dropped = {_DROPPED: int((~ok).sum())} if not ok.all() else {}
    if reordered:
        dropped[REORDERED] = reordered
    return Samples(
        t[ok][order],
        acc[ok][order],
        None if gyro is None else gyro[ok][order],
        {k: _sorted(ch) for k, ch in channels.items()},
        source=where,
        dropped=dropped,
        notes=layout.notes,
        gravity_free=layout.gravity_free,
    )


def _sorted(ch: Channel) -> Channel:
    order = np.argsort(ch.t_s, kind="stable")
    return Channel(ch.t_s[order], ch.value[order])


def read_mapped(path: Path, layout: Layout, read_as: dict[str, str]) -> Samples:
    """The whole table's samples (sorted by time)."""
    where = str(path)
    frames = list(_frames(path, layout, read_as, None))
    df = frames[0] if len(frames) == 1 else pd.concat(frames, ignore_index=True)
    if len(df) > max_rows():
        raise too_many_rows(where, "table rows", len(df))
    samples = _samples(df, layout, where)
    if not len(samples):
        raise InputError(
            where,
            "numbers in the columns read as time, ax, ay, az "
            f"({', '.join(layout.columns[r].name for r in ('time', *ACC))})",
            "no row with numbers in all of them",
            "Check the column map and units.",
        )
    return samples


def iter_mapped(path: Path, layout: Layout, read_as: dict[str, str], max_samples: int) -> Iterator[Samples]:
    """The table's samples in batches of at most ``max_samples`` rows (each sorted by time)."""
    where = str(path)
    for df in _frames(path, layout, read_as, max_samples):
        yield _samples(df, layout, where, whole=False)


def check_magnitude(samples: Samples, layout: Layout, where: str) -> Samples:
    """``samples`` after a look at their acceleration's median magnitude, which gravity sets near 1 g.

    Below 0.5 m/s², the acceleration has no gravity in it: the samples are marked gravity-free (they
    read, but do not calibrate). Outside 0.5–1.5 g otherwise, the unit is wrong: refused, with the unit
    the magnitude fits (g, mg, or counts of 1/N g).
    """
    if not len(samples) or layout.gravity_free:
        return samples
    marked = marked_gravity_free(samples)
    if marked.gravity_free:
        return marked
    m = float(np.median(np.linalg.norm(samples.acc_s, axis=1)))  # m/s², as read
    lo, hi = GRAVITY_BAND_G
    if lo * G_N <= m <= hi * G_N:
        return samples
    read_as = layout.columns["ax"].unit or "m/s2"
    fits = fitting_unit(m, read_as)
    todo = (
        f"If the columns are in {fits}, say so: {option('columns', _column_map(layout, fits))}."
        if fits
        else f"Give the columns' unit in {option('columns')} (g, mg, m/s2, or g/N for counts of 1/N g)."
    )
    return _refuse(where, read_as, m, todo)


def fitting_unit(m: float, read_as: str = "m/s2") -> str:
    """The acceleration unit a median magnitude ``m`` (m/s², as read in ``read_as``) fits: ``g``, ``mg``, or
    raw counts ``g/N`` (N per g, a power of two for most sensors); "" where none does."""
    per_g = m / G_N if read_as.split("/")[0] == "g" else m  # the value 1 g takes in the column, roughly
    if 0.8 <= per_g <= 1.25:
        return "g"
    if 800 <= per_g <= 1250:
        return "mg"
    if per_g > 16:
        return f"g/{2 ** round(np.log2(per_g))}"
    return ""


def _column_map(layout: Layout, acc_unit: str) -> str:
    """The column map reading this layout with the acceleration in ``acc_unit`` (every column it reads)."""
    items = []
    for role, c in layout.columns.items():
        unit = acc_unit if role in ACC else c.unit
        items.append(f"{role}={c.name}" + (f":{unit}" if unit else ""))
    return ",".join(items)


def _refuse(where: str, read_as: str, m: float, todo: str) -> Samples:
    raise InputError(
        where,
        f"accelerations of magnitude near 1 g ({GRAVITY_BAND_G[0]:g}–{GRAVITY_BAND_G[1]:g} g) read in {read_as}",
        f"a median magnitude of {m:.4g} m/s² ({m / G_N:.4g} g)",
        todo,
    )


__all__ = ["check_magnitude", "check_text", "csv_header", "dialect", "header", "iter_mapped", "read_mapped"]
