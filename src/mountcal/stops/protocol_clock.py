"""A protocol sheet's clock against the log's: the one place a sheet's times meet a log (:func:`on_log_clock`).

A sheet's times must be on the log's clock. A sheet with an interval on the log is used as it is (a
sheet at the wrong place on the log is the stop search's to refuse). Where none lies on the log, the two
clocks are compared: a sheet counting from the log's start, on a log dated in Unix time, is shifted and
said (``protocol_clock``, inferred); a sheet a time zone's offset from the log, a dated sheet on an
undated log, or no relation at all are refused with the spans of both and the fix.
"""

from __future__ import annotations

import math
from datetime import UTC, datetime

import numpy as np
import pandas as pd

from mountcal.core.errors import InputError
from mountcal.core.option_names import option
from mountcal.core.result import Convention
from mountcal.io.samples import Samples
from mountcal.stops.detect import StopDetection, find_stops

DATED_S = 1e8  # a clock past 1973-03-03 is Unix time; a relative clock counts from a start or a boot
ZONE_STEP_S = 900.0  # time zones are quarter hours apart (India +5:30, Nepal +5:45, Chatham +12:45)
MAX_ZONE_S = 14 * 3600.0  # UTC−12 … UTC+14
COLUMNS = ["t_start_s", "t_end_s"]
PLAN_MARK = "# mountcal plan:"  # the first line of a sheet `mountcal plan` wrote, its times placeholders


def on_log_clock(
    protocol: pd.DataFrame, samples: Samples, cfg: StopDetection | None = None
) -> tuple[pd.DataFrame, Convention | None]:
    """The sheet on the log's clock, with the convention said when its clock was inferred.

    Raises
    ------
    InputError
        No interval of the sheet lies on the log, and its times are not the log's from its start (or are the
        placeholder times of ``mountcal plan``, which are not taken for them).
    """
    t = samples.t_s
    lo, hi = (protocol[c].to_numpy(dtype=float) for c in COLUMNS)
    if not lo.size or not t.size:
        return protocol, None
    t0, t1 = float(np.min(t)), float(np.max(t))
    sheet, log_span, duration = (float(lo.min()), float(hi.max())), (t0, t1), t1 - t0
    where = str(protocol.attrs.get("path") or f"the protocol sheet ({option('protocol')})")
    expected = f"the sheet's times on the log's clock ({_clock(log_span, samples)})"
    if np.any((hi >= t0) & (lo <= t1)):  # on the log: as stated
        return protocol, None
    margin = max(5.0, 0.01 * duration)  # a stopwatch stopped a little after the recording
    from_start = -margin <= sheet[0] and sheet[1] <= duration + margin
    if t0 >= DATED_S and from_start and protocol.attrs.get("planned"):  # not inferred: mountcal said placeholders
        raise InputError(
            where,
            expected,
            f"the placeholder times of `mountcal plan` ({_span(sheet)}; its first line {PLAN_MARK!r} says so)",
            "Replace t_start_s and t_end_s with the stops' times on the log's clock (or, if they are the stops' times "
            "from the log's start, delete that first line).",
        )
    if t0 >= DATED_S and from_start:
        shifted = protocol.copy()
        shifted[COLUMNS] = shifted[COLUMNS] + t0  # exact: the sheet's times were the log's minus its start
        shifted.attrs = dict(protocol.attrs)
        by = (
            f"the sheet's times {_span(sheet)}, all within the log's {_span((0.0, duration))} from its start, on a "
            f"log dated in Unix time ({_date(t0)})"
        )
        return shifted, Convention(
            "protocol_clock", f"seconds from the log's start, shifted by {t0:.17g} s", "inferred", by
        )
    if t0 >= DATED_S and sheet[0] >= DATED_S:
        zones = zone_offsets(lo, hi, samples, cfg)
        if zones:
            raise InputError(where, *_zone(zones[0], len(zones) > 1, sheet, log_span, samples))
    if sheet[0] >= DATED_S and t0 < DATED_S:
        raise InputError(
            where,
            expected,
            f"dated times, {_span(sheet)}: the log's clock has no date"
            + (", its times count from the start of the recording" if t0 < margin else ""),
            f"Write the sheet's times as seconds from the log's start (its stops lie within {_span(log_span)}): "
            "subtract the recording's start, in Unix time, from t_start_s and t_end_s, e.g. "
            "df[['t_start_s', 't_end_s']] -= START.",
        )
    raise InputError(
        where,
        expected,
        f"no interval on the log: the sheet spans {_span(sheet)}",
        "Write the sheet's times on the log's clock"
        + (
            f" (if they count from the log's start, add {t0:.17g} s to t_start_s and t_end_s)"
            if from_start
            else f" (its stops lie within {_span(log_span)})"
        )
        + ".",
    )


