"""The command line's conventions: results on stdout or in the file, status on stderr, --json, -q/-v, '-'."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from mountcal.cli import main
from mountcal.core.result import Calibration

REPO = Path(__file__).resolve().parents[1]
STOPS = REPO / "data" / "zhang2011_stops.csv"
PARKING, PROTOCOL = REPO / "data" / "parking.mcap", REPO / "data" / "parking_protocol.csv"


def test_dash_o_dash_writes_the_result_json_to_stdout_and_no_file_named_dash(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    assert main(["calibrate", str(STOPS), "-o", "-"]) == 0
    out, err = capsys.readouterr()
    cal = Calibration.from_dict(json.loads(out))  # stdout is the result document, nothing else
    assert cal.roll_sigma_deg is not None and "roll" in err  # the summary went to stderr
    assert not (tmp_path / "-").exists()


def test_json_and_a_file_give_the_same_result(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    result = tmp_path / "r.json"
    assert main(["calibrate", str(STOPS), "--json", "-o", str(result)]) == 0
    out = capsys.readouterr().out
    assert json.loads(out)["mounting"] == json.loads(result.read_text(encoding="utf-8"))["mounting"]


def test_a_log_s_summary_and_status_go_to_stderr_the_answer_first(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    result = tmp_path / "r.json"
    assert main(["calibrate", str(PARKING), "--protocol", str(PROTOCOL), "-o", str(result)]) == 0
    out, err = capsys.readouterr()
    assert out == ""  # nothing asked on stdout: the result is in -o's file
    first, *rest = err.splitlines()
    assert first.startswith("roll 5.001 ± ") and first.endswith("  confident")  # the answer, first
    assert "  read 39600 samples from 1 file(s)" in rest and "  full method, model: rotation, slope, gravity" in err
    assert rest[-1] == f"mountcal: wrote {result}"


def test_quiet_keeps_the_answer_alone_and_verbose_keeps_the_status(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["stops", str(PARKING), "--protocol", str(PROTOCOL), "-o", str(tmp_path / "s.csv")]
    assert main([*args, "-q"]) == 0
    assert capsys.readouterr() == (
        "",
        f"12 stops at 12 headings (protocol sheet), from 39600 samples: {tmp_path / 's.csv'}\n",
    )
    assert main([*args, "-qq"]) == 0
    assert capsys.readouterr() == ("", "")
    assert main([*args, "-v"]) == 0
    assert "found 12 stops" in capsys.readouterr().err


def test_stops_to_stdout_read_back_by_calibrate_from_stdin(tmp_path: Path) -> None:
    """`mountcal stops LOG -o - | mountcal calibrate - -o -`: the stop table through a pipe."""
    cmd = [sys.executable, "-m", "mountcal"]
    stops = subprocess.run(
        [*cmd, "stops", str(PARKING), "--protocol", str(PROTOCOL), "-o", "-", "-qq"],
        capture_output=True,
        check=True,
    )
    assert stops.stderr == b"" and b"beta_deg" in stops.stdout.split(b"\n")[0]  # -qq: nothing but the table
    done = subprocess.run([*cmd, "calibrate", "-", "-o", "-"], input=stops.stdout, capture_output=True, check=True)
    piped = Calibration.from_dict(json.loads(done.stdout))
    direct = tmp_path / "direct.json"
    assert main(["calibrate", str(PARKING), "--protocol", str(PROTOCOL), "--use", "stops", "-o", str(direct)]) == 0
    alone = Calibration.load(direct)
    # the file form holds 15 significant digits: the fit may stop a hair apart (its convergence tolerance)
    assert piped.roll_deg == pytest.approx(alone.roll_deg, abs=1e-6)
    assert piped.yaw_deg == pytest.approx(alone.yaw_deg, abs=1e-6)


def test_a_user_error_is_one_line_on_stderr_with_its_exit_code(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["calibrate", "no-such-stops.csv"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.startswith("mountcal: error: no-such-stops.csv") and "Traceback" not in err


def test_inspect_json_lists_the_streams(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["inspect", str(PARKING), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["format"] == "mcap" and doc["streams"] and all("count" in s for s in doc["streams"])


def test_an_empty_csv_is_refused_alike_by_calibrate_and_by_fleet(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """One stop-table sniffer: the same message whether one log is calibrated or a fleet of them."""
    import pandas as pd

    empty = tmp_path / "van" / "empty.csv"
    empty.parent.mkdir()
    empty.write_bytes(b"")
    assert main(["calibrate", str(empty)]) == 2
    assert "an empty file (0 bytes)" in capsys.readouterr().err
    assert main(["fleet", str(empty.parent), "-o", str(tmp_path / "f.parquet")]) == 0
    row = pd.read_parquet(tmp_path / "f.parquet").iloc[0]
    assert row["status"] == "failed" and "an empty file (0 bytes)" in row["error"]


def test_a_library_refusal_names_no_option_and_the_cli_names_its_own(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from mountcal.core.errors import NotEnoughInformation
    from mountcal.outputs.exporters import export

    result = tmp_path / "level.json"
    assert main(["calibrate", str(STOPS), "--headings", "relative", "-o", str(result)]) == 0  # yaw not determined
    with pytest.raises(NotEnoughInformation) as err:
        export(Calibration.load(result), "json")
    assert "--" not in str(err.value) and "yaw='zero'" in str(err.value)
    capsys.readouterr()
    assert main(["export", str(result), "--to", "json", "-o", "-"]) == 3
    assert "--yaw-undetermined zero" in capsys.readouterr().err
