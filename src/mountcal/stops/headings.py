"""A log's stops as a stop table with their headings: from the vehicle's heading channel while parked, or
from a protocol sheet (:func:`tabulate`, what ``mountcal stops`` and a log's calibration run)."""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
import pandas as pd

from mountcal.core.conventions import FloatArray
from mountcal.core.errors import NotEnoughInformation
from mountcal.core.option_names import option
from mountcal.core.result import Convention
from mountcal.io.input_conventions import HeadingUnit, compass_to_beta, headings_in_degrees, uphill_azimuth
from mountcal.io.samples import Samples
from mountcal.stops.detect import StillPeriod, Stop, StopDetection, find_stops
from mountcal.stops.heading_at_rest import stop_headings
from mountcal.stops.near_misses import NearMiss
from mountcal.stops.protocol_clock import PLAN_MARK, on_log_clock, rows_on_stops
from mountcal.stops.table import Headings, StopTable, check_degrees, checked

beta_from_heading = compass_to_beta  # β (counter-clockwise from uphill) from compass headings (clockwise from north)


def stop_table(
    stops: list[Stop],
    beta_deg: FloatArray | None = None,
    headings: Headings = "uphill",
    source: str = "log",
    conventions: tuple[Convention, ...] = (),
) -> StopTable:
    """The stop table of detected stops (checked like a table read from a file).

    ``std_s`` holds the standard deviations of the samples of each stop (what a user sees in the
    data); ``cov_s`` the full covariance of each stop mean the fit uses: correlated vibration and
    the quantisation floor make it larger than ``s²/n``, and vibration correlates the axes.
    """
    if not stops:
        raise NotEnoughInformation(f"{source}: no stops to tabulate")

    def channel(key: str) -> FloatArray | None:
        values = np.array([s.channels.get(key, np.nan) for s in stops], dtype=float)
        return values if np.any(np.isfinite(values)) else None

    return checked(
        StopTable(
            acc_s=np.array([s.acc_mean_s for s in stops], dtype=float),
            beta_rad=None if beta_deg is None else np.radians(np.asarray(beta_deg, dtype=float) % 360.0),
            headings=headings if beta_deg is not None else "none",
            cov_s=np.array([s.acc_cov_mean_s for s in stops], dtype=float),
            temperature_c=channel("temperature_c"),
            t_s=np.array([s.t_start_s for s in stops], dtype=float),
            lat_deg=channel("lat_deg"),
            alt_m=channel("alt_m"),
            lon_deg=channel("lon_deg"),
            std_s=np.array([s.acc_std_s for s in stops], dtype=float),
            count=np.array([s.n for s in stops], dtype=float),
            duration_s=np.array([s.duration_s for s in stops], dtype=float),
            heading_deg=channel("heading_deg"),
            source=source,
            conventions=conventions,
        ),
        min_stops=1,  # a log may hold fewer stops than a fit needs: calibrate says so
    )


@dataclass(frozen=True)
class StopTableFromLog:
    """The stop table of a log and how its headings were found."""

    table: StopTable
    heading_source: str
    unmatched_protocol_rows: int = 0
    notes: tuple[str, ...] = ()  # the thresholds used and what detection changed or dropped
    dropped: tuple[StillPeriod, ...] = ()  # still periods not kept as a stop
    near_misses: tuple[NearMiss, ...] = ()  # parked periods that nearly became stops
    gyro_rejection: str = ""  # the still periods the gyro's thresholds rejected, and what may explain it


def near_miss_advice(missed: tuple[NearMiss, ...] | list[NearMiss]) -> str:
    """A sentence for a refusal: the parked periods that nearly became stops, and the option that keeps each."""
    if not missed:
        return ""
    many = len(missed) > 1
    return (
        f" The log holds {len(missed)} parked period{'s' if many else ''} that nearly became "
        f"{'stops' if many else 'a stop'}: " + "; ".join(m.line() for m in missed) + "."
    )


