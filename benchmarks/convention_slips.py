"""Convention slips a user makes, run through the command line: how many end in a confident wrong
answer, a traceback, or a refusal that does not name the option (or column) that fixes it.

Each slip changes a *convention* of a correct input — a sign, an axis swap, a unit, a heading
reference, a direction — the way a person does: a DBC sign, a spreadsheet column, a value typed in
g, an azimuth taken from the wrong end of the slope. Inputs are stop tables and logs (sample tables
of a simulated parking session, with and without a drive with speed) of random mountings; every case
runs `mountcal` in-process on the files, as a user would, and is scored:

- answered: right (within 5σ + 0.5° per determined angle, the tilt and the yaw about the vertical),
  not confident (an honest doubt), or **confident and wrong**;
- refused (exit 2 or 3): the message names the fix (one of the slip's options or columns), or **not**;
- **traceback**: anything but a clean exit.

Slips whose effect the data cannot show are listed apart ("the data cannot tell"): β from downhill or
with an unknown offset in a hand-made table without a drive turns the answer about the vertical and
fits exactly as well; the result states the assumption (``provenance.conventions``).

Usage::

    python benchmarks/convention_slips.py --cases 4 --seed 1 [--markdown]

The table in docs/conventions.md was made with ``--cases 4 --seed 1``.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import io
import json
import sys
import tempfile
import time
import traceback
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from mountcal.apply.rotate_log import to_frame
from mountcal.cli import main
from mountcal.core.result import Calibration
from mountcal.io.samples import Channel, Samples
from mountcal.simulate.drive import simulate_drive
from mountcal.simulate.stops import simulate_parking_log, simulate_stops

G = 9.80665
LOG_DETECTION = ["--min-stop-s", "25"]  # the parking stops (36 s), not a drive's waits at junctions


@dataclass
class Case:
    """One run: the command line, the truth, and what names the fix when it is refused."""

    argv: list[str]
    truth: Rotation | None  # None: any answer is wrong (a mirror image has no right rotation)
    fixes: tuple[str, ...]  # strings one of which a refusal must name
    cannot_tell: bool = False  # the data cannot show this slip
    refuse: bool = False  # a command that writes a file (rotate, triad, export): only a refusal is right


@dataclass
class Tally:
    counts: Counter[str] = field(default_factory=Counter)
    examples: dict[str, str] = field(default_factory=dict)


# --------------------------------------------------------------------------- scenarios


def _truth(rng: np.random.Generator) -> tuple[float, float, float, float]:
    return (
        float(rng.uniform(-20, 20)),
        float(rng.uniform(-20, 20)),
        float(rng.uniform(-180, 180)),
        float(rng.uniform(3, 15)),
    )


def _table(rng: np.random.Generator, headings: str = "uphill") -> tuple[pd.DataFrame, Rotation]:
    roll, pitch, yaw, slope = _truth(rng)
    table, truth = simulate_stops(
        roll,
        pitch,
        yaw,
        slope_deg=slope,
        noise_g=float(rng.uniform(0.0005, 0.002)),
        headings=headings,  # type: ignore[arg-type]
        heading_offset_deg=float(rng.uniform(10, 350)) if headings == "relative" else 0.0,
        seed=int(rng.integers(1 << 30)),
    )
    return table.to_frame(), truth.rot_vs


def _csv(df: pd.DataFrame, folder: Path, name: str) -> str:
    path = folder / name
    df.to_csv(path, index=False, float_format="%.15g")
    return str(path)


def _flip(df: pd.DataFrame, col: str) -> pd.DataFrame:
    out = df.copy()
    out[col] = -out[col]
    return out


def table_slips(rng: np.random.Generator, folder: Path) -> dict[str, Case]:
    """Slips on a stop table (each from its own random mounting)."""
    cases: dict[str, Case] = {}
    for axis in "xyz":
        df, truth = _table(rng)
        cases[f"table: a{axis} negated (a DBC sign)"] = Case(
            ["calibrate", _csv(_flip(df, f"a{axis}"), folder, f"neg_{axis}.csv")], None, ("--axes",)
        )
    df, truth = _table(rng)
    swapped = df.rename(columns={"ax": "ay", "ay": "ax"})
    cases["table: ax and ay swapped"] = Case(["calibrate", _csv(swapped, folder, "swap.csv")], None, ("--axes",))
    df, truth = _table(rng)
    in_g = df.copy()
    for c in ("ax", "ay", "az", "sx", "sy", "sz"):
        in_g[c] = in_g[c] / G
    cases["table: in g, no --unit"] = Case(["calibrate", _csv(in_g, folder, "g.csv")], truth, ("--unit g",))
    df, truth = _table(rng)
    cases["table: --unit g on m/s²"] = Case(
        ["calibrate", _csv(df, folder, "mps2.csv"), "--unit", "g"], truth, ("--unit g",)
    )
    df, truth = _table(rng)
    noisy = df.copy()
    for c in ("ax", "ay", "az"):
        noisy[c] = noisy[c] / G
    cases["table: ax, ay, az in g, sx, sy, sz left in m/s² (--unit g)"] = Case(
        ["calibrate", _csv(noisy, folder, "noise_unit.csv"), "--unit", "g"], truth, ()
    )
    df, truth = _table(rng)
    rad = df.copy()
    rad["beta_deg"] = np.radians(rad["beta_deg"])
    cases["table: β in radians"] = Case(["calibrate", _csv(rad, folder, "rad.csv")], truth, ("--heading-unit",))
    df, truth = _table(rng)
    cw = df.copy()
    cw["beta_deg"] = (-cw["beta_deg"]) % 360.0
    cases["table: β clockwise (compass-like)"] = Case(
        ["calibrate", _csv(cw, folder, "cw.csv")], truth, ("--axes", "--uphill-azimuth-deg")
    )
    df, truth = _table(rng)
    cases["table: --heading-unit rad on degrees"] = Case(
        ["calibrate", _csv(df, folder, "deg.csv"), "--heading-unit", "rad"], truth, ("--heading-unit",)
    )
    df, truth = _table(rng, "relative")
    edited = df.drop(columns=["heading_ref"]).assign(heading_deg=(-df["beta_deg"]) % 360.0)
    cases["table from `stops` (relative): heading_ref deleted in a spreadsheet"] = Case(
        ["calibrate", _csv(edited, folder, "edited.csv")], truth, ("heading_ref",)
    )
    df, truth = _table(rng, "relative")
    parquet = folder / "rel.parquet"
    df.to_parquet(parquet, index=False)
    cases["table (Parquet): relative β, --headings uphill"] = Case(
        ["calibrate", str(parquet), "--headings", "uphill"], truth, ("heading_ref",)
    )
    df, truth = _table(rng, "relative")
    cases["table: relative β, --headings uphill"] = Case(
        ["calibrate", _csv(df, folder, "rel.csv"), "--headings", "uphill"], truth, ("heading_ref",)
    )
    df, truth = _table(rng)
    cases["table: --gravity 1 (g for m/s²)"] = Case(
        ["calibrate", _csv(df, folder, "grav.csv"), "--gravity", "1"], truth, ("--gravity",)
    )
    df, truth = _table(rng)
    down = df.drop(columns=["heading_ref"])
    down["beta_deg"] = (down["beta_deg"] + 180.0) % 360.0
    cases["table: β from downhill, no heading_ref (hand-made)"] = Case(
        ["calibrate", _csv(down, folder, "down.csv")], truth, (), cannot_tell=True
    )
    df, truth = _table(rng, "relative")
    cases["table: relative β, no heading_ref (hand-made)"] = Case(
        ["calibrate", _csv(df.drop(columns=["heading_ref"]), folder, "rel_bare.csv")], truth, (), cannot_tell=True
    )
    return cases


def _parking(
    rng: np.random.Generator, drive_s: float = 0.0
) -> tuple[Samples, Rotation, list[tuple[float, float, float]]]:
    """A parking session on a slope (uphill azimuth 30°), optionally followed by a drive, as one log."""
    roll, pitch, yaw, slope = _truth(rng)
    park = simulate_parking_log(roll, pitch, yaw, slope_deg=slope, seed=int(rng.integers(1 << 30)))
    t, acc, gyro = park.t_s, park.acc_s, park.gyro_s
    speed_t, speed, heading = park.t_s, park.speed_mps, park.heading_deg
    if drive_s > 0:
        d = simulate_drive(roll, pitch, yaw, duration_s=drive_s, seed=int(rng.integers(1 << 30)))
        t0 = t[-1] + 10.0
        speed_t = np.concatenate([speed_t, d.speed_t_s + t0])
        speed = np.concatenate([speed, d.speed_mps])
        heading = np.concatenate([heading, d.heading_deg])
        t, acc, gyro = np.concatenate([t, d.t_s + t0]), np.concatenate([acc, d.acc_s]), np.concatenate([gyro, d.gyro_s])
    channels = {"speed_mps": Channel(speed_t, speed), "heading_deg": Channel(t, heading)}
    return Samples(t, acc, gyro, channels, source="<simulated>"), park.truth.rot_vs, park.protocol


def _reversed_into(s: Samples, rows: list[tuple[float, float, float]], k: int) -> Samples:
    """The log with stop ``k`` entered in reverse as a course over ground sees it: the heading channel a half turn
    off from 3 s before the stop until the vehicle moves again."""
    h, v = s.channels["heading_deg"], s.channels["speed_mps"]
    start, end = rows[k][0] - 3.0, rows[k][1]
    moving = v.t_s[(v.t_s > end) & (v.value > 0.3)]
    end = float(moving[0]) if moving.size else float(h.t_s[-1])
    inside = (h.t_s >= start) & (h.t_s <= end)
    turned = Channel(h.t_s, np.where(inside, (h.value + 180.0) % 360.0, h.value))
    return dataclasses.replace(s, channels={**s.channels, "heading_deg": turned})


def _course_at_rest(s: Samples, value: float) -> Samples:
    """The log with its heading channel as a receiver's course over ground: ``value`` (NaN: empty) wherever the
    vehicle is at rest."""
    h, v = s.channels["heading_deg"], s.channels["speed_mps"]
    still = np.interp(h.t_s, v.t_s, v.value) < 0.2
    course = Channel(h.t_s, np.where(still, value, h.value))
    return dataclasses.replace(s, channels={**s.channels, "heading_deg": course})


def _log(samples: Samples, folder: Path, name: str) -> str:
    path = folder / name
    to_frame(samples).to_parquet(path, index=False)
    return str(path)


def _protocol(rows: list[tuple[float, float, float]], folder: Path, name: str, f: Callable[[float], float]) -> str:
    path = folder / name
    pd.DataFrame([(a, b, f(c)) for a, b, c in rows], columns=["t_start_s", "t_end_s", "beta_deg"]).to_csv(
        path, index=False
    )
    return str(path)


def log_slips(rng: np.random.Generator, folder: Path) -> dict[str, Case]:
    """Slips on logs: a parking session (and a drive with speed) as a sample table."""
    cases: dict[str, Case] = {}
    s, truth, rows = _parking(rng)
    flip = np.array([1.0, -1.0, 1.0])
    mirrored = dataclasses.replace(s, acc_s=s.acc_s * flip, gyro_s=s.gyro_s * flip)  # type: ignore[operator]
    cases["log: y negated (accelerometer and gyro), protocol"] = Case(
        ["calibrate", _log(mirrored, folder, "mirror.parquet"), "--protocol", _protocol(rows, folder, "p.csv", float)],
        None,
        ("--axes",),
    )
    s, truth, rows = _parking(rng)
    cases["log: --axes x,-y,z given on a right-handed log"] = Case(
        ["calibrate", _log(s, folder, "right.parquet"), "--uphill-azimuth-deg", "30", "--axes", "x,-y,z"],
        None,
        ("--axes",),
    )
    s, truth, rows = _parking(rng)
    cases["log: protocol β in radians"] = Case(
        ["calibrate", _log(s, folder, "a.parquet"), "--protocol", _protocol(rows, folder, "r.csv", np.radians)],
        truth,
        ("--heading-unit",),
    )
    s, truth, rows = _parking(rng)
    cases["log: protocol β clockwise"] = Case(
        ["calibrate", _log(s, folder, "b.parquet"), "--protocol", _protocol(rows, folder, "c.csv", lambda b: -b % 360)],
        truth,
        ("--axes", "clockwise"),
    )
    s, truth, rows = _parking(rng)
    h = s.channels["heading_deg"]
    rad = dataclasses.replace(s, channels={**s.channels, "heading_deg": Channel(h.t_s, np.radians(h.value))})
    cases["log: heading channel in radians, --uphill-azimuth-deg"] = Case(
        ["calibrate", _log(rad, folder, "hrad.parquet"), "--uphill-azimuth-deg", "30"], truth, ("--heading-unit",)
    )
    s, truth, rows = _parking(rng)
    enu = dataclasses.replace(s, channels={**s.channels, "heading_deg": Channel(h.t_s, (90.0 - h.value) % 360.0)})
    cases["log: ENU yaw as the compass heading, --uphill-azimuth-deg"] = Case(
        ["calibrate", _log(enu, folder, "enu.parquet"), "--uphill-azimuth-deg", "30"], truth, ("--axes", "compass")
    )
    s, truth, rows = _parking(rng, drive_s=500.0)
    log = _log(s, folder, "drive.parquet")
    cases["log + drive: uphill azimuth given downhill"] = Case(
        ["calibrate", log, "--uphill-azimuth-deg", "210", *LOG_DETECTION], truth, ("--uphill-azimuth-deg",)
    )
    cases["log + drive: uphill azimuth counter-clockwise from east"] = Case(
        ["calibrate", log, "--uphill-azimuth-deg", "60", *LOG_DETECTION], truth, ("--uphill-azimuth-deg",)
    )
    cases["log + drive: uphill azimuth from another north (declination 8°)"] = Case(
        ["calibrate", log, "--uphill-azimuth-deg", "38", *LOG_DETECTION], truth, ("--uphill-azimuth-deg",)
    )
    cases["log + drive: relative β called uphill (azimuth 0)"] = Case(
        ["calibrate", log, "--uphill-azimuth-deg", "0", *LOG_DETECTION], truth, ("--uphill-azimuth-deg",)
    )
    cases["log + drive: uphill azimuth given downhill, --use stops"] = Case(
        ["calibrate", log, "--uphill-azimuth-deg", "210", "--use", "stops", *LOG_DETECTION],
        truth,
        ("--uphill-azimuth-deg",),
    )
    for name, at_rest, file in (("empty at rest (NaN)", np.nan, "cog_nan"), ("held at 0° at rest", 0.0, "cog_0")):
        s_cog, truth_cog, _ = _parking(rng)
        cases[f"log: heading channel a course over ground, {name}, --uphill-azimuth-deg"] = Case(
            [
                "calibrate",
                _log(_course_at_rest(s_cog, at_rest), folder, f"{file}.parquet"),
                "--uphill-azimuth-deg",
                "30",
            ],
            truth_cog,
            ("--uphill-azimuth-deg",),
        )
    s_rev, truth_rev, rows_rev = _parking(rng)
    cases["log: one stop entered in reverse (its heading a course over ground), --uphill-azimuth-deg"] = Case(
        ["calibrate", _log(_reversed_into(s_rev, rows_rev, 3), folder, "rev.parquet"), "--uphill-azimuth-deg", "30"],
        truth_rev,
        ("--uphill-azimuth-deg",),
    )
    mirrored = dataclasses.replace(s, acc_s=s.acc_s * flip, gyro_s=s.gyro_s * flip)  # type: ignore[operator]
    cases["log + drive: y negated, driving only"] = Case(
        ["calibrate", _log(mirrored, folder, "dm.parquet"), "--use", "driving"], None, ("--axes",)
    )
    vertical = dataclasses.replace(s, acc_s=s.acc_s * np.array([1.0, 1.0, -1.0]))
    cases["log + drive: accelerometer z negated alone, driving only"] = Case(
        ["calibrate", _log(vertical, folder, "dz.parquet"), "--use", "driving"], None, ("--axes", "sign")
    )
    cases["plan: --noise 0.005 (g for mg)"] = Case(
        ["plan", "--target", "roll=0.5,pitch=0.5", "--slope-deg", "5", "--noise", "0.005"], None, ("--noise",)
    )
    return cases


def _quiet(argv: list[str]) -> None:
    """A preparing step (calibrate, rotate) that must succeed."""
    with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
        assert main([*argv, "-q"]) == 0, argv


def seam_slips(rng: np.random.Generator, folder: Path) -> dict[str, Case]:
    """Slips where a number crosses a convention into mountcal or out of it: a table's time unit, a gyro's or a
    speed's unit, a protocol sheet's clock, and mountcal's own outputs taken back in as if they were inputs."""
    cases: dict[str, Case] = {}
    s, truth, rows = _parking(rng)
    start = 1714557600.0  # the log dated (Unix time, UTC) as a logger's clock dates it: a sheet's clock can be compared
    s = dataclasses.replace(
        s, t_s=s.t_s + start, channels={k: Channel(c.t_s + start, c.value) for k, c in s.channels.items()}
    )
    rows = [(a + start, b + start, c) for a, b, c in rows]
    sheet = _protocol(rows, folder, "seam_p.csv", float)
    relative = [(a - start, b - start, c) for a, b, c in rows]  # a sheet counting from the log's start
    ms = dataclasses.replace(s, t_s=(s.t_s - start) * 1000.0)  # milliseconds under the column name t_s
    cases["log: t_s in milliseconds"] = Case(
        ["calibrate", _log(ms, folder, "ms.parquet"), "--protocol", _protocol(relative, folder, "msp.csv", float)],
        truth,
        ("--columns", "ms"),
    )
    deg = dataclasses.replace(s, gyro_s=np.degrees(s.gyro_s))  # type: ignore[arg-type]
    cases["log: gyro in deg/s as gx, gy, gz"] = Case(
        ["calibrate", _log(deg, folder, "deg.parquet"), "--protocol", sheet], truth, ("deg/s",)
    )
    local = [(a + 7200.0, b + 7200.0, c) for a, b, c in rows]  # the sheet written in local time, UTC+2
    cases["log: protocol sheet in local time (UTC+2)"] = Case(
        ["calibrate", _log(s, folder, "seam.parquet"), "--protocol", _protocol(local, folder, "local.csv", float)],
        truth,
        ("time zone", "UTC"),
    )
    cases["log: protocol sheet counting from the log's start"] = Case(
        ["calibrate", str(folder / "seam.parquet"), "--protocol", _protocol(relative, folder, "rel.csv", float)],
        truth,
        ("--protocol",),
    )
    d, truth_d, _ = _parking(rng, drive_s=500.0)
    speed = d.channels["speed_mps"]
    kmh = dataclasses.replace(d, channels={**d.channels, "speed_mps": Channel(speed.t_s, speed.value * 3.6)})
    cases["log + drive: speed in km/h as speed_mps, driving only"] = Case(
        ["calibrate", _log(kmh, folder, "kmh.parquet"), "--use", "driving"], truth_d, ("km/h", "speed")
    )
    deg_drive = dataclasses.replace(d, gyro_s=np.degrees(d.gyro_s))  # type: ignore[arg-type]
    cases["log + drive: gyro in deg/s, driving only"] = Case(
        ["calibrate", _log(deg_drive, folder, "degd.parquet"), "--use", "driving"], truth_d, ("deg/s",)
    )
    # mountcal's own outputs taken back in
    log, cal, veh = str(folder / "seam.parquet"), str(folder / "seam_r.json"), str(folder / "seam_veh.parquet")
    leftover = str(folder / "seam_left.json")
    _quiet(["calibrate", log, "--protocol", sheet, "-o", cal])
    _quiet(["rotate", log, "--calibration", cal, "-o", veh])
    _quiet(["calibrate", veh, "--protocol", sheet, "-o", leftover])
    cases["rotate: the vehicle-frame output rotated again"] = Case(
        ["rotate", veh, "--calibration", cal, "-o", str(folder / "twice.parquet")], None, ("original log",), refuse=True
    )
    veh_csv = str(folder / "seam_veh.csv")
    _quiet(["rotate", log, "--calibration", cal, "-o", veh_csv])
    cases["rotate: the vehicle-frame CSV rotated again"] = Case(
        ["rotate", veh_csv, "--calibration", cal, "-o", str(folder / "twice.csv")], None, ("original log",), refuse=True
    )
    cases["rotate: the log with the calibration of its rotated output"] = Case(
        ["rotate", log, "--calibration", leftover, "-o", str(folder / "left.parquet")],
        None,
        ("original log", "calibration that rotation applied"),
        refuse=True,
    )
    # the deg/s log calibrated with the column map that reads it, then rotated without that map
    cases["rotate: a gyro in deg/s, rotated without the column map its calibration read it with"] = Case(
        ["rotate", str(folder / "deg.parquet"), "--calibration", cal, "-o", str(folder / "deg_veh.parquet")],
        None,
        ("deg/s",),
        refuse=True,
    )
    # a drive's log rotated with a calibration made from the same vehicle's drive in rad/s (rotate's TurnWatch)
    drive_log, drive_cal = _log(d, folder, "drive.parquet"), str(folder / "drive_r.json")
    _quiet(["calibrate", drive_log, "--use", "driving", "-o", drive_cal])
    stated_deg = "time=t_s,ax=ax,ay=ay,az=az,gx=gx:deg/s,gy=gy:deg/s,gz=gz:deg/s,speed=speed_mps,heading=heading_deg"
    cases["rotate: a drive's gyro in rad/s, stated deg/s by the column map"] = Case(
        ["rotate", drive_log, "--calibration", drive_cal, "--columns", stated_deg, "-o", str(folder / "dv.parquet")],
        None,
        ("57.3 times too small",),
        refuse=True,
    )
    gz_negated = dataclasses.replace(d, gyro_s=d.gyro_s * np.array([1.0, 1.0, -1.0]))  # type: ignore[operator]
    cases["rotate: a drive with its gyro's z negated (a DBC sign)"] = Case(
        ["rotate", _log(gz_negated, folder, "gzn.parquet"), "--calibration", drive_cal, "-o", str(folder / "g.csv")],
        None,
        ("wrong sign",),
        refuse=True,
    )
    right = Calibration.load(drive_cal)
    half_cal = str(folder / "drive_half.json")
    half = Rotation.from_euler("z", 180.0, degrees=True) * right.rot_vs
    dataclasses.replace(right, rot_vs=half, yaw_deg=((right.yaw_deg or 0.0) + 360.0) % 360.0 - 180.0).save(half_cal)
    cases["rotate: a drive with a calibration half a turn off in yaw"] = Case(
        ["rotate", drive_log, "--calibration", half_cal, "-o", str(folder / "h.parquet")],
        None,
        ("half a turn",),
        refuse=True,
    )
    cases["triad: on the vehicle-frame output"] = Case(
        ["triad", veh, "-o", str(folder / "triad.json")], None, ("original log",), refuse=True
    )
    cases["export: the calibration of the rotated output"] = Case(
        ["export", leftover, "--to", "ros2-static-tf", "-o", str(folder / "tf.txt")],
        None,
        ("original log", "calibration that rotation applied"),
        refuse=True,
    )
    return cases


