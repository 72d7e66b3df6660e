"""A log format added by one new file: a plugin reader found through the entry-point group
``mountcal.readers`` and used by the real command line — calibrate, rotate and fleet — with no
other edit. The plugin is installed the way pip leaves a package: a module and a ``*.dist-info``
folder (METADATA, entry_points.txt) on the path."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from mountcal.apply.rotate import acc_to_vehicle
from mountcal.core.result import Calibration
from mountcal.io.writers import write_protocol
from mountcal.simulate.stops import ParkingLog, simulate_parking_log

SRC = Path(__file__).resolve().parents[2] / "src"
TRUTH = (4.0, -3.0, 25.0)

# The one new file: an invented text format, "t ax ay az gx gy gz" per line (s, m/s², rad/s).
PLUGIN = '''
"""IMU text logs: one sample per line, t ax ay az gx gy gz (s, m/s^2, rad/s); # starts a comment."""

from pathlib import Path

import numpy as np

from mountcal.core.errors import InputError
from mountcal.io.reader import LogReader
from mountcal.io.samples import Samples


class ImuTxtReader(LogReader):
    name = "imutxt"
    suffixes = (".imutxt",)
    description = "IMU text (t ax ay az gx gy gz)"

    def read(self, path: Path, options: object) -> Samples:
        try:
            rows = np.loadtxt(path, comments="#", ndmin=2)
        except (OSError, ValueError) as err:
            raise InputError(str(path), "lines of 7 numbers", str(err), "Check the file.") from err
        if rows.shape[1] != 7:
            raise InputError(str(path), "lines of 7 numbers", f"{rows.shape[1]} per line", "Check the file.")
        return Samples(rows[:, 0], rows[:, 1:4], rows[:, 4:7], source=str(path))
