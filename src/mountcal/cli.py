"""The ``mountcal`` command line: a thin shell over the library. Each command returns an exit code."""

from __future__ import annotations

import argparse
import importlib
import json
import logging
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from mountcal import terms as model_terms
from mountcal.atomic import atomic_path
from mountcal.calibrate import Options, calibrate
from mountcal.errors import InputError, MountcalError
from mountcal.io.logs import LogOptions, inspect_log
from mountcal.paths import SystemFailure, check_outputs, special_kind
from mountcal.pipeline import LogJob, describe, stops_of_log
from mountcal.result import Calibration
from mountcal.result_file import read_json
from mountcal.simulate.stops import PRESETS, simulate_stops
from mountcal.stops import StopDetection
from mountcal.stoptable import read_stop_table, same_stops, write_stop_table
from mountcal.terminal import safe
from mountcal.version import software_version


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the console script."""
    parser = _parser()
    args = parser.parse_args(argv)
    _progress_on_stderr()
    try:
        return int(args.func(args))
    except MountcalError as err:
        print(f"mountcal: error: {safe(err, keep=chr(10))}", file=sys.stderr)
        return err.exit_code
    except BrokenPipeError:  # output piped into `head` and the like
        sys.stderr.close()
        return 0
    except OSError as err:  # the system refused a read or a write
        failure = SystemFailure(str(err.filename or f"mountcal {args.command}"), "reading or writing", err)
        print(f"mountcal: error: {safe(failure)}", file=sys.stderr)
        return failure.exit_code
    except KeyboardInterrupt:
        print("mountcal: interrupted; no output was written", file=sys.stderr)
        return 130


class _StderrProgress(logging.Handler):
    """Progress of long steps (``mountcal.*`` loggers at INFO) on the current stderr, never stdout."""

    def emit(self, record: logging.LogRecord) -> None:
        print(f"mountcal: {record.getMessage()}", file=sys.stderr, flush=True)


def _progress_on_stderr() -> None:
    root = logging.getLogger("mountcal")
    if not any(isinstance(h, _StderrProgress) for h in root.handlers):
        root.addHandler(_StderrProgress(logging.INFO))
        root.setLevel(logging.INFO)


def cmd_calibrate(args: argparse.Namespace) -> int:
    """``mountcal calibrate STOPS|LOG…``: estimate the mounting and write the result JSON."""
    inputs = [Path(p) for p in args.input]
    check_outputs({"-o": args.output, "--report": args.report}, _log_inputs(args))
    if args.report is not None:
        require("matplotlib", "report", "calibrate --report")  # before any work: nothing is written without it
    options = Options(
        method=args.method, model=args.model, gravity_mps2=args.gravity, max_yaw_sigma_deg=args.max_yaw_sigma
    )
    if len(inputs) == 1 and _is_stop_table(inputs[0], args):
        table = read_stop_table(inputs[0], unit=args.unit, headings=args.headings)
        cal = calibrate(table, options)
    else:
        from mountcal.pipeline_drive import calibrate_any, describe_any

        done = calibrate_any(_job(args, options), use=args.use)
        print(safe("\n".join(describe_any(done, len(inputs))), keep="\n"))
        cal, table = done.calibration, done.table  # type: ignore[assignment]  # no stop table: from driving alone
    print(summary(cal))
    if args.output is not None:
        cal.save(args.output)
        print(f"wrote {args.output}")
    if args.report is not None:
        from mountcal.report import render  # matplotlib is needed for reports only

        with atomic_path(args.report) as tmp:
            tmp.write_text(render(cal.to_dict(), table), encoding="utf-8")
        print(f"wrote {args.report}")
    return 0


def cmd_stops(args: argparse.Namespace) -> int:
    """``mountcal stops LOG…``: detect the parked periods and write the stop table."""
    check_outputs({"-o": args.output}, _log_inputs(args))
    samples, found = stops_of_log(_job(args))
    print(safe("\n".join(describe(samples, found, len(args.input))), keep="\n"))
    with atomic_path(args.output) as tmp:
        if Path(args.output).suffix.lower() in (".parquet", ".pq"):
            found.frame.to_parquet(tmp, index=False)
        else:
            found.frame.to_csv(tmp, index=False, float_format="%.15g")
    print(f"wrote {args.output} ({len(found.frame)} stops; headings: {found.heading_source})")
    return 0


def cmd_inspect(args: argparse.Namespace) -> int:
    """``mountcal inspect LOG``: list what the log holds."""
    info = inspect_log(args.input, LogOptions(dbc=_dbcs(args.dbc)))
    print(safe(f"{info.source}: {info.format}, {info.duration_s:.1f} s"))
    for st in info.streams:  # names come from the file: shown escaped (no terminal control, no bidi)
        fields = f"  [{', '.join(map(safe, st.fields))}]" if st.fields else ""
        fields += f"  DLC {','.join(map(str, st.dlcs))}" if st.dlcs else ""
        print(f"  {safe(st.name):<32} {safe(st.kind):<28} {st.count:>9} msgs {st.rate_hz:>9.2f} Hz{fields}")
    return 0


def cmd_rotate(args: argparse.Namespace) -> int:
    """``mountcal rotate LOG… --calibration result.json -o OUT``: the log's samples in the vehicle frame."""
    from mountcal.apply.rotate import check_applicable
    from mountcal.apply.rotate_log import rotate_log

    check_outputs({"-o": args.output}, _log_inputs(args) | {"--calibration": args.calibration})
    if args.chunk < 1:
        raise InputError("--chunk", "a number of samples ≥ 1", str(args.chunk), "Pass --chunk 100000 (the default).")
    cal = Calibration.load(args.calibration)
    check_applicable(  # refused before any reading, naming the calibration file
        cal, level_only=args.level_only, require_confident=args.require_confident, where=str(args.calibration)
    )
    report = rotate_log(
        args.input,
        cal,
        args.output,
        fmt=args.format,
        options=LogOptions(dbc=_dbcs(args.dbc), mapping=args.mapping, channel=args.channel, topic=args.topic),
        chunk_samples=args.chunk,
        level_only=args.level_only,
        require_confident=args.require_confident,
    )
    for text in report.warnings:
        print(f"mountcal: warning: {text} (recorded in {args.output}'s metadata)", file=sys.stderr)
    print("\n".join(report.lines()))
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    """``mountcal report RESULT.json [--stops STOPS]``: a self-contained HTML report of a calibration."""
    require("matplotlib", "report", "mountcal report")
    from mountcal.report import render  # matplotlib is needed by this command only

    result = Path(args.result)
    output = Path(args.output) if args.output is not None else result.with_suffix(".html")
    check_outputs({"-o": output}, {"result": result, "--stops": args.stops})
    cal = Calibration.load(result)  # validates format and version
    doc = read_json(result)  # the whole document: entries Calibration may not keep
    table = None
    if args.stops:
        headings = cal.fit.get("headings")
        table = read_stop_table(
            args.stops, unit=args.unit, headings=headings if headings in ("uphill", "relative", "none") else "uphill"
        )
        stored = cal.provenance.get("stops_fingerprint")
        if not isinstance(stored, dict) or not same_stops(stored, table):
            raise InputError(
                str(args.stops),
                f"the stop table of this result (the one {result} was fitted to: same stops, order, headings, --unit)",
                "a different table" if isinstance(stored, dict) else f"no record of that table in {result}",
                "Pass the table given to `mountcal calibrate` (or written by `mountcal stops` for its log), "
                "or re-run calibrate on this one; omit --stops to report without it.",
            )
    html = render(doc, table, image_format=args.figures)
    with atomic_path(output) as tmp:
        tmp.write_text(html, encoding="utf-8")
    shown = html.count("<figure>")
    print(f"wrote {output} ({shown} figures{'' if table is not None else '; pass --stops for the 3-D stop figure'})")
    return 0


