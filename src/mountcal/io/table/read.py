"""CSV and Parquet sample tables: ``t_s, ax, ay, az`` (s, m/s²), optionally ``gx, gy, gz`` (rad/s)
and the channels :data:`TABLE_CHANNELS`; read whole (:func:`read_table`) or in batches
(:func:`iter_table`, bounded memory). Rows with a missing or non-numeric value are dropped and counted.

A CSV whose last line has no line break, or a Parquet file without its footer, was cut short
(:mod:`mountcal.io.whole`): refused, or a CSV's whole lines read with ``--allow-truncated``.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.csv as pa_csv
import pyarrow.parquet as pq
from numpy.typing import NDArray

from mountcal.core import budget
from mountcal.core.errors import InputError
from mountcal.core.option_names import option
from mountcal.core.ranges import in_range
from mountcal.io.inputs import check_parquet_rows, check_regular_file, csv_columns
from mountcal.io.samples import Channel, FloatArray, Samples
from mountcal.io.timestamps import REORDERED, table_order
from mountcal.io.whole import parquet_end, text_end, text_source

TABLE_CHANNELS = ("speed_mps", "heading_deg", "temperature_c", "lat_deg", "lon_deg", "alt_m")


def read_table(path: Path) -> Samples:
    """A CSV or Parquet table of samples: ``t_s, ax, ay, az`` in s and m/s²."""
    check_regular_file(path, "sample table")
    parquet = path.suffix.lower() in (".parquet", ".pq")
    if parquet:
        parquet_end(path)
        check_parquet_rows(path)
    else:  # a header of a million columns is refused before pandas parses it
        csv_columns(path, str(path))
    source = path if parquet else text_source(path)  # a cut CSV: refused, or its whole lines (allowed)
    try:
        df = pd.read_parquet(source) if parquet else pd.read_csv(source, low_memory=False)
    except FileNotFoundError as err:
        raise InputError(str(path), "a readable sample table", "no such file", "Check the path.") from err
    except Exception as err:  # pandas raises many types for malformed files
        raise InputError(
            str(path),
            "a CSV or Parquet sample table",
            f"a file that does not parse ({err})",
            "Write columns t_s, ax, ay, az (s, m/s²).",
        ) from err
    missing = [c for c in ("t_s", "ax", "ay", "az") if c not in df.columns]
    if missing:
        raise InputError(
            str(path),
            "columns t_s, ax, ay, az",
            f"no {', '.join(missing)}",
            f"Rename the columns; a CAN log in CSV needs a DBC ({option('dbc')}).",
        )
    budget.charge("rows", len(df), str(path), "table rows")
    values = df[["t_s", "ax", "ay", "az"]].apply(pd.to_numeric, errors="coerce").to_numpy(dtype=float)
    gyro = (
        df[["gx", "gy", "gz"]].apply(pd.to_numeric, errors="coerce").to_numpy(dtype=float)
        if {"gx", "gy", "gz"} <= set(df.columns)
        else None
    )
    numeric = np.all(np.isfinite(values), axis=1) & (gyro is None or np.all(np.isfinite(gyro), axis=1))
    ok = numeric & _in_range(values[:, 0], values[:, 1:], gyro)
    dropped = {}
    if not numeric.all():
        dropped["rows with missing or non-numeric values"] = int((~numeric).sum())
    if (numeric & ~ok).any():
        dropped[_OUT_OF_RANGE] = int((numeric & ~ok).sum())
    if not ok.any() and numeric.any():  # numbers, all outside a physical range: a unit, said as such
        raise _outside(str(path), values[numeric], gyro is not None)
    if not ok.any():
        raise InputError(
            str(path),
            "numeric t_s, ax, ay, az",
            "no row with numbers in all of them",
            "Check the table's columns and units.",
        )
    order, reordered = table_order(values[ok, 0], str(path))  # joined recordings refused; out of order: said
    if reordered:
        dropped[REORDERED] = reordered
    channels = {}
    for name in TABLE_CHANNELS:
        if name in df.columns:
            v = pd.to_numeric(df[name], errors="coerce").to_numpy(dtype=float)
            channels[name] = _channel(name, values[:, 0], v, dropped)  # t_s as the samples read it (a text row: NaN)
    return Samples(
        values[ok, 0][order],
        values[ok, 1:][order],
        None if gyro is None else gyro[ok][order],
        channels,
        source=str(path),
        dropped=dropped,
    )


_REQUIRED = ("t_s", "ax", "ay", "az")
_OUT_OF_RANGE = "rows with a time, acceleration or rate outside its physical range (docs/reliability.md)"


def _outside(where: str, values: FloatArray, gyro: bool) -> InputError:
    """The refusal of a table whose rows are numbers but none inside the physical ranges: the acceleration's
    median magnitude, and the unit it fits (:func:`mountcal.io.table.mapped.fitting_unit`)."""
    from mountcal.io.table.mapped import fitting_unit

    m = float(np.median(np.linalg.norm(values[:, 1:], axis=1)))
    unit = fitting_unit(m)
    rest = ",gx=gx,gy=gy,gz=gz" if gyro else ""
    fix = f"time=t_s,ax=ax:{unit},ay=ay:{unit},az=az:{unit}{rest}"
    return InputError(
        where,
        "t_s, ax, ay, az in s and m/s² inside their physical ranges (docs/reliability.md)",
        f"{values.shape[0]} rows of numbers, none inside them: the acceleration's median magnitude is {m:.4g} "
        "read as m/s²" + (f", as 1 g reads in {unit}" if unit else ""),
        f"If ax, ay, az are in {unit}, say so: {option('columns', fix)}."
        if unit
        else f"Give the columns' units in {option('columns')} (g, mg, m/s2, or g/N for counts of 1/N g).",
    )


def _channel(name: str, t: FloatArray, v: FloatArray, dropped: dict[str, int]) -> Channel:
    """A channel's finite values inside its range (mountcal.core.ranges); those outside it are counted."""
    finite = np.isfinite(v) & np.isfinite(t)
    good = finite & in_range(name, v) & in_range("time_s", t)  # each channel is named as its quantity
    if (finite & ~good).any():
        dropped[f"{name} values outside the physical range (docs/reliability.md)"] = int((finite & ~good).sum())
    return Channel(t[good], v[good])


