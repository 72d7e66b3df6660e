"""The log over time, as the report draws it: what the pipeline knows about a log, reduced to a small value.

A :class:`Timeline` holds the accelerometer (and speed) as a min/max envelope per pixel column —
a spike of one sample stays visible, and a log of hours costs no more to draw than one of
minutes — the stops with their number in the stop table and whether the fit used them, the still
periods detection did not keep, and the intervals the driving fit used. :func:`timeline_of`
builds it from :func:`mountcal.calibration.pipeline.calibrate_log`'s result; :func:`timeline` from the parts.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np

from mountcal.core.conventions import FloatArray
from mountcal.io.samples import Samples
from mountcal.stops.table import StopTable

if TYPE_CHECKING:
    from mountcal.calibration.pipeline import LogResult
    from mountcal.estimate.driving import DrivingFit
    from mountcal.stops.detect import StillPeriod

COLUMNS = 800  # pixel columns of the drawn log: finer detail cannot be seen
StopStatus = Literal["used", "left out", "not used", "dropped"]


@dataclass(frozen=True)
class Envelope:
    """Signals over time as drawn: per column the smallest and largest sample, NaN where a column is empty.

    ``t_s`` holds the column centres (the sample times when ``decimated`` is False: a short log is
    drawn sample by sample, ``low`` equal to ``high``); ``low`` and ``high`` have shape (m, k).
    """

    t_s: FloatArray
    low: FloatArray
    high: FloatArray
    decimated: bool


@dataclass(frozen=True)
class StopSpan:
    """A stop or a still period: its times on the log's clock (s), what became of it, and why.

    ``number`` is its row in the stop table (from 1); None for a still period detection did not keep.
    """

    t_start_s: float
    t_end_s: float
    status: StopStatus
    number: int | None = None
    why: str | None = None


@dataclass(frozen=True)
class Timeline:
    """A log over time, for the report (times on the log's clock, s).

    ``driving_s`` are the (start, end) of the driving fit's segments, touching ones merged;
    ``driving_use`` says what the result took from the drive (None: no driving fit);
    ``speed_offset_s`` is the driving fit's offset of the speed clock (the speed is drawn as logged).
    """

    source: str
    t_start_s: float
    t_end_s: float
    samples: int
    acc_mps2: Envelope
    speed_mps: Envelope | None = None
    stops: tuple[StopSpan, ...] = ()
    driving_s: tuple[tuple[float, float], ...] = ()
    driving_use: str | None = None
    speed_offset_s: float | None = None


def envelope(
    t_s: FloatArray, values: FloatArray, columns: int = COLUMNS, span: tuple[float, float] | None = None
) -> Envelope:
    """The min/max envelope of ``values`` (shape (n,) or (n, k)) in ``columns`` equal slices of time.

    Unlike a stride (every m-th sample), it keeps every extreme: a one-sample spike is the maximum
    of its column. Times need not be sorted. ``span`` sets the time range (default: the samples');
    samples outside it are left out. Up to ``2·columns`` samples are returned as they are.
    """
    t = np.asarray(t_s, dtype=float)
    v = np.asarray(values, dtype=float)
    v = v[:, None] if v.ndim == 1 else v
    lo, hi = (float(t.min()), float(t.max())) if span is None else span
    inside = (t >= lo) & (t <= hi)
    if not inside.all():
        t, v = t[inside], v[inside]
    if t.size > 1 and np.any(np.diff(t) < 0):
        order = np.argsort(t, kind="stable")
        t, v = t[order], v[order]
    width = (hi - lo) / columns
    if t.size <= 2 * columns or not width > 0:
        return Envelope(t, v, v, decimated=False)
    col = np.minimum(((t - lo) / width).astype(np.int64), columns - 1)  # sorted times: columns in order
    starts = np.flatnonzero(np.concatenate([[True], col[1:] != col[:-1]]))
    low = np.full((columns, v.shape[1]), np.nan)
    high = np.full((columns, v.shape[1]), np.nan)
    low[col[starts]] = np.fmin.reduceat(v, starts, axis=0)
    high[col[starts]] = np.fmax.reduceat(v, starts, axis=0)
    return Envelope(np.asarray(lo + (np.arange(columns) + 0.5) * width, dtype=float), low, high, decimated=True)


def timeline(
    samples: Samples,
    table: StopTable | None = None,
    *,
    left_out: Sequence[int] = (),
    not_used: str | None = None,
    dropped: Sequence[StillPeriod] = (),
    driving: DrivingFit | None = None,
    driving_use: str | None = None,
    columns: int = COLUMNS,
) -> Timeline:
    """The timeline of a log from its parts.

    Parameters
    ----------
    samples : Samples
        The log as read.
    table : StopTable, optional
        Its stops (``t_s`` and ``duration_s`` give each one's span), numbered in the table's order.
    left_out : sequence of int
        Stop numbers (from 1) the fit left out (``fit.excluded_stops``).
    not_used : str, optional
        Why the result was not fitted to these stops at all (every stop is then "not used").
    dropped : sequence of StillPeriod
        Still periods detection did not keep as a stop.
    driving : DrivingFit, optional
        The driving fit; its segments are the intervals it used.
    driving_use : str, optional
        What the result took from the drive, in words.
    columns : int
        Pixel columns the signals are reduced to.
    """
    t = samples.t_s
    lo, hi = (float(np.min(t)), float(np.max(t))) if t.size else (0.0, 0.0)
    speed = samples.channels.get("speed_mps")
    speed_env = None
    if speed is not None and np.any((speed.t_s >= lo) & (speed.t_s <= hi)):
        speed_env = envelope(speed.t_s, speed.value, columns, (lo, hi))
    pixel = (hi - lo) / columns
    stops = _table_stops(table, set(left_out), not_used)
    stops += tuple(
        StopSpan(a, b, "dropped", None, why)
        for a, b, why in _merged([(p.t_start_s, p.t_end_s, p.why) for p in dropped], pixel)
    )
    spans = () if driving is None else [(float(a), float(b), "") for a, b in driving.segments_s]
    return Timeline(
        source=samples.source or "log",
        t_start_s=lo,
        t_end_s=hi,
        samples=int(t.size),
        acc_mps2=envelope(t, samples.acc_s, columns) if t.size else Envelope(t, samples.acc_s, samples.acc_s, False),
        speed_mps=speed_env,
        stops=stops,
        driving_s=tuple((a, b) for a, b, _ in _merged(spans, pixel)),
        driving_use=driving_use if driving is not None else None,
        speed_offset_s=None if driving is None else driving.time_offset_s,
    )


def timeline_of(result: LogResult, columns: int = COLUMNS) -> Timeline:
    """The timeline of :func:`mountcal.calibration.pipeline.calibrate_log`'s result: its stops, dropped still
    periods and drive."""
    found = result.stops
    table = result.table if result.table is not None else (None if found is None else found.table)
    fitted = result.table is not None
    return timeline(
        result.samples,
        table,
        left_out=result.calibration.fit.excluded_stops if fitted else (),
        not_used=None if fitted else result.skipped.get("stops", "the result was not fitted to them"),
        dropped=() if found is None else found.dropped,
        driving=result.driving,
        driving_use=result.used,
        columns=columns,
    )


def _table_stops(table: StopTable | None, left_out: set[int], not_used: str | None) -> tuple[StopSpan, ...]:
    if table is None or table.t_s is None:
        return ()
    duration = table.duration_s if table.duration_s is not None else np.zeros(len(table))
    out = []
    for k, (start, length) in enumerate(zip(table.t_s, duration, strict=True), start=1):
        status: StopStatus = "not used" if not_used is not None else ("left out" if k in left_out else "used")
        out.append(StopSpan(float(start), float(start + length), status, k, not_used))
    return tuple(out)


def _merged(spans: Sequence[tuple[float, float, str]], gap: float) -> list[tuple[float, float, str]]:
    """Spans sorted and joined where less than ``gap`` apart (a pixel: the drawing stays bounded); a
    joined span keeps the first one's reason."""
    out: list[tuple[float, float, str]] = []
    for a, b, why in sorted(spans):
        if out and a - out[-1][1] < gap:
            out[-1] = (out[-1][0], max(out[-1][1], b), out[-1][2])
        else:
            out.append((a, b, why))
    return out
