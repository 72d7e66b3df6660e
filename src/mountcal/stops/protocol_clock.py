"""A protocol sheet's clock against the log's: the one place a sheet's times meet a log (:func:`on_log_clock`).

A sheet's times must be on the log's clock. A sheet with an interval on the log is used as it is, unless its rows
sit on their neighbours' stops (:func:`rows_on_stops`, once the stop search left rows without a stop: refused,
naming the offset); a sheet at the wrong place otherwise is the stop search's to refuse. Where none lies on the
log, the two clocks are compared: a sheet counting from the log's start, on a log dated in Unix time, is shifted and
said (``protocol_clock``, inferred); a sheet a time zone's offset from the log, a dated sheet on an
undated log, or no relation at all are refused with the spans of both and the fix.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
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
    if np.any((hi >= t0) & (lo <= t1)):  # on the log: as stated (its rows on the wrong stops: rows_on_stops)
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


SHIFT_STEP_S = 1.0  # the grid of offsets a sheet's rows are tried at against the log's still periods
SHIFT_REACH = 2.5  # … out to this many times the sheet's median row spacing (a row or two off)


@dataclass(frozen=True)
class Shift:
    """A sheet on the log whose rows hold more of the log's still periods at another offset, where rows that
    hold one as written would hold another: its β would be attached to other stops' data."""

    offset_s: float  # to add to the sheet's times
    rows: int
    held: int  # rows holding a still period as written
    held_shifted: int  # … at the offset
    moved: list[int]  # rows (0-based) whose still period changes

    def refusal(self) -> tuple[str, str, str]:
        late = self.offset_s < 0
        size = f"{abs(self.offset_s):.0f} s"
        first = ", ".join(str(i + 1) for i in self.moved[:5]) + (" …" if len(self.moved) > 5 else "")
        return (
            "the sheet's rows on the log's stops, each row on the still period of its own heading",
            f"its rows {size} {'late' if late else 'early'}: as written {self.held} of its {self.rows} rows hold one "
            f"of the log's still periods, and the sheet {size} {'earlier' if late else 'later'} "
            f"{self.held_shifted}, with rows {first} then on another still period than as written (each would take "
            "a neighbour's β: the yaw turned by the headings' step, the fit as good)",
            f"If the sheet's times are {size} {'late' if late else 'early'} (a stopwatch or a clock off), "
            f"{'subtract' if late else 'add'} {size[:-2]} s {'from' if late else 'to'} t_start_s and t_end_s "
            f"(df[['t_start_s', 't_end_s']] {'-' if late else '+'}= {abs(self.offset_s):.0f}); if they are right, "
            "check its rows against the drive: a row missing or one too many shifts every heading after it.",
        )


def rows_on_stops(protocol: pd.DataFrame, samples: Samples, cfg: StopDetection | None = None) -> None:
    """Refuse a sheet on the log whose rows sit on their neighbours' stops (:func:`misplaced`). Called where some of
    its rows found no stop in their interval: a sheet each of whose rows holds one is never shifted, so the common
    case costs no second stop search.

    Raises
    ------
    InputError
        Naming the offset that puts the rows on the log's stops and the line that fixes the sheet.
    """
    lo, hi = (protocol[c].to_numpy(dtype=float) for c in COLUMNS)
    shift = misplaced(lo, hi, samples, cfg)
    if shift is not None:
        where = str(protocol.attrs.get("path") or f"the protocol sheet ({option('protocol')})")
        raise InputError(where, *shift.refusal())


def misplaced(lo: np.ndarray, hi: np.ndarray, samples: Samples, cfg: StopDetection | None = None) -> Shift | None:
    """The offset at which a sheet's rows hold more of the log's still periods than as written, where rows that hold
    one as written would hold another (None where the rows sit on the log's stops as well as any offset puts them).

    Each row is taken to hold the still period it overlaps most, if by ``min_duration_s`` (what the stop search
    keeps in a row). A sheet whose rows all hold a still period is never shifted; one with rows off the log or
    between stops is, only where the shift fills more rows and moves the rows' still periods: a sheet a stop or part
    of one late or early, whose headings would otherwise each fit a neighbour's data.
    """
    cfg = cfg or StopDetection()
    if lo.size < 3:
        return None
    stops = find_stops(samples, cfg).stops
    if len(stops) < 3:
        return None
    a = np.array([x.t_start_s for x in stops])
    b = np.array([x.t_end_s for x in stops])

    def picks(offset: float) -> tuple[np.ndarray, float]:
        overlap = np.minimum(hi[:, None] + offset, b[None, :]) - np.maximum(lo[:, None] + offset, a[None, :])
        best = overlap.argmax(axis=1)
        most = overlap[np.arange(lo.size), best]
        held = most >= cfg.min_duration_s
        return np.where(held, best, -1), float(np.sum(most[held]))

    written, _ = picks(0.0)
    held = int(np.sum(written >= 0))
    if held == lo.size:
        return None
    spacing = float(np.median(np.diff(np.sort(lo))))
    reach = SHIFT_REACH * max(spacing, float(np.median(hi - lo)))
    offsets = np.arange(-reach, reach + 0.5 * SHIFT_STEP_S, SHIFT_STEP_S)
    tried = [(int(np.sum(p >= 0)), round(total, 3)) for d in offsets for p, total in [picks(d)]]
    top = max(tried)
    count = top[0]
    offset = float(np.median(offsets[[k for k, x in enumerate(tried) if x == top]]))  # the middle of its plateau
    shifted, _ = picks(offset)
    moved = [i for i in range(lo.size) if written[i] >= 0 and shifted[i] >= 0 and written[i] != shifted[i]]
    if count <= held or not moved:
        return None
    return Shift(offset, int(lo.size), held, count, moved)


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


__all__ = ["DATED_S", "PLAN_MARK", "Shift", "misplaced", "on_log_clock", "rows_on_stops", "zone_offsets"]
