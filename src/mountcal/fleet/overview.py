"""The fleet on one page: ``<stem>_overview.html`` beside the tables.

For fleet people rather than for a program: a table of the vehicles — the current mounting ± σ,
since when, its remounts, and whether it is confident (those that are not come first) — and a
plot per vehicle of each log's roll, pitch and yaw over time with its 1σ, the consensus of each
mounting period, and the remounts marked. Plots need matplotlib (``mountcal[report]``); without
it the page holds the table and says so. At most :data:`MAX_PLOTS` vehicles are drawn (those not
confident and those remounted first); the rest are counted.
"""

from __future__ import annotations

import html
import io
import math
from pathlib import Path
from typing import Any

import pandas as pd

from mountcal.atomic import atomic_path
from mountcal.errors import InputError

MAX_PLOTS = 60
MARK = '<meta name="generator" content="mountcal fleet overview">'
ANGLES = (("roll", "tab:blue"), ("pitch", "tab:orange"), ("yaw", "tab:green"))


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
        "td,th{padding:2px 8px;border-bottom:1px solid #ddd;text-align:left}.bad{color:#b00}"
        ".fig{display:inline-block;margin:4px;vertical-align:top}</style></head><body>",
        f"<h1>{html.escape(title)}</h1>",
        f"<p>{len(vehicles)} vehicles, {len(logs)} logs ({int((logs['status'] == 'ok').sum())} ok). "
        "Angles in degrees, ± 1σ; conventions: docs/conventions.md.</p>",
        _table(order),
        "<h2>Mounting over time</h2>",
        "<p>Each log's angles with 1σ bars; lines: the consensus of each mounting period; "
        "dashed: a remount.</p>" + plots,
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


def _angle(value: Any, sigma: Any) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "—"
    return f"{value:.3f} ± {sigma:.3f}" if sigma is not None and not pd.isna(sigma) else f"{value:.3f}"


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
            f"{_time(r['time'])} ({r['change_deg']:.2f}° ± {r['change_sigma_deg']:.2f}°)" for r in (v.remounts or [])
        )
        yaw = _angle(v.yaw_deg, v.yaw_sigma_deg) if not pd.isna(v.yaw_deg) else f"— ({html.escape(str(v.yaw_reason))})"
        rows.append(
            f"<tr><td>{html.escape(str(v.vehicle_id))}</td><td>{_angle(v.roll_deg, v.roll_sigma_deg)}</td>"
            f"<td>{_angle(v.pitch_deg, v.pitch_sigma_deg)}</td><td>{yaw if v.status == 'ok' else '—'}</td>"
            f"<td>{html.escape(_time(v.since_time) or str(v.since_log or ''))}</td>"
            f"<td>{html.escape(remounts) or 'none'}</td><td>{state}</td></tr>"
        )
    return f"<table>{head}{''.join(rows)}</table>"


def _time(value: Any) -> str:
    return "" if value is None or pd.isna(value) else pd.Timestamp(value).strftime("%Y-%m-%d %H:%M")


def _plots(vehicles: pd.DataFrame, logs: pd.DataFrame) -> tuple[str, int]:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return "<p>(Plots need matplotlib: pip install 'mountcal[report]'.)</p>", 0
    figures = []
    for v in vehicles[vehicles["status"] == "ok"].head(MAX_PLOTS).itertuples():
        mine = logs[(logs["vehicle_id"] == v.vehicle_id) & (logs["status"] == "ok")]
        by_time = v.order == "start_time"
        mine = mine.sort_values("start_time" if by_time else "log")
        x = list(mine["start_time"]) if by_time else list(range(len(mine)))
        fig, axes = plt.subplots(3, 1, figsize=(4.2, 3.6), sharex=True)
        for ax, (name, color) in zip(axes, ANGLES, strict=True):
            ax.errorbar(x, mine[f"{name}_deg"], yerr=mine[f"{name}_sigma_deg"], fmt="o", ms=3, color=color, lw=1)
            for m in v.mountings:
                value = m.get(f"{name}_deg")
                if value is None:
                    continue
                lo, hi = (m["first_start_time"], m["last_start_time"]) if by_time else _span(mine, m)
                ax.plot([lo, hi], [value, value], color="k", lw=1)
            for r in v.remounts:
                at = r["time"] if by_time else _index(mine, r["log"])
                if at is not None:
                    ax.axvline(at, color="r", ls="--", lw=1)
            ax.set_ylabel(f"{name} °", fontsize=8)
            ax.tick_params(labelsize=7)
        axes[0].set_title(str(v.vehicle_id), fontsize=9)
        fig.autofmt_xdate()
        buffer = io.StringIO()
        fig.savefig(buffer, format="svg", bbox_inches="tight")
        plt.close(fig)
        svg = buffer.getvalue()
        figures.append(f"<div class='fig'>{svg[svg.index('<svg') :]}</div>")
    return "".join(figures), len(figures)


def _index(mine: pd.DataFrame, log: str) -> int | None:
    hits = [i for i, name in enumerate(mine["log"]) if name == log]
    return hits[0] if hits else None


def _span(mine: pd.DataFrame, mounting: dict[str, Any]) -> tuple[int, int]:
    a, b = _index(mine, mounting["first_log"]), _index(mine, mounting["last_log"])
    return (a or 0, b if b is not None else len(mine) - 1)


__all__ = ["MAX_PLOTS", "check_overview_overwritable", "overview_path", "write_overview"]