def read_protocol(path: str, heading_unit: HeadingUnit | None = None) -> pd.DataFrame:
    """A protocol sheet: CSV ``t_start_s, t_end_s, beta_deg`` (times on the log's clock; β in degrees
    unless ``heading_unit`` says radians, checked). ``attrs["conventions"]`` says how β's unit is known."""
    from mountcal.core.errors import InputError
    from mountcal.core.paths import input_file
    from mountcal.core.ranges import check_values
    from mountcal.io.inputs import csv_columns
    from mountcal.io.table.mapped import dialect

    checked = input_file(path, "a protocol sheet CSV")  # not a FIFO or a device: reading ends
    csv_columns(checked, path)  # a header of a million columns is refused before pandas parses it
    try:
        with open(checked, "rb") as f:
            read_as = dialect(f.read(1 << 16), path)[1]  # ";" with decimal commas, as every table's reader
        df = pd.read_csv(path, skipinitialspace=True, **{"comment": "#", **read_as})
    except (OSError, ValueError) as err:
        raise InputError(
            path,
            "a protocol sheet CSV (t_start_s, t_end_s, beta_deg)",
            f"an unreadable file ({err})",
            "Check the path and the format.",
        ) from err
    missing = [c for c in ("t_start_s", "t_end_s", "beta_deg") if c not in df.columns]
    if not missing:
        df = sheet_times(df, path)
    values = None if missing else df[["t_start_s", "t_end_s", "beta_deg"]].apply(pd.to_numeric, errors="coerce")
    if missing or values is None or not np.all(np.isfinite(values.to_numpy())):
        raise InputError(
            path,
            "columns t_start_s, t_end_s, beta_deg with numbers in every row",
            f"missing columns {missing}" if missing else "empty or non-numeric cells",
            "Write one row per stop.",
        )
    check_values("time_s", values[["t_start_s", "t_end_s"]].to_numpy(), path, "t_start_s, t_end_s")
    values = protocol_sheet(values, path, heading_unit)
    with open(path, encoding="utf-8", errors="replace") as f:
        values.attrs["planned"] = f.readline(len(PLAN_MARK)) == PLAN_MARK  # times from `mountcal plan`: placeholders
    return values


ZONE = re.compile(r"(?:Z|[+-]\d{2}:?\d{2})\s*$", re.IGNORECASE)


def sheet_times(df: pd.DataFrame, path: str) -> pd.DataFrame:
    """``df`` with ISO-8601 date-times in ``t_start_s, t_end_s`` as Unix seconds, where each states its zone
    (``Z``, ``+02:00``): an instant. A date-time without a zone is a wall clock's, a sheet's often local while the
    log's is UTC: refused, naming the zone to write. Numbers are left as they are.

    Raises
    ------
    InputError
        Date-times without a zone.
    """
    from mountcal.core.errors import InputError
    from mountcal.io.table.time_unit import iso_seconds

    out = df.copy()
    for column in ("t_start_s", "t_end_s"):
        text = out[column].dropna().astype(str).str.strip()
        if text.empty or pd.to_numeric(text, errors="coerce").notna().all():
            continue
        dated = pd.to_datetime(text, utc=True, errors="coerce", format="ISO8601").notna()
        if not dated.any():
            continue  # neither numbers nor date-times: refused below as non-numeric
        naive = text[dated & ~text.str.contains(ZONE)]
        if not naive.empty:
            raise InputError(
                path,
                f"{column} in Unix seconds, or as ISO-8601 date-times with their zone (2024-05-01T10:00:00Z, "
                "2024-05-01T12:00:00+02:00)",
                f"date-times without a zone ({naive.iloc[0]!r}): a wall clock's, which the sheet does not name "
                "(a sheet in local time against a log in UTC puts every stop hours off)",
                "Add the zone the times were written in to each (Z for UTC, +02:00 for CEST), or write Unix seconds.",
            )
        out[column] = iso_seconds(out[column].astype(str))
    return out


