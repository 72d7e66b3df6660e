"""The ``mountcal`` command line: a thin shell over the library. Each command returns an exit code."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from mountcal.atomic import atomic_path
from mountcal.calibrate import Options, calibrate
from mountcal.errors import InputError, MountcalError
from mountcal.io.logs import LogOptions, inspect_log
from mountcal.pipeline import LogJob, calibrate_log, describe, stops_of_log
from mountcal.result import Calibration
from mountcal.simulate import PRESETS, simulate_stops
from mountcal.stops import StopDetection
from mountcal.stoptable import read_stop_table, write_stop_table


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the console script."""
    parser = _parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except MountcalError as err:
        print(f"mountcal: error: {err}", file=sys.stderr)
        return err.exit_code
    except BrokenPipeError:  # output piped into `head` and the like
        sys.stderr.close()
        return 0
    except KeyboardInterrupt:
        print("mountcal: interrupted; no output was written", file=sys.stderr)
        return 130


def cmd_calibrate(args: argparse.Namespace) -> int:
    """``mountcal calibrate STOPS|LOG…``: estimate the mounting and write the result JSON."""
    inputs = [Path(p) for p in args.input]
    if args.output is not None and any(Path(args.output).resolve() == p.resolve() for p in inputs):
        raise InputError(
            str(args.output),
            "an output path other than the input",
            "the input file itself",
            "Choose another -o path; mountcal never overwrites its input.",
        )
    options = Options(
        method=args.method, model=args.model, gravity_mps2=args.gravity, max_yaw_sigma_deg=args.max_yaw_sigma
    )
    if len(inputs) == 1 and _is_stop_table(inputs[0], args):
        cal = calibrate(read_stop_table(inputs[0], unit=args.unit, headings=args.headings), options)
    else:
        done = calibrate_log(_job(args, options))
        print("\n".join(describe(done.samples, done.stops, len(inputs))))
        cal = done.calibration
    print(summary(cal))
    if args.output is not None:
        cal.save(args.output)
        print(f"wrote {args.output}")
    return 0


def cmd_stops(args: argparse.Namespace) -> int:
    """``mountcal stops LOG…``: detect the parked periods and write the stop table."""
    if any(Path(args.output).resolve() == Path(p).resolve() for p in args.input):
        raise InputError(
            str(args.output),
            "an output path other than the input",
            "the input file itself",
            "Choose another -o path; mountcal never overwrites its input.",
        )
    samples, found = stops_of_log(_job(args))
    print("\n".join(describe(samples, found, len(args.input))))
    with atomic_path(args.output) as tmp:
        if Path(args.output).suffix.lower() in (".parquet", ".pq"):
            found.frame.to_parquet(tmp, index=False)
        else:
            found.frame.to_csv(tmp, index=False, float_format="%.10g")
    print(f"wrote {args.output} ({len(found.frame)} stops; headings: {found.heading_source})")
    return 0


def cmd_inspect(args: argparse.Namespace) -> int:
    """``mountcal inspect LOG``: list what the log holds."""
    info = inspect_log(args.input, LogOptions(dbc=args.dbc))
    print(f"{info.source}: {info.format}, {info.duration_s:.1f} s")
    for st in info.streams:
        fields = f"  [{', '.join(st.fields)}]" if st.fields else ""
        print(f"  {st.name:<32} {st.kind:<28} {st.count:>9} msgs {st.rate_hz:>9.2f} Hz{fields}")
    return 0


def _is_stop_table(path: Path, args: argparse.Namespace) -> bool:
    if path.suffix.lower() not in (".csv", ".parquet", ".pq") or getattr(args, "dbc", None):
        return False
    try:
        cols = set(
            pd.read_parquet(path).columns
            if path.suffix.lower() != ".csv"
            else pd.read_csv(path, nrows=0, comment="#", skipinitialspace=True).columns
        )
    except Exception:  # unreadable: let the stop-table reader say why
        return True
    return bool(cols & {"beta_deg", "n", "sx"}) or "t_s" not in cols


