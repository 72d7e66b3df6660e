"""A fleet folder holding logs that are folders (a comma2k19 segment here; Sensor Logger recordings in
tests/test_sensor_logger.py): each is one log of the vehicle its parent folder names, keyed by its files'
contents, and its files are not searched as logs of their own."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from mountcal.cli import main


def test_a_real_comma2k19_segment_inside_a_fleet_folder_is_one_log(
    real_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    segment = real_data / "comma2k19" / "rav4_2018-08-02--08-34-47_seg40"
    logs = tmp_path / "logs" / "rav4"
    logs.mkdir(parents=True)
    (logs / "seg40").symlink_to(segment, target_is_directory=True)
    out = tmp_path / "fleet.parquet"
    assert main(["fleet", str(tmp_path / "logs"), "-o", str(out)]) == 0, capsys.readouterr().err  # was: "no log"
    table = pd.read_parquet(out)
    assert list(table["vehicle_id"]) == ["rav4"] and Path(table["log"].iloc[0]).name == "seg40"
    assert main(["calibrate", str(segment), "-o", str(tmp_path / "one.json")]) == 0
    capsys.readouterr()
    assert main(["fleet", str(tmp_path / "logs"), "-o", str(out)]) == 0
    assert "0 calibrated now, 1 from earlier runs" in capsys.readouterr().err
