"""Text that is not UTF-8 where mountcal reads or writes (issue 27, item 7): a mapping or DBC with a
byte 0x81, an input file name that is not UTF-8 in a report, a terminal that is not UTF-8 — a clear
message or an escaped character, never a UnicodeDecodeError or UnicodeEncodeError traceback."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from mountcal.cli import main
from mountcal.core.terminal import decodable, safe

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "data"


def test_a_mapping_with_a_byte_that_is_not_utf8_is_refused_naming_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    mapping = tmp_path / "map.toml"
    mapping.write_bytes((DATA / "imu_mm5_10.toml").read_bytes() + b"\n# Beschleunigung \x81\n")
    args = ["calibrate", str(DATA / "parking.blf"), "--dbc", str(DATA / "imu_mm5_10.dbc"), "--mapping", str(mapping)]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "byte 0x81" in err and "not UTF-8" in err and "Save it as UTF-8" in err


def test_a_dbc_with_a_byte_0x81_in_a_comment_is_read(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    dbc = tmp_path / "imu.dbc"
    dbc.write_bytes((DATA / "imu_mm5_10.dbc").read_bytes() + b'\nCM_ BO_ 112 "Drehrate \x81";\n')
    args = ["inspect", str(DATA / "parking.blf"), "--dbc", str(dbc), "--json"]
    assert main(args) == 0
    assert {s["name"] for s in json.loads(capsys.readouterr().out)["streams"]} >= {"MM5_10_TX1"}


def test_an_input_named_in_bytes_that_are_not_utf8_reports_and_logs_them(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    name = tmp_path / os.fsdecode(b"stops-\xff.csv")  # a Latin-1 "ÿ" from another system
    name.write_bytes((DATA / "zhang2011_stops.csv").read_bytes())
    report, result = tmp_path / os.fsdecode(b"r\xfe.html"), tmp_path / "r.json"
    assert main(["calibrate", str(name), "--report", str(report), "-o", str(result)]) == 0
    html = report.read_bytes().decode("utf-8")  # a valid UTF-8 document
    assert "stops-\\xff.csv" in html
    captured = capsys.readouterr()
    assert "r\\xfe.html" in captured.err and "Traceback" not in captured.err
    assert main(["report", str(result), "-o", "-"]) == 0
    assert "stops-\\xff.csv" in capsys.readouterr().out
    assert decodable("a\udcff") == safe("a\udcff") == "a\\xff"


@pytest.mark.parametrize("encoding", ["ascii", "latin-1"])
def test_results_on_a_terminal_that_is_not_utf8_are_escaped_not_a_traceback(encoding: str) -> None:
    env = {**os.environ, "PYTHONPATH": str(REPO / "src"), "PYTHONIOENCODING": encoding}
    done = subprocess.run(
        [sys.executable, "-m", "mountcal", "calibrate", str(DATA / "zhang2011_stops.csv")],
        env=env,
        capture_output=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    assert b"Traceback" not in done.stderr
    assert b"roll" in done.stderr and b"\\u03c7" in done.stderr  # the summary's "χ²" shown as its escape
