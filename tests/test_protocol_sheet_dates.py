"""A protocol sheet whose times are ISO-8601 date-times (mountcal/stops/headings.py, ``sheet_times``): with their
zone (``Z``, ``+02:00``) they are instants, read as Unix seconds; without one they are a wall clock's and refused
naming the zone to write.

Before, every date-time sheet was refused as "empty or non-numeric cells. Write one row per stop.": the wrong fix
for a sheet whose every cell holds a time, and no word of the zone a local sheet against a UTC log needs.
"""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from mountcal.cli import main

REPO = Path(__file__).resolve().parents[1]
PARKING, PROTOCOL = REPO / "data" / "parking.mcap", REPO / "data" / "parking_protocol.csv"


def dated(path: Path, zone: str | None) -> Path:
    """data/parking_protocol.csv with its times as ISO-8601 text in ``zone`` (None: naive, the local wall clock),
    written by pandas."""
    df = pd.read_csv(PROTOCOL)
    for column in ("t_start_s", "t_end_s"):
        when = pd.to_datetime(df[column], unit="s", utc=True).dt.tz_convert(zone or "Europe/Berlin")
        df[column] = when.map(lambda t: t.isoformat()) if zone else when.dt.strftime("%Y-%m-%d %H:%M:%S.%f")
    df.to_csv(path, index=False)
    return path


def _mounting(args: list[str], out: Path) -> dict[str, float]:
    assert main([*args, "-o", str(out)]) == 0
    return dict(json.loads(out.read_text())["mounting"])


@pytest.mark.parametrize("zone", ["UTC", "Europe/Berlin", "America/New_York"])
def test_a_sheet_of_date_times_with_their_zone_calibrates_as_the_unix_sheet(zone: str, tmp_path: Path) -> None:
    unix = _mounting(["calibrate", str(PARKING), "--protocol", str(PROTOCOL)], tmp_path / "unix.json")
    sheet = dated(tmp_path / "dated.csv", zone)
    assert "+" in sheet.read_text() or "-04:00" in sheet.read_text()  # the zone is in the text
    assert _mounting(["calibrate", str(PARKING), "--protocol", str(sheet)], tmp_path / "dated.json") == pytest.approx(
        unix, abs=1e-6
    )


def test_a_sheet_of_date_times_without_a_zone_is_refused_naming_the_zone(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sheet = dated(tmp_path / "local.csv", None)
    out = tmp_path / "r.json"
    capsys.readouterr()
    assert main(["calibrate", str(PARKING), "--protocol", str(sheet), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert not out.exists() and "Traceback" not in err
    assert "found date-times without a zone ('2024-05-01 12:00:00.000000')" in err
    assert "Add the zone the times were written in" in err and "non-numeric" not in err
