"""The unit of a table's time column: stated, checked against its spacing, or inferred from it — once, for
every table reader (mountcal's own columns, a column map, a known export; CSV and Parquet; whole or in chunks).

A table's time column states its unit by its **type** (a Parquet timestamp or duration: read as seconds,
timestamps since the Unix epoch), by its **text** (ISO-8601 date-times: read as such), by its **name**
(``t_s``), by the column map (``time=ts:ms``) or by a known export's documentation. A stated unit is
checked against the column's spacing: a name's unit that makes a log (:data:`EVIDENCE_ROWS`) slower or
faster than any logger's while another unit makes it an IMU's rate (a logger's milliseconds written under
``t_s``) is refused, naming the unit that fits; a user's unit (``time=ts:s``) is read as stated. A map
that names no unit states none: the unit is **inferred** from the spacing when exactly one of s, ms, us, ns
gives an IMU's rate, and said; otherwise it is asked for.

The decision rests on the first rows (:data:`ROWS_LOOKED_AT`), read before the samples: the layout it
settles reads every chunk of the table alike.
"""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from mountcal.core.errors import InputError
from mountcal.core.option_names import option
from mountcal.core.result import Convention
from mountcal.io.table.layout import TIME_UNITS, Column, Layout
from mountcal.io.whole import text_source

ROWS_LOOKED_AT = 2000  # rows whose spacing decides (a look, not a read: the first chunk holds them)
# The sampling rates an IMU log has. Below 2.5 Hz a 2 s window holds fewer than the 5 samples the stop
# finder needs (mountcal could not use the log), and no IMU logs that slowly; above 10 kHz is beyond the
# output rates of the accelerometers logged in vehicles (a few kHz at most). The s, ms, us and ns readings
# of one spacing lie 1000× apart, so at most two of them fall in this band, and only for 2.5–10 Hz in
# seconds (2.5–10 kHz in ms): there an unstated unit is asked for rather than guessed.
IMU_RATE_HZ = (2.5, 10_000.0)
UNITS = ("s", "ms", "us", "ns")
# A unit a column's name states is doubted only on a log's evidence: at least EVIDENCE_ROWS rows (a table of
# stops has tens, minutes apart, and rotates as it is) slower than SLOWEST_LOG_HZ (no logger of vehicle
# dynamics samples that slowly; 1 Hz telematics does) or faster than the band. A unit the user states in the
# column map is never refused: its spacing is said beside it.
EVIDENCE_ROWS = 500
SLOWEST_LOG_HZ = 0.5
TYPED = ("timestamp", "duration")  # units a column's type states


def first_times(path: Path, name: str, read_as: dict[str, str], whole_lines: bool = True) -> pd.Series:
    """The first :data:`ROWS_LOOKED_AT` values of column ``name`` as stored: a CSV's as text, a Parquet's
    in its own type (a timestamp stays a timestamp). ``whole_lines``: a cut CSV's whole lines only (read
    under the completeness policy, :mod:`mountcal.io.whole`)."""
    try:
        if path.suffix.lower() in (".parquet", ".pq"):
            import pyarrow.parquet as pq

            batch = next(pq.ParquetFile(path).iter_batches(batch_size=ROWS_LOOKED_AT, columns=[name]), None)
            return pd.Series([], dtype=float) if batch is None else batch.column(0).to_pandas()
        frame = pd.read_csv(
            text_source(path) if whole_lines else path,
            usecols=lambda c: str(c).strip() == name,
            nrows=ROWS_LOOKED_AT,
            dtype=str,
            skipinitialspace=True,
            encoding="utf-8-sig",
            **{"comment": "#", **read_as},
        )
    except (ValueError, pd.errors.ParserError, UnicodeDecodeError, OSError) as err:
        raise InputError(
            str(path), "a CSV or Parquet sample table", f"a file that does not parse ({err})", "Check the file."
        ) from err
    return frame.iloc[:, 0] if frame.shape[1] else pd.Series([], dtype=str)


