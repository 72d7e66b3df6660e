"""A plain-text progress line on stderr: logs done, failed, remaining, rate and ETA.

On a terminal the line is redrawn in place with ``\\r`` (at most :data:`TTY_PERIOD_S` apart);
elsewhere (a CI log, a file) a full line is written at most every :data:`PIPE_PERIOD_S`.
"""

from __future__ import annotations

import sys
import time
from typing import TextIO

TTY_PERIOD_S = 0.1
PIPE_PERIOD_S = 10.0


class Progress:
    """Counts finished logs and draws the progress line.

    Parameters
    ----------
    total : int
        Logs of the run.
    stream : text stream, optional
        Default ``sys.stderr``.
    enabled : bool
    """

    def __init__(self, total: int, stream: TextIO | None = None, enabled: bool = True) -> None:
        self.total = total
        self.done = self.failed = self.reused = 0
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.started = time.monotonic()
        self._last_draw = -float("inf")
        self._width = 0

    def update(self, ok: bool) -> None:
        """Count one log finished by this run."""
        self.done += 1
        self.failed += 0 if ok else 1
        self._draw(final=False)

    def reuse(self) -> None:
        """Count one log whose result is already known: stored by an earlier run, or the same files
        and options as a log of this run (not in the rate)."""
        self.reused += 1
        self._draw(final=False)

    def finish(self) -> None:
        """Draw the last state and end the line."""
        self._draw(final=True)

    def line(self) -> str:
        """The progress text."""
        elapsed = time.monotonic() - self.started
        left = self.total - self.done - self.reused
        rate = self.done / elapsed if elapsed > 0 else 0.0
        eta = "0:00:00" if left <= 0 else (_clock(left / rate) if rate > 0 else "?")
        reused = f", {self.reused} reused" if self.reused else ""
        return (
            f"fleet: {self.done + self.reused}/{self.total} logs done ({self.failed} failed{reused}), "
            f"{left} remaining, {rate:.2f} logs/s, ETA {eta}"
        )

    def _draw(self, final: bool) -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        period = TTY_PERIOD_S if self.tty else PIPE_PERIOD_S
        if not final and now - self._last_draw < period:
            return
        self._last_draw = now
        text = self.line()
        if self.tty:
            pad = max(self._width - len(text), 0)
            self._width = len(text)
            self.stream.write("\r" + text + " " * pad + ("\n" if final else ""))
        else:
            self.stream.write(text + "\n")
        self.stream.flush()


def _clock(seconds: float) -> str:
    s = round(seconds)
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}"