def command_slips(rng: np.random.Generator, folder: Path) -> dict[str, Case]:
    """Slips at the seams of the newer commands (plan, stops, inspect, report, export, simulate, triad): a file
    that is not what the command expects, a number in another unit than its option's. Each must be refused
    naming what the file is or the unit; none of them has a right answer."""
    cases: dict[str, Case] = {}
    df, _ = _table(rng)
    df["t_s"] = 1714557600.0 + 60.0 * np.arange(len(df))  # as `mountcal stops` writes a table
    table, cal = _csv(df, folder, "cmd_stops.csv"), str(folder / "cmd_r.json")
    _quiet(["calibrate", table, "-o", cal])
    out = str(folder / "cmd_out")
    fix = ("mountcal calibrate",)
    cases["rotate: a stop table given as the log"] = Case(
        ["rotate", table, "--calibration", cal, "-o", out + ".parquet"], None, fix, refuse=True
    )
    cases["stops: a stop table given as the log"] = Case(["stops", table, "-o", out + ".csv"], None, fix, refuse=True)
    cases["inspect: a stop table given as the log"] = Case(["inspect", table], None, fix, refuse=True)
    cases["plan: a stop table given as --from-log"] = Case(
        ["plan", "--target", "roll=0.5", "--from-log", table, "-o", out + ".csv"], None, fix, refuse=True
    )
    s, _, _ = _parking(rng)
    log = _log(s, folder, "cmd_log.parquet")
    suffix = {"report": ".html", "export": ".json", "rotate": ".parquet"}
    for command in (["report"], ["export", "--to", "json"], ["rotate", log, "--calibration"]):
        cases[f"{command[0]}: a Parquet log given as the calibration"] = Case(
            [*command, log, "-o", out + suffix[command[0]]],
            None,
            ("a Parquet table",),
            refuse=True,
        )
    raw = Path(cal).read_bytes()
    cut = folder / "cmd_cut.json"
    cut.write_bytes(raw[: int(rng.integers(len(raw) // 4, len(raw) - 2))])
    cases["export: a calibration cut short"] = Case(
        ["export", str(cut), "--to", "json", "-o", out + ".json"], None, ("cut short",), refuse=True
    )
    mm = [str(int(v)) for v in rng.uniform(100, 2000, 3)]
    cases["export: --translation in mm"] = Case(
        ["export", cal, "--to", "urdf", "--translation", *mm, "-o", out + ".urdf"], None, ("mm is",), refuse=True
    )
    cases["simulate: --noise-g in mg"] = Case(
        ["simulate", "--noise-g", str(int(rng.integers(1, 20))), "-o", out + ".csv"], None, ("1 mg is",), refuse=True
    )
    return cases


# --------------------------------------------------------------------------- scoring


def _angle_errors(doc: dict, truth: Rotation) -> tuple[float, float | None, float, float | None]:  # type: ignore[type-arg]
    """Tilt error and yaw error (about the vertical; None when yaw is not determined), with their 1σ."""
    rot = Rotation.from_quat(doc["rotation"]["quaternion_xyzw"])
    up_est, up_true = rot.inv().apply([0, 0, 1.0]), truth.inv().apply([0, 0, 1.0])
    tilt = float(np.degrees(np.arccos(np.clip(up_est @ up_true, -1, 1))))
    sig = doc["uncertainty"]["rotation_about_vehicle_xyz_deg"]
    s_tilt = max(s for s in (sig[0], sig[1], doc["uncertainty"]["roll_deg"], doc["uncertainty"]["pitch_deg"]) if s)
    if doc["mounting"]["yaw_deg"] is None:
        return tilt, None, s_tilt, None
    x = rot.apply(truth.inv().apply([1.0, 0, 0]))
    yaw = abs(float(np.degrees(np.arctan2(x[1], x[0]))))
    return tilt, yaw, s_tilt, sig[2] or doc["uncertainty"]["yaw_deg"]


def run_case(case: Case, folder: Path) -> tuple[str, str]:
    """The outcome of one case and the text behind it."""
    out = folder / "result.json"
    out.unlink(missing_ok=True)
    argv = case.argv + (["-o", str(out)] if case.argv[0] == "calibrate" else [])
    err, std = io.StringIO(), io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(std):
            code = main(argv)
    except SystemExit as exc:  # argparse
        code = int(exc.code or 0)
    except BaseException:
        return "traceback", traceback.format_exc(limit=3)
    text = err.getvalue()
    if code in (2, 3):
        named = any(f in text for f in case.fixes)
        return ("refused, names the fix" if named else "refused, fix NOT named"), text.strip().splitlines()[-1][:300]
    if code != 0:
        return f"exit {code}", text[-300:]
    if case.refuse:
        return "SILENT WRONG FILE", " ".join(case.argv[:2])
    if case.argv[0] != "calibrate":
        return "answered, not checked", ""
    doc = json.loads(out.read_text(encoding="utf-8"))
    if not doc["confident"]:
        return "answered, not confident", "; ".join(c["name"] for c in doc.get("checks", []) if c["passed"] is False)
    if case.truth is None:
        return "CONFIDENT WRONG", f"a rotation for a mirror image: {doc['mounting']}"
    tilt, yaw, s_tilt, s_yaw = _angle_errors(doc, case.truth)
    wrong = tilt > 5 * s_tilt + 0.5 or (yaw is not None and s_yaw is not None and yaw > 5 * s_yaw + 0.5)
    detail = f"tilt off {tilt:.2f}° (σ {s_tilt:.2f}), yaw off {yaw}°"
    return ("CONFIDENT WRONG" if wrong else "answered, right"), detail


def main_cli(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=4, help="random inputs per slip")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--markdown", action="store_true", help="print the table as Markdown")
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    tallies: dict[str, Tally] = {}
    cannot: set[str] = set()
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.cases):
            folder = Path(tmp) / f"case{k}"
            folder.mkdir()
            for name, case in {
                **table_slips(rng, folder),
                **log_slips(rng, folder),
                **seam_slips(rng, folder),
                **command_slips(rng, folder),
            }.items():
                outcome, detail = run_case(case, folder)
                tally = tallies.setdefault(name, Tally())
                tally.counts[outcome] += 1
                tally.examples.setdefault(outcome, detail)
                if case.cannot_tell:
                    cannot.add(name)
    columns = [
        "answered, right",
        "answered, not confident",
        "refused, names the fix",
        "CONFIDENT WRONG",
        "SILENT WRONG FILE",
        "refused, fix NOT named",
        "traceback",
    ]
    _print(tallies, cannot, columns, args)
    bad = sum(t.counts[c] for n, t in tallies.items() if n not in cannot for c in columns[3:])
    bad += sum(t.counts[o] for t in tallies.values() for o in t.counts if o.startswith("exit"))
    unsaid = sum(t.counts["CONFIDENT WRONG"] for n, t in tallies.items() if n in cannot)
    print(
        f"\n{sum(sum(t.counts.values()) for t in tallies.values())} runs in {time.perf_counter() - start:.0f} s; "
        f"slips the data can show ending badly: {bad}; slips they cannot show ending confident and wrong: {unsaid}"
    )
    for name, tally in tallies.items():
        for outcome in ("CONFIDENT WRONG", "SILENT WRONG FILE", "refused, fix NOT named", "traceback"):
            if outcome in tally.examples and (name not in cannot or outcome == "CONFIDENT WRONG"):
                print(f"  {name} — {outcome}: {tally.examples[outcome]}", file=sys.stderr)
    return 0


def _print(tallies: dict[str, Tally], cannot: set[str], columns: list[str], args: argparse.Namespace) -> None:
    def row(name: str, t: Tally) -> list[str]:
        other = sum(v for k, v in t.counts.items() if k not in columns)
        return [name, *(str(t.counts[c]) for c in columns), str(other)]

    header = ["slip", *columns, "other"]
    groups = [
        ("the data can show the slip", [n for n in tallies if n not in cannot]),
        ("the data cannot tell (not confident until the convention is stated)", [n for n in tallies if n in cannot]),
    ]
    if args.markdown:
        print("| " + " | ".join(header) + " |")
        print("|" + "---|" * len(header))
        for title, names in groups:
            print(f"| *{title}* |" + " |" * (len(header) - 1))
            for n in names:
                print("| " + " | ".join(row(n, tallies[n])) + " |")
        return
    for title, names in groups:
        print(f"\n{title}:")
        print("  " + " | ".join(header))
        for n in names:
            print("  " + " | ".join(row(n, tallies[n])))


if __name__ == "__main__":
    sys.exit(main_cli())
