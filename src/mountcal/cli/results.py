"""The two streams of a command: results on stdout, only when asked; everything else on stderr.

stdout carries a command's results and nothing else (``-o -``, ``--json``, and ``export`` without
``-o``): what libraries print goes to stderr.

asammdf prints the tracebacks of errors it recovers from with ``print()``, python-can and cantools
warn, matplotlib and plugins may print: on stdout any of it would corrupt ``--json``, ``-o -`` or a
pipe. So while a command runs (:func:`results_only`, entered once in :func:`mountcal.cli.main`),
``sys.stdout`` is ``sys.stderr`` and, when it is the process's own stdout, file descriptor 1 is a
copy of 2 (output of C code and of child processes too); Python warnings and the records of
other libraries' loggers become ``mountcal:`` lines of the log on stderr. A command writes its
results through :func:`result_stream`, the private handle of the real stdout.

On stderr a command says its summary once, through :func:`say`: the answer in one line first
(kept by ``-q``), then what supports it, then its notes, each line once. Status lines and
warnings logged before the answer (what was read, found, used, doubted) are held and follow it,
so the first line a person reads is the answer; errors, and lines logged with ``extra={"now":
True}`` (a live session's events), are shown at once.

stderr may lose its reader while a command runs (``2>&1 | head`` once head has ended): what is
still written there then goes to /dev/null (:func:`unread_stderr_tolerated`), and the command goes
on to write its results — a status line or a progress bar must not end it with exit 0 and no file.
"""

from __future__ import annotations

import io
import logging
import os
import sys
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import TextIO

from mountcal.core.paths import SystemFailure

_results: list[TextIO | None] = []  # the result handles of the commands running (innermost last)

ANSWER = logging.INFO + 5  # the level of a command's answer line: shown by default and with -q, not with -qq
logging.addLevelName(ANSWER, "ANSWER")
log = logging.getLogger("mountcal")


@dataclass
class _Said:
    """What one running command has said on stderr: its answer (once), the lines shown, the records held."""

    answered: bool = False
    lines: set[str] = field(default_factory=set)
    held: list[tuple[Callable[[logging.LogRecord], None], logging.LogRecord]] = field(default_factory=list)


_said: list[_Said] = []  # one per running command (innermost last)


def say(answer: str, details: Iterable[str] = (), notes: Iterable[str] = ()) -> None:
    """The command's summary on stderr: ``answer`` in one line, then ``details`` (what supports it, with the
    status lines held until now), then ``notes``; a line already shown by this command is not shown again.

    ``-q`` keeps the answer alone; ``-qq`` drops it too.
    """
    if "\n" in answer:
        raise ValueError(f"an answer is one line: {answer!r}")
    state = _said[-1] if _said else None
    if state is not None and state.answered:
        raise RuntimeError(f"a command answers once: {answer!r}")
    log.log(ANSWER, "%s", answer, extra={"plain": True, "now": True})
    if state is not None:
        state.answered = True
        release()
    for line in [*(f"  {d}" for d in details), *(f"  note: {n}" for n in notes)]:
        if state is not None:
            if line.strip() in state.lines:
                continue
            state.lines.add(line.strip())
        log.info("%s", line, extra={"plain": True})


def held(write: Callable[[logging.LogRecord], None], record: logging.LogRecord) -> bool:
    """Whether ``record`` (a status line) waits for the running command's answer; a record shown counts as said."""
    if not _said:
        return False
    state = _said[-1]
    if not state.answered and record.levelno < logging.ERROR and not getattr(record, "now", False):
        state.held.append((write, record))
        return True
    state.lines.add(record.getMessage().strip())
    return False


def release() -> None:
    """Show the status lines held for the answer (after it, or at the command's end when it gave none)."""
    if not _said:
        return
    state = _said[-1]
    state.answered = True  # from here on, lines are shown as they come
    waiting, state.held = state.held, []
    for write, record in waiting:
        text = record.getMessage().strip()
        if text in state.lines:
            continue
        state.lines.add(text)
        if record.levelno == logging.INFO and record.name.startswith("mountcal") and not getattr(record, "plain", 0):
            # a status line logged before the answer: one of the lines that support it, below it
            record = logging.makeLogRecord(record.__dict__ | {"msg": f"  {text}", "args": (), "plain": True})
        write(record)


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


class _UnreadTolerated:
    """``sys.stderr`` while a command runs: the same stream, but a write or flush that finds its reader
    gone (EPIPE) points the descriptor at /dev/null and goes on instead of raising."""

    def __init__(self, stream: TextIO) -> None:
        self._stream = stream

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            self._discard()
            return len(text)

    def flush(self) -> None:
        try:
            self._stream.flush()
        except BrokenPipeError:
            self._discard()

    def _discard(self) -> None:
        try:
            fd = self._stream.fileno()
        except (OSError, ValueError):  # not a file (a test's capture): nothing reaches a reader anyway
            return
        null = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(null, fd)
        finally:
            os.close(null)

    def __getattr__(self, name: str) -> object:
        return getattr(self._stream, name)


@contextmanager
def unread_stderr_tolerated() -> Iterator[None]:
    """``sys.stderr`` for the body: once nobody reads it, what follows goes to /dev/null (module docstring)."""
    original = sys.stderr
    sys.stderr = _UnreadTolerated(original)
    try:
        yield
    finally:
        sys.stderr = original


@contextmanager
def results_only() -> Iterator[TextIO | None]:
    """Send everything but the results to stderr while the body runs; yield the results' handle."""
    original = sys.stdout
    results, saved_fd = _private_stdout(original)
    _results.append(results)
    _said.append(_Said())
    sys.stdout = sys.stderr
    logging.captureWarnings(True)
    try:
        yield results
    finally:
        logging.captureWarnings(False)
        try:
            release()  # a command that ended without an answer (an error, Ctrl-C) still shows its status
        finally:
            _said.pop()
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


__all__ = ["ANSWER", "held", "release", "result_stream", "results_only", "say"]