'''


def install(folder: Path, module: str, source: str, entry: str) -> dict[str, str]:
    """``module.py`` and its distribution's metadata in ``folder``; the environment that sees them."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{module}.py").write_text(source, encoding="utf-8")
    info = folder / f"{module}-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {module}\nVersion: 1.0\n", encoding="utf-8")
    (info / "entry_points.txt").write_text(f"[mountcal.readers]\nimutxt = {entry}\n", encoding="utf-8")
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(SRC), str(folder)])}


def mountcal(env: dict[str, str], *args: str | Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "mountcal", *map(str, args)], env=env, capture_output=True, text=True, timeout=600
    )


def write_imutxt(path: Path, log: ParkingLog) -> None:
    rows = np.column_stack([log.t_s, log.acc_s, log.gyro_s])
    np.savetxt(path, rows, fmt="%.9g", header="t ax ay az gx gy gz")
    write_protocol(path.with_name(path.stem + ".protocol.csv"), log, start_time_s=0.0)


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict[str, str], Path, ParkingLog]:
    root = tmp_path_factory.mktemp("plugin")
    env = install(root / "site", "mountcal_imutxt", PLUGIN, "mountcal_imutxt:ImuTxtReader")
    log = simulate_parking_log(
        *TRUTH, beta_deg=tuple(range(0, 360, 45)), stop_s=20.0, drive_s=10.0, rate_hz=50.0, seed=3
    )
    folder = root / "car_7"
    folder.mkdir()
    write_imutxt(folder / "session.imutxt", log)
    return env, folder / "session.imutxt", log


def test_calibrate_and_rotate_read_the_plugin_format(session: tuple[dict[str, str], Path, ParkingLog]) -> None:
    env, log_path, log = session
    result = log_path.with_name("result.json")
    done = mountcal(env, "calibrate", log_path, "--protocol", log_path.with_name("session.protocol.csv"), "-o", result)
    assert done.returncode == 0, done.stderr
    cal = Calibration.load(result)
    for value, sigma, truth in (
        (cal.roll_deg, cal.roll_sigma_deg, TRUTH[0]),
        (cal.pitch_deg, cal.pitch_sigma_deg, TRUTH[1]),
        (cal.yaw_deg, cal.yaw_sigma_deg, TRUTH[2]),
    ):
        assert value is not None and sigma is not None and abs(value - truth) < 5 * sigma + 0.01

    rotated = log_path.with_name("rotated.parquet")
    done = mountcal(env, "rotate", log_path, "--calibration", result, "-o", rotated)
    assert done.returncode == 0, done.stderr
    table = pd.read_parquet(rotated)
    assert len(table) == log.t_s.size
    np.testing.assert_allclose(table["t_s"], log.t_s, atol=1e-6)
    # the same rotation as the library applies to the simulated samples themselves
    np.testing.assert_allclose(table[["ax", "ay", "az"]], acc_to_vehicle(log.acc_s, cal), atol=1e-6)
    parked = np.abs(log.speed_mps) < 1e-6
    assert abs(float(np.median(table["az"][parked])) - 9.80665) < 0.05  # gravity on the vehicle's z


def test_fleet_finds_and_reads_the_plugin_format(session: tuple[dict[str, str], Path, ParkingLog]) -> None:
    env, log_path, _ = session
    output = log_path.parent.parent / "fleet.parquet"
    done = mountcal(env, "fleet", log_path.parent, "-o", output, "-q", "--workers", "1")
    assert done.returncode == 0, done.stderr
    logs = pd.read_parquet(output)
    assert list(logs["log"].map(lambda p: Path(p).name)) == ["session.imutxt"]
    row = logs.iloc[0]
    assert row["status"] == "ok" and row["vehicle_id"] == "car_7" and row["n_stops"] == 8
    assert row["heading_source"] == "protocol sheet"
    assert abs(row["yaw_deg"] - TRUTH[2]) < 5 * row["yaw_sigma_deg"] + 0.01


def test_a_broken_plugin_is_named_not_a_traceback(
    tmp_path: Path, session: tuple[dict[str, str], Path, ParkingLog]
) -> None:
    _, log_path, _ = session
    env = install(tmp_path, "mountcal_broken", "raise ImportError('needs libfoo')\n", "mountcal_broken:Reader")
    done = mountcal(env, "inspect", log_path)
    assert done.returncode != 0 and "Traceback" not in done.stderr
    assert "mountcal_broken" in done.stderr and "needs libfoo" in done.stderr
    # the built-in formats still read: plugins are loaded only for a path no built-in reader claims
    table = tmp_path / "samples.csv"
    pd.DataFrame({"t_s": [0.0, 0.01], "ax": [0.0, 0.0], "ay": [0.0, 0.0], "az": [9.8, 9.8]}).to_csv(table, index=False)
    done = mountcal(env, "inspect", table)
    assert done.returncode == 0 and "Traceback" not in done.stderr and "mountcal_broken" not in done.stderr


def test_the_registry_picks_readers_by_path_and_options(tmp_path: Path) -> None:
    from mountcal.core.errors import InputError
    from mountcal.io.reader import LogOptions
    from mountcal.io.registry import reader_for

    plain, with_dbc = LogOptions(), LogOptions(dbc="x.dbc")
    assert reader_for(Path("a.mcap"), plain).name == "mcap"
    assert reader_for(Path("a.BLF"), plain).name == "can"  # listed without a DBC; read with one
    assert reader_for(Path("a.csv"), plain).name == "table"
    assert reader_for(Path("a.csv"), with_dbc).name == "can"
    segment = tmp_path / "seg" / "processed_log" / "IMU" / "accelerometer"
    segment.mkdir(parents=True)
    assert reader_for(tmp_path / "seg", plain).name == "comma2k19"
    with pytest.raises(InputError, match=r"\(\.mcap\).*found a file ending in \.xyz"):
        reader_for(Path("a.xyz"), plain)


def test_the_can_readers_gravity_is_the_conventions() -> None:
    from mountcal.core.conventions import G_N
    from mountcal.io.can import signals

    assert signals.G_N == G_N and signals.si_scale("ax", "g") == (G_N, 0.0)


def test_the_log_front_loads_no_numerical_library() -> None:
    code = (
        "import sys, mountcal.io.logs, mountcal.io.registry\n"
        "print(sorted(m for m in ('numpy', 'pandas', 'scipy') if m in sys.modules))"
    )
    env = {**os.environ, "PYTHONPATH": str(SRC)}
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]"


# ------------------------------------------------------------------ plugins isolated (issue 27)

READ = "    def read(self, path: Path, options: object) -> Samples:\n"
RAISING = PLUGIN.replace(READ, READ + "        raise {error}\n")
CLAIMING = (
    PLUGIN
    + """

class Claimer(ImuTxtReader):
    def claims(self, path, options):
        raise {error}
"""
)


def _stop_table(folder: Path) -> Path:
    """A stop table a built-in reader reads (so a fleet has a log besides the plugin's)."""
    from mountcal.cli import main

    path = folder / "car_1" / "stops.csv"
    assert main(["simulate", "-o", str(path), "--seed", "2"]) == 0
    return path


@pytest.mark.parametrize("at_import", ["import sys; sys.exit(0)", "raise KeyboardInterrupt", "raise SystemExit(3)"])
def test_a_plugin_that_exits_or_interrupts_at_import_is_named_and_nothing_else_stops(
    tmp_path: Path, session: tuple[dict[str, str], Path, ParkingLog], at_import: str
) -> None:
    _, log_path, _ = session
    env = install(tmp_path / "site", "mountcal_exits", at_import + "\n", "mountcal_exits:Reader")
    result = tmp_path / "result.json"
    done = mountcal(env, "calibrate", log_path, "-o", result)  # only a plugin could read .imutxt: plugins load
    assert done.returncode == 2 and not result.exists(), done.stderr
    assert "mountcal_exits" in done.stderr and "Traceback" not in done.stderr
    assert ("SystemExit" if "xit" in at_import else "KeyboardInterrupt") in done.stderr
    stops = _stop_table(tmp_path / "fleet")
    done = mountcal(env, "fleet", stops.parent.parent, "-o", tmp_path / "fleet.parquet", "--workers", "1", "-q")
    assert done.returncode == 0 and (tmp_path / "fleet.parquet").is_file(), done.stderr
    assert "mountcal_exits" in done.stderr and "left out" in done.stderr and "Traceback" not in done.stderr


def test_output_of_a_plugin_at_import_goes_to_stderr_named(
    tmp_path: Path, session: tuple[dict[str, str], Path, ParkingLog]
) -> None:
    import json

    _, log_path, _ = session
    noisy = "import os, sys\nprint('hello from the plugin')\nos.write(1, b'raw bytes from the plugin\\n')\n" + PLUGIN
    env = install(tmp_path / "site", "mountcal_noisy", noisy, "mountcal_noisy:ImuTxtReader")
    done = mountcal(env, "inspect", log_path, "--json")
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["format"]  # stdout holds the JSON alone
    assert "hello from the plugin" in done.stderr and "raw bytes from the plugin" in done.stderr
    assert "mountcal_noisy" in done.stderr  # the printed text is reported with the plugin's name


@pytest.mark.parametrize("where", ["read", "claims"])
@pytest.mark.parametrize("error", ["ZeroDivisionError('bug in the plugin')", "SystemExit(0)"])
def test_a_plugin_raising_in_claims_or_read_is_a_message_naming_it(
    tmp_path: Path, session: tuple[dict[str, str], Path, ParkingLog], where: str, error: str
) -> None:
    _, log_path, _ = session
    source = (RAISING if where == "read" else CLAIMING).replace("{error}", error)
    entry = "mountcal_raising:" + ("ImuTxtReader" if where == "read" else "Claimer")
    env = install(tmp_path / "site", "mountcal_raising", source, entry)
    result = tmp_path / "result.json"
    done = mountcal(env, "calibrate", log_path, "-o", result)
    assert done.returncode == 2 and not result.exists(), done.stderr
    assert "Traceback" not in done.stderr and "mountcal_raising" in done.stderr
    assert error.split("(")[0] in done.stderr
    if where == "read":
        assert str(log_path) in done.stderr
