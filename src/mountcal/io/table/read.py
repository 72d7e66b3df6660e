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

from mountcal.errors import InputError
from mountcal.io.inputs import check_parquet_rows, check_regular_file
from mountcal.io.whole import parquet_end, text_end, text_source
from mountcal.option_names import option
from mountcal.samples import Channel, FloatArray, Samples

TABLE_CHANNELS = ("speed_mps", "heading_deg", "temperature_c", "lat_deg", "lon_deg", "alt_m")


def read_table(path: Path) -> Samples:
    """A CSV or Parquet table of samples: ``t_s, ax, ay, az`` in s and m/s²."""
    check_regular_file(path, "sample table")
    parquet = path.suffix.lower() in (".parquet", ".pq")
    if parquet:
        parquet_end(path)
        check_parquet_rows(path)
    source = path if parquet else text_source(path)  # a cut CSV: refused, or its whole lines (allowed)
    try:
        df = pd.read_parquet(source) if parquet else pd.read_csv(source)
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
    values = df[["t_s", "ax", "ay", "az"]].apply(pd.to_numeric, errors="coerce").to_numpy(dtype=float)
    ok = np.all(np.isfinite(values), axis=1)
    gyro = (
        df[["gx", "gy", "gz"]].apply(pd.to_numeric, errors="coerce").to_numpy(dtype=float)
        if {"gx", "gy", "gz"} <= set(df.columns)
        else None
    )
    if gyro is not None:
        ok &= np.all(np.isfinite(gyro), axis=1)
    dropped = {"rows with missing or non-numeric values": int((~ok).sum())} if not ok.all() else {}
    if not ok.any():
        raise InputError(
            str(path),
            "numeric t_s, ax, ay, az",
            "no row with numbers in all of them",
            "Check the table's columns and units.",
        )
    order = np.argsort(values[ok, 0], kind="stable")
    channels = {}
    for name in TABLE_CHANNELS:
        if name in df.columns:
            v = pd.to_numeric(df[name], errors="coerce").to_numpy(dtype=float)
            good = np.isfinite(v) & np.isfinite(df["t_s"].to_numpy(dtype=float))
            channels[name] = Channel(df["t_s"].to_numpy(dtype=float)[good], v[good])
    return Samples(
        values[ok, 0][order],
        values[ok, 1:][order],
        None if gyro is None else gyro[ok][order],
        channels,
        source=str(path),
        dropped=dropped,
    )


_REQUIRED = ("t_s", "ax", "ay", "az")




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
    ok = np.isfinite(t) & np.isfinite(acc).all(axis=1)
    if g is not None:
        ok &= np.isfinite(g).all(axis=1)
    channels = {}
    for name in TABLE_CHANNELS:
        if name in batch.schema.names:
            v = col(name)
            good = np.isfinite(v) & np.isfinite(t)
            channels[name] = Channel(t[good], v[good])
    dropped = {"non-finite sample rows": int((~ok).sum())} if not ok.all() else {}
    return Samples(t[ok], acc[ok], None if g is None else g[ok], channels, source=where, dropped=dropped)


__all__ = ["TABLE_CHANNELS", "iter_table", "read_table"]
