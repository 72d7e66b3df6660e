"""``mountcal live --interface … --channel … --dbc …``: a session on a live CAN bus (record, refit, suggest)."""

from __future__ import annotations

import argparse
import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

from mountcal.cli.options import (
    STDOUT,
    add_axes_option,
    add_command,
    add_heading_unit_option,
    add_model_option,
    print_json,
)
from mountcal.cli.path_options import add_path
from mountcal.cli.results import result_stream, say
from mountcal.core.ranges import Number
from mountcal.core.terminal import safe

log = logging.getLogger("mountcal")


def add_parser(sub: Any) -> None:
    p = add_command(
        sub,
        "live",
        "run a session on a live CAN bus: record, refit at each stop, suggest",
        json_help="the session's result (why it ended, stops, files written, the calibration) as JSON on stdout at "
        "its end; the events as they come are on stderr (or --json-events)",
    )
    p.add_argument("--interface", required=True, help="python-can interface: socketcan, virtual, pcan, vector, …")
    p.add_argument("--channel", required=True, help="bus channel, e.g. can0")
    add_path(p, "--dbc", role="input", what="a DBC", small=True, required=True, help="DBC describing the bus")
    add_path(
        p, "--mapping", role="input", what="a mapping", small=True, default=None,
        help="TOML naming the accelerometer signals",
    )  # fmt: skip
    add_axes_option(p)
    p.add_argument(
        "--can-channel", type=Number("can_channel"), default=None, help="channel number of the IMU frames (recorded)"
    )
    p.add_argument("--target", default="roll=0.1,pitch=0.1,yaw=0.5", help="stop when every 1σ is below (deg)")
    add_model_option(p)
    add_path(
        p, "--plan", role="input", what="a protocol sheet", small=True, default=None,
        help="protocol sheet from `mountcal plan`: stops take its β in order",
    )  # fmt: skip
    p.add_argument(
        "--uphill-azimuth-deg", type=Number("angle_deg"), default=None, help="β from the bus's heading signal"
    )
    add_heading_unit_option(p)
    p.add_argument(
        "--timeout", type=Number("timeout_s"), default=10.0, help="a bus silent this long ends the session (s)"
    )
    p.add_argument(
        "--max-acc-std", type=Number("acc_limit_mps2"), default=None, help="stillness (m/s²; default: StopDetection's)"
    )
    p.add_argument(
        "--min-stop-s", type=Number("duration_s"), default=None, help="shortest stop (s; default: StopDetection's)"
    )
    add_path(
        p, "--json-events", role="output", what="the events", stdio=True, formats=(".jsonl", ".ndjson", ".json"),
        default=None,
        help="also write the events as JSON lines here ('-': stdout)",
    )  # fmt: skip
    add_path(
        p, "-o", "--output", role="output", what="the session's files", writes=_writes, default="session",
        help="prefix: PREFIX.blf, PREFIX.json, PREFIX_stops.csv, PREFIX_protocol.csv",
    )  # fmt: skip
    add_path(
        p, "--report", role="output", what="the HTML report", formats=(".html", ".htm"), default=None,
        help="also write the HTML report here",
    )  # fmt: skip
    p.set_defaults(run=run)


def _writes(prefix: str, _: argparse.Namespace) -> list[tuple[str, str]]:
    from mountcal.sessions.live import session_files

    return [(str(path), f"{prefix}, writing") for path in session_files(Path(prefix)).values()]


def _file_sink(file: Any, line: Callable[[dict[str, Any]], str]) -> Callable[[dict[str, Any]], None]:
    """Each event appended as one whole line (a GrowingFile: a full disk leaves whole lines only)."""

    def write(event: dict[str, Any]) -> None:
        file.write(line(event).encode("utf-8"))
        file.commit()

    return write