def cmd_fleet(args: argparse.Namespace) -> int:
    """``mountcal fleet INPUTS… -o fleet.parquet``: calibrate many logs of many vehicles, resumably."""
    from mountcal.fleet import FleetOptions, JobDefaults, collect_jobs, outputs_of, run_fleet, summary_lines

    if args.scheduler is not None:
        require("distributed", "fleet", "fleet --scheduler")  # before any log is read or hashed
    defaults = JobDefaults(
        log=LogOptions(dbc=args.dbc, mapping=args.mapping, channel=args.channel, topic=args.topic),
        detection=_detection(args),
        uphill_azimuth_deg=args.uphill_azimuth_deg,
        options=Options(method=args.method, model=args.model, max_yaw_sigma_deg=args.max_yaw_sigma),
        headings=args.headings,
    )
    table, vehicles, _ = outputs_of(args.output)
    check_outputs({"-o": table, "its vehicles table": vehicles}, _log_inputs(args))
    ours: list[Path] = []
    jobs = collect_jobs(args.input, defaults, exclude=outputs_of(args.output), set_aside=ours)
    if ours:
        listed = ", ".join(map(str, ours[:5])) + (" …" if len(ours) > 5 else "")
        print(safe(f"set aside {len(ours)} file(s) mountcal wrote (fleet tables, rotated logs): {listed}"))
    options = FleetOptions(
        workers=args.workers,
        scheduler=args.scheduler,
        retry_failed=args.retry_failed,
        progress=not args.quiet,
        floor_deg=args.floor_deg,
        require_confident=args.require_confident,
    )
    try:
        result = run_fleet(jobs, args.output, options)
    except KeyboardInterrupt:
        print(
            f"mountcal: interrupted; the logs finished so far are kept in {outputs_of(args.output)[2]}: "
            "run the same command again to resume",
            file=sys.stderr,
        )
        return 130
    if result.not_confident:
        listed = ", ".join(result.not_confident[:5]) + (" …" if len(result.not_confident) > 5 else "")
        print(
            safe(
                f"mountcal: warning: {len(result.not_confident)} log(s) not confident (flag not_confident; recorded "
                f"in the tables' metadata, mountcal.not_confident_logs): {listed}"
            ),
            file=sys.stderr,
        )
    print(safe("\n".join(summary_lines(result)), keep="\n"))
    return 0


