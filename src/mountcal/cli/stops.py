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
from mountcal.cli.results import result_stream, say
from mountcal.core.terminal import safe

log = logging.getLogger("mountcal")


def add_parser(sub: Any) -> None:
    p = add_command(
        sub,
        "stops",
        "detect the parked periods of a log and write the stop table",
        json_help="a summary (stops, headings, output) as JSON on stdout (not with -o -, where the table is)",
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
    if to_stdout and args.json:  # stdout holds one document
        from mountcal.core.errors import InputError

        raise InputError("--json", "the stop table in a file (-o FILE)", "-o -", "Name a file with -o, or drop --json.")
    with working(args, "reading the log and finding its stops"):
        samples, found = stops_of_log(log_job(args, Options()))
    table = found.table
    where = "stdout" if to_stdout else safe(args.output)
    headings = (
        "without headings" if table.beta_rad is None else f"at {_distinct(table)} headings ({found.heading_source})"
    )
    say(
        f"{len(table)} stops {headings}, from {len(samples)} samples: {where}",
        describe((samples, found), len(args.input)),
    )
    if to_stdout:
        table.to_frame().to_csv(result_stream(), index=False, float_format="%.15g")
    else:
        write_stop_table(table, args.output)
        log.info("wrote %s (%d stops; headings: %s)", safe(args.output), len(table), found.heading_source)
    if args.json:
        print_json(
            {
                "output": args.output,
                "stops": len(table),
                "headings": table.headings,
                "heading_source": found.heading_source,
                "samples": len(samples),
                "incomplete_inputs": list(samples.incomplete),
            }
        )
    return 0


def _distinct(table: Any) -> int:
    """The number of distinct headings of a stop table (to 0.1°)."""
    import numpy as np

    return len(np.unique(np.round(np.degrees(table.beta_rad) % 360.0, 1)))
