"""``mountcal inspect LOG``: list what the log holds (streams, signals, counts, rates) and, with ``--stops``, its
parked periods: the stops found and those that nearly became stops."""

from __future__ import annotations

import argparse
from dataclasses import asdict, replace
from typing import Any

from mountcal.cli.options import add_command, add_detection_options, detection, log_options, print_json, working
from mountcal.cli.path_options import add_path
from mountcal.cli.results import say
from mountcal.core.ranges import Number
from mountcal.core.terminal import safe


def add_parser(sub: Any) -> None:
    p = add_command(
        sub,
        "inspect",
        "list what a log holds",
        json_help="the listing as JSON on stdout",
        inputs=("LOG", "the log"),
        many=False,
    )
    add_path(
        p, "--dbc", role="input", what="a DBC", small=True, action="append", default=None,
        help="DBC naming the CAN messages (repeat for several)",
    )  # fmt: skip
    p.add_argument("--columns", default=None, help="a table's columns as ROLE=COLUMN[:UNIT] pairs (see calibrate)")
    p.add_argument(
        "--stops",
        action="store_true",
        help="also read the IMU and list its parked periods: the stops found, and those that nearly became stops "
        "(which threshold failed, by how much, and the option that would keep each)",
    )
    add_path(
        p, "--mapping", role="input", what="a mapping", small=True, default=None,
        help="with --stops: TOML naming the accelerometer signals (CAN)",
    )  # fmt: skip
    p.add_argument("--channel", type=Number("can_channel"), default=None, help="with --stops: CAN channel of the IMU")
    p.add_argument("--topic", default=None, help="with --stops: IMU topic (MCAP)")
    add_detection_options(p)
    p.set_defaults(run=run, field=None)


def run(args: argparse.Namespace) -> int:
    from mountcal.io.logs import inspect_log

    opts = log_options(args)
    with working(args, "reading the log"):
        info = inspect_log(args.input, replace(opts, mapping=None, channel=None, topic=None))  # every stream
    parked = _parked(args, opts) if args.stops else None
    lines = []
    for st in info.streams:  # names come from the file: shown escaped (no terminal control, no bidi)
        fields = f"  [{', '.join(map(safe, st.fields))}]" if st.fields else ""
        fields += f"  DLC {','.join(map(str, st.dlcs))}" if st.dlcs else ""
        lines.append(f"{safe(st.name):<32} {safe(st.kind):<28} {st.count:>9} msgs {st.rate_hz:>9.2f} Hz{fields}")
    lines += [safe(f"input file: {line}") for line in info.incomplete]
    found = ""
    if parked is not None:
        found = f"; parked periods: {len(parked['stops'])} stops, {len(parked['near_misses'])} near misses"
        for stop in parked["stops"]:
            lines.append(f"stop at {stop['t_start_s']:.1f}–{stop['t_end_s']:.1f} s ({stop['duration_s']:.1f} s)")
        lines += parked["lines"]
    n = len(info.streams)
    head = safe(f"{info.source}: {info.format}, {info.duration_s:.1f} s, {n} stream{'s' if n != 1 else ''}")
    say(head + found, lines, [safe(note) for note in info.notes])
    if args.json:
        print_json(asdict(info) | ({} if parked is None else {"parked": parked}))
    return 0


def _parked(args: argparse.Namespace, opts: Any) -> dict[str, Any]:
    """The stops of the log and its near misses, with the thresholds used (lines for the reader)."""
    from mountcal.io.logs import read_log
    from mountcal.stops.detect import find_stops

    with working(args, "reading the IMU and finding its parked periods"):
        search = find_stops(read_log([args.input], opts), detection(args))
    return {
        "stops": [{"t_start_s": s.t_start_s, "t_end_s": s.t_end_s, "duration_s": s.duration_s} for s in search.stops],
        "near_misses": [m.to_dict() for m in search.near_misses],
        "lines": search.thresholds.lines() + search.near_miss_lines(),
    }
