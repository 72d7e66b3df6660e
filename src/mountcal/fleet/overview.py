"""The fleet on one page: ``<stem>_overview.html`` beside the tables.

For fleet people rather than for a program: a table of the vehicles — the current mounting ± σ,
since when, its remounts, and whether it is confident (those that are not come first) — and a
plot per vehicle of each log's roll, pitch and yaw over time with its 1σ, the consensus of each
mounting period, and the remounts marked. At most :data:`MAX_PLOTS` vehicles are drawn (those not
confident and those remounted first); the rest are counted.

The plots are small SVG written here rather than by matplotlib: the page is written at the end of
every run, on the command's serial path, where matplotlib's import and figures cost 1–3 s for twenty
vehicles against well under a millisecond per vehicle for these.
"""

from __future__ import annotations

import html
import math
from pathlib import Path
from typing import Any

import pandas as pd

from mountcal.core.angles import AngleName, Angles
from mountcal.core.atomic import atomic_path
from mountcal.core.errors import InputError

MAX_PLOTS = 200
MARK = '<meta name="generator" content="mountcal fleet overview">'
ANGLES: tuple[tuple[AngleName, str], ...] = (("roll", "#1f77b4"), ("pitch", "#ff7f0e"), ("yaw", "#2ca02c"))


def overview_path(output: str | Path) -> Path:
    output = Path(output)
    return output.with_name(f"{output.stem}_overview.html")


def check_overview_overwritable(path: Path) -> None:
    """Refuse to replace an existing file that is not an overview this module wrote."""
    if not path.exists():
        return
    try:
        with path.open("rb") as f:
            head = f.read(4096)
    except OSError:
        head = b""
    if MARK.encode() not in head:
        raise InputError(
            str(path),
            "a new path, or an overview an earlier `mountcal fleet` run wrote",
            "an existing file that mountcal did not write",
            "Move it, or choose another -o path (the overview is named after it).",
        )


def write_overview(path: Path, vehicles: pd.DataFrame, logs: pd.DataFrame, title: str) -> None:
    """Write the page atomically."""
    order = vehicles.assign(
        _rank=[0 if s != "ok" or not c else 1 if r else 2 for s, c, r in _flags(vehicles)]
    ).sort_values(["_rank", "vehicle_id"], kind="stable")
    plots, drawn = _plots(order, logs)
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'>",
        MARK,
        f"<title>{html.escape(title)}</title>",
        "<style>body{font:14px system-ui,sans-serif;margin:1.5em}table{border-collapse:collapse}"
        "td,th{padding:2px 8px;white-space:nowrap;border-bottom:1px solid #ddd;text-align:left}.bad{color:#b00}"
        ".fig{display:inline-block;margin:4px;vertical-align:top}</style></head><body>",
        f"<h1>{html.escape(title)}</h1>",
        f"<p>{len(vehicles)} vehicles, {len(logs)} logs ({int((logs['status'] == 'ok').sum())} ok). "
        "Angles in degrees, ± 1σ; conventions: docs/conventions.md.</p>",
        _table(order),
        "<h2>Mounting over time</h2>",
        "<p>Each log's angles with 1σ bars; black lines: the consensus of each mounting period; "
        "red dashed: a remount.</p>" + plots,
    ]
    if drawn < len(order):
        parts.append(f"<p>{len(order) - drawn} more vehicles not drawn (see fleet_vehicles.parquet).</p>")
    parts.append("</body></html>")
    with atomic_path(path) as tmp:
        tmp.write_text("\n".join(parts), encoding="utf-8")


def _flags(vehicles: pd.DataFrame) -> list[tuple[Any, bool, bool]]:
    return [
        (s, bool(c) if c is not None and c is not pd.NA else False, bool(n))
        for s, c, n in zip(vehicles["status"], vehicles["latest_confident"], vehicles["n_remounts"], strict=True)
    ]


