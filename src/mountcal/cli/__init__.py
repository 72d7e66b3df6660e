"""The ``mountcal`` command line: a thin shell over the library, one module per command.

Each command module has ``add_parser(subparsers)`` and ``run(args) -> int``. Building the parser
imports no numerical library (``mountcal --help`` and ``mountcal CMD --help`` stay fast); a
command imports what it needs when it runs.

Conventions: results go to the file named by ``-o`` or to stdout (``-o -``, ``--json``), written
through :func:`mountcal.cli.results.result_stream`; status lines, warnings, progress bars and
whatever a library prints go to stderr (:mod:`mountcal.cli.results`); ``-q`` keeps only warnings
and errors, ``-v`` adds detail.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from collections.abc import Sequence

from mountcal.cli.options import EXIT_CODES, check_output_suffixes, configure_logging
from mountcal.cli.results import results_only
from mountcal.errors import MountcalError
from mountcal.io.whole import reading
from mountcal.option_names import as_flags
from mountcal.paths import SystemFailure
from mountcal.terminal import safe

COMMANDS = ("calibrate", "stops", "inspect", "rotate", "report", "fleet", "simulate", "plan", "live", "export", "triad")

log = logging.getLogger("mountcal")


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command; return its exit code (see :data:`mountcal.cli.options.EXIT_CODES`)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    configure_logging(args.verbose - args.quiet)
    try:
        # library messages name the flags, not the Python parameters; stdout holds the results alone
        with as_flags(), results_only(), reading(getattr(args, "allow_truncated", False)):
            check_output_suffixes(args)  # before any work: an output named for another format
            return int(args.run(args))
    except MountcalError as err:
        log.error("error: %s", safe(err, keep=chr(10)))
        return err.exit_code
    except BrokenPipeError:  # output piped into `head` and the like
        sys.stderr.close()
        return 0
    except OSError as err:  # the system refused a read or a write
        failure = SystemFailure(str(err.filename or f"mountcal {args.command}"), "reading or writing", err)
        log.error("error: %s", safe(failure))
        return failure.exit_code
    except KeyboardInterrupt:
        log.error("interrupted; no output was written")
        return 130


def build_parser() -> argparse.ArgumentParser:
    """The parser of every command (no numerical import)."""
    epilog = "exit codes:\n" + "\n".join(f"  {code:<4} {meaning}" for code, meaning in EXIT_CODES.items())
    parser = argparse.ArgumentParser(
        prog="mountcal",
        description="How an accelerometer or IMU is mounted in a vehicle (roll, pitch, yaw, each with its 1σ).",
        epilog=epilog + "\n\nConventions (frames, angles, signs): docs/conventions.md",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action=_Version, nargs=0, help="show the version and exit")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(f"mountcal.cli.{name}").add_parser(sub)
    return parser


class _Version(argparse.Action):
    """``--version``: the installed distribution's version, looked up only when asked (the lookup is slow)."""

    def __call__(self, parser: argparse.ArgumentParser, *_: object) -> None:
        from mountcal.version import software_version

        print(f"mountcal {software_version()}")  # on stdout, as argparse's own version action
        parser.exit()


__all__ = ["COMMANDS", "build_parser", "main"]