def run(args: argparse.Namespace) -> int:
    from mountcal.calibration.options import Options
    from mountcal.calibration.summary import summary_parts
    from mountcal.core.atomic import GrowingFile, atomic_path
    from mountcal.core.errors import InputError
    from mountcal.io.can.bus import BUS_ERRORS, open_bus
    from mountcal.sessions.live import (
        Live,
        LiveOptions,
        event_line,
        fail_if_empty,
        json_sink,
        line_of,
        session_files,
        write_outputs,
    )
    from mountcal.sessions.plan import parse_target
    from mountcal.stops.detect import StopDetection
    from mountcal.stops.headings import read_protocol

    if args.json and args.json_events == STDOUT:  # stdout holds one document
        raise InputError(
            "--json", "the events in a file (--json-events FILE)", "--json-events -", "Name a file for the events."
        )
    prefix = Path(args.output)
    recording = session_files(prefix)["recording"]
    plan = read_protocol(args.plan, args.heading_unit) if args.plan else None
    plan_beta = None if plan is None else tuple(float(b) for b in plan["beta_deg"])
    stillness = {"max_acc_std_mps2": args.max_acc_std, "min_duration_s": args.min_stop_s}
    opts = LiveOptions(
        dbc=args.dbc,
        mapping=args.mapping,
        can_channel=args.can_channel,
        target_deg=parse_target(args.target),
        options=Options(model=args.model),
        detection=StopDetection(**{k: v for k, v in stillness.items() if v is not None}),
        uphill_azimuth_deg=args.uphill_azimuth_deg,
        plan_beta_deg=plan_beta,
        silence_s=args.timeout,
        axes=args.axes,
        heading_unit=args.heading_unit,
    )
    try:
        bus = open_bus(args.interface, args.channel)
    except BUS_ERRORS as err:
        raise InputError(
            f"--interface {args.interface} --channel {args.channel}",
            "a CAN bus python-can can open",
            str(err),
            "Check the interface name, the channel and that the device is up.",
        ) from err

    def shown(event: dict[str, Any]) -> None:  # a line for the person in the vehicle, at once (not held)
        log.info("%s", safe(line_of(event)), extra={"plain": True, "now": True})

    sinks: list[Callable[[dict[str, Any]], None]] = [shown]
    events_file: GrowingFile | None = None
    if args.json_events == STDOUT:
        sinks = [json_sink(result_stream())]
    elif args.json_events:
        try:
            events_file = GrowingFile(args.json_events, "the events")  # a line at a time, whole
        except BaseException:
            bus.shutdown()
            raise
        sinks.append(_file_sink(events_file, event_line))

    def emit(event: dict[str, Any]) -> None:
        for sink in sinks:
            sink(event)

    try:
        session = Live(opts, recording, emit).run(bus)
    finally:
        bus.shutdown()
        if events_file is not None:
            events_file.close()
    dropped = ", ".join(f"{k}: {v}" for k, v in session.dropped.items())
    if dropped:
        log.info("dropped frames/rows: %s", dropped)
    if session.ignored_frames:
        log.info("error/remote frames recorded but not decoded: %d", session.ignored_frames)
    written = [str(path) for path in write_outputs(session, prefix)]
    for path in written:
        log.info("wrote %s", safe(path))
    fail_if_empty(session)
    assert session.calibration is not None
    first, details, notes = summary_parts(session.calibration)
    n = 0 if session.table is None else len(session.table)
    say(f"session ended ({session.reason}), {n} stops: {first}", details, notes)
    if args.report and session.table is not None:
        from mountcal.outputs.report import render
        from mountcal.outputs.report.timeline import timeline

        cal, samples = session.calibration, session.samples
        drawn = None
        if samples is not None:  # the session over time, its stops numbered as in its stop table
            drawn = timeline(samples, session.table, left_out=cal.fit.excluded_stops, dropped=session.still_not_kept)
        with atomic_path(args.report) as tmp:
            tmp.write_text(render(cal, session.table, timeline=drawn), encoding="utf-8")
        log.info("wrote %s", safe(args.report))
        written.append(str(args.report))
    if args.json:
        print_json(
            {
                "reason": session.reason,
                "recording": str(session.recording),
                "frames": session.frames,
                "stops": n,
                "dropped": dict(session.dropped),
                "written": written,
                "calibration": session.calibration.document(),
            }
        )
    return 130 if session.reason == "interrupted" else 0
