"""Simulated sessions written to files: a stop table, or a parking session as logs (``mountcal simulate``).

The command line parses and checks that no output lands on an input (from the paths its parser
declares: :mod:`mountcal.cli.path_options`); this module simulates, writes atomically and says what
it wrote (lines for the user). The truth goes to a JSON file when asked.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from mountcal.core import ranges
from mountcal.core.atomic import atomic_path
from mountcal.core.conventions import G_N, normal_gravity
from mountcal.core.errors import InputError
from mountcal.simulate.stops import PRESETS, ParkingLog, simulate_parking_log, simulate_stops
from mountcal.stops.table import Headings, write_stop_table

PathLike = str | os.PathLike[str]


@dataclass(frozen=True)
class FieldEffects:
    """What field loggers add to a simulated log (units in the names; 0/None: none)."""

    gyro_bias_dps: tuple[float, float, float] | None = None
    acc_lsb_mps2: float = 0.0
    gyro_lsb_dps: float = 0.0
    paired_stamps: bool = False


def session_params(
    preset: str = "zhang2011",
    overrides: Mapping[str, float | None] | None = None,
    bias_mg: Sequence[float] | None = None,
) -> dict[str, Any]:
    """A preset's parameters with the given ones replaced (None keeps the preset's); bias in mg."""
    if preset not in PRESETS:
        raise InputError("the simulation preset", f"one of {', '.join(PRESETS)}", repr(preset), "Choose a listed one.")
    params: dict[str, Any] = dict(PRESETS[preset])
    params.update({k: v for k, v in (overrides or {}).items() if v is not None})
    if bias_mg is not None:
        params["bias_mps2"] = np.asarray(bias_mg, dtype=float) * 1e-3 * G_N
    return params


class Simulated(NamedTuple):
    """What a simulation wrote: lines for the user (the first says what was simulated), the truth, the files."""

    lines: list[str]
    truth: dict[str, Any]
    written: list[str]


def write_stop_session(
    output: PathLike,
    params: Mapping[str, Any],
    *,
    headings: Headings = "uphill",
    heading_offset_deg: float = 0.0,
    seed: int = 0,
    truth: PathLike | None = None,
) -> Simulated:
    """Simulate stops and write the stop table (and the truth): lines for the user, the truth, the files."""
    table, found = simulate_stops(headings=headings, heading_offset_deg=heading_offset_deg, seed=seed, **params)
    write_stop_table(table, Path(output))
    roll, pitch, yaw = found.angles_deg
    true = {
        "roll_deg": roll,
        "pitch_deg": pitch,
        "yaw_deg": yaw,
        "slope_deg": found.slope_deg,
        "bias_mps2": found.bias_mps2.tolist(),
        "g_mps2": found.g_mps2,
    }
    if truth is not None:
        _write_json(truth, true)
    written = [str(output), *([str(truth)] if truth is not None else [])]
    lines = [
        f"simulated {len(table)} stops (seed {seed}): roll {roll:g}°, pitch {pitch:g}°, yaw {yaw:g}°, "
        f"slope {found.slope_deg:g}°, bias {np.round(found.bias_mps2, 4).tolist()} m/s²",
        *(f"wrote {path}" for path in written),
    ]
    return Simulated(lines, true | {"seed": seed, "stops": len(table)}, written)


def write_log_session(
    logs: Sequence[PathLike],
    params: Mapping[str, Any],
    *,
    seed: int = 0,
    dbc: PathLike | None = None,
    fix: tuple[float, float, float] | None = None,
    start_time_s: float | None = None,
    session: Mapping[str, Any] | None = None,
    effects: FieldEffects = FieldEffects(),
    protocol: PathLike | None = None,
    truth: PathLike | None = None,
    each_log: Callable[[str], None] | None = None,
) -> Simulated:
    """Simulate a parking session and write it as each of ``logs`` (and its protocol sheet, its truth).

    ``session`` may set ``stop_s``, ``drive_s``, ``rate_hz``; ``each_log`` is called with every
    log's path once it is written (a progress bar). Returns lines for the user, the truth and the files.
    """
    from mountcal.io import writers as export

    formats = [export.check_log_path(p, dbc) for p in logs]
    if protocol is not None and "asc" in formats and len(formats) > 1:
        raise InputError(
            str(logs[formats.index("asc")]),
            "logs sharing one clock for the one protocol sheet",
            "an ASC log (python-can reads it from its first frame) among others",
            "Write the ASC log by itself, with its own protocol sheet.",
        )
    timing: dict[str, Any] = dict(session or {})
    n_stops = len(params["beta_deg"])
    rate, stop, drive = (
        timing.get(k, default) for k, default in (("rate_hz", 100.0), ("stop_s", 40.0), ("drive_s", 20.0))
    )
    # the session's samples, checked before any is made: memory and time grow with them
    ranges.check(
        "simulated_samples",
        round(rate * (n_stops * stop + (n_stops - 1) * drive)),
        "the samples of --rate-hz × the session's duration (--stop-s, --drive-s)",
        todo="Simulate a lower rate or shorter stops and drives.",
    )
    log = simulate_parking_log(
        params["roll_deg"],
        params["pitch_deg"],
        params["yaw_deg"],
        slope_deg=params["slope_deg"],
        beta_deg=tuple(params["beta_deg"]),
        bias_mps2=params.get("bias_mps2"),
        g_mps2=G_N if fix is None else normal_gravity(fix[0], fix[2]),
        seed=seed,
        gyro_bias_rad_s=None if effects.gyro_bias_dps is None else np.radians(effects.gyro_bias_dps),
        acc_lsb_mps2=effects.acc_lsb_mps2,
        gyro_lsb_rad_s=float(np.radians(effects.gyro_lsb_dps)),
        paired_stamps=effects.paired_stamps,
        **timing,
    )
    start = export.START_TIME_S if start_time_s is None else start_time_s
    roll, pitch, yaw = log.truth.angles_deg
    lines = [
        f"simulated a parking session ({len(log.protocol)} stops, {log.t_s[-1] - log.t_s[0]:.0f} s, "
        f"{log.t_s.size} samples; seed {seed}): roll {roll:g}°, pitch {pitch:g}°, yaw {yaw:g}°, "
        f"slope {log.truth.slope_deg:g}°, g {log.truth.g_mps2:.5f} m/s²"
    ]
    for path in logs:
        done = export.write_log(path, log, dbc_path=dbc, with_fix=fix, start_time_s=start)
        counts = ", ".join(f"{k} {v}" for k, v in done.messages.items())
        lines.append(f"wrote {path} ({done.format}: {counts})")
        for what, tally in (("saturated at the DBC range", done.saturated), ("not written", done.skipped)):
            if tally:
                lines.append(f"  {what}: " + ", ".join(f"{k} {v}" for k, v in tally.items()))
        if each_log is not None:
            each_log(str(path))
    if protocol is not None:
        export.write_protocol(protocol, log, start_time_s=done.start_time_s)
        lines.append(f"wrote {protocol} (protocol sheet on the log's clock, start {done.start_time_s:.6f} s)")
    true = session_truth(log, start_time_s=start, with_fix=fix) | {"seed": seed}
    if truth is not None:
        _write_json(truth, true)
        lines.append(f"wrote {truth}")
    written = [*map(str, logs), *(str(p) for p in (protocol, truth) if p is not None)]
    return Simulated(lines, true, written)


def _write_json(path: PathLike, doc: Mapping[str, Any]) -> None:
    with atomic_path(Path(path)) as tmp:
        tmp.write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n", encoding="utf-8")


def session_truth(
    log: ParkingLog, *, start_time_s: float, with_fix: tuple[float, float, float] | None
) -> dict[str, Any]:
    """What a simulated parking session really was, as a JSON-ready dict (units in the keys)."""
    truth = log.truth
    roll, pitch, yaw = truth.angles_deg
    return {
        "roll_deg": roll,
        "pitch_deg": pitch,
        "yaw_deg": yaw,
        "slope_deg": truth.slope_deg,
        "beta_deg": truth.beta_deg.tolist(),
        "uphill_azimuth_deg": log.uphill_azimuth_deg,
        "g_mps2": truth.g_mps2,
        "bias_mps2": truth.bias_mps2.tolist(),
        "start_time_s": start_time_s,
        "fix": None if with_fix is None else dict(zip(("lat_deg", "lon_deg", "alt_m"), with_fix, strict=True)),
        "samples": int(log.t_s.size),
        "duration_s": float(log.t_s[-1] - log.t_s[0]),
    }
