"""``mountcal`` and ``python -m mountcal``: the command line (the commands are in :mod:`mountcal.cli`).

A local ``mountcal fleet`` starts its worker server first thing, so that the server imports
mountcal's numerical code while this process does the same (0.7–0.9 s each, at the same time on
two cores instead of one after the other). The look at the arguments here is only that; the parser
in :mod:`mountcal.cli` decides everything.
"""

from __future__ import annotations

import gc
import sys
from collections.abc import Sequence

INTERRUPTED = (129, 130, 143)  # SIGHUP, Ctrl-C, SIGTERM


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the console script."""
    code = _run(list(sys.argv[1:] if argv is None else argv))
    # A Ctrl-C that lands in code run from a string (a dataclass's generated methods, while modules
    # import) marks the interpreter as ended by an unhandled KeyboardInterrupt even once it is
    # handled, and CPython then ends itself by SIGINT at exit (status -2, not 130). Running any
    # string clears that mark.
    exec("pass")
    if argv is None:  # this process ends now: nothing it holds needs collecting
        _skip_exit_collection()
        if code in INTERRUPTED:  # and its exit too (threads joined) ends in time
            from mountcal.core.atomic import Deadline

            Deadline().arm(code)
    return code


def _run(args: list[str]) -> int:
    try:
        if _local_fleet(args):
            from mountcal.fleet.engines import start_worker_server

            start_worker_server()
        from mountcal.cli import main as run

        return run(args)  # handles Ctrl-C itself once the command runs
    except KeyboardInterrupt:  # Ctrl-C while starting up or parsing: nothing was read or written yet
        sys.stderr.write("mountcal: interrupted; no output was written\n")
        return 130


def _skip_exit_collection() -> None:
    """Spare the process CPython's full garbage collections at exit.

    Every object alive now goes to the collector's permanent generation, which the collections run
    while the interpreter ends skip; memory goes back to the system with the process. After a fleet
    run (pandas, pyarrow and Dask loaded) those collections took 0.25-0.35 s, serial time at the end
    of every run; now ~0.03 s. The commands close their own files and remove their temporary ones
    before they return, so nothing waits for a collection to be flushed or deleted. Only for the
    process's own entry point: a caller that runs :func:`main` in-process (the tests) keeps its
    collector.
    """
    gc.freeze()


def _local_fleet(args: list[str]) -> bool:
    """Whether the arguments ask for a fleet run on local workers (not --scheduler, not --help)."""
    return (
        bool(args)
        and args[0] == "fleet"
        and not any(a.startswith("--scheduler") or a in ("-h", "--help") for a in args[1:])
    )


if __name__ == "__main__":
    sys.exit(main())
