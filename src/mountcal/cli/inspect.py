"""``mountcal inspect LOG``: list what the log holds (streams, signals, counts, rates)."""

from __future__ import annotations

import argparse
from dataclasses import asdict
from typing import Any

from mountcal.cli.options import add_command, log_options, print_json, working
from mountcal.cli.path_options import add_path
from mountcal.cli.results import result_stream
from mountcal.terminal import safe


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
    p.set_defaults(run=run, mapping=None, channel=None, topic=None, field=None)


def run(args: argparse.Namespace) -> int:
    from mountcal.io.logs import inspect_log

    with working(args, "reading the log"):
        info = inspect_log(args.input, log_options(args))
    if args.json:
        print_json(asdict(info))
        return 0
    out = result_stream()
    print(safe(f"{info.source}: {info.format}, {info.duration_s:.1f} s"), file=out)
    for st in info.streams:  # names come from the file: shown escaped (no terminal control, no bidi)
        fields = f"  [{', '.join(map(safe, st.fields))}]" if st.fields else ""
        fields += f"  DLC {','.join(map(str, st.dlcs))}" if st.dlcs else ""
        print(f"  {safe(st.name):<32} {safe(st.kind):<28} {st.count:>9} msgs {st.rate_hz:>9.2f} Hz{fields}", file=out)
    for note in info.notes:
        print(f"  note: {safe(note)}", file=out)
    for line in info.incomplete:
        print(safe(f"  input file: {line}"), file=out)
    return 0
