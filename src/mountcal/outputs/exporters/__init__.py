"""Hand a calibration to the systems that use it, each in its vendor's own conventions.

``mountcal export result.json --to FORMAT``. Every format is built from one :class:`Mounting`
(the rotation, its σ, what was assumed), which refuses a result whose yaw is not determined or
that is not confident unless told otherwise. Definitions and sources: docs/exporters.md.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path

from mountcal.atomic import atomic_path
from mountcal.errors import InputError
from mountcal.outputs.exporters.autoware import DEFAULT_FRAMES as AUTOWARE_FRAMES
from mountcal.outputs.exporters.autoware import autoware_yaml
from mountcal.outputs.exporters.common import Mounting, YawPolicy, mounting
from mountcal.outputs.exporters.novatel import novatel_rotation, novatel_text
from mountcal.outputs.exporters.ros import Frames, static_transform_command, tf2_quaternion, urdf_joint
from mountcal.outputs.exporters.rotation import rotation_json, rotation_yaml
from mountcal.outputs.exporters.ublox import ublox_mount, ublox_text, ucenter_config, valset
from mountcal.result import Calibration

Writer = Callable[[Mounting, Frames | None], str | bytes]

FORMATS: dict[str, Writer] = {
    "ublox": lambda m, f: ublox_text(ublox_mount(m)),
    "ublox-ucenter": lambda m, f: ucenter_config(ublox_mount(m).raw),
    "ublox-ubx": lambda m, f: valset(ublox_mount(m).raw),
    "novatel": lambda m, f: novatel_text(novatel_rotation(m)),
    "ros2-static-tf": lambda m, f: static_transform_command(m, f or Frames()),
    "urdf": lambda m, f: urdf_joint(m, f or Frames()),
    "tf2": lambda m, f: tf2_quaternion(m, f or Frames()),
    "autoware": lambda m, f: autoware_yaml(m, f or AUTOWARE_FRAMES),
    "json": lambda m, f: rotation_json(m),
    "yaml": lambda m, f: rotation_yaml(m),
}


def export(
    cal: Calibration,
    fmt: str,
    *,
    yaw: YawPolicy = "refuse",
    accept_unconfident: bool = False,
    frames: Frames | None = None,
) -> str | bytes:
    """The calibration in ``fmt`` (text, or bytes for ``ublox-ubx``)."""
    if fmt not in FORMATS:
        raise InputError("mountcal export --to", f"one of {', '.join(FORMATS)}", repr(fmt), "Choose a listed format.")
    return FORMATS[fmt](mounting(cal, yaw, accept_unconfident), frames)


def cmd_export(args: argparse.Namespace) -> int:
    """``mountcal export RESULT.json --to FORMAT [-o FILE]``; no -o or ``-o -`` writes to stdout."""
    result = Path(args.result)
    to_stdout = args.output in (None, "-")
    if not to_stdout and Path(args.output).resolve() == result.resolve():
        raise InputError(
            str(args.output),
            "an output path other than the input",
            "the result file itself",
            "Choose another -o path; mountcal never overwrites its input.",
        )
    cal = Calibration.load(result)
    frames = None
    if args.parent or args.child or args.translation:
        base = AUTOWARE_FRAMES if args.to == "autoware" else Frames()
        frames = Frames(
            parent=args.parent or base.parent,
            child=args.child or base.child,
            translation_m=tuple(args.translation) if args.translation else base.translation_m,
        )
    out = export(cal, args.to, yaw=args.yaw_undetermined, accept_unconfident=args.accept_unconfident, frames=frames)
    if to_stdout:
        if isinstance(out, bytes):
            if sys.stdout.isatty():
                raise InputError(
                    "mountcal export --to ublox-ubx",
                    "-o FILE or a pipe for the binary message",
                    "a terminal",
                    "Pass -o FILE.ubx (the text format `--to ublox` shows the message in hex).",
                )
            sys.stdout.buffer.write(out)
            sys.stdout.flush()
        else:
            sys.stdout.write(out)
        return 0
    try:
        with atomic_path(args.output) as tmp:
            if isinstance(out, bytes):
                tmp.write_bytes(out)
            else:
                tmp.write_text(out, encoding="utf-8")
    except OSError as err:
        raise InputError(
            str(args.output), "a writable file path", f"an error writing it ({err.strerror})", "Choose another -o path."
        ) from err
    print(f"wrote {args.output} ({args.to})", file=sys.stderr)
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """The ``export`` subcommand's arguments."""
    exp = sub.add_parser("export", help="write the mounting for u-blox, NovAtel, ROS 2, Autoware, or as JSON/YAML")
    exp.add_argument("result", metavar="RESULT.json", help="result written by `mountcal calibrate -o`")
    exp.add_argument("--to", required=True, choices=tuple(FORMATS), help="target format (see docs/exporters.md)")
    exp.add_argument("-o", "--output", default=None, help="file to write; none or '-' writes to stdout")
    exp.add_argument(
        "--yaw-undetermined",
        choices=("refuse", "zero"),
        default="refuse",
        help="when the result's yaw is not determined: refuse (default) or write yaw = 0, marked in the output",
    )
    exp.add_argument("--accept-unconfident", action="store_true", help="export a result marked not confident")
    exp.add_argument("--parent", default=None, help="parent frame (ROS: base_link; Autoware: sensor_kit_base_link)")
    exp.add_argument("--child", default=None, help="the IMU's frame (default imu_link)")
    exp.add_argument(
        "--translation",
        type=float,
        nargs=3,
        metavar=("X", "Y", "Z"),
        default=None,
        help="the IMU's position in the parent frame, m (ROS, Autoware; mountcal does not estimate it; default 0)",
    )
    exp.set_defaults(func=cmd_export)


__all__ = ["FORMATS", "Frames", "Mounting", "add_parser", "cmd_export", "export", "mounting"]