def _in_range(t: FloatArray, acc: FloatArray, gyro: FloatArray | None) -> NDArray[np.bool_]:
    """Rows whose time, acceleration and rate are finite and inside their ranges (mountcal.core.ranges)."""
    ok = np.asarray(in_range("time_s", t) & in_range("acc_mps2", acc).all(axis=1), dtype=np.bool_)
    return ok if gyro is None else ok & in_range("gyro_rad_s", gyro).all(axis=1)


def iter_table(path: Path, max_samples: int) -> Iterator[Samples]:
    """A CSV or Parquet sample table in batches; rows with a non-finite value dropped and counted."""
    where = str(path)
    if not path.is_file():
        raise InputError(where, "a readable sample table", "no such file", "Check the path.")
    if path.suffix.lower() == ".csv":
        text_end(path)  # a cut CSV: refused here, before any parse (allowed: its whole lines are read)
    else:
        parquet_end(path)
    try:
        if path.suffix.lower() == ".csv":
            csv_columns(path, where)  # a header of a million columns is refused before it is parsed
            names = pa_csv.open_csv(text_source(path)).schema.names
            wanted = [c for c in (*_REQUIRED, "gx", "gy", "gz", *TABLE_CHANNELS) if c in names]
            reader: Any = pa_csv.open_csv(
                text_source(path),
                read_options=pa_csv.ReadOptions(block_size=1 << 22),
                convert_options=pa_csv.ConvertOptions(
                    include_columns=wanted, column_types=dict.fromkeys(wanted, pa.float64())
                ),
            )
        else:
            parquet = pq.ParquetFile(path)
            names = parquet.schema_arrow.names
            budget.charge("columns", len(names), where, "table columns")
            wanted = [c for c in (*_REQUIRED, "gx", "gy", "gz", *TABLE_CHANNELS) if c in names]
            reader = parquet.iter_batches(batch_size=max_samples, columns=wanted)
    except (pa.ArrowInvalid, OSError) as err:
        raise InputError(
            where, "a CSV or Parquet sample table", f"a file that does not parse ({err})", "Check the file."
        ) from err
    missing = [c for c in _REQUIRED if c not in names]
    if missing:
        raise InputError(
            where,
            "columns t_s, ax, ay, az",
            f"no {', '.join(missing)}",
            f"Rename the columns; a CAN log in CSV needs a DBC ({option('dbc')}).",
        )
    gyro = all(c in names for c in ("gx", "gy", "gz"))
    try:
        for batch in reader:
            for start in range(0, batch.num_rows, max_samples):
                yield _table_samples(batch.slice(start, max_samples), gyro, where)
    except pa.ArrowInvalid as err:
        raise InputError(
            where, "numbers in every sample column", f"a value that is not one ({err})", "Fix or remove that row."
        ) from err


def _table_samples(batch: pa.RecordBatch, gyro: bool, where: str) -> Samples:
    def col(name: str) -> FloatArray:
        return np.asarray(batch.column(name).to_numpy(zero_copy_only=False), dtype=np.float64)

    t = col("t_s")
    acc = np.column_stack([col(c) for c in ("ax", "ay", "az")])
    g = np.column_stack([col(c) for c in ("gx", "gy", "gz")]) if gyro else None
    ok = _in_range(t, acc, g)
    channels = {}
    finite = np.isfinite(t) & np.isfinite(acc).all(axis=1) & (g is None or np.isfinite(g).all(axis=1))
    dropped: dict[str, int] = {}
    for name in TABLE_CHANNELS:
        if name in batch.schema.names:
            channels[name] = _channel(name, t, col(name), dropped)
    if not finite.all():
        dropped["non-finite sample rows"] = int((~finite).sum())
    if (finite & ~ok).any():
        dropped[_OUT_OF_RANGE] = int((finite & ~ok).sum())
    return Samples(t[ok], acc[ok], None if g is None else g[ok], channels, source=where, dropped=dropped)


__all__ = ["TABLE_CHANNELS", "iter_table", "read_table"]
