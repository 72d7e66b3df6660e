"""A protocol sheet's clock against the log's (mountcal/stops/protocol_clock.py): a sheet counting from the log's
start is shifted and said; a time zone's offset, a dated sheet on an undated log, or no relation are refused with
the true reason and the fix, through every command that takes a sheet and the library alike."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pandas as pd
import pytest
from tests.conftest import Refused

from mountcal.calibration.pipeline import calibrate_log
from mountcal.cli import main
from mountcal.core.errors import InputError, NotEnoughInformation
from mountcal.io.logs import read_log
from mountcal.io.reader import LogOptions
from mountcal.io.writers import write_log

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "data"
PARKING, PROTOCOL = DATA / "parking.mcap", DATA / "parking_protocol.csv"
DBC, MAPPING = DATA / "imu_mm5_10.dbc", DATA / "imu_mm5_10.toml"
T0 = 1714557600.0  # data/parking.mcap's first sample, Unix time (2024-05-01 10:00:00 UTC)


def sheet(path: Path, shift_s: float) -> Path:
    """data/parking_protocol.csv with its times moved by ``shift_s``, written by pandas."""
    df = pd.read_csv(PROTOCOL)
    df[["t_start_s", "t_end_s"]] += shift_s
    df.to_csv(path, index=False, float_format="%.17g")
    return path


def test_a_sheet_counting_from_the_log_s_start_calibrates_as_the_unix_sheet_and_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    relative = sheet(tmp_path / "relative.csv", -T0)
    assert pd.read_csv(relative)["t_start_s"].iloc[0] == 0.0
    unix, rel = tmp_path / "unix.json", tmp_path / "rel.json"
    assert main(["calibrate", str(PARKING), "--protocol", str(PROTOCOL), "-o", str(unix)]) == 0
    assert main(["calibrate", str(PARKING), "--protocol", str(relative), "-o", str(rel)]) == 0
    err = capsys.readouterr().err
    a, b = (json.loads(p.read_text(encoding="utf-8")) for p in (unix, rel))
    for key in ("roll_deg", "pitch_deg", "yaw_deg"):
        assert b["mounting"][key] == pytest.approx(a["mounting"][key], rel=1e-9, abs=0.0)
    clock = [c for c in b["provenance"]["conventions"] if c["name"] == "protocol_clock"]
    assert len(clock) == 1 and clock[0]["how"] == "inferred"
    assert "from the log's start" in clock[0]["value"] and "1714557600" in clock[0]["value"]
    assert "0–395.99 s" in clock[0]["by"] and "Unix time (2024-05-01 10:00:00 UTC)" in clock[0]["by"]
    assert not [c for c in a["provenance"]["conventions"] if c["name"] == "protocol_clock"]  # on the log: as stated
    assert "input protocol_clock: seconds from the log's start" in err

    done = calibrate_log(PARKING, protocol=relative)  # the library: the same place
    assert done.calibration.roll_deg == pytest.approx(a["mounting"]["roll_deg"], rel=1e-9, abs=0.0)
    assert any(c.name == "protocol_clock" for c in done.calibration.provenance.conventions)


def test_stops_takes_the_relative_sheet_at_the_log_s_times(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    relative = sheet(tmp_path / "relative.csv", -T0)
    out = tmp_path / "s.csv"
    assert main(["stops", str(PARKING), "--protocol", str(relative), "-o", str(out)]) == 0
    assert "protocol sheet's times: seconds from the log's start" in capsys.readouterr().err
    table = pd.read_csv(out, comment="#")
    assert len(table) == 12 and table["t_s"].min() >= T0


@pytest.mark.parametrize(
    ("shift_s", "said", "fix"),
    [
        (7200.0, "2 h after it", "subtract 7200 s from t_start_s and t_end_s"),
        (-5.5 * 3600, "5 h 30 min before it", "add 19800 s to t_start_s and t_end_s"),
    ],
)
def test_a_sheet_a_time_zone_off_the_log_is_refused_naming_the_hours_and_the_fix(
    refused: Refused, tmp_path: Path, shift_s: float, said: str, fix: str
) -> None:
    zoned = sheet(tmp_path / "zoned.csv", shift_s)
    out = tmp_path / "r.json"
    err = refused(["calibrate", str(PARKING), "--protocol", str(zoned), "-o", str(out)], out)
    assert f"{zoned}: expected the sheet's times on the log's clock (Unix time" in err
    assert said in err and "a time zone's offset" in err and fix in err
    assert "2024-05-01 10:00:00" in err  # the log's start, as a date
    assert "its first stop then starting at 1714557600 (2024-05-01 10:00:00 UTC)" in err
    assert "--max-acc-std" not in err  # not the stillness thresholds: they are not the reason
    stops = tmp_path / "s.csv"
    assert said in refused(["stops", str(PARKING), "--protocol", str(zoned), "-o", str(stops)], stops)
    with pytest.raises(InputError, match=said):
        calibrate_log(PARKING, protocol=zoned)


def test_a_dated_sheet_on_a_log_whose_clock_counts_from_its_start_is_refused(refused: Refused, tmp_path: Path) -> None:
    asc = tmp_path / "parking.asc"
    write_log(asc, read_log(str(PARKING)), dbc_path=str(DBC))
    out = tmp_path / "r.json"
    argv = ["calibrate", str(asc), "--dbc", str(DBC), "--mapping", str(MAPPING), "--protocol", str(PROTOCOL)]
    err = refused([*argv, "-o", str(out)], out)
    assert f"{PROTOCOL}: expected the sheet's times on the log's clock (its times 0.00025–395.99" in err
    assert "the log's clock has no date, its times count from the start of the recording" in err
    assert "Write the sheet's times as seconds from the log's start" in err and "--max-acc-std" not in err
    with pytest.raises(InputError, match="the log's clock has no date"):
        calibrate_log(asc, log=LogOptions(dbc=str(DBC), mapping=str(MAPPING)), protocol=PROTOCOL)


def test_a_sheet_with_no_relation_to_the_log_is_refused_with_both_spans(refused: Refused, tmp_path: Path) -> None:
    far = sheet(tmp_path / "far.csv", 5000.0)  # 1 h 23 min 20 s: no time zone's offset
    out = tmp_path / "r.json"
    err = refused(["calibrate", str(PARKING), "--protocol", str(far), "-o", str(out)], out)
    assert "found no interval on the log: the sheet spans 1714562600–1714562996 s = 2024-05-01 11:23:20" in err
    assert "(Unix time, 1714557600–1714557996 s = 2024-05-01 10:00:00 – 10:06:35 UTC)" in err
    assert "--max-acc-std" not in err


def test_a_sheet_on_the_log_at_the_wrong_place_behaves_as_before(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Half a stop late (11 s of 22): every row overlaps the log, so its clock is not questioned; each row's
    still half is too short once trimmed, and the refusal stays the stop search's, with its thresholds."""
    late = sheet(tmp_path / "late.csv", 11.0)
    out = tmp_path / "r.json"
    capsys.readouterr()
    assert main(["calibrate", str(PARKING), "--protocol", str(late), "-o", str(out)]) == 3
    err = capsys.readouterr().err
    assert "no parked period found inside any protocol interval. Check that the sheet's times" in err
    assert "--max-acc-std" in err and "protocol_clock" not in err and not out.exists()
    with pytest.raises(NotEnoughInformation, match="no parked period found inside any protocol interval"):
        calibrate_log(PARKING, protocol=late, use="stops")


