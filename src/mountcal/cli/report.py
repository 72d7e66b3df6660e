"""``mountcal report RESULT.json [--stops STOPS]``: a self-contained HTML report of a calibration."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path
from typing import Any

from mountcal.cli.options import STDOUT, add_command, declare_output_suffixes, print_json, require, working
from mountcal.cli.results import result_stream
from mountcal.terminal import safe

log = logging.getLogger("mountcal")


def add_parser(sub: Any) -> None:
    p = add_command(
        sub,
        "report",
        "write a self-contained HTML report of a calibration result",
        json_help="the output and its figures as JSON on stdout",
        inputs=("RESULT.json", "result written by `mountcal calibrate -o`"),
        many=False,
        output="HTML file to write (default: RESULT with .html; '-': stdout)",
    )
    p.add_argument(
        "--stops", default=None, help="the stop table the result was fitted to (adds the 3-D figure, headings, σ)"
    )
    p.add_argument("--unit", choices=("mps2", "g"), default="mps2", help="unit of ax, ay, az in --stops")
    p.add_argument("--figures", choices=("svg", "png"), default="svg", help="inline SVG (default) or base64 PNG")
    declare_output_suffixes(p, {"output": (".html", ".htm")})
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    require("matplotlib", "report", "mountcal report")
    from mountcal.atomic import atomic_path
    from mountcal.errors import InputError
    from mountcal.outputs.report import render  # matplotlib is needed by this command only
    from mountcal.paths import check_outputs
    from mountcal.result import Calibration
    from mountcal.result_file import read_json
    from mountcal.stoptable import read_stop_table, same_stops

    result = Path(args.input)
    to_stdout = args.output == STDOUT
    output = Path(args.output) if args.output is not None else result.with_suffix(".html")
    check_outputs({"-o": None if to_stdout else output}, {"result": result, "--stops": args.stops})
    cal = Calibration.load(result)  # validates format and version
    doc = read_json(result)  # the whole document: entries Calibration may not keep
    table = None
    if args.stops:
        table = read_stop_table(args.stops, unit=args.unit, headings=cal.fit.headings or "uphill")
        stored = cal.provenance.stops_fingerprint
        if stored is None or not same_stops(stored, table):
            raise InputError(
                str(args.stops),
                f"the stop table of this result (the one {result} was fitted to: same stops, order, headings, --unit)",
                "a different table" if stored is not None else f"no record of that table in {result}",
                "Pass the table given to `mountcal calibrate` (or written by `mountcal stops` for its log), "
                "or re-run calibrate on this one; omit --stops to report without it.",
            )
    with working(args, "drawing the report"):
        html = render(doc, table, image_format=args.figures)
    shown = html.count("<figure>")
    if to_stdout:
        print(html, end="", file=result_stream())
        return 0
    with atomic_path(output) as tmp:
        tmp.write_text(html, encoding="utf-8")
    hint = "" if table is not None else "; pass --stops for the 3-D stop figure"
    log.info("wrote %s (%d figures%s)", safe(output), shown, hint)
    if args.json:
        print_json({"output": str(output), "figures": shown})
    return 0