def require(module: str, extra: str, needed_by: str) -> None:
    """Refuse, before any work, an option whose optional dependency is not installed; name the extra."""
    try:
        importlib.import_module(module)
    except ImportError as err:
        raise InputError(
            needed_by,
            f"the optional package {module} installed",
            f"it missing ({err})",
            f"Install it: pip install 'mountcal[{extra}]'. Nothing was written.",
        ) from err


def _is_stop_table(path: Path, args: argparse.Namespace) -> bool:
    if path.suffix.lower() not in (".csv", ".parquet", ".pq") or getattr(args, "dbc", None):
        return False
    if special_kind(path) is not None:  # a FIFO or a device: let the stop-table reader refuse it unopened
        return True
    try:
        cols = set(
            pd.read_parquet(path).columns
            if path.suffix.lower() != ".csv"
            else pd.read_csv(path, nrows=0, comment="#", skipinitialspace=True).columns
        )
    except Exception:  # unreadable: let the stop-table reader say why
        return True
    return bool(cols & {"beta_deg", "n", "sx"}) or "t_s" not in cols


def _dbcs(given: list[str] | None) -> str | tuple[str, ...] | None:
    """``--dbc`` given once (a path) or repeated (their messages together)."""
    if not given:
        return None
    return given[0] if len(given) == 1 else tuple(given)


def _log_inputs(args: argparse.Namespace) -> dict[str, Any]:
    """Every file a log command reads, by option name (for :func:`check_outputs`)."""
    return {
        "input": args.input,
        **{f"--{k}": getattr(args, k, None) for k in ("dbc", "mapping", "protocol")},
    }


def _job(args: argparse.Namespace, options: Options | None = None) -> LogJob:
    return LogJob(
        paths=tuple(args.input),
        log=LogOptions(dbc=_dbcs(args.dbc), mapping=args.mapping, channel=args.channel, topic=args.topic),
        detection=_detection(args),
        protocol=args.protocol,
        uphill_azimuth_deg=args.uphill_azimuth_deg,
        options=options or Options(),
    )


