"""stdout holds the results alone: what asammdf, python-can, cantools, matplotlib or a plugin print
while a command runs lands on stderr, so ``--json`` and ``-o -`` stay parseable (issue 27, item 4).

Each command runs in its own process, as a user runs it: the protection is at the level of file
descriptors, which an in-process capture would not show.
"""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from mountcal.simulate.stops import simulate_parking_log

REPO = Path(__file__).resolve().parents[1]
SRC = REPO / "src"
DATA = REPO / "data"
DBC = DATA / "imu_mm5_10.dbc"

# A reader plugin that makes noise the three ways a library can: print(), a write to file
# descriptor 1 (C code, a child process) and a Python warning; then it reads the log as a table.
NOISY = """
import os
import warnings
from pathlib import Path

from mountcal.io.reader import LogReader
from mountcal.io.table.read import read_table

print("NOISE AT IMPORT")


class NoisyReader(LogReader):
    name = "noisy"
    suffixes = (".noisy",)
    description = "a table that prints"

    def read(self, path, options):
        print("NOISE FROM print()")
        os.write(1, b"NOISE ON FD 1\\n")
        warnings.warn("NOISE AS A WARNING", UserWarning, stacklevel=1)
        copy = path.with_suffix(".parquet")
        copy.write_bytes(path.read_bytes())
        return read_table(copy)
"""


def run(*args: str | Path, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    environ = {**os.environ, "PYTHONPATH": str(SRC), **(env or {})}
    return subprocess.run(
        [sys.executable, "-m", "mountcal", *map(str, args)],
        env=environ,
        capture_output=True,
        text=True,
        timeout=600,
    )


@pytest.fixture(scope="module")
def parking_mf4_cut(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """data/parking.mf4 without its last 360 bytes (its attachment block: asammdf prints two tracebacks)."""
    path = tmp_path_factory.mktemp("cut") / "parking.mf4"
    data = (DATA / "parking.mf4").read_bytes()
    path.write_bytes(data[:-360])
    return path


def test_an_mf4_missing_its_last_bytes_is_refused_with_the_byte_where_it_ends(parking_mf4_cut: Path) -> None:
    size = parking_mf4_cut.stat().st_size
    for args in (
        ("inspect", parking_mf4_cut, "--json", "--dbc", DBC),
        ("calibrate", parking_mf4_cut, "--json", "--dbc", DBC),
        ("stops", parking_mf4_cut, "-o", "-", "--dbc", DBC),
    ):
        done = run(*args)
        assert done.returncode == 2, (args, done.stderr)
        assert done.stdout == "", args
        assert "Traceback" not in done.stderr
        assert f"ends at byte {size}" in done.stderr, done.stderr
        assert "--allow-truncated" in done.stderr


def test_with_allow_truncated_stdout_parses_and_the_library_noise_is_not_shown(parking_mf4_cut: Path) -> None:
    inspected = run("inspect", parking_mf4_cut, "--json", "--dbc", DBC, "--allow-truncated")
    assert inspected.returncode == 0, inspected.stderr
    listing = json.loads(inspected.stdout)
    assert listing["streams"] and listing["incomplete"], listing
    # asammdf prints the traceback of an error it recovers from while finalising the cut file: captured where
    # the MF4 is opened (mountcal.io.can.mf4), neither on stdout nor on stderr; the cut is said instead
    assert "Traceback" not in inspected.stderr + inspected.stdout and "read in part" in inspected.stderr

    calibrated = run("calibrate", parking_mf4_cut, "--json", "--dbc", DBC, "--allow-truncated")
    assert calibrated.returncode == 0, calibrated.stderr
    result = json.loads(calibrated.stdout)
    assert result["provenance"]["incomplete_inputs"], result["provenance"]
    assert "Traceback" not in calibrated.stdout

    stops = run("stops", parking_mf4_cut, "-o", "-", "--dbc", DBC, "--allow-truncated")
    assert stops.returncode == 0, stops.stderr
    table = pd.read_csv(io.StringIO(stops.stdout))
    assert len(table) >= 8 and {"ax", "ay", "az"} <= set(table.columns)


def test_a_plugin_printing_warning_and_writing_to_fd_1_leaves_stdout_to_the_result(tmp_path: Path) -> None:
    site = tmp_path / "site"
    site.mkdir()
    (site / "noisy_reader.py").write_text(NOISY, encoding="utf-8")
    info = site / "noisy_reader-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: noisy_reader\nVersion: 1.0\n", encoding="utf-8")
    (info / "entry_points.txt").write_text("[mountcal.readers]\nnoisy = noisy_reader:NoisyReader\n", encoding="utf-8")
    env = {"PYTHONPATH": os.pathsep.join([str(SRC), str(site)])}
    log = tmp_path / "drive.noisy"
    parked = simulate_parking_log(seed=1, stop_s=20.0, rate_hz=50.0)
    table = {"t_s": parked.t_s, **dict(zip(("ax", "ay", "az"), parked.acc_s.T, strict=True))}
    pd.DataFrame(table).to_parquet(log)
    for args in (("inspect", log, "--json"), ("calibrate", log, "--json")):
        done = run(*args, env=env)
        assert "NOISE" not in done.stdout, (args, done.stdout)
        for noise in ("NOISE AT IMPORT", "NOISE FROM print()", "NOISE ON FD 1", "NOISE AS A WARNING"):
            assert noise in done.stderr, (args, noise, done.stderr)
        if done.returncode == 0:
            json.loads(done.stdout)
        else:
            assert done.stdout == "", args