def zone_offsets(lo: np.ndarray, hi: np.ndarray, samples: Samples, cfg: StopDetection | None = None) -> list[float]:
    """The offsets of a time zone (quarter hours, ±14 h) by which the sheet is after the log, those that put
    at least half its intervals on the log's still periods (the most first), else none."""
    stops = find_stops(samples, cfg).stops
    if not stops:
        return []
    mid = np.array([(s.t_start_s + s.t_end_s) / 2.0 for s in stops])
    need = max(1, math.ceil(lo.size / 2))
    scores = {}
    for k in range(-int(MAX_ZONE_S / ZONE_STEP_S), int(MAX_ZONE_S / ZONE_STEP_S) + 1):
        off = k * ZONE_STEP_S
        held = ((lo[:, None] - off <= mid[None, :]) & (mid[None, :] <= hi[:, None] - off)).any(axis=1)
        if k and int(held.sum()) >= need:
            scores[off] = int(held.sum())
    best = max(scores.values(), default=0)
    return sorted((off for off, n in scores.items() if n == best), key=lambda off: (off % 3600 != 0, abs(off)))


def _zone(
    off: float, more: bool, sheet: tuple[float, float], log: tuple[float, float], samples: Samples
) -> tuple[str, str, str]:
    """The refusal of a sheet a time zone's offset from the log: expected, found, what to do."""
    side = "after" if off > 0 else "before"
    first = sheet[0] - off
    utc = "" if any(c.name == "clock" for c in samples.conventions) else " (UTC)"
    return (
        f"the sheet's times on the log's clock ({_clock(log, samples)})",
        f"them {_hours(abs(off))} {side} it ({_span(sheet)}), a time zone's offset"
        + (" (another zone's offset fits as well)" if more else "")
        + ": a sheet, or a log, on a local clock",
        f"Write the sheet on the log's clock{utc}: "
        + (f"subtract {off:.0f} s from" if off > 0 else f"add {-off:.0f} s to")
        + f" t_start_s and t_end_s, its first stop then starting at {first:.17g} ({_date(first)}), e.g. in pandas "
        f"df[['t_start_s', 't_end_s']] {'-' if off > 0 else '+'}= {abs(off):.0f}.",
    )


def _clock(span: tuple[float, float], samples: Samples) -> str:
    """What the log's clock is, with its span."""
    said = next((c.value for c in samples.conventions if c.name == "clock"), "")
    if span[0] < DATED_S:
        return f"its times {_span(span)}, not dated"
    return f"Unix time, {_span(span)}" + (f"; {said}" if said else "")


def _span(span: tuple[float, float]) -> str:
    """Two times as numbers, and as UTC dates where they are Unix times."""
    text = f"{span[0]:.10g}–{span[1]:.10g} s"
    if span[0] < DATED_S:
        return text
    a, b = _date(span[0]), _date(span[1])
    same_day = a[:10] == b[:10]
    return f"{text} = {a[:-4]} – {b[11:] if same_day else b}"


def _date(t: float) -> str:
    return datetime.fromtimestamp(t, tz=UTC).strftime("%Y-%m-%d %H:%M:%S UTC")


def _hours(seconds: float) -> str:
    h, m = divmod(round(seconds / 60.0), 60)
    return f"{h} h" + (f" {m} min" if m else "")


__all__ = ["DATED_S", "PLAN_MARK", "on_log_clock", "zone_offsets"]
