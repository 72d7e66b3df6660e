"""A real Dask cluster for tests: `dask scheduler` and `dask worker` processes started by Dask's own
CLI (or a given scheduler command), each in its own session, all ended by :meth:`Cluster.close`."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

DASK = Path(sys.executable).with_name("dask")


class Cluster:
    """A scheduler (its address read from its scheduler file) and the workers added to it."""

    def __init__(
        self, folder: Path, scheduler: Sequence[str] | None = None, env: Mapping[str, str] = os.environ
    ) -> None:
        self.started: list[subprocess.Popen[bytes]] = []
        folder.mkdir(parents=True, exist_ok=True)
        scheduler_file = folder / "scheduler.json"
        command = [*(scheduler or [str(DASK), "scheduler"]), "--port", "0", "--no-dashboard"]
        self._start([*command, "--scheduler-file", str(scheduler_file)], env)
        deadline = time.monotonic() + 60
        while not scheduler_file.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        self.address: str = json.loads(scheduler_file.read_text())["address"]

    def _start(self, command: list[str], env: Mapping[str, str]) -> None:
        self.started.append(
            subprocess.Popen(
                command, env=dict(env), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True
            )
        )

    def add_worker(
        self, env: Mapping[str, str] = os.environ, wait: bool = True, arguments: Sequence[str] | None = None
    ) -> None:
        """``dask worker ARGUMENTS --no-dashboard`` (by default one single-threaded worker of this
        scheduler); ``wait``: until the scheduler sees a worker per worker command started."""
        words = arguments or ["worker", self.address, "--nthreads", "1"]
        self._start([str(DASK), *words, "--no-dashboard"], env)
        if wait:
            from distributed import Client

            with Client(self.address, timeout=60) as client:
                client.wait_for_workers(len(self.started) - 1, timeout=60)

    def close(self) -> None:
        for proc in reversed(self.started):
            os.killpg(proc.pid, signal.SIGTERM)
            proc.wait(30)
        self.started.clear()