def test_fleet_finds_the_clock_of_a_sheet_beside_its_log(tmp_path: Path) -> None:
    van = tmp_path / "van"
    van.mkdir()
    for name, shift in (("relative", -T0), ("zoned", 7200.0)):
        shutil.copy(PARKING, van / f"{name}.mcap")
        sheet(van / f"{name}.protocol.csv", shift)
    out = tmp_path / "fleet.parquet"
    assert main(["fleet", str(van), "-o", str(out), "--workers", "1", "-q"]) == 0  # the fleet records failures
    logs = pd.read_parquet(out)
    logs.index = logs["log"].map(lambda p: Path(p).name)
    assert logs.loc["relative.mcap", "status"] == "ok" and logs.loc["relative.mcap", "n_stops"] == 12
    zoned = logs.loc["zoned.mcap"]
    assert zoned["status"] == "failed" and zoned["error_type"] == "InputError" and "2 h after it" in zoned["error"]


def test_the_placeholder_times_of_a_plan_are_refused_not_taken_from_the_log_s_start(
    refused: Refused, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    plan = tmp_path / "plan.csv"
    argv = ["plan", "--noise", "1", "--target", "roll=1,pitch=1,yaw=2", "--slope-deg", "5", "-o", str(plan)]
    assert main(argv) == 0
    out = tmp_path / "r.json"
    err = refused(["calibrate", str(PARKING), "--protocol", str(plan), "-o", str(out)], out)
    assert "found the placeholder times of `mountcal plan` (0–240 s" in err and "delete that first line" in err
    lines = plan.read_text(encoding="utf-8").splitlines(keepends=True)
    edited = tmp_path / "edited.csv"  # the same times without the plan's first line: the user's own, from the start
    edited.write_text("".join(lines[1:]), encoding="utf-8")
    assert main(["stops", str(PARKING), "--protocol", str(edited), "-o", str(tmp_path / "s.csv")]) == 0
    err = capsys.readouterr().err
    assert "protocol sheet's times: seconds from the log's start" in err and "placeholder times" not in err
