"""What the commands share: option groups, logging, progress bars, ``-`` for stdout, optional packages.

Nothing here imports a numerical library at module level: the parser is built from it.
"""

from __future__ import annotations

import argparse
import importlib
import json
import logging
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any

from mountcal.calibration.options import DEFAULT_USE, METHODS, USES, Options, default
from mountcal.cli.path_options import add_path
from mountcal.core.errors import InputError
from mountcal.core.ranges import Number, numbers

if TYPE_CHECKING:
    from tqdm import tqdm

    from mountcal.calibration.job import LogJob
    from mountcal.io.reader import LogOptions
    from mountcal.stops.detect import StopDetection

EXIT_CODES = {
    0: "success",
    2: "bad input or usage (the message names the file or option, what was expected and what to do)",
    3: "not enough information in the data for an answer (e.g. too few headings)",
    4: "the fit failed",
    5: "the system refused a read or a write",
    130: "interrupted (nothing partial is written)",
    143: "terminated by SIGTERM (129: SIGHUP; nothing partial is written)",
}
STDOUT = "-"
HEADINGS = ("uphill", "relative", "none")

log = logging.getLogger("mountcal")


class _Stderr(logging.Handler):
    """Status lines of ``mountcal.*`` loggers on the current stderr (never stdout), prefixed ``mountcal:``;
    another library's records (asammdf, python-can, Python warnings) name that library. The lines of a
    command's summary (:func:`mountcal.cli.results.say`) are shown as they are, and status lines wait
    for the answer (:func:`mountcal.cli.results.held`)."""

    def emit(self, record: logging.LogRecord) -> None:
        from mountcal.cli.results import held

        if not held(self.write, record):
            self.write(record)

    def write(self, record: logging.LogRecord) -> None:
        from tqdm import tqdm  # writes above a progress bar being drawn, instead of through it

        if getattr(record, "plain", False):
            text = record.getMessage()
        else:
            level = "" if record.levelno in (logging.INFO, logging.ERROR) else f"{record.levelname.lower()}: "
            origin = "" if record.name.startswith("mountcal") else f"[{record.name}] "
            text = f"mountcal: {level}{origin}{record.getMessage()}"
        tqdm.write(text, file=sys.stderr)
        sys.stderr.flush()


QUIET_RULE = (
    "output: results go to stdout only when asked (-o -, --json), one document; "
    "everything else goes to stderr: first the answer in one line, then what supports it, then notes (each once), "
    "then what was written. -q keeps only the answer line, warnings and errors; -qq only warnings and errors; "
    "-v adds detail."
)


def configure_logging(verbosity: int) -> None:
    """One logging set-up for every command: -qq (warnings and errors), -q (and the answer line), default
    (the summary and status), -v (detail).

    Other libraries' warnings (their loggers, and Python warnings while a command runs) join the
    log on stderr through the root logger."""
    from mountcal.cli.results import ANSWER

    root = logging.getLogger("mountcal")
    if not any(isinstance(h, _Stderr) for h in root.handlers):
        root.addHandler(_Stderr())
    root.propagate = False
    levels = {-1: ANSWER, 0: logging.INFO}
    root.setLevel(levels.get(verbosity, logging.WARNING if verbosity < 0 else logging.DEBUG))
    libraries = logging.getLogger()
    if not any(isinstance(h, _Stderr) for h in libraries.handlers):
        libraries.addHandler(_Stderr(logging.WARNING))


def common_options() -> argparse.ArgumentParser:
    """-q/-v/--progress: a parent parser of every command."""
    common = argparse.ArgumentParser(add_help=False)
    g = common.add_argument_group("output")
    g.add_argument(
        "-q",
        "--quiet",
        action="count",
        default=0,
        help="only the answer line, warnings and errors on stderr (-qq: no answer)",
    )
    g.add_argument("-v", "--verbose", action="count", default=0, help="more detail on stderr")
    g.add_argument(
        "--progress",
        action="store_true",
        help="progress bars on stderr even when it is not a terminal (never with -q)",
    )
    i = common.add_argument_group("input")
    i.add_argument(
        "--allow-truncated",
        action="store_true",
        help="read the whole part of an input file that was cut short (an interrupted copy or recording); "
        "the result names it. Without it such a file is refused",
    )
    return common


def add_input_kind(p: argparse.ArgumentParser) -> None:
    """``--input-kind``: what the input is, where its name and content leave it open (:mod:`mountcal.io.kind`)."""
    p.add_argument(
        "--input-kind",
        choices=("auto", "stop-table", "log"),
        default="auto",
        help="a CSV/Parquet input is a stop table or a sample log: by default told from its columns and rows "
        "(and said); name it where they do not settle it",
    )


