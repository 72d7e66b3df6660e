"""``mountcal calibrate STOPS|LOG…``: estimate the mounting; the result JSON to -o (``-o -``: stdout)."""

from __future__ import annotations

import argparse
import logging
import sys
from typing import Any

from mountcal.cli.options import (
    STDOUT,
    add_command,
    add_fit_options,
    add_input_kind,
    add_log_options,
    log_job,
    print_json,
    require,
    working,
)
from mountcal.cli.path_options import add_path
from mountcal.cli.results import result_stream, say
from mountcal.core.ranges import add_quantity
from mountcal.core.terminal import safe

log = logging.getLogger("mountcal")


def add_parser(sub: Any) -> None:
    p = add_command(
        sub,
        "calibrate",
        "estimate the mounting from a stop table or a log",
        json_help="write the result JSON on stdout",
        inputs=("STOPS|LOG", "stop table (beta_deg, ax, ay, az, ...; '-': CSV on stdin) or log file(s)"),
        reads={"what": "a stop table or log", "folders": True, "stdio": True},
        output="result JSON to write ('-': stdout)",
        writes={"what": "the result", "stdio": True, "formats": (".json",)},
    )
    add_path(
        p, "--report", role="output", what="the HTML report", formats=(".html", ".htm"), default=None,
        help="also write a self-contained HTML report here",
    )  # fmt: skip
    add_log_options(p)
    add_input_kind(p)
    g = p.add_argument_group("fit")
    add_fit_options(
        g,
        headings_help="what a stop table's beta_deg is measured from: the uphill direction, relative (an unknown "
        "common offset), or none (default: the table's heading_ref column, else uphill, said in the result)",
    )
    g.add_argument(
        "--unit", choices=("mps2", "g"), default=None, help="unit of a stop table's ax, ay, az (default m/s², checked)"
    )
    add_quantity(
        g,
        "--gravity",
        quantity="gravity_mps2",
        default=None,
        help="local gravity in m/s², or with its unit (1g; default: from lat_deg/alt_m when the data have them, "
        "else 9.80665); a bare number outside 9.7–9.9 is refused",
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from mountcal.calibration.pipeline import calibrate_input, describe
    from mountcal.calibration.summary import summary_parts
    from mountcal.core.atomic import atomic_path
    from mountcal.core.errors import InputError

    to_stdout = args.json or args.output == STDOUT
    if args.input == [STDOUT] and sys.stdin.isatty():
        raise InputError("-", "a CSV stop table piped on stdin", "a terminal", "Pipe one in, or name the file.")
    if args.report is not None:
        require("matplotlib", "report", "calibrate --report")  # before any work: nothing is written without it
    with working(args, "reading and fitting"):
        done = calibrate_input(log_job(args), unit=args.unit, headings=args.headings, declared=args.input_kind)
    log.info("%s", safe(f"input: {done.kind.sentence}"))
    if done.log is not None:
        for line in describe(done.log, len(args.input)):
            log.info("%s", safe(line))
    cal, table = done.calibration, done.table  # no stop table: calibrated from driving alone
    doc = cal.document()  # checked as a loader checks it, before anything is shown or written
    say(*summary_parts(cal))
    if to_stdout:
        print_json(doc)
    if args.output not in (None, STDOUT):
        cal.save(args.output)
        log.info("wrote %s", safe(args.output))
    if args.report is not None:
        from mountcal.outputs.report import render, timeline_of  # matplotlib is needed for reports only

        with working(args, "writing the report"):
            html = render(cal, table, timeline=None if done.log is None else timeline_of(done.log))
        with atomic_path(args.report) as tmp:
            tmp.write_text(html, encoding="utf-8")
        log.info("wrote %s", safe(args.report))
    result_stream().flush()
    return 0