def typed_seconds(values: pd.Series) -> np.ndarray | None:
    """Seconds of a timestamp (since the Unix epoch; a zone's instant) or duration column; None for others."""
    kind = values.dtype
    if isinstance(kind, pd.DatetimeTZDtype):
        values = values.dt.tz_convert("UTC").dt.tz_localize(None)
    elif not (pd.api.types.is_datetime64_dtype(kind) or pd.api.types.is_timedelta64_dtype(kind)):
        return None
    raw = values.to_numpy(dtype="timedelta64[ns]" if pd.api.types.is_timedelta64_dtype(kind) else "datetime64[ns]")
    ns = raw.view(np.int64)
    out = (ns // 1_000_000_000).astype(np.float64) + (ns % 1_000_000_000) * 1e-9  # exact seconds, then the rest
    out[np.isnat(raw)] = np.nan
    return np.asarray(out, dtype=np.float64)


def first_seconds(path: Path, name: str, read_as: dict[str, str] | None = None) -> np.ndarray:
    """The first rows of a time column as numbers: seconds where its type or text says so (a timestamp, a
    duration, ISO-8601 text), else its numbers as they are (what the kind of a table is told by); a CSV read
    as ``read_as`` says (:func:`mountcal.io.table.mapped.dialect`)."""
    values = first_times(path, name, read_as or {}, whole_lines=False)
    if read_as and read_as.get("decimal") == "," and _is_text(values):
        values = values.str.replace(",", ".", regex=False)
    typed = typed_seconds(values)
    if typed is not None:
        return typed
    if _is_text(values) and _is_iso_text(values):
        return iso_seconds(values)
    if _is_text(values) and _is_clock_text(values):
        return clock_seconds(values)
    return np.asarray(pd.to_numeric(values, errors="coerce"), dtype=np.float64)


def _is_text(values: pd.Series) -> bool:
    return bool(values.dtype == object or pd.api.types.is_string_dtype(values.dtype))


def iso_seconds(values: pd.Series) -> np.ndarray:
    """Seconds since the Unix epoch of ISO-8601 date-time text (without a zone, UTC); NaN where unreadable."""
    seconds = typed_seconds(pd.Series(pd.to_datetime(values, utc=True, errors="coerce", format="ISO8601")))
    assert seconds is not None  # to_datetime gives a timestamp column
    return seconds


def _is_iso_text(values: pd.Series) -> bool:
    """Whether the (text) values are date-times: most parse as ISO-8601 and are no plain numbers."""
    text = values.dropna().astype(str).str.strip()
    text = text[text != ""]
    if text.empty or pd.to_numeric(text, errors="coerce").notna().mean() > 0.5:
        return False
    parsed = pd.to_datetime(text, utc=True, errors="coerce", format="ISO8601")
    return bool(parsed.notna().mean() > 0.5)


_CLOCK = re.compile(r"\s*(\d{1,2}):(\d{2}):(\d{2})(?:([:.,])(\d{1,9}))?\s*")
DAY_S = 86400.0


def _is_clock_text(values: pd.Series) -> bool:
    """Whether the (text) values are times of day, ``HH:MM:SS`` with milliseconds after ``:`` (Physics
    Toolbox Sensor Suite's ``HH:MM:SS:mmm``) or a fraction after ``.``: most of them."""
    text = values.dropna().astype(str)
    text = text[text.str.strip() != ""]
    return bool(not text.empty and text.str.fullmatch(_CLOCK).mean() > 0.5)


def clock_seconds(values: pd.Series) -> np.ndarray:
    """Seconds since midnight of time-of-day text (:func:`_is_clock_text`), NaN where unreadable; a step back
    of more than half a day is midnight passed, so the day after counts on (86 400 s later)."""
    parts = values.astype(str).str.extract(_CLOCK.pattern)
    h, m, sec = (pd.to_numeric(parts[i], errors="coerce").to_numpy(dtype=np.float64) for i in range(3))
    digits = parts[4].fillna("")
    sub = pd.to_numeric(digits, errors="coerce").fillna(0.0).to_numpy(dtype=np.float64)
    per = np.where(parts[3].fillna("") == ":", 1000.0, 10.0 ** digits.str.len().to_numpy(dtype=np.float64))
    out = h * 3600.0 + m * 60.0 + sec + sub / per
    bad = (h > 23) | (m > 59) | (sec > 60) | ((parts[3] == ":").to_numpy() & (sub >= 1000.0))
    out[bad] = np.nan
    finite = np.flatnonzero(np.isfinite(out))
    if finite.size > 1:
        wraps = np.concatenate([[0.0], np.cumsum(np.diff(out[finite]) < -DAY_S / 2)]) * DAY_S
        out[finite] += wraps
    return np.asarray(out, dtype=np.float64)


def _check_resolution(where: str, name: str, values: pd.Series, numbers: np.ndarray, step: float) -> None:
    """Refuse times stored as 32-bit floats too coarse for their samples: 24 bits hold Unix seconds to 128 s,
    so every sample of two minutes shares a time, and the spacing is the format's, not the logger's.

    Raises
    ------
    InputError
        Naming the column, its resolution where its values lie, and the types that hold them.
    """
    finite = numbers[np.isfinite(numbers)]
    if values.dtype != np.float32 or finite.size < 2:
        return
    resolution = float(np.spacing(np.float32(np.abs(finite).max())))
    if np.isfinite(step) and step > 2.0 * resolution:
        return
    raise InputError(
        where,
        f"times in the column {name} finer than the samples' spacing",
        f"32-bit floats: at {np.abs(finite).max():.10g} their resolution is {resolution:g} (its unit), and "
        + (
            f"the first rows' median step is {step:g}: the format's, not the logger's"
            if np.isfinite(step)
            else "the first rows share one time"
        ),
        "Write the times as 64-bit floats, integer nanoseconds (int64) or a timestamp type.",
    )


EXCEL_DAYS = (20_000.0, 80_000.0)  # a spreadsheet's serial days of 1954–2119 (day 25 569 is 1970-01-01)


def _excel_days(numbers: np.ndarray, step: float) -> bool:
    """Whether times are a spreadsheet's serial days: all within :data:`EXCEL_DAYS`, an IMU's rate in days
    (no unit of seconds gives one: their step is a 10⁻⁷ of a day)."""
    finite = numbers[np.isfinite(numbers)]
    lo, hi = EXCEL_DAYS
    return bool(finite.size >= 2 and finite.min() >= lo and finite.max() <= hi and fits(step, DAY_S))


def _mostly_text(values: pd.Series, numbers: np.ndarray) -> bool:
    """Whether most non-empty values of a text column are no numbers (a units row under a header is one)."""
    text = values.dropna().astype(str).str.strip()
    filled = int((text != "").sum())
    return filled > 0 and int(np.isfinite(numbers).sum()) < filled / 2


def median_step(values: np.ndarray) -> float:
    """The median of the positive steps between sorted times: robust to gaps, jitter, repeated stamps."""
    t = np.sort(values[np.isfinite(values)])
    steps = np.diff(t)
    steps = steps[steps > 0]
    return float(np.median(steps)) if steps.size else float("nan")


def fits(step: float, scale: float) -> bool:
    """Whether a median step read at ``scale`` s per unit gives an IMU's rate (:data:`IMU_RATE_HZ`)."""
    lo, hi = IMU_RATE_HZ
    return bool(np.isfinite(step)) and lo <= 1.0 / (step * scale) <= hi


def _rate(step: float, scale: float) -> str:
    return f"{1.0 / (step * scale):.4g} Hz"


def settle_time(layout: Layout, path: Path, read_as: dict[str, str]) -> tuple[Layout, Convention]:
    """``layout`` with its time column's unit settled from the first rows, and how the unit is known.

    Raises
    ------
    InputError
        A stated unit the spacing contradicts while another fits; a unit stated against the column's
        type or text; a unit not stated that the spacing does not settle.
    """
    where = str(path)
    time = layout.time
    values = first_times(path, time.name, read_as)
    stated, by = _statement(layout)
    explicit = stated if layout.source == "the column map" else ""  # a name cannot outweigh a type or a text
    seconds = typed_seconds(values)
    if seconds is not None:
        typed = "timestamp" if pd.api.types.is_datetime64_any_dtype(values.dtype) else "duration"
        if explicit and explicit != "iso":
            raise _against_type(where, time, explicit, f"a {typed} type ({values.dtype})", by)
        what = "seconds since the Unix epoch (UTC)" if typed == "timestamp" else "seconds"
        if typed == "timestamp" and not isinstance(values.dtype, pd.DatetimeTZDtype):
            # Arrow's timestamp without a zone is a wall clock's in a zone it does not name: taken as UTC, and said
            what += "; the type names no time zone: taken as UTC (a local clock's times are off by its offset)"
        return _with(layout, Column(time.name, typed)), Convention(
            "time_unit", typed, "stated", f"the column {time.name}'s type ({values.dtype}): read as {what}"
        )
    text = values.dtype == object or pd.api.types.is_string_dtype(values.dtype)
    iso = text and _is_iso_text(values)
    if time.unit == "iso" or iso:
        if explicit and explicit != "iso":
            raise _against_type(where, time, explicit, "date-time text (ISO-8601)", by)
        if time.unit == "iso":
            return layout, Convention("time_unit", "iso", "stated", by)
        return _with(layout, Column(time.name, "iso")), Convention(
            "time_unit", "iso", "stated", f"the column {time.name}'s text: ISO-8601 date-times (without a zone, UTC)"
        )
    clock = text and _is_clock_text(values)
    if time.unit == "clock" or clock:
        if explicit and explicit != "clock":
            raise _against_type(where, time, explicit, "time-of-day text (HH:MM:SS…)", by)
        return _with(layout, Column(time.name, "clock")), Convention(
            "time_unit",
            "clock",
            "stated",
            f"the column {time.name}'s text: a time of day ({values.dropna().astype(str).iloc[0].strip()!r}; "
            "after the seconds, ':' counts milliseconds, '.' starts a fraction) without a date: read as seconds "
            "since midnight, carried over midnight",
        )
    if read_as.get("decimal") == "," and text:
        values = values.str.replace(",", ".", regex=False)
    numbers = np.asarray(pd.to_numeric(values, errors="coerce"), dtype=np.float64)
    if text and _mostly_text(values, numbers):
        raise InputError(
            where,
            f"times in the column {time.name}: numbers, ISO-8601 date-times or a time of day (HH:MM:SS.fff)",
            f"text that is none of these, e.g. {values.dropna().astype(str).iloc[0].strip()!r}",
            "Write the times as ISO-8601 (2024-05-01T10:00:00.000, with a zone where they are not UTC) or as "
            f"numbers with their unit ({option('columns', f'time={time.name}:s')}; s, ms, us, ns).",
        )
    step = median_step(numbers)
    _check_resolution(where, time.name, values, numbers, step)
    given = layout.source == "the column map" and bool(time.unit.strip())  # the user's word, not a name's
    if not given and _excel_days(numbers, step):
        raise InputError(
            where,
            f"the time column {time.name} in {stated or 's, ms, us or ns'}" + (f" ({by})" if stated else ""),
            f"numbers from {np.nanmin(numbers):.6f} to {np.nanmax(numbers):.6f} in its first rows, a median "
            f"{step:.3g} apart: "
            f"a spreadsheet's serial days (days since 1899-12-30; {_rate(step, DAY_S)} in days), not "
            "seconds or any unit of them",
            "Write the times as ISO-8601 text (a spreadsheet's format yyyy-mm-ddThh:mm:ss.000) or as Unix seconds "
            "((days − 25569) × 86400).",
        )
    if stated and "/" in stated:  # a sample index at a stated rate: the rate is the statement
        return layout, Convention("time_unit", stated, "stated", by)
    if stated:
        if not time.unit:  # stated by the name alone: read in that unit
            layout = _with(layout, Column(time.name, stated, TIME_UNITS[stated]))
        doubted = not given and int(np.isfinite(numbers).sum()) >= EVIDENCE_ROWS
        return layout, _checked(where, layout, stated, step, by, doubted)
    return _inferred(where, layout, step)


def _statement(layout: Layout) -> tuple[str, str]:
    """The stated unit of the time column ("" where none is) and what states it."""
    time = layout.time
    if layout.source == "mountcal's own columns":
        return "s", f"the column name {time.name}"
    if layout.source == "the column map":
        if time.unit.strip():
            return time.unit.strip(), f"the column map ({option('columns')} time={time.name}:{time.unit.strip()})"
        named = re.search(r"_(s|ms|us|ns)$", time.name.strip(), re.IGNORECASE)  # t_s, stamp_ms: the name says it
        return (named.group(1).lower(), f"the column name {time.name}") if named else ("", "")
    return time.unit or "", f"{layout.source} (its documented unit)"


def _with(layout: Layout, time: Column) -> Layout:
    return replace(layout, columns={**layout.columns, "time": time})


def column_map(columns: dict[str, Column]) -> str:
    """The ``--columns`` text that reads ``columns`` (each role with its column and unit)."""
    return ",".join(f"{role}={c.name}" + (f":{c.unit}" if c.unit else "") for role, c in columns.items())


def _checked(where: str, layout: Layout, stated: str, step: float, by: str, doubted: bool) -> Convention:
    """A stated unit, refused where it may be ``doubted`` (a name's, on a log's rows: :data:`EVIDENCE_ROWS`)
    and the spacing makes the log slower or faster than any logger's while another unit makes it an IMU's
    rate; otherwise said with what its spacing says."""
    time = layout.time
    scale = time.scale
    if not np.isfinite(step) or fits(step, scale):
        checked = f" (checked: a median step of {step:.4g} {stated}, {_rate(step, scale)})" if np.isfinite(step) else ""
        return Convention("time_unit", stated, "stated", by + checked)
    others = [u for u in UNITS if u != stated.lower() and fits(step, TIME_UNITS[u])]
    if not others:  # nothing fits better: not an IMU's rate in any unit, left to the commands to judge
        return Convention("time_unit", stated, "stated", f"{by} (its spacing, {_rate(step, scale)}, fits no unit)")
    fit = others[0]
    rate = 1.0 / (step * scale)
    than = "slower" if rate < IMU_RATE_HZ[0] else "faster"
    if not doubted or SLOWEST_LOG_HZ <= rate < IMU_RATE_HZ[0]:
        spacing = f"its spacing: {_rate(step, scale)}, {than} than an IMU's; in {fit} it would be"
        return Convention("time_unit", stated, "stated", f"{by} ({spacing} {_rate(step, TIME_UNITS[fit])})")
    fixed = {**layout.columns, "time": Column(time.name, fit)}
    raise InputError(
        where,
        f"the time column {time.name} in {stated} ({by}) at an IMU's rate, {_band()}",
        f"a median step of {step:.6g} between its first rows: {_rate(step, scale)} in {stated}, "
        f"{than} than any IMU logs; in {fit} it would be {_rate(step, TIME_UNITS[fit])}",
        f"If {time.name} is in {fit}, say so: {option('columns', column_map(fixed))}.",
    )


def _band() -> str:
    return f"{IMU_RATE_HZ[0]:g} Hz to {IMU_RATE_HZ[1] / 1000:g} kHz"


def _inferred(where: str, layout: Layout, step: float) -> tuple[Layout, Convention]:
    """A unit not stated: the one of s, ms, us, ns that gives an IMU's rate, else asked for."""
    time = layout.time
    units = [u for u in UNITS if fits(step, TIME_UNITS[u])]
    if len(units) == 1:
        unit = units[0]
        by = (
            f"the column {time.name}'s spacing: a median step of {step:.6g} between its first rows is "
            f"{_rate(step, TIME_UNITS[unit])} in {unit} (the only unit giving an IMU's rate, "
            f"{_band()}; state it with time={time.name}:UNIT)"
        )
        return _with(layout, Column(time.name, unit, TIME_UNITS[unit])), Convention("time_unit", unit, "inferred", by)
    found = (
        f"no distinct times in the first rows of {time.name}"
        if not np.isfinite(step)
        else f"a median step of {step:.6g}, "
        + (
            f"an IMU's rate in {' or '.join(units)} ({', '.join(_rate(step, TIME_UNITS[u]) for u in units)})"
            if units
            else "an IMU's rate in none of s, ms, us, ns"
        )
    )
    named = " or ".join(option("columns", f"time={time.name}:{u}") for u in units or ["UNIT"])
    raise InputError(
        where,
        f"the unit of the time column {time.name} (the column map names none)",
        found,
        f"Name it: {named} (s, ms, us, ns, iso, or s/N for a sample index at N Hz).",
    )


def _against_type(where: str, time: Column, stated: str, what: str, by: str) -> InputError:
    keep = "iso" if "text" in what else ""
    todo = f"{option('columns', f'time={time.name}:iso')}" if keep else f"{option('columns', f'time={time.name}')}"
    return InputError(
        where,
        f"the time column {time.name} in {stated} ({by})",
        f"{what}, which states its own unit",
        f"Read it as what it holds: {todo}" + ("." if keep else " (no unit: the type says it)."),
    )


__all__ = [
    "IMU_RATE_HZ",
    "ROWS_LOOKED_AT",
    "clock_seconds",
    "first_seconds",
    "first_times",
    "fits",
    "iso_seconds",
    "median_step",
    "settle_time",
    "typed_seconds",
]