def _angles(row: dict[str, Any]) -> list[str]:
    """The cells of roll, pitch and yaw ± σ of a vehicle's row ("—" without a calibration)."""
    if row["status"] != "ok":
        return ["—"] * 3
    a = Angles.from_columns(row)

    def cell(name: AngleName) -> str:
        value, sigma = a.value(name), a.sigma(name)
        if value is None:
            return f"— ({html.escape(str(a.yaw_reason))})" if name == "yaw" else "—"
        return f"{value:.3f} ± {sigma:.3f}" if sigma is not None else f"{value:.3f}"

    return [cell(name) for name, _ in ANGLES]


def _table(vehicles: pd.DataFrame) -> str:
    names = ("vehicle", "roll", "pitch", "yaw", "since", "remounts", "current mounting")
    head = "<tr>" + "".join(f"<th>{n}</th>" for n in names) + "</tr>"
    rows = []
    for v in vehicles.itertuples():
        if v.status != "ok":
            state = f"<span class='bad'>no calibration: {html.escape(str(v.reason))}</span>"
        elif not v.latest_confident:
            state = f"<span class='bad'>not confident: {html.escape(str(v.confidence_note))}</span>"
        else:
            state = "confident"
        remounts = "; ".join(
            f"{_time(r['time'])} ({r['change_deg']:.2f}° ± {r['change_sigma_deg']:.2f}°)" for r in _list(v.remounts)
        )
        roll, pitch, yaw = _angles(v._asdict())
        rows.append(
            f"<tr><td>{html.escape(str(v.vehicle_id))}</td><td>{roll}</td><td>{pitch}</td><td>{yaw}</td>"
            f"<td>{html.escape(_time(v.since_time) or str(v.since_log or ''))}</td>"
            f"<td>{html.escape(remounts) or 'none'}</td><td>{state}</td></tr>"
        )
    return f"<table>{head}{''.join(rows)}</table>"


def _time(value: Any) -> str:
    return "" if value is None or pd.isna(value) else pd.Timestamp(value).strftime("%Y-%m-%d %H:%M")


def _plots(vehicles: pd.DataFrame, logs: pd.DataFrame) -> tuple[str, int]:
    figures = []
    ok_logs = logs[logs["status"] == "ok"]
    by_vehicle = dict(tuple(ok_logs.groupby("vehicle_id", sort=False)))
    for v in vehicles[vehicles["status"] == "ok"].head(MAX_PLOTS).itertuples():
        mine = by_vehicle.get(v.vehicle_id, ok_logs.iloc[:0])
        figures.append(f"<div class='fig'>{_svg(v, mine)}</div>")
    return "".join(figures), len(figures)


W, PAD_L, PAD_R, PAD_T, PANEL, GAP = 380, 52, 8, 18, 66, 8
H = PAD_T + 3 * (PANEL + GAP) + 14