def protocol_sheet(
    values: pd.DataFrame, where: str, heading_unit: HeadingUnit | None = None, stated_by: str | None = None
) -> pd.DataFrame:
    """A protocol sheet's numbers (``t_start_s, t_end_s, beta_deg``) with β's unit checked (degrees unless
    ``heading_unit`` says radians) and ``attrs["conventions"]``: β from uphill, stated by ``stated_by`` (the
    ``protocol`` option unless said), and how β's unit is known. What :func:`read_protocol` makes of a file and
    a live session of the sheet it writes, so both calibrations state the same conventions."""
    values = values.copy()
    values["beta_deg"], unit = headings_in_degrees(values["beta_deg"].to_numpy(dtype=float), heading_unit, where)
    check_degrees(values["beta_deg"].to_numpy(), unit, where, "beta_deg")
    values.attrs["path"] = where  # a refusal of the sheet's clock names it
    values.attrs["conventions"] = (
        Convention("heading_reference", "uphill", "stated", stated_by or f"the protocol sheet ({option('protocol')})"),
        unit,
    )
    return values


def one_stop_per_row(stops: list[Stop], windows: list[tuple[float, float]], protocol: pd.DataFrame) -> None:
    """Refuse a sheet two of whose rows took the same still period (rows that repeat or overlap another's times): its
    data would be fitted twice, at two headings, and the stop between left out.

    Raises
    ------
    InputError
        Naming the rows, their β and the still period they share.
    """
    from mountcal.core.errors import InputError

    spans = [(s.t_start_s, s.t_end_s) for s in stops]
    for span in dict.fromkeys(spans):
        if spans.count(span) < 2:
            continue
        rows = [i for i, (lo, hi) in enumerate(windows) if lo <= span[0] and span[1] <= hi]
        beta = protocol["beta_deg"].to_numpy()
        named = " and ".join(
            f"{i + 1} ({lo:.10g}–{hi:.10g} s, β {beta[i]:g}°)" for i in rows for lo, hi in [windows[i]]
        )
        raise InputError(
            str(protocol.attrs.get("path") or f"the protocol sheet ({option('protocol')})"),
            "one still period per row: the vehicle stands at one heading at a time",
            f"rows {named} on the same still period, {span[0]:.10g}–{span[1]:.10g} s: its data would be fitted "
            "once at each of their headings",
            "Correct the rows' times (each row's t_start_s–t_end_s around its own stop), or delete the row that "
            "repeats another.",
        )


