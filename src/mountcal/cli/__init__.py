"""The ``mountcal`` command line: a thin shell over the library, one module per command.

Each command module has ``add_parser(subparsers)`` and ``run(args) -> int``. Building the parser
imports no numerical library (``mountcal --help`` and ``mountcal CMD --help`` stay fast); a
command imports what it needs when it runs.

Conventions (:data:`mountcal.cli.options.QUIET_RULE`, in every ``--help``): results go to the file
named by ``-o`` or, only when asked, to stdout (``-o -``, ``--json``: one document), written through
:func:`mountcal.cli.results.result_stream`; every command accepts ``--json``. Everything else goes to
stderr: the summary (:func:`mountcal.cli.results.say`: the answer in one line, then what supports it,
then notes, each once), status lines, warnings, progress bars and whatever a library prints. ``-q``
keeps the answer line, warnings and errors, ``-qq`` warnings and errors; ``-v`` adds detail.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import re
import sys
import textwrap
from collections.abc import Sequence

from mountcal.cli.options import EXIT_CODES, QUIET_RULE, configure_logging
from mountcal.cli.path_options import CommandParser, check_paths, command_parser
from mountcal.cli.results import results_only, unread_stderr_tolerated
from mountcal.core import budget
from mountcal.core.atomic import Terminated, raise_if_interrupted, removed_on_signals
from mountcal.core.errors import InputError, MountcalError
from mountcal.core.option_names import as_flags
from mountcal.core.paths import SystemFailure
from mountcal.core.terminal import safe
from mountcal.io.whole import reading

COMMANDS = ("calibrate", "stops", "inspect", "rotate", "report", "fleet", "simulate", "plan", "live", "export", "triad")

log = logging.getLogger("mountcal")


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command; return its exit code (see :data:`mountcal.cli.options.EXIT_CODES`)."""
    stdout_closed = _standard_streams()
    with unread_stderr_tolerated():  # status, bars and errors alike: a stderr nobody reads ends nothing
        return _command(argv, stdout_closed)


def _command(argv: Sequence[str] | None, stdout_closed: bool) -> int:
    parser = build_parser()
    args = parser.parse_args(_signed_maps(sys.argv[1:] if argv is None else list(argv)))
    configure_logging(args.verbose - args.quiet)
    try:
        if stdout_closed:
            raise InputError(
                "stdout",
                "an open standard output (mountcal writes results there when asked)",
                "it closed (`>&-`)",
                "Redirect it to a file or to /dev/null instead. Nothing was written.",
            )
        # messages name flags; SIGTERM/SIGHUP unwind like Ctrl-C; one budget for the whole command;
        # stdout holds the results alone
        with (
            as_flags(),
            removed_on_signals(),
            budget.scope(),
            results_only(),
            reading(getattr(args, "allow_truncated", False)),
        ):
            check_paths(command_parser(parser, args.command), args)  # every declared path, before any work
            code = int(args.run(args))
            if code == 0:  # a command that returned 130 has handled its Ctrl-C already
                raise_if_interrupted()  # a Ctrl-C Python dropped in a callback still ends the command as one
            return code
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
    except Terminated as err:
        log.error("terminated by %s; no output was written", err)
        return 128 + err.signum
    except KeyboardInterrupt:
        log.error("interrupted; no output was written")
        return 130


def _standard_streams() -> bool:
    """Give a closed stdin, stdout or stderr ``/dev/null`` (so that no file mountcal opens takes its
    descriptor, and no child process writes into one); True when stdout was closed."""
    closed = False
    for fd, name in ((0, "stdin"), (1, "stdout"), (2, "stderr")):
        try:
            os.fstat(fd)
            continue
        except OSError:
            pass
        null = os.open(os.devnull, os.O_RDWR)
        if null != fd:
            os.dup2(null, fd)
            os.close(null)
        if getattr(sys, name) is None:  # closed when Python started
            setattr(sys, name, open(fd, "w" if fd else "r", encoding="utf-8", closefd=False))
        closed = closed or fd == 1
    return closed


_AXIS_MAP = re.compile(r"-[xyzXYZ]\s*,.*")


def _signed_maps(argv: list[str]) -> list[str]:
    """``--axes -y,x,z`` as ``--axes=-y,x,z``: argparse would take a value starting with "-" for an option."""
    out: list[str] = []
    i = 0
    while i < len(argv):
        if argv[i] == "--axes" and i + 1 < len(argv) and _AXIS_MAP.fullmatch(argv[i + 1]):
            out.append(f"--axes={argv[i + 1]}")
            i += 2
        else:
            out.append(argv[i])
            i += 1
    return out


def build_parser() -> argparse.ArgumentParser:
    """The parser of every command (no numerical import)."""
    epilog = "exit codes:\n" + "\n".join(f"  {code:<4} {meaning}" for code, meaning in EXIT_CODES.items())
    parser = argparse.ArgumentParser(
        prog="mountcal",
        description="How an accelerometer or IMU is mounted in a vehicle (roll, pitch, yaw, each with its 1σ).",
        epilog=epilog
        + "\n\n"
        + textwrap.fill(QUIET_RULE, 100)
        + "\n\nConventions (frames, angles, signs): docs/conventions.md",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action=_Version, nargs=0, help="show the version and exit")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=CommandParser)
    for name in COMMANDS:
        importlib.import_module(f"mountcal.cli.{name}").add_parser(sub)
    return parser


class _Version(argparse.Action):
    """``--version``: the installed distribution's version, looked up only when asked (the lookup is slow)."""

    def __call__(self, parser: argparse.ArgumentParser, *_: object) -> None:
        from mountcal.core.version import software_version

        print(f"mountcal {software_version()}")  # on stdout, as argparse's own version action
        parser.exit()


__all__ = ["COMMANDS", "build_parser", "main"]