def _job(args: argparse.Namespace, options: Options | None = None) -> LogJob:
    return LogJob(
        paths=tuple(args.input),
        log=LogOptions(dbc=args.dbc, mapping=args.mapping, channel=args.channel, topic=args.topic),
        detection=StopDetection(max_acc_std_mps2=args.max_acc_std, min_duration_s=args.min_stop_s),
        protocol=args.protocol,
        uphill_azimuth_deg=args.uphill_azimuth_deg,
        options=options or Options(),
    )


def cmd_simulate(args: argparse.Namespace) -> int:
    """``mountcal simulate``: write a simulated stop table (and its truth) from a preset."""
    params: dict[str, Any] = dict(PRESETS[args.preset])
    for key in ("roll_deg", "pitch_deg", "yaw_deg", "slope_deg", "noise_g"):
        if getattr(args, key) is not None:
            params[key] = getattr(args, key)
    if args.bias_mg is not None:
        params["bias_mps2"] = np.array(args.bias_mg) * 1e-3 * 9.80665
    table, truth = simulate_stops(
        headings=args.headings, heading_offset_deg=args.heading_offset, seed=args.seed, **params
    )
    write_stop_table(table, args.output)
    roll, pitch, yaw = truth.angles_deg
    print(
        f"simulated {len(table)} stops ({args.preset}, seed {args.seed}): roll {roll:g}°, pitch {pitch:g}°, "
        f"yaw {yaw:g}°, slope {truth.slope_deg:g}°, bias {np.round(truth.bias_mps2, 4).tolist()} m/s²"
    )
    print(f"wrote {args.output}")
    if args.truth is not None:
        Path(args.truth).write_text(
            json.dumps(
                {
                    "roll_deg": roll,
                    "pitch_deg": pitch,
                    "yaw_deg": yaw,
                    "slope_deg": truth.slope_deg,
                    "bias_mps2": truth.bias_mps2.tolist(),
                    "g_mps2": truth.g_mps2,
                },
                indent=2,
            )
            + "\n",
            encoding="utf-8",
        )
    return 0


def summary(cal: Calibration) -> str:
    """A readable summary: angles ± 1σ, slope, model, residual, what could not be determined."""

    def pm(value: float | None, sigma: float | None, unit: str = "°", fmt: str = ".3f") -> str:
        if value is None:
            return "not determined"
        return f"{value:{fmt}}{unit} ± {sigma:{fmt}}{unit}" if sigma is not None else f"{value:{fmt}}{unit}"

    sel = cal.model_selection
    how = "fixed by --model" if sel.get("mode") == "fixed" else "auto: " + " → ".join(sel.get("steps", []))
    lines = [
        f"mountcal — {cal.method} method, model: {', '.join(cal.model)} ({how if cal.method == 'full' else 'paper'})",
        f"  roll   {pm(cal.roll_deg, cal.roll_sigma_deg)}",
        f"  pitch  {pm(cal.pitch_deg, cal.pitch_sigma_deg)}",
        f"  yaw    {pm(cal.yaw_deg, cal.yaw_sigma_deg)}",
        f"  slope  {pm(cal.slope_deg, cal.slope_sigma_deg)}",
    ]
    if cal.bias_mps2 is not None and cal.bias_sigma_mps2 is not None:
        b = ", ".join(f"{v:+.4f} ± {s:.4f}" for v, s in zip(cal.bias_mps2, cal.bias_sigma_mps2, strict=True))
        lines.append(f"  bias   ({b}) m/s² (sensor x, y, z)")
    fit = cal.fit
    chi = f", χ² = {fit['chi2']:.1f} on {fit['dof']} dof" if "chi2" in fit else ""
    if fit.get("p_value") is not None:
        chi += f" (p = {fit['p_value']:.2g})"
    lines.append(f"  residual RMS {cal.residual_rms_mps2:.4g} m/s²{chi}")
    lines.append(f"  gravity {cal.gravity_mps2:.5f} m/s² ({cal.gravity_source})")
    if cal.yaw_reason:
        lines.append(f"  yaw not determined: {cal.yaw_reason}")
    if cal.slope_deg is None:
        lines.append("  slope not determined (see notes)")
    lines += [f"  note: {n}" for n in cal.notes]
    lines.append("  (uncertainties are 1σ)")
    return "\n".join(lines)


