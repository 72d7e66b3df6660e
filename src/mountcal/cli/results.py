"""stdout carries a command's results and nothing else: what libraries print goes to stderr.

asammdf prints the tracebacks of errors it recovers from with ``print()``, python-can and cantools
warn, matplotlib and plugins may print: on stdout any of it would corrupt ``--json``, ``-o -`` or a
pipe. So while a command runs (:func:`results_only`, entered once in :func:`mountcal.cli.main`),
``sys.stdout`` is ``sys.stderr`` and, when it is the process's own stdout, file descriptor 1 is a
copy of 2 (output of C code and of child processes too); Python warnings and the records of
other libraries' loggers become ``mountcal:`` lines of the log on stderr. A command writes its
results through :func:`result_stream`, the private handle of the real stdout.
"""

from __future__ import annotations

import io
import logging
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TextIO

from mountcal.core.paths import SystemFailure

_results: list[TextIO | None] = []  # the result handles of the commands running (innermost last)


def result_stream() -> TextIO:
    """Where the running command writes its results (the real stdout; sys.stdout outside a command).

    Raises
    ------
    SystemFailure
        The process has no stdout (started with it closed, ``>&-``).
    """
    stream = _results[-1] if _results else sys.stdout
    if stream is None:
        err = OSError(9, "the standard output is closed")
        raise SystemFailure("stdout", "writing the result (name a file with -o instead)", err)
    return stream


@contextmanager
def results_only() -> Iterator[TextIO | None]:
    """Send everything but the results to stderr while the body runs; yield the results' handle."""
    original = sys.stdout
    results, saved_fd = _private_stdout(original)
    _results.append(results)
    sys.stdout = sys.stderr
    logging.captureWarnings(True)
    try:
        yield results
    finally:
        logging.captureWarnings(False)
        sys.stdout = original
        _results.pop()
        if saved_fd is not None and results is not None:
            try:
                results.flush()  # a closed pipe (`| head`) raises here, after the restore below
            finally:
                os.dup2(saved_fd, 1)
                try:
                    results.close()
                except OSError:
                    pass


def _private_stdout(stream: TextIO | None) -> tuple[TextIO | None, int | None]:
    """A handle of the real stdout, and the descriptor it was copied to when fd 1 was moved to stderr.

    Only the process's own stdout (fd 1) is moved; a stream put in its place (a test's capture, a
    notebook) is used as it is.
    """
    real = sys.__stdout__
    if stream is None or real is None or stream is not real:
        return stream, None
    try:
        if real.fileno() != 1:
            return stream, None
        real.flush()
        saved = os.dup(1)
    except (OSError, ValueError):  # no descriptor (closed, or not a real file)
        return stream, None
    try:
        os.dup2(2, 1)
    except OSError:  # no stderr to point at: leave stdout where it is
        os.close(saved)
        return stream, None
    handle = io.TextIOWrapper(
        open(saved, "wb", closefd=True),  # closed with the wrapper, by results_only
        encoding=real.encoding,
        errors="backslashreplace",  # a character the terminal's encoding lacks: shown escaped, not a traceback
        line_buffering=real.line_buffering,
    )
    return handle, saved


__all__ = ["result_stream", "results_only"]
