"""The fleet's progress bar on stderr (tqdm): logs done of the total, failed, reused, rate and ETA.

On a terminal the bar is redrawn in place; elsewhere (a CI log, a file) at most every
:data:`PIPE_PERIOD_S`.
"""

from __future__ import annotations

import sys
from typing import TextIO

from tqdm import tqdm

PIPE_PERIOD_S = 10.0


class Progress:
    """Counts finished logs and draws the bar.

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
        self.done = self.failed = self.reused = self._workers = 0
        stream = stream if stream is not None else sys.stderr
        tty = bool(getattr(stream, "isatty", lambda: False)())
        self.bar = tqdm(
            total=total,
            desc="mountcal: fleet",
            unit="log",
            file=stream,
            disable=not enabled,
            mininterval=0.1 if tty else PIPE_PERIOD_S,
        )

    def update(self, ok: bool) -> None:
        """Count one log finished by this run."""
        self.done += 1
        self.failed += 0 if ok else 1
        self._step()

    def reuse(self) -> None:
        """Count one log whose result is already known: stored by an earlier run, or the same files
        and options as a log of this run."""
        self.reused += 1
        self._step()

    def finish(self) -> None:
        """Draw the last state and end the line."""
        self.bar.close()

    def workers(self, n: int) -> None:
        """Show the cluster's workers now (a Dask cluster may grow or shrink during the run)."""
        if n and n != self._workers:
            self._workers = n
            self.bar.set_description_str(f"mountcal: fleet on {n} Dask worker{'s' if n > 1 else ''}", refresh=False)

    def _step(self) -> None:
        self.bar.set_postfix_str(f"{self.failed} failed, {self.reused} reused", refresh=False)
        self.bar.update(1)