def cmd_simulate(args: argparse.Namespace) -> int:
    """``mountcal simulate``: write a simulated stop table, or (``--log``) a parking session as logs."""
    params: dict[str, Any] = dict(PRESETS[args.preset])
    for key in ("roll_deg", "pitch_deg", "yaw_deg", "slope_deg", "noise_g"):
        if getattr(args, key) is not None:
            params[key] = getattr(args, key)
    if args.bias_mg is not None:
        params["bias_mps2"] = np.array(args.bias_mg) * 1e-3 * 9.80665
    if args.log:
        from mountcal.conventions import G_N, normal_gravity
        from mountcal.simulate import logs as export
        from mountcal.simulate.stops import simulate_parking_log

        if args.output is not None:
            raise InputError(
                "mountcal simulate --log",
                "no -o (which writes a stop table)",
                "-o",
                "Name the logs with --log, and the protocol sheet and the truth with their options.",
            )
        logs = {f"--log #{i + 1}" if len(args.log) > 1 else "--log": p for i, p in enumerate(args.log)}
        check_outputs(logs | {"--protocol": args.protocol, "--truth": args.truth}, {"--dbc": args.dbc})
        formats = [export.check_log_path(p, args.dbc) for p in args.log]
        if args.protocol is not None and "asc" in formats and len(formats) > 1:
            raise InputError(
                "mountcal simulate --log",
                "logs sharing one clock for the one --protocol sheet",
                "an ASC log (python-can reads it from its first frame) among others",
                "Write the ASC log by itself, with its own --protocol.",
            )
        fix = None if args.fix is None else (float(args.fix[0]), float(args.fix[1]), float(args.fix[2]))
        session = {k: getattr(args, k) for k in ("stop_s", "drive_s", "rate_hz") if getattr(args, k) is not None}
        field_effects = {  # what field loggers add (simulate_parking_log)
            "gyro_bias_rad_s": None if args.gyro_bias_dps is None else np.radians(args.gyro_bias_dps),
            "acc_lsb_mps2": args.acc_lsb,
            "gyro_lsb_rad_s": float(np.radians(args.gyro_lsb_dps)),
            "paired_stamps": args.paired_stamps,
        }
        log = simulate_parking_log(
            params["roll_deg"],
            params["pitch_deg"],
            params["yaw_deg"],
            slope_deg=params["slope_deg"],
            beta_deg=tuple(params["beta_deg"]),
            bias_mps2=params.get("bias_mps2"),
            g_mps2=G_N if fix is None else normal_gravity(fix[0], fix[2]),
            seed=args.seed,
            **session,
            **field_effects,
        )
        start = export.START_TIME_S if args.start_time is None else args.start_time
        roll, pitch, yaw = log.truth.angles_deg
        print(
            f"simulated a parking session ({len(log.protocol)} stops, {log.t_s[-1] - log.t_s[0]:.0f} s, "
            f"{log.t_s.size} samples; seed {args.seed}): roll {roll:g}°, pitch {pitch:g}°, yaw {yaw:g}°, "
            f"slope {log.truth.slope_deg:g}°, g {log.truth.g_mps2:.5f} m/s²"
        )
        for path in args.log:
            done = export.write_log(path, log, dbc_path=args.dbc, with_fix=fix, start_time_s=start)
            counts = ", ".join(f"{k} {v}" for k, v in done.messages.items())
            print(f"wrote {path} ({done.format}: {counts})")
            for what, tally in (("saturated at the DBC range", done.saturated), ("not written", done.skipped)):
                if tally:
                    print(f"  {what}: " + ", ".join(f"{k} {v}" for k, v in tally.items()))
        if args.protocol is not None:
            export.write_protocol(args.protocol, log, start_time_s=done.start_time_s)
            print(f"wrote {args.protocol} (protocol sheet on the log's clock, start {done.start_time_s:.6f} s)")
        if args.truth is not None:
            truth_doc = export.session_truth(log, start_time_s=start, with_fix=fix) | {"seed": args.seed}
            with atomic_path(args.truth) as tmp:
                tmp.write_text(json.dumps(truth_doc, indent=2) + "\n", encoding="utf-8")
            print(f"wrote {args.truth}")
        return 0
    if args.output is None:
        raise InputError(
            "mountcal simulate", "-o STOPS.csv (a stop table) or --log LOG", "neither", "Name what to write."
        )
    check_outputs({"-o": args.output, "--truth": args.truth}, {})
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
        truth_doc = {
            "roll_deg": roll,
            "pitch_deg": pitch,
            "yaw_deg": yaw,
            "slope_deg": truth.slope_deg,
            "bias_mps2": truth.bias_mps2.tolist(),
            "g_mps2": truth.g_mps2,
        }
        with atomic_path(args.truth) as tmp:
            tmp.write_text(json.dumps(truth_doc, indent=2) + "\n", encoding="utf-8")
    return 0


