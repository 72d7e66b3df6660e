"""One entry point for every log format: pick the reader by the file, join split logs.

- ``.mcap``: :mod:`mountcal.io.mcap.read` (ROS 2 Imu, CDR or JSON).
- CAN logs (``.blf .asc .log .trc .mf4 .mdf``, and ``.csv`` when a DBC is given):
  :mod:`mountcal.io.can.read`, decoded with the DBC.
- Sample tables (``.csv``/``.parquet`` with ``t_s, ax, ay, az`` and optionally ``gx, gy, gz``
  in rad/s, ``speed_mps``, ``heading_deg``, ``temperature_c``, ``lat_deg``, ``alt_m``).

A log split over several files (a logger's 10-minute MF4 splits) is read file by file and joined
in time order. Files whose clocks overlap are not splits of one log (two loggers, or one session
given twice): joining them would interleave two recordings, so they are refused.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from itertools import pairwise
from pathlib import Path

import numpy as np
import pandas as pd

from mountcal.errors import InputError
from mountcal.io.inputs import check_parquet_rows, check_regular_file
from mountcal.samples import Channel, LogSummary, Samples

CAN_SUFFIXES = {".blf", ".asc", ".log", ".trc", ".mf4", ".mdf"}
TABLE_CHANNELS = ("speed_mps", "heading_deg", "temperature_c", "lat_deg", "lon_deg", "alt_m")


@dataclass(frozen=True)
class LogOptions:
    """How to read a log: the DBC and mapping for CAN, the topic for MCAP."""

    dbc: str | tuple[str, ...] | None = None  # several DBCs: their messages together (no clash allowed)
    mapping: str | None = None
    channel: int | None = None
    topic: str | None = None


def read_log(paths: str | Path | Sequence[str | Path], options: LogOptions | None = None) -> Samples:
    """Samples of one log (one file, or several splits joined in time order)."""
    opts = options or LogOptions()
    files = [Path(p) for p in ([paths] if isinstance(paths, str | Path) else paths)]
    if not files:
        raise InputError("LOG", "at least one log file", "none", "Name the log file(s).")
    parts = [_read_one(f, opts) for f in files]
    return parts[0] if len(parts) == 1 else join(parts)


def inspect_log(path: str | Path, options: LogOptions | None = None) -> LogSummary:
    """What a log holds: topics or messages, signals, rates, duration."""
    opts = options or LogOptions()
    path = Path(path)
    # a CAN log is listed without a DBC too: ids per channel with counts, rates and DLCs
    kind = "can" if path.suffix.lower() in CAN_SUFFIXES else log_kind(path, opts)
    if kind == "mcap":
        from mountcal.io.mcap.read import inspect_mcap

        return inspect_mcap(path)
    if kind == "can":
        from mountcal.io.can.read import inspect_can

        return inspect_can(path, opts.dbc)
    s = read_table_samples(path)
    from mountcal.samples import Stream

    dur = float(s.t_s[-1] - s.t_s[0]) if len(s) > 1 else 0.0
    rate = (len(s) - 1) / dur if dur > 0 else 0.0
    fields = ("ax", "ay", "az", *(("gx", "gy", "gz") if s.gyro_s is not None else ()), *s.channels)
    return LogSummary(
        str(path), path.suffix.lstrip(".").lower(), dur, (Stream("samples", "table", len(s), rate, fields),)
    )


def read_table_samples(path: Path) -> Samples:
    """A CSV or Parquet table of samples: ``t_s, ax, ay, az`` in s and m/s²."""
    check_regular_file(path, "sample table")
    parquet = path.suffix.lower() in (".parquet", ".pq")
    if parquet:
        check_parquet_rows(path)
    try:
        df = pd.read_parquet(path) if parquet else pd.read_csv(path)
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
            "Rename the columns; a CAN log in CSV needs --dbc.",
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


def join(parts: Sequence[Samples]) -> Samples:
    """Samples of several files in time order, with channels and drop counts merged.

    Raises
    ------
    InputError
        When two files' clocks overlap: they are not consecutive splits of one log.
    """
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


def log_kind(path: Path, opts: LogOptions) -> str:
    """``"mcap"``, ``"can"`` or ``"table"``: which reader a log file needs (a CAN log needs a DBC)."""
    suffix = path.suffix.lower()
    if suffix == ".mcap":
        return "mcap"
    if suffix in CAN_SUFFIXES or (suffix == ".csv" and opts.dbc is not None):
        if opts.dbc is None:
            raise InputError(
                str(path),
                "a DBC to decode this CAN log",
                "no --dbc",
                "Pass --dbc FILE (and --mapping FILE when the signals are not named plainly).",
            )
        return "can"
    if suffix in (".csv", ".parquet", ".pq"):
        return "table"
    raise InputError(
        str(path),
        "an MCAP, CAN (BLF, ASC, log, TRC, CSV, MF4) or CSV/Parquet log",
        f"a file ending in {suffix or '(nothing)'}",
        "Convert it, or name it by its format.",
    )


def _read_one(path: Path, opts: LogOptions) -> Samples:
    kind = log_kind(path, opts)
    if kind == "mcap":
        from mountcal.io.mcap.read import read_mcap

        return read_mcap(path, topic=opts.topic)
    if kind == "can":
        from mountcal.io.can.read import read_can

        return read_can(path, opts.dbc, mapping=opts.mapping, channel=opts.channel)
    return read_table_samples(path)
