"""docs/inputs.md: every command of its table runs, in order, on the files it names."""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from rosbags.convert.converter import convert
from tests.io.test_bags import write_vn_mcap
from tests.test_sensor_logger import still_ios_zip

from mountcal.cli import main

REPO = Path(__file__).resolve().parents[2]
DOC = REPO / "docs" / "inputs.md"
REAL = ("robot_localization", "imucal-ferraris", "comma2k19", "canedge")
G_N = 9.80665


def _commands() -> list[str]:
    return [
        line[len("$ mountcal ") :]
        for line in DOC.read_text(encoding="utf-8").splitlines()
        if line.startswith("$ mountcal ")
    ]


def _tomls() -> dict[str, str]:
    """The doc's TOML blocks, by the file name of their first comment line."""
    blocks = re.findall(r"```toml\n(.*?)```", DOC.read_text(encoding="utf-8"), re.S)
    return {block.split(":", 1)[0].lstrip("# ").strip(): block for block in blocks}


def test_every_command_of_the_table_is_among_those_run() -> None:
    rows = [
        line for line in DOC.read_text(encoding="utf-8").splitlines() if line.startswith("| ") and "`mountcal " in line
    ]
    in_table = [c for row in rows for c in re.findall(r"`mountcal ([^`]+)`", row.split(" | ")[2])]
    assert len(rows) >= 20 and set(in_table) <= set(_commands())


def _phone_exports(folder: Path) -> None:
    """A still phone, flat, as phyphox, Sensor Logger and Physics Toolbox name their columns."""
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 30.0, 0.01)
    acc = rng.normal(0, 0.02, (t.size, 3)) + np.array([0.0, 0.0, G_N])
    (folder / "phyphox").mkdir()
    pd.DataFrame({"Time (s)": t} | {f"Acceleration {c} (m/s^2)": acc[:, i] for i, c in enumerate("xyz")}).to_csv(
        folder / "phyphox" / "Raw_Data.csv", index=False
    )
    (folder / "sensorlogger").mkdir()
    ns = 1_716_979_893_874_983_200 + np.round(t * 1e9).astype(np.int64)
    pd.DataFrame({"time": ns, "seconds_elapsed": t, "z": acc[:, 2], "y": acc[:, 1], "x": acc[:, 0]}).to_csv(
        folder / "sensorlogger" / "TotalAcceleration.csv", index=False
    )
    still_ios_zip(folder / "sensorlogger.zip")  # a whole recording, as the app zips it
    gforce = pd.DataFrame({"time": t} | {f"gF{c}": acc[:, i] / G_N for i, c in enumerate("xyz")})
    gforce.assign(TgF=np.linalg.norm(acc, axis=1) / G_N).to_csv(folder / "ptss_gforce.csv", index=False)


@pytest.mark.real_data
def test_the_inputs_doc_commands_run(
    real_data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "data").symlink_to(REPO / "data")
    for name in REAL:
        (tmp_path / name).symlink_to(real_data / name)
    for name, text in _tomls().items():
        (tmp_path / name).write_text(text, encoding="utf-8")
    write_vn_mcap(tmp_path / "vn.mcap")
    convert(
        [REPO / "data" / "parking.mcap"],
        tmp_path / "parking_db3",
        "sqlite3",
        9,
        None,
        "file",
        None,
        None,
        [],
        [],
        [],
        [],
    )
    _phone_exports(tmp_path)
    monkeypatch.chdir(tmp_path)
    outputs = {}
    for command in _commands():
        argv = shlex.split(command)
        if "vehicle_g.csv" in argv:  # the rotated samples in g
            frame = pd.read_csv(tmp_path / "vehicle.csv")
            frame[["ax", "ay", "az"]] /= G_N
            frame.to_csv(tmp_path / "vehicle_g.csv", index=False, float_format="%.17g")
        assert main(argv) == 0, command
        outputs[command] = capsys.readouterr()
    result = json.loads((tmp_path / "result.json").read_text())["mounting"]
    assert result["roll_deg"] == pytest.approx(5.0, abs=0.1) and result["yaw_deg"] == pytest.approx(7.0, abs=0.2)
    for other in ("db3_result.json", "blf_result.json"):
        got = json.loads((tmp_path / other).read_text())["mounting"]
        assert got["roll_deg"] == pytest.approx(result["roll_deg"], abs=1e-9 if other.startswith("db3") else 0.1)
    assert len(pd.read_csv(tmp_path / "vehicle_stops.csv")) == 12
    assert len(pd.read_csv(tmp_path / "imucal_stops.csv")) == 6
    assert len(pd.read_csv(tmp_path / "vn_vehicle.csv")) == 300
    g = json.loads((tmp_path / "g_result.json").read_text())["mounting"]
    vehicle = [c for c in outputs if c.startswith("stops vehicle.csv")]
    assert vehicle and abs(g["roll_deg"]) < 0.2  # the rotated samples are level in the vehicle frame
    text = "".join(o.err + o.out for o in outputs.values())  # the summaries (stderr), the exports (stdout)
    assert "ros1 bag" in text and "ros2 bag (mcap)" in text and "/imu/data" in text and "imu_link" in text
    for export in (
        "a phyphox export",
        "a Sensor Logger TotalAcceleration.csv",
        "a Sensor Logger recording (iOS)",
        "a Physics Toolbox Sensor Suite export",
    ):
        assert f"note: read as {export}" in text, export  # recognised, and said