def cmd_plan(args: argparse.Namespace) -> int:
    """``mountcal plan --target …``: the smallest session reaching the target (issue 17)."""
    from mountcal.plan import run_plan_command

    options = LogOptions(dbc=args.dbc, mapping=args.mapping, channel=args.channel, topic=args.topic)
    return run_plan_command(
        args.target,
        args.model,
        args.noise,
        args.rate_hz,
        args.from_log,
        options,
        args.slope_deg,
        args.max_stops,
        args.stop_s,
        args.drive_s,
        args.output,
    )


def cmd_live(args: argparse.Namespace) -> int:
    """``mountcal live --interface … --channel … --dbc …``: a session on a live CAN bus (issue 17)."""
    from mountcal.live import run_live_command

    return run_live_command(args)


def summary(cal: Calibration) -> str:
    """A readable summary: angles ± 1σ, slope, model, residual, what could not be determined."""

    def pm(value: float | None, sigma: float | None, unit: str = "°", fmt: str = ".3f") -> str:
        if value is None:
            return "not determined"
        return f"{value:{fmt}}{unit} ± {sigma:{fmt}}{unit}" if sigma is not None else f"{value:{fmt}}{unit}"

    sel = cal.model_selection
    how = "fixed by --model" if sel.get("mode") == "fixed" else "auto: " + " → ".join(sel.get("steps", []))
    how = how if cal.method == "full" else cal.method  # "paper", or "driving" when there were no stops
    lines = [
        f"mountcal — {cal.method} method, model: {', '.join(cal.model)} ({how})",
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
    if not cal.confident:
        found = "; ".join(f"{u.get('what')} ({u.get('size')})" for u in cal.unexplained) or "see the notes"
        lines.append(f"  NOT CONFIDENT: {found}; rotate warns, --require-confident refuses")
    lines.append("  (uncertainties are 1σ)")
    return "\n".join(lines)


def _log_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("logs")
    g.add_argument("--dbc", action="append", default=None, help="DBC to decode a CAN log (repeat for several)")
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
    _detection_arguments(g)


def _detection_arguments(g: argparse._ArgumentGroup) -> None:
    """The thresholds of stop detection (:class:`mountcal.stops.StopDetection`); unset ones come from the log."""
    d = StopDetection()

    def add(flag: str, default: float | None, text: str) -> None:
        shown = "from the log" if default is None else f"{default:g}"
        g.add_argument(flag, type=float, default=default, help=f"{text}; default {shown})")

    add("--max-acc-std", d.max_acc_std_mps2, "stillness: moving std of each axis below this (m/s²")
    add("--max-gyro-std", d.max_gyro_std_rad_s, "stillness: moving std of each gyro axis below this (rad/s")
    add("--max-gyro-rate", d.max_gyro_rad_s, "stillness: angular rate within this of the gyro's bias (rad/s")
    add("--max-speed", d.max_speed_mps, "stillness: speed at most this (m/s")
    add("--still-window-s", d.window_s, "window of the moving statistics (s")
    add("--min-stop-s", d.min_duration_s, "shortest stop (s")
    add("--trim-s", d.trim_s, "settling cut from both ends of a stop (s")
    add("--max-heading-wander", d.max_heading_wander_deg, "a stop whose heading wanders more is split (deg")


def _detection(args: argparse.Namespace) -> StopDetection:
    return StopDetection(
        window_s=args.still_window_s,
        max_acc_std_mps2=args.max_acc_std,
        max_gyro_std_rad_s=args.max_gyro_std,
        max_gyro_rad_s=args.max_gyro_rate,
        max_speed_mps=args.max_speed,
        min_duration_s=args.min_stop_s,
        trim_s=args.trim_s,
        max_heading_wander_deg=args.max_heading_wander,
    )


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="mountcal", description=__doc__)
    parser.add_argument("--version", action="version", version=f"mountcal {software_version()}")
    sub = parser.add_subparsers(dest="command", required=True)

    cal = sub.add_parser("calibrate", help="estimate the mounting from a stop table or a log")
    cal.add_argument(
        "input", nargs="+", metavar="STOPS|LOG", help="stop table (beta_deg, ax, ay, az, ...) or log file(s)"
    )
    _log_arguments(cal)
    cal.add_argument("--method", choices=("full", "paper"), default="full")
    cal.add_argument("--model", default="auto", help=model_terms.help_text())
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
    cal.add_argument(
        "--use",
        choices=("auto", "stops", "driving"),
        default="auto",
        help="for a log: its parked stops, its driving (speed changes), or whatever it supports (default)",
    )
    cal.add_argument("-o", "--output", default=None, help="result JSON to write")
    cal.add_argument("--report", default=None, help="also write a self-contained HTML report here")
    cal.set_defaults(func=cmd_calibrate)

    stp = sub.add_parser("stops", help="detect the parked periods of a log and write the stop table")
    stp.add_argument("input", nargs="+", metavar="LOG", help="log file(s); splits of one log are joined")
    _log_arguments(stp)
    stp.add_argument("-o", "--output", required=True, help="stop table to write (CSV or .parquet)")
    stp.set_defaults(func=cmd_stops)

    rot = sub.add_parser("rotate", help="write a log's samples in the vehicle frame (Parquet, CSV or MCAP)")
    rot.add_argument("input", nargs="+", metavar="LOG", help="log file(s); splits of one log are joined")
    rot.add_argument("--calibration", required=True, help="result JSON written by `mountcal calibrate`")
    rot.add_argument("-o", "--output", required=True, help="file to write (.parquet, .csv or .mcap)")
    rot.add_argument(
        "--format", choices=("parquet", "csv", "mcap"), default=None, help="default: from -o's suffix, else parquet"
    )
    rot.add_argument("--chunk", type=int, default=100_000, help="samples per chunk: bounds the memory (default 100000)")
    rot.add_argument(
        "--level-only",
        action="store_true",
        help="accept a calibration without yaw: write a levelled frame (z up, heading the sensor's own)",
    )
    rot.add_argument("--require-confident", action="store_true", help="refuse a calibration that is not confident")
    rot_log = rot.add_argument_group("logs")
    rot_log.add_argument("--dbc", action="append", default=None, help="DBC to decode a CAN log (repeat for several)")
    rot_log.add_argument("--mapping", default=None, help="TOML naming the accelerometer signals (CAN)")
    rot_log.add_argument("--channel", type=int, default=None, help="CAN channel of the IMU")
    rot_log.add_argument("--topic", default=None, help="IMU topic (MCAP)")
    rot.set_defaults(func=cmd_rotate)

    ins = sub.add_parser("inspect", help="list what a log holds")
    ins.add_argument("input", metavar="LOG")
    ins.add_argument("--dbc", action="append", default=None, help="DBC naming the CAN messages (repeat for several)")
    ins.set_defaults(func=cmd_inspect)

    sim = sub.add_parser("simulate", help="write a simulated stop table, or (--log) a parking session as logs")
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
    sim.add_argument("-o", "--output", default=None, help="stop table to write (CSV or .parquet)")
    lg = sim.add_argument_group("parking session as logs (--noise-g and --headings apply to stop tables only)")
    lg.add_argument(
        "--log", nargs="+", default=None, metavar="LOG", help="logs to write: .mcap, .blf, .mf4, .asc, .log, .trc, .csv"
    )
    lg.add_argument("--protocol", default=None, help="also write the protocol sheet (t_start_s, t_end_s, beta_deg)")
    lg.add_argument("--dbc", default=None, help="DBC to encode CAN logs (data/imu_mm5_10.dbc: Bosch MM5.10)")
    lg.add_argument(
        "--fix", type=float, nargs=3, metavar=("LAT", "LON", "ALT"), help="site position logged (deg, deg, m)"
    )
    lg.add_argument("--start-time", type=float, default=None, help="Unix time of the start (s; default 1714557600)")
    lg.add_argument("--stop-s", type=float, default=None, help="duration of each stop (s; default 40)")
    lg.add_argument("--drive-s", type=float, default=None, help="duration of each drive between stops (s; default 20)")
    lg.add_argument("--rate-hz", type=float, default=None, help="IMU sample rate (Hz; default 100)")
    lg.add_argument("--gyro-bias-dps", type=float, nargs=3, metavar=("BX", "BY", "BZ"), help="gyro bias (°/s)")
    lg.add_argument("--acc-lsb", type=float, default=0.0, help="accelerometer quantisation step (m/s²; default none)")
    lg.add_argument("--gyro-lsb-dps", type=float, default=0.0, help="gyro quantisation step (°/s; default none)")
    lg.add_argument("--paired-stamps", action="store_true", help="stamp the IMU samples in pairs, as some loggers do")
    sim.set_defaults(func=cmd_simulate)

    rep = sub.add_parser("report", help="write a self-contained HTML report of a calibration result")
    rep.add_argument("result", metavar="RESULT.json", help="result written by `mountcal calibrate -o`")
    rep.add_argument(
        "--stops", default=None, help="the stop table the result was fitted to (adds the 3-D figure, headings, σ)"
    )
    rep.add_argument("--unit", choices=("mps2", "g"), default="mps2", help="unit of ax, ay, az in --stops")
    rep.add_argument("--figures", choices=("svg", "png"), default="svg", help="inline SVG (default) or base64 PNG")
    rep.add_argument("-o", "--output", default=None, help="HTML file to write (default: RESULT with .html)")
    rep.set_defaults(func=cmd_report)

    flt = sub.add_parser("fleet", help="calibrate many logs of many vehicles: consensus per vehicle, remounts")
    flt.add_argument(
        "input", nargs="+", metavar="INPUTS", help="folders of logs (vehicle = parent folder), globs, manifest CSVs"
    )
    flt.add_argument("-o", "--output", required=True, help="per-log Parquet table (vehicles go to <stem>_vehicles)")
    flt.add_argument("--workers", type=int, default=None, help="local worker processes (default: all cores)")
    flt.add_argument("--scheduler", default=None, help="run on this Dask scheduler, tcp://HOST:PORT")
    flt.add_argument("--retry-failed", action="store_true", help="recalculate logs an earlier run recorded as failed")
    flt.add_argument(
        "--floor-deg", type=float, default=0.0, help="mounting scatter between logs added to each log's σ (deg)"
    )
    flt.add_argument("-q", "--quiet", action="store_true", help="no progress line")
    flt.add_argument(
        "--require-confident", action="store_true", help="refuse (write no table) if a log's result is not confident"
    )
    fg = flt.add_argument_group("every log (a manifest's cells take precedence)")
    fg.add_argument("--dbc", default=None, help="DBC to decode CAN logs")
    fg.add_argument("--mapping", default=None, help="TOML naming the accelerometer signals (CAN)")
    fg.add_argument("--channel", type=int, default=None, help="CAN channel of the IMU")
    fg.add_argument("--topic", default=None, help="IMU topic (MCAP)")
    fg.add_argument("--uphill-azimuth-deg", type=float, default=None, help="compass azimuth of the slopes' uphill")
    _detection_arguments(fg)
    fg.add_argument("--method", choices=("full", "paper"), default="full")
    fg.add_argument("--model", default="auto", help=model_terms.help_text())
    fg.add_argument(
        "--headings", choices=("uphill", "relative", "none"), default="uphill", help="beta_deg of stop tables"
    )
    fg.add_argument("--max-yaw-sigma", type=float, default=5.0, help="report yaw only below this 1σ (deg)")
    flt.set_defaults(func=cmd_fleet)
    pln = sub.add_parser("plan", help="plan a session from the bound: stops, headings, dwell, slope")
    pln.add_argument("--target", required=True, help="1σ targets in degrees, e.g. roll=0.1,pitch=0.1,yaw=0.5")
    pln.add_argument("--noise", type=float, default=None, help="accelerometer noise per sample, 1σ per axis (mg)")
    pln.add_argument("--rate-hz", type=float, default=100.0, help="sample rate with --noise (Hz; default 100)")
    pln.add_argument("--from-log", nargs="+", default=None, metavar="LOG", help="measure noise and rate on a log")
    pln.add_argument("--slope-deg", type=float, default=None, help="the slope available (default: find one)")
    pln.add_argument("--model", default="rotation,slope,bias", help="rotation,slope,bias (default) or rotation,slope")
    pln.add_argument("--max-stops", type=int, default=24, help="most stops to plan (default 24)")
    pln.add_argument("--stop-s", type=float, default=None, help="dwell of each stop (s; default: chosen)")
    pln.add_argument("--drive-s", type=float, default=60.0, help="time between stops, for the session length (s)")
    pln.add_argument("-o", "--output", default=None, help="protocol sheet CSV to write")
    pln_log = pln.add_argument_group("--from-log")
    pln_log.add_argument("--dbc", default=None, help="DBC to decode a CAN log")
    pln_log.add_argument("--mapping", default=None, help="TOML naming the accelerometer signals (CAN)")
    pln_log.add_argument("--channel", type=int, default=None, help="CAN channel of the IMU")
    pln_log.add_argument("--topic", default=None, help="IMU topic (MCAP)")
    pln.set_defaults(func=cmd_plan)

    liv = sub.add_parser("live", help="run a session on a live CAN bus: record, refit at each stop, suggest")
    liv.add_argument("--interface", required=True, help="python-can interface: socketcan, virtual, pcan, vector, …")
    liv.add_argument("--channel", required=True, help="bus channel, e.g. can0")
    liv.add_argument("--dbc", required=True, help="DBC describing the bus")
    liv.add_argument("--mapping", default=None, help="TOML naming the accelerometer signals")
    liv.add_argument("--can-channel", type=int, default=None, help="channel number of the IMU frames (recorded)")
    liv.add_argument("--target", default="roll=0.1,pitch=0.1,yaw=0.5", help="stop when every 1σ is below (deg)")
    liv.add_argument("--model", default="auto", help="auto (default), rotation,slope or rotation,slope,bias")
    liv.add_argument("--plan", default=None, help="protocol sheet from `mountcal plan`: stops take its β in order")
    liv.add_argument("--uphill-azimuth-deg", type=float, default=None, help="β from the bus's heading signal")
    liv.add_argument("--timeout", type=float, default=10.0, help="a bus silent this long ends the session (s)")
    liv.add_argument("--max-acc-std", type=float, default=StopDetection.max_acc_std_mps2, help="stillness (m/s²)")
    liv.add_argument("--min-stop-s", type=float, default=StopDetection.min_duration_s, help="shortest stop (s)")
    liv.add_argument("--json-events", default=None, help="also write the events as JSON lines here (- = stdout)")
    liv.add_argument("-o", "--output", default="session", help="prefix: PREFIX.blf, PREFIX.json, PREFIX_stops.csv")
    liv.add_argument("--report", default=None, help="also write the HTML report here")
    liv.set_defaults(func=cmd_live)

    from mountcal.exporters import add_parser as add_export_parser  # `mountcal export`: issue 16

    add_export_parser(sub)
    return parser


if __name__ == "__main__":
    sys.exit(main())