def _svg(v: Any, mine: pd.DataFrame) -> str:
    """One vehicle: three panels (roll, pitch, yaw) of its logs over time (or in log order)."""
    by_time = v.order == "start_time" and bool(mine["start_time"].notna().all())
    mine = mine.sort_values("start_time" if by_time else "log", kind="stable")
    xs = [pd.Timestamp(t).timestamp() for t in mine["start_time"]] if by_time else [float(i) for i in range(len(mine))]
    lo, hi = (min(xs), max(xs)) if xs else (0.0, 1.0)
    span = hi - lo or 1.0

    def x_of(value: float) -> float:
        return PAD_L + (W - PAD_L - PAD_R) * ((value - lo) / span if len(xs) > 1 else 0.5)

    names = [str(n) for n in mine["log"]]
    out = [f"<svg xmlns='http://www.w3.org/2000/svg' width='{W}' height='{H}' font-size='10'>"]
    out.append(f"<text x='{PAD_L}' y='12' font-weight='bold'>{html.escape(str(v.vehicle_id))}</text>")
    for k, (name, color) in enumerate(ANGLES):
        top = PAD_T + k * (PANEL + GAP)
        points = [
            (x, float(y), float(e))
            for x, y, e in zip(xs, mine[Angles.value_column(name)], mine[Angles.sigma_column(name)], strict=True)
            if y is not None and math.isfinite(y)
        ]
        box = f"x='{PAD_L}' y='{top}' width='{W - PAD_L - PAD_R}' height='{PANEL}'"
        out.append(f"<rect {box} fill='none' stroke='#999'/>")
        out.append(f"<text x='2' y='{top + PANEL / 2 + 3}'>{name} °</text>")
        if not points:
            out.append(f"<text x='{PAD_L + 6}' y='{top + PANEL / 2 + 3}' fill='#777'>not determined</text>")
            continue
        y_lo = min(y - (e if math.isfinite(e) else 0.0) for _, y, e in points)
        y_hi = max(y + (e if math.isfinite(e) else 0.0) for _, y, e in points)
        y_span = (y_hi - y_lo) or 1.0

        def y_of(value: float, top: float = top, y_lo: float = y_lo, y_span: float = y_span) -> float:
            return top + PANEL - 4 - (PANEL - 8) * (value - y_lo) / y_span

        out.append(f"<text x='{PAD_L - 2}' y='{top + 8}' text-anchor='end' fill='#555'>{y_hi:.2f}</text>")
        out.append(f"<text x='{PAD_L - 2}' y='{top + PANEL}' text-anchor='end' fill='#555'>{y_lo:.2f}</text>")
        for x, y, e in points:
            cx = x_of(x)
            if math.isfinite(e):
                out.append(_line(cx, cx, y_of(y - e), y_of(y + e), color))
            out.append(f"<circle cx='{cx:.1f}' cy='{y_of(y):.1f}' r='2.5' fill='{color}'/>")
        for m in _list(v.mountings):
            value = m.get(Angles.value_column(name))
            if value is None or not math.isfinite(value):
                continue
            a, b = _extent(m, names, by_time)
            out.append(_line(x_of(a), x_of(b), y_of(value), y_of(value), "black"))
        for r in _list(v.remounts):
            timed = by_time and r["time"] is not None
            at = pd.Timestamp(r["time"]).timestamp() if timed else _position(names, r["log"])
            if at is not None:
                out.append(_line(x_of(at), x_of(at), top, top + PANEL, "red", dashed=True))
    bottom = PAD_T + 3 * (PANEL + GAP) + 4
    if by_time and len(mine):
        first, last = _time(mine["start_time"].iloc[0]), _time(mine["start_time"].iloc[-1])
    else:
        first, last = "log 1", f"log {len(xs)}"
    out.append(f"<text x='{PAD_L}' y='{bottom}' fill='#555'>{first}</text>")
    out.append(f"<text x='{W - PAD_R}' y='{bottom}' text-anchor='end' fill='#555'>{last}</text>")
    out.append("</svg>")
    return "".join(out)


def _line(x1: float, x2: float, y1: float, y2: float, color: str, dashed: bool = False) -> str:
    dash = " stroke-dasharray='4 3'" if dashed else ""
    return f"<line x1='{x1:.1f}' x2='{x2:.1f}' y1='{y1:.1f}' y2='{y2:.1f}' stroke='{color}'{dash}/>"


def _list(value: Any) -> list[Any]:
    """A nested column's value as a list (Parquet gives arrays, the run gives lists)."""
    return [] if value is None else list(value)


def _position(names: list[str], log: str) -> float | None:
    return float(names.index(log)) if log in names else None


def _extent(mounting: dict[str, Any], names: list[str], by_time: bool) -> tuple[float, float]:
    """Where a mounting period starts and ends on the plot's x axis."""
    if by_time:
        first, last = mounting["first_start_time"], mounting["last_start_time"]
        return pd.Timestamp(first).timestamp(), pd.Timestamp(last).timestamp()
    a, b = _position(names, mounting["first_log"]), _position(names, mounting["last_log"])
    return (a or 0.0, b if b is not None else float(len(names) - 1))


__all__ = ["MAX_PLOTS", "check_overview_overwritable", "overview_path", "write_overview"]
