"""``mountcal stops LOG… -o STOPS``: detect the parked periods and write the stop table (``-o -``: CSV on stdout)."""

from __future__ import annotations

import argparse
import logging
from typing import Any

from mountcal.cli.options import (
    STDOUT,
    add_command,
    add_log_options,
    log_job,
    print_json,
    working,
)
from mountcal.cli.results import result_stream
from mountcal.core.terminal import safe

log = logging.getLogger("mountcal")


def add_parser(sub: Any) -> None:
    p = add_command(
        sub,
        "stops",
        "detect the parked periods of a log and write the stop table",
        json_help="a summary (stops, headings, output) on stdout",
        inputs=("LOG", "log file(s); splits of one log are joined"),
        output="stop table to write (CSV or .parquet; '-': CSV on stdout)",
        writes={"what": "the stop table", "stdio": True, "formats": (".csv", ".parquet", ".pq")},
        output_required=True,
    )
    add_log_options(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from mountcal.calibration.options import Options
    from mountcal.calibration.pipeline import describe, stops_of_log
    from mountcal.stops.table import write_stop_table

    to_stdout = args.output == STDOUT
    with working(args, "reading the log and finding its stops"):
        samples, found = stops_of_log(log_job(args, Options()))
    for line in describe((samples, found), len(args.input)):
        log.info("%s", safe(line))
    if to_stdout:
        found.table.to_frame().to_csv(result_stream(), index=False, float_format="%.15g")
    else:
        write_stop_table(found.table, args.output)
        log.info("wrote %s (%d stops; headings: %s)", safe(args.output), len(found.table), found.heading_source)
    if args.json and not to_stdout:
        print_json(
            {
                "output": args.output,
                "stops": len(found.table),
                "headings": found.table.headings,
                "samples": len(samples),
                "incomplete_inputs": list(samples.incomplete),
            }
        )
    return 0
