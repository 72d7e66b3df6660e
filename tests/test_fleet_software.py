"""One mountcal across the Dask seam: a fleet's results are keyed by the command's mountcal version,
so a scheduler that cannot import it, or workers that run another version, are refused — at connect
time, and per record for a worker that joins later — and nothing they computed is stored.

Real schedulers and workers started by Dask's own code; "another version" is another installed
distribution's metadata ahead on the worker's path (what a second install looks like to it).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pandas as pd
import pytest
from tests.dask_processes import Cluster

from mountcal.core.version import software_version
from mountcal.simulate.stops import simulate_stops
from mountcal.stops.table import write_stop_table

pytest.importorskip("distributed")
REPO = Path(__file__).resolve().parents[1]
# a scheduler whose Python cannot import a package (an image built without it): sys.argv[1]
SCHEDULER_WITHOUT = """
import sys
missing = sys.argv.pop(1)
class Without:
    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] == missing:
            raise ModuleNotFoundError(f"No module named {name!r}")
sys.meta_path.insert(0, Without())
from distributed.cli.dask_scheduler import main
sys.argv = ["dask-scheduler", *sys.argv[1:]]
main()
"""


def _stop_tables(folder: Path, n: int) -> Path:
    folder.mkdir(parents=True)
    for i in range(n):
        table, _ = simulate_stops(5.0, 6.0, 7.0, noise_g=0.001, seed=i)
        write_stop_table(table, folder / f"log_{i:02d}.csv")
    return folder


def _other_version(tmp_path: Path) -> dict[str, str]:
    """The environment of a worker whose installed mountcal says it is version 99.0."""
    dist = tmp_path / "other" / "mountcal-99.0.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: mountcal\nVersion: 99.0\n")
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(dist.parent), str(REPO / "src")])}


@pytest.fixture
def cluster(tmp_path: Path) -> Iterator[Cluster]:
    started = Cluster(tmp_path)
    try:
        yield started
    finally:
        started.close()


def _outputs(output: Path) -> list[str]:
    """What a fleet run wrote beside its output (its lock file aside)."""
    return sorted(p.name for p in output.parent.glob("*") if p.name != f".{output.name}.lock")


def _fleet(logs: Path, output: Path, address: str) -> subprocess.CompletedProcess[str]:
    command = [sys.executable, "-m", "mountcal", "fleet", str(logs), "-o", str(output), "--scheduler", address]
    env = {**os.environ, "PYTHONPATH": str(REPO / "src")}
    return subprocess.run(command, capture_output=True, text=True, env=env, timeout=300)


@pytest.mark.parametrize("missing", ["mountcal", "pandas"])
def test_a_scheduler_that_cannot_import_mountcal_is_refused_at_once(tmp_path: Path, missing: str) -> None:
    """Without mountcal, or with mountcal but without a package its jobs need (pandas)."""
    started = Cluster(tmp_path, [sys.executable, "-c", SCHEDULER_WITHOUT, missing])
    try:
        started.add_worker()
        output = tmp_path / "out" / "fleet.parquet"
        done = _fleet(_stop_tables(tmp_path / "logs", 2), output, started.address)
    finally:
        started.close()
    assert done.returncode == 2, done.stderr
    message = done.stderr
    assert f"--scheduler {started.address}" in message and "scheduler that imports mountcal" in message, message
    assert f"No module named '{missing}" in message and f"Install mountcal {software_version()}" in message, message
    assert "Traceback" not in message
    assert not _outputs(output)


def test_workers_of_another_mountcal_version_are_refused_at_once(tmp_path: Path, cluster: Cluster) -> None:
    cluster.add_worker(_other_version(tmp_path))
    output = tmp_path / "out" / "fleet.parquet"
    done = _fleet(_stop_tables(tmp_path / "logs", 2), output, cluster.address)
    assert done.returncode == 2, done.stderr
    assert f"expected mountcal {software_version()} on every Dask worker" in done.stderr, done.stderr
    assert "found mountcal 99.0 on tcp://" in done.stderr and "Traceback" not in done.stderr
    assert not _outputs(output)


def test_a_worker_of_another_version_that_joins_later_stores_nothing(tmp_path: Path, cluster: Cluster) -> None:
    """No worker when the command connects (nothing to refuse yet); one of another version joins:
    each of its records is a failed row that is not stored, and the next run on a right worker
    calibrates every log afresh."""
    logs = _stop_tables(tmp_path / "logs", 3)
    output = tmp_path / "out" / "fleet.parquet"
    env = {**os.environ, "PYTHONPATH": str(REPO / "src")}
    command = [sys.executable, "-m", "mountcal", "fleet", str(logs), "-o", str(output), "--scheduler", cluster.address]
    run = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    time.sleep(3.0)  # connected, its first tasks waiting for a worker
    cluster.add_worker(_other_version(tmp_path), wait=False)
    _, stderr = run.communicate(timeout=300)
    assert run.returncode == 0, stderr
    table = pd.read_parquet(output)
    assert list(table["status"]) == ["failed"] * 3, table[["log", "status", "error"]]
    assert set(table["error_type"]) == {"VersionMismatch"}
    assert all("found it calibrated by mountcal 99.0" in e for e in table["error"]), table["error"].tolist()
    assert not any((output.parent / "fleet.parquet.parts").glob("*.json"))

    cluster.close()
    right = Cluster(tmp_path / "again")
    try:
        right.add_worker()
        again = _fleet(logs, output, right.address)
    finally:
        right.close()
    assert again.returncode == 0, again.stderr
    table = pd.read_parquet(output)
    assert list(table["status"]) == ["ok"] * 3, table[["log", "status", "error"]]
    assert set(table["mountcal_version"]) == {software_version()}
