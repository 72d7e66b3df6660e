"""``mountcal triad``: a triad calibration (bias, scale, cross-axis ± covariance) from a multi-position session.

The session's stops point gravity along many sensor directions; :mod:`mountcal.estimate.sphere`
fits all three terms. With ``--imucal CAL.json`` the values are imucal's (its Ferraris JSON) and
the covariance is mountcal's fit on the same session, after checking the two agree. The result
is what ``mountcal calibrate --triad`` applies. Imports are deferred: building the parser stays light.
"""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mountcal.cli.options import (
    add_axes_option,
    add_command,
    add_input_kind,
    gravity,
    print_json,
)
from mountcal.cli.path_options import add_path
from mountcal.cli.results import say
from mountcal.core.ranges import Number, add_quantity
from mountcal.core.terminal import safe
from mountcal.estimate.triad_session import MIN_STOP_S, TRIM_S

if TYPE_CHECKING:
    pass

log = logging.getLogger("mountcal")


def add_parser(subparsers: Any) -> None:
    p = add_command(
        subparsers,
        "triad",
        "fit bias, scale and cross-axis from a multi-position session",
        json_help="the triad JSON written to -o, on stdout as well",
        inputs=("LOG_OR_STOPTABLE", "the session's log(s), or its stop table"),
        reads={"what": "a log or stop table", "folders": True},
        output="triad JSON to write (for calibrate --triad)",
        output_required=True,
        writes={"what": "the triad calibration", "formats": (".json",)},
    )
    p.add_argument("--unit", choices=("mps2", "g"), default="mps2", help="unit of ax, ay, az in a stop table")
    add_quantity(
        p,
        "--gravity",
        quantity="gravity_mps2",
        default=None,
        help="local gravity in m/s², or with its unit (1g; default 9.80665)",
    )
    add_axes_option(p)
    add_path(
        p, "--imucal", role="input", what="an imucal calibration", small=True, default=None,
        help="imucal's Ferraris calibration JSON made from this session",
    )  # fmt: skip
    p.add_argument(
        "--min-stop-s",
        type=Number("duration_s"),
        default=MIN_STOP_S,
        help="shortest still period in a log (s; hand-held: short; default %(default)s)",
    )
    p.add_argument(
        "--trim-s",
        type=Number("trim_s"),
        default=TRIM_S,
        help="cut from each end of a still period in a log (s; default %(default)s)",
    )
    p.add_argument(
        "--columns", default=None, help="a sample table's columns as ROLE=COLUMN[:UNIT] pairs (see calibrate --help)"
    )
    add_path(
        p, "--mapping", role="input", what="a mapping", small=True, default=None,
        help="a TOML with a sample table's [columns]",
    )  # fmt: skip
    add_input_kind(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from mountcal.core.conventions import G_N
    from mountcal.estimate import sphere
    from mountcal.estimate.triad import describe, fit_all, from_sphere, session_stops, with_imucal_values
    from mountcal.io.reader import LogOptions
    from mountcal.io.table.layout import parse_columns

    columns = None if args.columns is None else parse_columns(args.columns)
    acc, cov, conventions = session_stops(
        args.input,
        args.unit,
        args.min_stop_s,
        args.trim_s,
        LogOptions(mapping=args.mapping, columns=columns, allow_truncated=args.allow_truncated, axes=args.axes),
        declared=args.input_kind,
    )
    given = gravity(args)
    g = G_N if given is None else given
    source = " + ".join(str(Path(p)) for p in args.input)
    for _, why in sphere.loop(acc, g, cov):
        log.info("  %s", why)
    fit = fit_all(acc, g, cov, source)
    triad = from_sphere(fit, source, conventions)
    if args.imucal is not None:
        triad = with_imucal_values(triad, args.imucal)
    first, *rest = describe(triad, fit)
    say(
        first.replace("mountcal triad — ", "triad calibration from ", 1) + f": {safe(args.output)}",
        [line.strip() for line in rest if not line.startswith("  note: ")],
        [line.removeprefix("  note: ") for line in rest if line.startswith("  note: ")],
    )
    triad.save(args.output)
    log.info("wrote %s", safe(args.output))
    if args.json:
        print_json(json.loads(Path(args.output).read_text(encoding="utf-8")))
    return 0
