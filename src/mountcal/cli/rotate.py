"""``mountcal rotate LOG… --calibration result.json -o OUT``: the log's samples in the vehicle frame."""

from __future__ import annotations

import argparse
import logging
from dataclasses import asdict
from typing import Any

from mountcal.cli.options import (
    add_command,
    add_log_options,
    log_options,
    print_json,
    working,
)
from mountcal.cli.path_options import add_path
from mountcal.cli.results import say
from mountcal.core.ranges import Number
from mountcal.core.terminal import safe
from mountcal.io.reader import CHUNK_SAMPLES

log = logging.getLogger("mountcal")


def add_parser(sub: Any) -> None:
    p = add_command(
        sub,
        "rotate",
        "write a log's samples in the vehicle frame (Parquet, CSV or MCAP)",
        json_help="what was read, written and dropped, as JSON on stdout",
        inputs=("LOG", "log file(s); splits of one log are joined"),
        output="file to write (.parquet, .csv or .mcap)",
        output_required=True,
        writes={"what": "the rotated log", "formats": (".parquet", ".pq", ".csv", ".mcap")},
    )
    add_path(
        p, "--calibration", role="input", what="a calibration JSON", small=True, required=True,
        help="result JSON written by `mountcal calibrate`",
    )  # fmt: skip
    p.add_argument(
        "--format", choices=("parquet", "csv", "mcap"), default=None, help="default: from -o's suffix, else parquet"
    )
    p.add_argument(
        "--chunk",
        type=Number("chunk_samples"),
        default=CHUNK_SAMPLES,
        help="samples per chunk: bounds the memory (default %(default)s)",
    )
    p.add_argument(
        "--level-only",
        action="store_true",
        help="accept a calibration without yaw: write a levelled frame (z up, heading the sensor's own)",
    )
    p.add_argument("--require-confident", action="store_true", help="refuse a calibration that is not confident")
    add_log_options(p, stops=False)
    p.set_defaults(run=run, protocol=None)


def run(args: argparse.Namespace) -> int:
    from mountcal.apply.rotate_log import rotate_log
    from mountcal.core.result import Calibration

    cal = Calibration.load(args.calibration)
    with working(args, "rotating"):
        report = rotate_log(
            args.input,
            cal,
            args.output,
            fmt=args.format,
            options=log_options(args),
            chunk_samples=args.chunk,
            level_only=args.level_only,
            require_confident=args.require_confident,
            where=str(args.calibration),  # refused before any reading (level_only, require_confident), naming the file
        )
    for text in report.warnings:
        log.warning("%s (recorded in %s's metadata)", text, safe(args.output))
    from mountcal.calibration.summary import answer

    frame = "vehicle" if report.frame.startswith("vehicle") else "levelled"
    say(
        f"wrote {report.samples_out} samples in the {frame} frame to {safe(args.output)} with {answer(cal)}",
        [safe(f"mounting from {args.calibration}"), *(safe(line) for line in report.lines())],
    )
    if args.json:
        print_json(asdict(report))
    return 0
