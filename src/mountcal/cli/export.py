"""``mountcal export RESULT.json --to FORMAT -o FILE|-``: the mounting in a vendor's format, written to FILE
(``-``: stdout; results go to stdout only when asked, as for every command)."""

from __future__ import annotations

import argparse
import logging
import textwrap
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from mountcal.cli.options import STDOUT, add_command, print_json
from mountcal.cli.path_options import add_path
from mountcal.cli.results import result_stream, say
from mountcal.core.ranges import Number
from mountcal.core.terminal import safe
from mountcal.outputs import exporters

log = logging.getLogger("mountcal")


class Formats:
    """``--to``'s choices: the registry's names (:mod:`mountcal.outputs.exporters`). A built-in name is
    checked without looking for plugins; only another name, or listing them all, reads the entry points."""

    def __contains__(self, name: object) -> bool:
        return name in exporters.builtin() or name in exporters.names()

    def __iter__(self) -> Iterator[str]:
        return iter(exporters.names())


def _formats_epilog() -> str:
    """The formats, one a line with what each writes (the registry's built-in ones; then where others come from)."""
    own = exporters.builtin().values()
    width = max(len(e.name) for e in own) + 2
    lines = [f"  {e.name:<{width}}{e.description}" for e in own]
    extra = f"  or a format an installed package registers (entry-point group {exporters.GROUP})"
    return "\n".join(["formats (--to; docs/exporters.md):", *lines, extra])


def add_parser(sub: Any) -> None:
    p = add_command(
        sub,
        "export",
        "write the mounting for u-blox, NovAtel, ROS 2, Autoware, or as JSON/YAML",
        json_help="what was exported where (format, file, the mounting) as JSON on stdout; with -o - the "
        "export itself is in it (content, or content_hex for a binary message)",
        inputs=("RESULT.json", "result written by `mountcal calibrate -o`"),
        reads={"what": "a result JSON", "small": True},
        many=False,
        output="file to write ('-': stdout)",
        output_required=True,
        writes={"what": "the export", "stdio": True, "formats": _suffixes, "formats_by": "--to"},
    )
    p.formatter_class = argparse.RawDescriptionHelpFormatter  # the epilog: one format a line
    p.epilog = _formats_epilog() + "\n\n" + textwrap.fill(p.epilog or "", width=100)  # and the output rule
    p.add_argument("--to", required=True, choices=Formats(), metavar="FORMAT", help="target format (listed below)")
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
    p.add_argument(
        "--child",
        default=None,
        help="the IMU's frame (default: the frame_id the calibration's log gave the IMU's messages, else imu_link)",
    )
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
    return exporters.get(args.to).suffixes


def run(args: argparse.Namespace) -> int:
    from mountcal.core.atomic import atomic_path
    from mountcal.core.errors import InputError
    from mountcal.core.result import Calibration
    from mountcal.outputs.exporters import Frames, export, frames_for, read_parent_pose

    result = Path(args.input)
    to_stdout = args.output == STDOUT
    cal = Calibration.load(result)
    frames = None
    own = exporters.get(args.to).frames
    if args.parent is not None or args.child is not None or args.translation or args.parent_pose:
        base = own or Frames()
        parent = base.parent if args.parent is None else args.parent
        read = args.parent_pose and own is not None  # export() refuses frames for the other formats
        frames = Frames(
            parent=parent,
            child=args.child,
            translation_m=tuple(args.translation) if args.translation else base.translation_m,
            parent_pose=read_parent_pose(args.parent_pose, parent) if read else None,
        )
    frames = frames_for(cal, args.to, frames)  # the child named, and what is said of its name
    if frames is not None and frames.warn:
        log.warning("%s", safe(frames.said[0]))  # a transform for another frame than the data's: said plainly
    out = export(cal, args.to, yaw=args.yaw_undetermined, accept_unconfident=args.accept_unconfident, frames=frames)
    from mountcal.calibration.summary import answer

    where = "stdout" if to_stdout and not args.json else "the JSON on stdout" if to_stdout else safe(args.output)
    said = [] if frames is None or frames.warn else [safe(line) for line in frames.said]
    say(f"exported to {args.to} ({where}): {answer(cal)}", [f"from {safe(result)}", *said])
    if to_stdout and not args.json:
        stdout = result_stream()
        if isinstance(out, bytes):
            if stdout.isatty():
                suffix = next(iter(exporters.get(args.to).suffixes), "")
                raise InputError(
                    f"mountcal export --to {args.to}",
                    "-o FILE or a pipe for the binary output",
                    "a terminal",
                    f"Pass -o FILE{suffix}.",
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
