"""``mountcal export RESULT.json --to FORMAT [-o FILE]``: the mounting in a vendor's format (default: stdout)."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path
from typing import Any

from mountcal.cli.options import STDOUT, add_command, print_json
from mountcal.cli.path_options import add_path
from mountcal.cli.results import result_stream, say
from mountcal.core.ranges import Number
from mountcal.core.terminal import safe

# the keys of mountcal.outputs.exporters.FORMATS (a test keeps them equal), here so that `--help` stays light
FORMAT_NAMES = (
    "ublox",
    "ublox-ucenter",
    "ublox-ubx",
    "novatel",
    "ros2-static-tf",
    "urdf",
    "tf2",
    "autoware",
    "json",
    "yaml",
)

log = logging.getLogger("mountcal")


def add_parser(sub: Any) -> None:
    p = add_command(
        sub,
        "export",
        "write the mounting for u-blox, NovAtel, ROS 2, Autoware, or as JSON/YAML",
        json_help="what was exported where (format, file, the mounting) as JSON on stdout; without -o FILE the "
        "export itself is in it (content, or content_hex for a binary message)",
        inputs=("RESULT.json", "result written by `mountcal calibrate -o`"),
        reads={"what": "a result JSON", "small": True},
        many=False,
        output="file to write; none or '-' writes to stdout",
        writes={"what": "the export", "stdio": True, "formats": _suffixes, "formats_by": "--to"},
    )
    p.add_argument("--to", required=True, choices=FORMAT_NAMES, help="target format (see docs/exporters.md)")
    p.add_argument(
        "--yaw-undetermined",
        choices=("refuse", "zero"),
        default="refuse",
        help="when the result's yaw is not determined: refuse (default) or write yaw = 0, marked in the output",
    )
    p.add_argument("--accept-unconfident", action="store_true", help="export a result marked not confident")
    p.add_argument(
        "--parent",
        default=None,
        help="parent frame (ROS: base_link, which must be a REP 103 body frame; Autoware: sensor_kit_base_link)",
    )
    add_path(
        p,
        "--parent-pose",
        role="input",
        what="a sensors_calibration.yaml",
        small=True,
        default=None,
        metavar="YAML",
        help="Autoware's sensors_calibration.yaml: the parent's pose in base_link, composed with the mounting "
        "(needed for a parent other than base_link in Autoware)",
    )
    p.add_argument("--child", default=None, help="the IMU's frame (default imu_link)")
    p.add_argument(
        "--translation",
        type=Number("offset_m"),
        nargs=3,
        metavar=("X", "Y", "Z"),
        default=None,
        help="the IMU's position in the parent frame, m (ROS, Autoware; mountcal does not estimate it; default 0)",
    )
    p.set_defaults(run=run)


def _suffixes(args: argparse.Namespace) -> tuple[str, ...]:
    """The suffixes ``-o`` may end in for ``--to`` (the first is the format's own)."""
    from mountcal.outputs.exporters import SUFFIXES

    return tuple(suffix for suffix, formats in SUFFIXES.items() if args.to in formats)


def run(args: argparse.Namespace) -> int:
    from mountcal.core.atomic import atomic_path
    from mountcal.core.errors import InputError
    from mountcal.core.result import Calibration
    from mountcal.outputs.exporters import DEFAULT_FRAMES, Frames, export, read_parent_pose

    result = Path(args.input)
    to_stdout = args.output in (None, STDOUT)
    cal = Calibration.load(result)
    frames = None
    if args.parent or args.child or args.translation or args.parent_pose:
        base = DEFAULT_FRAMES.get(args.to, Frames())
        parent = args.parent or base.parent
        read = args.parent_pose and args.to in DEFAULT_FRAMES  # export() refuses frames for the other formats
        frames = Frames(
            parent=parent,
            child=args.child or base.child,
            translation_m=tuple(args.translation) if args.translation else base.translation_m,
            parent_pose=read_parent_pose(args.parent_pose, parent) if read else None,
        )
    out = export(cal, args.to, yaw=args.yaw_undetermined, accept_unconfident=args.accept_unconfident, frames=frames)
    from mountcal.calibration.summary import answer

    where = "stdout" if to_stdout and not args.json else "the JSON on stdout" if to_stdout else safe(args.output)
    say(f"exported to {args.to} ({where}): {answer(cal)}", [f"from {safe(result)}"])
    if to_stdout and not args.json:
        stdout = result_stream()
        if isinstance(out, bytes):
            if stdout.isatty():
                raise InputError(
                    "mountcal export --to ublox-ubx",
                    "-o FILE or a pipe for the binary message",
                    "a terminal",
                    "Pass -o FILE.ubx (the text format `--to ublox` shows the message in hex).",
                )
            stdout.buffer.write(out)
            stdout.flush()
        else:
            stdout.write(out)
        return 0
    if not to_stdout:
        with atomic_path(args.output) as tmp:
            if isinstance(out, bytes):
                tmp.write_bytes(out)
            else:
                tmp.write_text(out, encoding="utf-8")
        log.info("wrote %s (%s)", safe(args.output), args.to)
    if args.json:
        doc: dict[str, Any] = {
            "format": args.to,
            "output": None if to_stdout else str(args.output),
            "result": str(result),
            "confident": cal.confident,
            "yaw_undetermined": cal.yaw_deg is None,
        }
        if to_stdout:
            doc |= {"content_hex": out.hex()} if isinstance(out, bytes) else {"content": out}
        print_json(doc)
    return 0
