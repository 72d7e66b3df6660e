"""``mountcal report RESULT.json [--stops STOPS]``: a self-contained HTML report of a calibration."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path
from typing import Any

from mountcal.cli.options import STDOUT, add_command, print_json, require, working
from mountcal.cli.path_options import add_path
from mountcal.cli.results import result_stream, say
from mountcal.core.terminal import safe

log = logging.getLogger("mountcal")


def add_parser(sub: Any) -> None:
    p = add_command(
        sub,
        "report",
        "write a self-contained HTML report of a calibration result",
        json_help="the output and its figures as JSON on stdout",
        inputs=("RESULT.json", "result written by `mountcal calibrate -o`"),
        reads={"what": "a result JSON", "small": True},
        many=False,
        output="HTML file to write (default: RESULT with .html; '-': stdout)",
        writes={"what": "the HTML report", "stdio": True, "writes": _writes, "formats": (".html", ".htm")},
    )
    add_path(
        p, "--stops", role="input", what="a stop table", small=True, default=None,
        help="the stop table the result was fitted to (adds the 3-D figure, headings, σ)",
    )  # fmt: skip
    p.add_argument(
        "--unit",
        choices=("mps2", "g"),
        default=None,
        help="unit of ax, ay, az in --stops (default: as calibrate read it)",
    )
    p.add_argument("--figures", choices=("svg", "png"), default="svg", help="inline SVG (default) or base64 PNG")
    p.set_defaults(run=run)


def _output(value: str | None, result: str) -> Path | None:
    """The HTML file written: -o, or the result's name with .html; None for stdout."""
    return None if value == STDOUT else Path(value) if value is not None else Path(result).with_suffix(".html")


def _writes(value: str | None, args: argparse.Namespace) -> list[tuple[str, str]]:
    output = _output(value, args.input)
    return [] if output is None else [(str(output), "" if value is not None else "(default)")]


def _reading(stops: Path, cal: Any, unit: str | None) -> dict[str, Any]:
    """How to read ``--stops``: as calibrate read it when it is the very file the result was fitted to (its
    SHA-256 in the provenance), else as the table states itself (a table `mountcal stops` wrote from a log)."""
    import hashlib

    from mountcal.io.input_conventions import stop_table_reading

    options: dict[str, Any] = {}
    if stops.is_file() and hashlib.sha256(stops.read_bytes()).hexdigest() in cal.provenance.input_sha256:
        options = stop_table_reading(cal.provenance.conventions)
        if not cal.provenance.conventions:  # a result written before the conventions were recorded
            options = {"headings": cal.fit.headings or "uphill"}
    return options | ({} if unit is None else {"unit": unit})


def run(args: argparse.Namespace) -> int:
    require("matplotlib", "report", "mountcal report")
    from mountcal.core.atomic import atomic_path
    from mountcal.core.errors import InputError
    from mountcal.core.result import Calibration
    from mountcal.outputs.report import render  # matplotlib is needed by this command only
    from mountcal.stops.identity import same_stops
    from mountcal.stops.table import read_stop_table

    result = Path(args.input)
    output = _output(args.output, args.input)
    if output is None and args.json:  # stdout holds one document
        raise InputError("--json", "the report in a file (-o FILE, or the default)", "-o -", "Name a file with -o.")
    cal = Calibration.load(result)  # validates format and version; every entry of the file is typed
    table = None
    if args.stops:
        table = read_stop_table(args.stops, **_reading(Path(args.stops), cal, args.unit))
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
        html = render(cal, table, image_format=args.figures)
    shown = html.count("<figure>")
    from mountcal.calibration.summary import answer

    where = "stdout" if output is None else safe(output)
    hint = [] if table is not None else ["pass --stops for the 3-D stop figure"]
    say(f"report of {answer(cal)} ({shown} figures): {where}", [safe(f"from {result}"), *hint])
    if output is None:
        print(html, end="", file=result_stream())
        return 0
    with atomic_path(output) as tmp:
        tmp.write_text(html, encoding="utf-8")
    log.info("wrote %s", safe(output))
    if args.json:
        print_json({"output": str(output), "figures": shown, "confident": cal.confident})
    return 0
