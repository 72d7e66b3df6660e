"""``mountcal simulate``: write a simulated stop table, or (``--log``) a parking session as logs."""

from __future__ import annotations

import argparse
import logging
from typing import Any

from mountcal.cli.options import HEADINGS, add_command, bar, print_json
from mountcal.cli.path_options import add_path
from mountcal.cli.results import say
from mountcal.core.errors import InputError
from mountcal.core.ranges import Number, numbers
from mountcal.core.terminal import safe

log = logging.getLogger("mountcal")


def add_parser(sub: Any) -> None:
    p = add_command(
        sub,
        "simulate",
        "write a simulated stop table, or (--log) a parking session as logs",
        json_help="the truth and the files written, as JSON on stdout",
    )
    p.add_argument("--preset", default="zhang2011", help="parameters to start from (default zhang2011, the paper's)")
    p.add_argument("--roll", dest="roll_deg", type=Number("angle_deg"))
    p.add_argument("--pitch", dest="pitch_deg", type=Number("angle_deg"))
    p.add_argument("--yaw", dest="yaw_deg", type=Number("angle_deg"))
    p.add_argument("--slope", dest="slope_deg", type=Number("slope_deg"))
    p.add_argument("--noise-g", dest="noise_g", type=Number("noise_g"), help="1σ noise of each stop mean, in g")
    p.add_argument("--bias-mg", type=Number("bias_mg"), nargs=3, metavar=("BX", "BY", "BZ"), help="constant bias in mg")
    p.add_argument("--headings", choices=HEADINGS, default="uphill")
    p.add_argument("--heading-offset", type=Number("angle_deg"), default=0.0, help="common offset added to β (deg)")
    p.add_argument("--seed", type=Number("seed"), default=0)
    add_path(
        p, "--truth", role="output", what="the truth", formats=(".json",), default=None,
        help="also write the truth as JSON",
    )  # fmt: skip
    add_path(
        p, "-o", "--output", role="output", what="the stop table", formats=(".csv", ".parquet", ".pq"), default=None,
        help="stop table to write (CSV or .parquet)",
    )  # fmt: skip
    lg = p.add_argument_group("parking session as logs (--noise-g and --headings apply to stop tables only)")
    add_path(
        lg, "--log", role="output", what="a log", nargs="+", default=None, metavar="LOG",
        help="logs to write: .mcap, .blf, .mf4, .asc, .log, .trc, .csv",
    )  # fmt: skip
    add_path(
        lg, "--protocol", role="output", what="the protocol sheet", formats=(".csv",), default=None,
        help="also write the protocol sheet (t_start_s, t_end_s, beta_deg)",
    )  # fmt: skip
    add_path(
        lg, "--dbc", role="input", what="a DBC", small=True, default=None,
        help="DBC to encode CAN logs (data/imu_mm5_10.dbc: Bosch MM5.10)",
    )  # fmt: skip
    lg.add_argument(
        "--fix",
        action=numbers("lat_deg", "lon_deg", "alt_m"),
        nargs=3,
        metavar=("LAT", "LON", "ALT"),
        help="site position logged (deg, deg, m)",
    )
    lg.add_argument(
        "--start-time", type=Number("unix_time_s"), default=None, help="Unix time of the start (s; default 1714557600)"
    )
    lg.add_argument("--stop-s", type=Number("simulated_s"), default=None, help="duration of each stop (s; default 40)")
    lg.add_argument(
        "--drive-s",
        type=Number("simulated_s"),
        default=None,
        help="duration of each drive between stops (s; default 20)",
    )
    lg.add_argument(
        "--rate-hz", type=Number("simulated_rate_hz"), default=None, help="IMU sample rate (Hz; default 100)"
    )
    lg.add_argument(
        "--gyro-bias-dps", type=Number("gyro_bias_dps"), nargs=3, metavar=("BX", "BY", "BZ"), help="gyro bias (°/s)"
    )
    lg.add_argument(
        "--acc-lsb", type=Number("lsb_mps2"), default=0.0, help="accelerometer quantisation step (m/s²; default none)"
    )
    lg.add_argument(
        "--gyro-lsb-dps", type=Number("gyro_lsb_dps"), default=0.0, help="gyro quantisation step (°/s; default none)"
    )
    lg.add_argument("--paired-stamps", action="store_true", help="stamp the IMU samples in pairs, as some loggers do")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from mountcal.simulate.session import FieldEffects, session_params, write_log_session, write_stop_session

    overrides = {k: getattr(args, k) for k in ("roll_deg", "pitch_deg", "yaw_deg", "slope_deg", "noise_g")}
    params = session_params(args.preset, overrides, args.bias_mg)
    if args.log:
        if args.output is not None:
            raise InputError(
                "mountcal simulate --log",
                "no -o (which writes a stop table)",
                "-o",
                "Name the logs with --log, and the protocol sheet and the truth with their options.",
            )
        session = {k: getattr(args, k) for k in ("stop_s", "drive_s", "rate_hz") if getattr(args, k) is not None}
        effects = FieldEffects(
            gyro_bias_dps=None if args.gyro_bias_dps is None else tuple(args.gyro_bias_dps),
            acc_lsb_mps2=args.acc_lsb,
            gyro_lsb_dps=args.gyro_lsb_dps,
            paired_stamps=args.paired_stamps,
        )
        with bar(args, len(args.log), "writing logs", unit="log") as shown:
            done = write_log_session(
                args.log,
                params,
                seed=args.seed,
                dbc=args.dbc,
                fix=None if args.fix is None else (float(args.fix[0]), float(args.fix[1]), float(args.fix[2])),
                start_time_s=args.start_time,
                session=session,
                effects=effects,
                protocol=args.protocol,
                truth=args.truth,
                each_log=lambda _: shown.update(),
            )
    elif args.output is not None:
        done = write_stop_session(
            args.output,
            params,
            headings=args.headings,
            heading_offset_deg=args.heading_offset,
            seed=args.seed,
            truth=args.truth,
        )
    else:
        raise InputError(
            "mountcal simulate", "-o STOPS.csv (a stop table) or --log LOG", "neither", "Name what to write."
        )
    first, *rest = (safe(line) for line in done.lines)
    say(first, rest)
    if args.json:
        print_json({"truth": done.truth, "written": done.written})
    return 0