def _log_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("logs")
    g.add_argument("--dbc", default=None, help="DBC to decode a CAN log")
    g.add_argument("--mapping", default=None, help="TOML naming the accelerometer signals (CAN)")
    g.add_argument("--channel", type=int, default=None, help="CAN channel of the IMU")
    g.add_argument("--topic", default=None, help="IMU topic (MCAP)")
    g.add_argument("--protocol", default=None, help="protocol sheet CSV: t_start_s, t_end_s, beta_deg")
    g.add_argument(
        "--uphill-azimuth-deg",
        type=float,
        default=None,
        help="compass azimuth of the slope's uphill direction, with a heading signal in the log",
    )
    g.add_argument(
        "--max-acc-std",
        type=float,
        default=StopDetection.max_acc_std_mps2,
        help="stillness: moving std of each axis below this (m/s²)",
    )
    g.add_argument("--min-stop-s", type=float, default=StopDetection.min_duration_s, help="shortest stop (s)")


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="mountcal", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)

    cal = sub.add_parser("calibrate", help="estimate the mounting from a stop table or a log")
    cal.add_argument(
        "input", nargs="+", metavar="STOPS|LOG", help="stop table (beta_deg, ax, ay, az, ...) or log file(s)"
    )
    _log_arguments(cal)
    cal.add_argument("--method", choices=("full", "paper"), default="full")
    cal.add_argument("--model", default="auto", help="auto (default), rotation,slope or rotation,slope,bias")
    cal.add_argument("--unit", choices=("mps2", "g"), default="mps2", help="unit of ax, ay, az (default m/s²)")
    cal.add_argument(
        "--headings",
        choices=("uphill", "relative", "none"),
        default="uphill",
        help="beta_deg is from the uphill direction (default), relative (unknown offset), or ignored",
    )
    cal.add_argument(
        "--gravity",
        type=float,
        default=None,
        help="local gravity in m/s² (default: from lat_deg/alt_m when the table has them, else 9.80665)",
    )
    cal.add_argument("--max-yaw-sigma", type=float, default=5.0, help="report yaw only below this 1σ (deg)")
    cal.add_argument("-o", "--output", default=None, help="result JSON to write")
    cal.set_defaults(func=cmd_calibrate)

    stp = sub.add_parser("stops", help="detect the parked periods of a log and write the stop table")
    stp.add_argument("input", nargs="+", metavar="LOG", help="log file(s); splits of one log are joined")
    _log_arguments(stp)
    stp.add_argument("-o", "--output", required=True, help="stop table to write (CSV or .parquet)")
    stp.set_defaults(func=cmd_stops)

    ins = sub.add_parser("inspect", help="list what a log holds")
    ins.add_argument("input", metavar="LOG")
    ins.add_argument("--dbc", default=None, help="DBC naming the CAN messages")
    ins.set_defaults(func=cmd_inspect)

    sim = sub.add_parser("simulate", help="write a simulated stop table")
    sim.add_argument("--preset", choices=tuple(PRESETS), default="zhang2011")
    sim.add_argument("--roll", dest="roll_deg", type=float)
    sim.add_argument("--pitch", dest="pitch_deg", type=float)
    sim.add_argument("--yaw", dest="yaw_deg", type=float)
    sim.add_argument("--slope", dest="slope_deg", type=float)
    sim.add_argument("--noise-g", dest="noise_g", type=float, help="1σ noise of each stop mean, in g")
    sim.add_argument("--bias-mg", type=float, nargs=3, metavar=("BX", "BY", "BZ"), help="constant bias in mg")
    sim.add_argument("--headings", choices=("uphill", "relative", "none"), default="uphill")
    sim.add_argument("--heading-offset", type=float, default=0.0, help="common offset added to β (deg)")
    sim.add_argument("--seed", type=int, default=0)
    sim.add_argument("--truth", default=None, help="also write the truth as JSON")
    sim.add_argument("-o", "--output", required=True)
    sim.set_defaults(func=cmd_simulate)
    return parser


if __name__ == "__main__":
    sys.exit(main())