def tabulate(
    samples: Samples,
    cfg: StopDetection | None = None,
    protocol: pd.DataFrame | None = None,
    uphill_azimuth_deg: float | None = None,
) -> StopTableFromLog:
    """Detect the stops of a log and attach their headings β.

    β comes from the protocol sheet when given; else from the log's heading channel and the
    slope's uphill azimuth; a heading channel alone gives relative headings; nothing gives none.
    """
    where = samples.source or "log"
    if protocol is not None:
        protocol, clock = on_log_clock(protocol, samples, cfg)  # refused unless on the log's clock, or said
        shifted = () if clock is None else (f"protocol sheet's times: {clock.value} (inferred from {clock.by})",)
        windows = list(zip(protocol["t_start_s"], protocol["t_end_s"], strict=True))
        search = find_stops(samples, cfg, windows=windows)
        stops = search.stops
        gyro = search.gyro_rejection(where, tuple(samples.channels))
        kept = [i for i, (lo, hi) in enumerate(windows) if any(lo <= s.t_start_s and s.t_end_s <= hi for s in stops)]
        if clock is None and len(kept) < len(windows):  # rows without a stop: perhaps on their neighbours' stops
            rows_on_stops(protocol, samples, cfg)
        if not stops:
            raise NotEnoughInformation(
                f"{where}: no parked period found inside any protocol interval"
                + (f" (the sheet's times taken as {clock.value}, inferred from {clock.by})" if clock else "")
                + ". "
                + (f"But {gyro}" if gyro else f"Check that the sheet's times are on the log's clock, or {relax()}.")
                + f" Used: {'; '.join(search.lines())}."
            )
        one_stop_per_row(stops, windows, protocol)
        beta = protocol["beta_deg"].to_numpy()[kept]
        stated = (*samples.conventions, *protocol.attrs.get("conventions", ()), *([clock] if clock else []))
        return StopTableFromLog(
            stop_table(stops, beta, "uphill", where, stated),
            "protocol sheet",
            len(windows) - len(kept),
            (*shifted, *search.lines()),
            search.dropped,
            gyro_rejection=gyro,
        )
    search = find_stops(samples, cfg)
    stops = search.stops
    notes = tuple(search.lines())
    gyro = search.gyro_rejection(where, tuple(samples.channels))
    if not stops:
        raise NotEnoughInformation(
            f"{where}: no parked period found (no still run ≥ {(cfg or StopDetection()).min_duration_s:g} s)."
            + (f" But {gyro}" if gyro else "")
            + (
                near_miss_advice(search.near_misses)
                or ("" if gyro else f" Check that the log holds parked periods, or {relax()}.")
            )
            + f" Used: {'; '.join(search.thresholds.lines() + [f'{k}: {v}' for k, v in search.counts.items()])}."
        )
    read = stop_headings(stops, samples, (cfg or StopDetection()).trim_s)
    stops, read_as = read.stops, (*samples.conventions, *([read.convention] if read.convention else []))
    heading = np.array([s.channels.get("heading_deg", np.nan) for s in stops])
    if np.all(np.isfinite(heading)):
        if uphill_azimuth_deg is not None:
            stated = uphill_azimuth(uphill_azimuth_deg, "the log's heading channel")
            return StopTableFromLog(
                stop_table(
                    stops,
                    beta_from_heading(heading, uphill_azimuth_deg),
                    "uphill",
                    where,
                    (*read_as, *stated),
                ),
                f"heading channel with uphill azimuth {uphill_azimuth_deg:g}°",
                notes=notes,
                dropped=search.dropped,
                near_misses=search.near_misses,
                gyro_rejection=gyro,
            )
        inferred = Convention(
            "heading_reference",
            "relative",
            "inferred",
            f"the log's heading channel without the slope's uphill azimuth ({option('uphill_azimuth')} or "
            f"{option('protocol')} would make the headings uphill)",
        )
        return StopTableFromLog(
            stop_table(stops, beta_from_heading(heading, 0.0), "relative", where, (*read_as, inferred)),
            "heading channel without the uphill azimuth (relative)",
            notes=notes,
            dropped=search.dropped,
            near_misses=search.near_misses,
            gyro_rejection=gyro,
        )
    none = Convention(
        "heading_reference",
        "none",
        "inferred",
        "no protocol sheet, and "
        + (
            read.missing
            or ("no heading channel in the log" if "heading_deg" not in samples.channels else "no heading at the stops")
        )
        + (
            f" ({option('uphill_azimuth')} {uphill_azimuth_deg:g} left unused)"
            if uphill_azimuth_deg is not None
            else ""
        ),
    )
    return StopTableFromLog(
        stop_table(stops, None, "none", where, (*samples.conventions, none)),
        "none",
        notes=notes,
        dropped=search.dropped,
        near_misses=search.near_misses,
        gyro_rejection=gyro,
    )


def relax() -> str:
    """Advice naming the options that change stop detection."""
    o = option
    return (
        f"relax the stillness thresholds: {o('max_acc_std')} (m/s²), {o('max_gyro_std')} and {o('max_gyro_rate')} "
        f"(rad/s), {o('max_speed')} (m/s), {o('min_stop')}, {o('trim')}, {o('still_window')}, "
        f"{o('max_heading_wander')} (deg)"
    )


__all__ = [
    "StopTableFromLog",
    "beta_from_heading",
    "near_miss_advice",
    "read_protocol",
    "relax",
    "stop_table",
    "tabulate",
]