def add_command(
    sub: Any,
    name: str,
    help_text: str,
    *,
    json_help: str,
    inputs: tuple[str, str] | None = None,
    reads: dict[str, Any] | None = None,
    many: bool = True,
    output: str | None = None,
    output_required: bool = False,
    writes: dict[str, Any] | None = None,
) -> argparse.ArgumentParser:
    """A subcommand with the common options; its inputs (``args.input``: metavar, help), its ``-o`` and
    ``--json`` (every command has one: ``json_help`` says what it writes). ``reads`` and ``writes`` declare the
    inputs and ``-o`` (:func:`mountcal.cli.path_options.add_path`; default: logs, which may be folders, and a
    file)."""
    p: argparse.ArgumentParser = sub.add_parser(
        name,
        help=help_text,
        description=help_text,
        epilog=QUIET_RULE,
        parents=[common_options()],
    )
    if inputs is not None:
        add_path(
            p,
            "input",
            role="input",
            **(reads or {"what": "a log", "folders": True}),
            nargs="+" if many else None,
            metavar=inputs[0],
            help=inputs[1],
        )
    if output is not None:
        add_path(
            p,
            "-o",
            "--output",
            role="output",
            **(writes or {"what": "the output"}),
            required=output_required,
            default=None,
            help=output,
        )
    p.add_argument("--json", action="store_true", help=f"{json_help} (the only thing on stdout)")
    return p


def add_log_options(
    p: argparse.ArgumentParser, *, repeat_dbc: bool = True, stops: bool = True, protocol: bool = True
) -> None:
    """How to read a log (and, with ``stops``, how to find its stops and their headings)."""
    g = p.add_argument_group("logs")
    if repeat_dbc:
        add_path(
            g, "--dbc", role="input", what="a DBC", small=True, action="append", default=None,
            help="DBC to decode a CAN log (repeat for several)",
        )  # fmt: skip
    else:
        add_path(g, "--dbc", role="input", what="a DBC", small=True, default=None, help="DBC to decode CAN logs")
    add_path(
        g, "--mapping", role="input", what="a mapping", small=True, default=None,
        help="TOML naming the accelerometer signals (CAN) or a table's [columns]",
    )  # fmt: skip
    g.add_argument(
        "--columns",
        default=None,
        help="a table's columns as ROLE=COLUMN[:UNIT] pairs, e.g. time=ts:ms,ax=acc_x:g,ay=acc_y:g,az=acc_z:g "
        "(roles time ax ay az gx gy gz speed heading temperature latitude longitude altitude)",
    )
    g.add_argument("--channel", type=Number("can_channel"), default=None, help="CAN channel of the IMU")
    g.add_argument("--topic", default=None, help="IMU topic (MCAP, ROS bags)")
    g.add_argument(
        "--field",
        default=None,
        help="the Imu or Vector3 inside the topic's message, e.g. imu or imu.linear_acceleration (MCAP, ROS bags)",
    )
    add_axes_option(g)
    add_heading_unit_option(g)
    if not stops:
        return
    if protocol:
        add_path(
            g, "--protocol", role="input", what="a protocol sheet", small=True, default=None,
            help="protocol sheet CSV: t_start_s, t_end_s, beta_deg",
        )  # fmt: skip
    g.add_argument(
        "--uphill-azimuth-deg",
        type=Number("angle_deg"),
        default=None,
        help="compass azimuth of the slope's uphill direction, with a heading signal in the log (or a stop table's "
        "compass column heading_deg), from the same north as that heading (true or magnetic: they differ by the "
        "local declination, which turns yaw by as much)",
    )
    add_detection_options(p)


