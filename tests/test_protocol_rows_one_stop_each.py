"""A protocol sheet two of whose rows take the same still period (mountcal/stops/headings.py,
``one_stop_per_row``): a row repeating another's times, or overlapping the next row's stop. Refused naming the rows.

Before, each row took the longest still run inside it, the same run for both: ``mountcal stops`` wrote a table of
12 stops with one stop's means twice, at β 0° and 30°, and the stop between left out (a silently wrong file), and
``calibrate`` fitted it, confident (yaw 6.98° and 7.01°: the model of each stop's heading error absorbed it).
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from mountcal.cli import main

REPO = Path(__file__).resolve().parents[1]
PARKING, PROTOCOL = REPO / "data" / "parking.mcap", REPO / "data" / "parking_protocol.csv"


def _sheet(path: Path, how: str) -> Path:
    """data/parking_protocol.csv with row 2 repeating row 1's times, or row 1 stretched over row 2's stop (pandas)."""
    df = pd.read_csv(PROTOCOL)
    if how == "repeated":
        df.loc[1, ["t_start_s", "t_end_s"]] = df.loc[0, ["t_start_s", "t_end_s"]].to_numpy()
    else:
        df.loc[0, "t_start_s"] += 15.0
        df.loc[0, "t_end_s"] = df.loc[1, "t_end_s"]
    df.to_csv(path, index=False, float_format="%.17g")
    return path


@pytest.mark.parametrize("how", ["repeated", "overlapping"])
@pytest.mark.parametrize("command", ["stops", "calibrate"])
def test_two_rows_on_one_still_period_are_refused_naming_them(
    how: str, command: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sheet = _sheet(tmp_path / "sheet.csv", how)
    out = tmp_path / ("stops.csv" if command == "stops" else "result.json")
    capsys.readouterr()
    assert main([command, str(PARKING), "--protocol", str(sheet), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert not out.exists() and "Traceback" not in err
    assert "found rows 1 (" in err and "β 0°) and 2 (" in err and "β 30°) on the same still period" in err


def test_the_sheet_as_written_keeps_one_stop_per_row(tmp_path: Path) -> None:
    out = tmp_path / "stops.csv"
    assert main(["stops", str(PARKING), "--protocol", str(PROTOCOL), "-o", str(out)]) == 0
    table = pd.read_csv(out, comment="#")
    assert len(table) == 12 and not table.duplicated(subset=["ax", "ay", "az"]).any()
