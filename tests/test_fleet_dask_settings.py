"""The Dask settings docs/fleet.md gives for fleets: the engine's own, read by Dask as written, and
a cluster started without them is told so (a real scheduler and worker, started by Dask's CLI)."""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from tests.dask_processes import Cluster

from mountcal.fleet.dask_cluster import FLEET_DASK_CONFIG
from mountcal.fleet.engines import DaskEngine

pytest.importorskip("distributed")
REPO = Path(__file__).resolve().parents[1]


def documented_section() -> str:
    """docs/fleet.md from its "Dask settings for fleets" heading on."""
    return (REPO / "docs" / "fleet.md").read_text().split("### Dask settings for fleets", 1)[1]


def documented_environment() -> dict[str, str]:
    block = re.search(r"```sh\n(.*?)```", documented_section(), re.S)
    assert block, "docs/fleet.md: no ```sh block under 'Dask settings for fleets'"
    return dict(re.findall(r"^export (DASK_\w+)=(\S+)$", block.group(1), re.M))


def documented_worker_arguments(address: str) -> list[str]:
    """The `dask worker` command docs/fleet.md shows, for this scheduler (its address replaced)."""
    (line,) = re.findall(r"^dask worker .*$", documented_section(), re.M)
    words = shlex.split(line)[1:]
    return [address if w.startswith("tcp://") else w for w in words]


def test_the_documented_settings_are_the_engines_and_dask_reads_them_as_written() -> None:
    env = documented_environment()
    assert len(env) == len(FLEET_DASK_CONFIG)
    read = subprocess.run(
        [
            sys.executable,
            "-c",
            f"import dask, json; print(json.dumps({{k: dask.config.get(k) for k in {list(FLEET_DASK_CONFIG)!r}}}))",
        ],
        env={**os.environ, **env},
        capture_output=True,
        text=True,
        check=True,
    )
    assert json.loads(read.stdout) == FLEET_DASK_CONFIG


@pytest.fixture
def documented_cluster(tmp_path: Path) -> Iterator[str]:
    """`dask scheduler` and `dask worker` started as docs/fleet.md starts them (with a scheduler file for the port)."""
    env = {**os.environ, **documented_environment()}
    cluster = Cluster(tmp_path, env=env)
    try:
        cluster.add_worker(env, arguments=documented_worker_arguments(cluster.address))
        yield cluster.address
    finally:
        cluster.close()


def test_a_cluster_started_as_documented_draws_no_note(documented_cluster: str) -> None:
    with DaskEngine(documented_cluster) as engine:
        engine.start()
        assert engine.notes == ()


def test_a_cluster_on_dask_defaults_is_told_which_settings_slow_a_fleet() -> None:
    from distributed import LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster:
        with DaskEngine(cluster.scheduler_address) as engine:
            engine.start()
            (note,) = engine.notes
    assert "worker.profile.enabled (True)" in note and "docs/fleet.md" in note, note
    assert "1 of 1 Dask workers have not imported mountcal" in note and "--preload mountcal.fleet.worker" in note