def add_heading_unit_option(g: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    """``--heading-unit``: for every command that reads headings (a heading channel, a protocol sheet, a stop
    table's ``beta_deg``), whose check refuses radians naming this option."""
    g.add_argument(
        "--heading-unit",
        choices=("deg", "rad"),
        default=None,
        help="unit of the headings (a heading channel, a protocol's or stop table's beta_deg); default degrees, "
        "checked: headings that look like radians are refused",
    )


def add_detection_options(p: argparse.ArgumentParser) -> None:
    """The thresholds of stop detection (unset: the library's defaults, some set from the log)."""
    d = p.add_argument_group("stop detection (default: mountcal.stops.detect.StopDetection, some from the log)")
    for flag, text, quantity in _DETECTION.values():
        d.add_argument(flag, type=Number(quantity), default=None, help=text)


def add_axes_option(g: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    """``--axes``: the device's axes onto the right-handed sensor frame, for every input of samples."""
    g.add_argument(
        "--axes",
        default=None,
        metavar="MAP",
        help='the device\'s axes as the sensor frame: a signed permutation, e.g. "x,-y,z" (sensor x, y, z in turn; a '
        "reflection states a left-handed device), applied to accelerometer and gyro after a mapping's own axes",
    )


# StopDetection field → (flag, help, quantity of mountcal.core.ranges); unset flags keep the library's defaults
_DETECTION = {
    "max_acc_std_mps2": ("--max-acc-std", "stillness: moving std of each axis below this (m/s²)", "acc_limit_mps2"),
    "max_gyro_std_rad_s": (
        "--max-gyro-std",
        "stillness: moving std of each gyro axis below this (rad/s)",
        "gyro_limit_rad_s",
    ),
    "max_gyro_rad_s": (
        "--max-gyro-rate",
        "stillness: angular rate within this of the gyro's bias (rad/s)",
        "gyro_limit_rad_s",
    ),
    "max_speed_mps": ("--max-speed", "stillness: speed at most this (m/s)", "speed_limit_mps"),
    "window_s": ("--still-window-s", "window of the moving statistics (s)", "duration_s"),
    "min_duration_s": ("--min-stop-s", "shortest stop (s)", "duration_s"),
    "trim_s": ("--trim-s", "settling cut from both ends of a stop (s)", "trim_s"),
    "max_heading_wander_deg": (
        "--max-heading-wander",
        "a stop whose heading wanders more is split (deg)",
        "tolerance_deg",
    ),
}


def add_sensor_options(g: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    """The sensor's limits and triad calibration: the systematic part of every σ."""
    add_path(
        g,
        "--sensor-spec",
        role="input",
        what="a sensor spec",
        small=True,
        default=None,
        help="limits for the systematic σ (TOML/JSON): scale, cross_axis, bias_mg, bias_tempco_mg_per_c, "
        "heading_deg (the headings' common error against the fall line); without it, the default class",
    )
    add_path(
        g, "--triad", role="input", what="a triad calibration", small=True, default=None,
        help="triad calibration from `mountcal triad`, applied to the stops",
    )  # fmt: skip


def add_fit_options(g: argparse.ArgumentParser | argparse._ArgumentGroup, *, headings_help: str) -> None:
    """Method, model, headings and the yaw threshold of the fit: the defaults are :class:`Options`'s, checked
    when :func:`fit_options` builds it (one rule for the CLI and the library)."""
    g.add_argument(
        "--method", choices=METHODS, default=default(Options, "method"), help="the estimator (default %(default)s)"
    )
    add_model_option(g)
    g.add_argument("--headings", choices=HEADINGS, default=None, help=headings_help)
    g.add_argument(
        "--max-yaw-sigma",
        type=Number("sigma_deg"),
        default=default(Options, "max_yaw_sigma_deg"),
        help="report yaw only below this 1σ (deg; default %(default)s)",
    )
    add_sensor_options(g)
    g.add_argument(
        "--slope-reference",
        nargs=2,
        action=numbers("slope_deg", "sigma_deg"),
        default=None,
        metavar=("DEG", "SIGMA_DEG"),
        help="the slope the body stands at, measured apart from the sensor (a level on the body facing uphill and "
        "downhill, half the difference; or the ground's, surveyed, which differs by the suspension's lean), and its "
        "1σ: checked against the stops' slope, it shows a horizontal scale error or a compliant mount the stops "
        "alone cannot",
    )
    g.add_argument(
        "--use",
        choices=USES,
        default=DEFAULT_USE,
        help="for a log: its parked stops, its driving (speed changes; it estimates the rotation only, so a --model "
        "naming an effect is refused), or whatever it supports (default %(default)s)",
    )


def add_model_option(g: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    """``--model``: its one description (:func:`mountcal.loop.terms.help_text`) and default (:class:`Options`);
    checked when :class:`Options` is built."""
    from mountcal.loop.terms import help_text

    g.add_argument("--model", default=default(Options, "model"), help=help_text())


def log_options(args: argparse.Namespace) -> LogOptions:
    from mountcal.io.reader import LogOptions

    dbc = args.dbc
    if isinstance(dbc, list):  # --dbc given once (a path) or repeated (their messages together)
        dbc = None if not dbc else dbc[0] if len(dbc) == 1 else tuple(dbc)
    from mountcal.io.table.layout import parse_columns

    columns = getattr(args, "columns", None)
    unit = getattr(args, "unit", None)
    return LogOptions(
        dbc=dbc,
        mapping=args.mapping,
        channel=args.channel,
        topic=args.topic,
        field=args.field,
        columns=None if columns is None else parse_columns(columns),
        unit=None if unit in (None, "mps2") else unit,
        allow_truncated=getattr(args, "allow_truncated", False),
        axes=getattr(args, "axes", None),
        heading_unit=getattr(args, "heading_unit", None),
    )


def detection(args: argparse.Namespace) -> StopDetection:
    from mountcal.stops.detect import StopDetection

    given = {field: getattr(args, flag[2:].replace("-", "_")) for field, (flag, _, _) in _DETECTION.items()}
    return StopDetection(**{k: v for k, v in given.items() if v is not None})


def fit_options(args: argparse.Namespace) -> Options:
    from mountcal.loop.slope_reference import SlopeReference

    reference = args.slope_reference
    options = Options(
        method=args.method,
        model=args.model,
        gravity_mps2=gravity(args),
        max_yaw_sigma_deg=args.max_yaw_sigma,
        slope_reference=None if reference is None else SlopeReference(*reference),
    )
    return sensor_options(options, getattr(args, "sensor_spec", None), getattr(args, "triad", None))


def sensor_options(options: Options, spec: str | None, triad: str | None) -> Options:
    """``options`` with the sensor's limits (``--sensor-spec``) and triad calibration (``--triad``) read in."""
    from dataclasses import replace

    if spec is not None:  # each read only when given: the triad's fit is scipy.optimize, 0.1 s to import
        from mountcal.io.sensor_spec import read_spec

        options = replace(options, spec=read_spec(spec))
    if triad is not None:
        from mountcal.estimate.triad import load

        options = replace(options, triad=load(triad))
    return options


def gravity(args: argparse.Namespace) -> float | None:
    """``--gravity`` in m/s²: a bare number in m/s² (checked to be Earth's), or a value with its unit (``1g``)."""
    text = getattr(args, "gravity", None)
    if text is None:
        return None
    from mountcal.io.input_conventions import GRAVITY, parse_quantity

    return parse_quantity(text, GRAVITY)[0]


def log_job(args: argparse.Namespace, options: Options | None = None) -> LogJob:
    from mountcal.calibration.job import LogJob

    return LogJob(
        paths=tuple(args.input),
        log=log_options(args),
        detection=detection(args),
        protocol=args.protocol,
        uphill_azimuth_deg=args.uphill_azimuth_deg,
        options=options if options is not None else fit_options(args),
        use=getattr(args, "use", DEFAULT_USE),
    )


def require(module: str, extra: str, needed_by: str) -> None:
    """Refuse, before any work, an option whose optional dependency is not installed; name the extra."""
    try:
        importlib.import_module(module)
    except ImportError as err:
        raise InputError(
            needed_by,
            f"the optional package {module} installed",
            f"it missing ({err})",
            f"Install it: pip install 'mountcal[{extra}]'. Nothing was written.",
        ) from err


def print_json(document: Any) -> None:
    """A machine-readable result on stdout (one JSON document)."""
    from mountcal.cli.results import result_stream

    out = result_stream()
    out.write(json.dumps(document, indent=2, allow_nan=False, default=str) + "\n")
    out.flush()


def progress_wanted(args: argparse.Namespace) -> bool:
    """Bars on stderr: on a terminal, or with --progress; never with -q."""
    if args.quiet > 0:
        return False
    return bool(args.progress) or bool(getattr(sys.stderr, "isatty", lambda: False)())


def bar(args: argparse.Namespace, total: int | None, label: str, unit: str = "it") -> tqdm[Any]:
    """A tqdm progress bar on stderr (disabled under -q or off a terminal unless --progress); without a
    total, the elapsed time."""
    from tqdm import tqdm

    return tqdm(
        total=total,
        desc=f"mountcal: {label}",
        unit=unit,
        file=sys.stderr,
        disable=not progress_wanted(args),
        bar_format=None if total is not None else "{desc} … {elapsed}",
    )


@contextmanager
def working(args: argparse.Namespace, label: str) -> Iterator[None]:
    """A bar for one long step that reports no progress of its own: the elapsed time, redrawn while it runs."""
    with bar(args, None, label) as shown:
        if shown.disable:
            yield
            return
        done = threading.Event()

        def tick() -> None:
            while not done.wait(0.2):
                shown.refresh()

        ticker = threading.Thread(target=tick, daemon=True)
        ticker.start()
        try:
            yield
        finally:
            done.set()
            ticker.join()
