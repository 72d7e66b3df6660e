"""The text the ``fleet`` command prints when a run is done."""

from __future__ import annotations

from pathlib import Path

from mountcal.fleet.overview import overview_path
from mountcal.fleet.run import FleetResult

MAX_LISTED = 20


def summary_lines(result: FleetResult) -> list[str]:
    """What was done, what failed and why, and which vehicles were remounted."""
    logs, vehicles = result.logs, result.mountings
    failed = logs[logs["status"] != "ok"]
    lines = [
        f"mountcal fleet — {len(logs)} logs of {logs['vehicle_id'].nunique()} vehicles on {result.engine}: "
        f"{len(logs) - len(failed)} ok, {len(failed)} failed; {result.computed} calibrated now, "
        f"{result.reused} from earlier runs ({result.elapsed_s:.1f} s)",
        "  layout: " + layout_line(result),
    ]
    for row in failed.head(MAX_LISTED).itertuples():
        named = Path(str(row.log).split(" + ")[0]).name in str(row.error)  # the message names the file
        lines.append(f"  failed  {row.vehicle_id}  {row.error if named else f'{row.log}: {row.error}'}")
    if len(failed) > MAX_LISTED:
        lines.append(f"  … and {len(failed) - MAX_LISTED} more failed logs (see the status and error columns)")
    disagreeing = int(logs["flags"].map(lambda f: "disagrees_with_consensus" in f).sum())
    if disagreeing:
        lines.append(f"  {disagreeing} logs disagree with their vehicle's consensus (flag disagrees_with_consensus)")
    for row in vehicles[vehicles["remount"].fillna(False).astype(bool)].itertuples():
        lines.append(
            f"  remount {row.vehicle_id} at {row.remount_log}: mounting changed by "
            f"{row.remount_change_deg:.3f}° ± {row.remount_change_sigma_deg:.3f}° ({_p(row.remount_p_value)})"
        )
    nothing = vehicles[vehicles["status"] != "ok"]
    for row in nothing.itertuples():
        lines.append(f"  no calibration for {row.vehicle_id}: {row.reason}")
    ok = result.vehicles[result.vehicles["status"] == "ok"]
    for row in ok[~ok["latest_confident"].astype(bool)].head(MAX_LISTED).itertuples():
        lines.append(f"  not confident: the current mounting of {row.vehicle_id}: {row.confidence_note}")
    lines += [f"  note: {note}" for note in result.engine_notes]
    set_aside = [f"{n} {reason}" for reason, n in result.discarded.items() if n]
    if set_aside:
        lines.append("  set aside: " + "; ".join(set_aside))
    lines.append(
        f"wrote {result.output}, {result.vehicles_path} and {overview_path(result.output)} "
        f"(finished logs are kept in {result.parts})"
    )
    return lines


def layout_line(result: FleetResult) -> str:
    """Which layout the inputs were read in, and the vehicles, sessions and splits it found."""
    logs = result.logs
    names = ", ".join(f"{name} ({n} logs)" for name, n in sorted(result.layout.items())) or "none"
    line = f"{names}; {logs['vehicle_id'].nunique()} vehicles"
    if result.sessions:
        gaps = int(logs["split_gaps"].fillna(0).sum())
        overlaps = int(logs["split_overlaps"].fillna(0).sum())
        gap_s = float(logs["split_gap_s"].fillna(0).sum())
        line += (
            f", {result.sessions} sessions, {result.splits} splits "
            f"({gaps} gaps of {gap_s:.1f} s in all, {overlaps} overlaps between splits)"
        )
    return line


def _p(p: float) -> str:
    return "p < 1e-15" if p < 1e-15 else f"p = {p:.2g}"
