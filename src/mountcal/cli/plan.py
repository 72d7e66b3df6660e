"""``mountcal plan --target …``: the smallest session reaching the target; exit 0, or 3 when not reachable.

The target is on the total σ calibrate will report: the sensor's limits (--sensor-spec, --triad, or the
default class) set a systematic part no number of stops on one slope lowers.
"""

from __future__ import annotations

import argparse
import logging
import math
from typing import Any

from mountcal.cli.options import (
    add_command,
    add_log_options,
    add_sensor_options,
    log_options,
    print_json,
    sensor_options,
    working,
)
from mountcal.cli.path_options import add_path
from mountcal.cli.results import say
from mountcal.core.ranges import Number, add_quantity
from mountcal.core.terminal import safe

log = logging.getLogger("mountcal")


def add_parser(sub: Any) -> None:
    p = add_command(
        sub,
        "plan",
        "plan a session from the bound: stops, headings, dwell, slope",
        json_help="the plan (stops, headings, dwell, slope, predicted σ) as JSON on stdout",
    )
    p.add_argument("--target", required=True, help="1σ targets in degrees, e.g. roll=0.1,pitch=0.1,yaw=0.5")
    add_quantity(
        p,
        "--noise",
        quantity="noise_mg",
        default=None,
        help="accelerometer noise per sample, 1σ per axis: mg, or with its unit (0.005g, 0.05m/s2); a bare number "
        "outside 0.05–200 mg is refused",
    )
    p.add_argument(
        "--rate-hz", type=Number("rate_hz"), default=100.0, help="sample rate with --noise (Hz; default 100)"
    )
    add_path(
        p, "--from-log", role="input", what="a log", folders=True, nargs="+", default=None, metavar="LOG",
        help="measure noise and rate on a log",
    )  # fmt: skip
    p.add_argument(
        "--slope-deg", type=Number("planned_slope_deg"), default=None, help="the slope available (default: find one)"
    )
    p.add_argument("--model", default="rotation,slope,bias", help="rotation,slope,bias (default) or rotation,slope")
    p.add_argument("--max-stops", type=Number("planned_stops"), default=24, help="most stops to plan (default 24)")
    p.add_argument("--stop-s", type=Number("duration_s"), default=None, help="dwell of each stop (s; default: chosen)")
    p.add_argument(
        "--drive-s", type=Number("drive_s"), default=60.0, help="time between stops, for the session length (s)"
    )
    add_path(
        p, "-o", "--output", role="output", what="the protocol sheet", formats=(".csv",), default=None,
        help="protocol sheet CSV to write",
    )  # fmt: skip
    add_sensor_options(p)
    add_log_options(p, repeat_dbc=False, stops=False)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from mountcal.calibration.fit import sensor_errors
    from mountcal.calibration.options import Options
    from mountcal.core.conventions import G_N
    from mountcal.core.errors import InputError, NotEnoughInformation
    from mountcal.sessions.plan import Noise, Request, make_plan, noise_from_log, parse_target, plan_terms

    if (args.noise is None) == (args.from_log is None):
        raise InputError(
            "mountcal plan",
            "exactly one of --noise MG or --from-log LOG",
            "both" if args.noise else "neither",
            "Give the sensor's per-sample noise in mg, or a log with parked periods to measure it on.",
        )
    if args.noise is not None:
        from mountcal.io.input_conventions import NOISE, parse_quantity

        noise_mg, _ = parse_quantity(args.noise, NOISE)
        if not (math.isfinite(args.rate_hz) and args.rate_hz > 0):
            raise InputError("--rate-hz", "a positive number", f"{args.rate_hz:g} Hz", "Give the sensor's sample rate.")
        noise = Noise(noise_mg * 1e-3 * G_N, args.rate_hz, f"given by --noise ({noise_mg:.6g} mg) and --rate-hz")
    else:
        with working(args, "measuring the noise on the log"):
            noise = noise_from_log(list(args.from_log), log_options(args))
    req = Request(
        parse_target(args.target),
        noise,
        plan_terms(args.model),
        args.slope_deg,
        args.max_stops,
        args.stop_s,
        args.drive_s,
        sensor=sensor_errors(sensor_options(Options(), args.sensor_spec, args.triad)),
    )
    with working(args, "planning"):
        plan = make_plan(req)
    first, *rest = plan.lines()
    say(first, [line.strip() for line in rest])
    written = plan.reachable and args.output is not None
    if written:
        plan.write_protocol(args.output)
        log.info("wrote %s (protocol sheet for calibrate --protocol; replace the placeholder times)", safe(args.output))
    if args.json:
        print_json(_document(plan, args.output if written else None))
    return 0 if plan.reachable else NotEnoughInformation.exit_code


def _document(plan: Any, protocol: str | None) -> dict[str, Any]:
    """The plan as JSON: reachable (or why not), the session, the σ it predicts, what it assumed."""
    req = plan.request
    return {
        "reachable": plan.reachable,
        "reason": plan.reason or None,
        "stops": plan.n_stops,
        "beta_deg": list(plan.beta_deg),
        "stop_s": plan.stop_s,
        "slope_deg": plan.slope_deg,
        "drive_s": req.drive_s,
        "session_s": plan.session_s,
        "target_deg": dict(req.target_deg),
        "sigma_deg": plan.sigma_deg.named(),
        "statistical_deg": plan.statistical_deg.named(),
        "systematic_deg": plan.systematic_deg.named(),
        "model": list(req.terms),
        "noise": {
            "sample_sigma_mps2": req.noise.sample_sigma_mps2,
            "rate_hz": req.noise.rate_hz,
            "source": req.noise.source,
        },
        "sensor": req.sensor.source,
        "protocol": protocol,
    }
