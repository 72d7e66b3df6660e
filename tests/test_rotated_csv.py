"""A CSV that mountcal rotate wrote says its frame in a column ``frame`` (a CSV has no metadata), and the
table reader recognises it: everything a rotated Parquet is refused or said to be, a rotated CSV is too —
rotating again and a triad refused, a calibration stating the frame and what its angles measure, a stop
table keeping the frame. A ``frame`` column holding several values, or one mountcal does not know, is
refused naming the file, the column and the values. Every file here is written by the command line.
"""

from __future__ import annotations

import hashlib
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from tests.conftest import Refused

from mountcal.cli import main
from mountcal.estimate.triad import Triad

DATA = Path(__file__).resolve().parents[1] / "data"
SHEET = DATA / "parking_protocol.csv"
COLUMNS = ["t_s", "ax", "ay", "az", "gx", "gy", "gz"]  # what rotate's CSV held before the frame column


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The parking log, its calibration, and the log rotated by it to CSV and to Parquet."""
    folder = tmp_path_factory.mktemp("rotated_csv")
    shutil.copy(DATA / "parking.mcap", folder / "parking.mcap")
    assert (
        main(["calibrate", str(folder / "parking.mcap"), "--protocol", str(SHEET), "-o", str(folder / "r.json"), "-q"])
        == 0
    )
    for name in ("veh.csv", "veh.parquet"):
        argv = ["rotate", str(folder / "parking.mcap"), "--calibration", str(folder / "r.json")]
        assert main([*argv, "-o", str(folder / name), "-q"]) == 0
    return folder


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _calibrated(log: Path, out: Path) -> dict:
    assert main(["calibrate", str(log), "--protocol", str(SHEET), "-o", str(out), "-q"]) == 0
    return json.loads(out.read_text(encoding="utf-8"))


def _frame(doc: dict) -> dict:
    found = [c for c in doc["provenance"]["conventions"] if c["name"] == "frame"]
    assert len(found) == 1, doc["provenance"]["conventions"]
    return found[0]


def test_rotate_writes_the_frame_word_in_every_row_after_the_columns_it_wrote_before(
    made: Path, tmp_path: Path
) -> None:
    lines = (made / "veh.csv").read_text(encoding="utf-8").splitlines()
    assert lines[0].replace('"', "").split(",") == [*COLUMNS, "frame"]
    assert len(lines) == 39601 and all(line.endswith(",vehicle") for line in lines[1:])  # 8 bytes a row
    table = pd.read_csv(made / "veh.csv")
    parquet = pd.read_parquet(made / "veh.parquet")
    assert list(parquet.columns) == COLUMNS and table[COLUMNS].equals(parquet)  # the numbers as before, exactly
    chunked = tmp_path / "chunked.csv"  # streamed: every chunk carries the column, the file is the same
    argv = ["rotate", str(made / "parking.mcap"), "--calibration", str(made / "r.json"), "--chunk", "1000"]
    assert main([*argv, "-o", str(chunked), "-q"]) == 0
    assert chunked.read_bytes() == (made / "veh.csv").read_bytes()


@pytest.mark.parametrize(("suffix", "chunk"), [(".csv", []), (".parquet", ["--chunk", "1000"]), (".mcap", [])])
def test_rotating_a_rotated_csv_again_is_refused(refused: Refused, made: Path, suffix: str, chunk: list[str]) -> None:
    before = _digest(made / "veh.csv")
    out = made / f"twice{suffix}"
    argv = ["rotate", str(made / "veh.csv"), "--calibration", str(made / "r.json"), *chunk, "-o", str(out)]
    err = refused(argv, out)
    assert f"{made / 'veh.csv'}: expected samples in the sensor's frame" in err
    assert "already put in the vehicle frame" in err and "apply the mounting twice" in err
    assert _digest(made / "veh.csv") == before


def test_a_triad_is_refused_on_a_rotated_csv_fitted_or_applied(refused: Refused, made: Path, tmp_path: Path) -> None:
    out = tmp_path / "t.json"
    err = refused(["triad", str(made / "veh.csv"), "-o", str(out)], out)
    assert f"{made / 'veh.csv'}: expected samples in the sensor's frame" in err and "sensor's own axes" in err
    triad = tmp_path / "triad.json"
    fitted = Triad(np.array([0.02, -0.01, 0.03]), np.zeros(6), np.eye(9) * 1e-8, "test")
    triad.write_text(json.dumps(fitted.to_dict()), encoding="utf-8")
    out = tmp_path / "r.json"
    argv = ["calibrate", str(made / "veh.csv"), "--protocol", str(SHEET), "--triad", str(triad), "-o", str(out)]
    err = refused(argv, out)
    assert "vehicle frame" in err and "--triad" in err


def test_calibrating_a_rotated_csv_states_its_frame_and_what_the_angles_measure(made: Path) -> None:
    doc = _calibrated(made / "veh.csv", made / "check_csv.json")
    frame = _frame(doc)
    assert frame["value"] == "vehicle (mountcal rotate's output)" and frame["how"] == "stated"
    assert frame["by"] == f"the column frame of {made / 'veh.csv'}"
    assert sum("already in mountcal's vehicle frame" in n and "column frame" in n for n in doc["notes"]) == 1
    for angle in ("roll_deg", "pitch_deg"):  # the rotation left over
        assert abs(doc["mounting"][angle]) < 0.15, doc["mounting"]


def test_the_stop_table_of_a_rotated_csv_keeps_its_frame(refused: Refused, made: Path, tmp_path: Path) -> None:
    stops = tmp_path / "stops.csv"
    assert main(["stops", str(made / "veh.csv"), "--protocol", str(SHEET), "-o", str(stops), "-q"]) == 0
    frames = set(pd.read_csv(stops, comment="#")["frame"].astype(str))
    assert frames == {"vehicle (mountcal rotate's output)"}
    out = tmp_path / "t.json"
    assert "sensor's own axes" in refused(["triad", str(stops), "-o", str(out)], out)


def _with_frames(made: Path, target: Path, word: str, rows: dict[int, str] | None = None) -> Path:
    """The rotated samples (read from the Parquet) as a CSV with a column ``frame``: ``word`` in every row,
    but the ``rows`` given (0-based)."""
    df = pd.read_parquet(made / "veh.parquet")
    df["frame"] = word
    for row, other in (rows or {}).items():
        df.loc[row, "frame"] = other
    df.to_csv(target, index=False)
    return target


@pytest.mark.parametrize(
    ("word", "rows", "found"),
    [
        ("vehicle", {39000: "sensor"}, "2 value(s) in the column frame: 'sensor', 'vehicle'"),  # past the first chunks
        ("vehicle", {0: "levelled"}, "2 value(s) in the column frame: 'levelled', 'vehicle'"),
        ("imu_link", None, "1 value(s) in the column frame: 'imu_link'"),
    ],
)
def test_a_frame_column_with_several_or_unknown_values_is_refused(
    refused: Refused, made: Path, tmp_path: Path, word: str, rows: dict[int, str] | None, found: str
) -> None:
    log = _with_frames(made, tmp_path / "mixed.csv", word, rows)
    for out, argv in (
        (tmp_path / "o.parquet", ["rotate", str(log), "--calibration", str(made / "r.json"), "--chunk", "1000"]),
        (tmp_path / "o.json", ["calibrate", str(log), "--protocol", str(SHEET)]),
    ):
        err = refused([*argv, "-o", str(out)], out)
        assert f"{log}: expected one frame in every row of the column frame" in err and found in err
        assert "one file per frame" in err


def test_a_frame_column_saying_sensor_reads_as_a_log(made: Path, tmp_path: Path) -> None:
    """``sensor`` in every row: the sensor's own axes, no mark — rotated as the same numbers without the column;
    a column ``frame`` that a column map reads as data is no mark either."""
    rotate = ["rotate", "--calibration", str(made / "r.json"), "-q", "-o"]
    log = _with_frames(made, tmp_path / "sensor.csv", "sensor")
    plain = tmp_path / "plain.csv"
    pd.read_parquet(made / "veh.parquet").to_csv(plain, index=False)
    for source in (log, plain):
        assert main([*rotate, str(tmp_path / f"again_{source.name}"), str(source)]) == 0
    again = pd.read_csv(tmp_path / "again_sensor.csv")
    assert (again["frame"] == "vehicle").all() and again.equals(pd.read_csv(tmp_path / "again_plain.csv"))
    counted = pd.read_parquet(made / "veh.parquet").drop(columns="t_s")  # a column frame a map reads as data
    counted.insert(0, "frame", range(len(counted)))
    counted.to_csv(tmp_path / "counted.csv", index=False)
    columns = "time=frame:s/100," + ",".join(f"{c}={c}" for c in ("ax", "ay", "az", "gx", "gy", "gz"))
    argv = [*rotate, str(tmp_path / "again_counted.csv"), str(tmp_path / "counted.csv"), "--columns", columns]
    assert main(argv) == 0
    assert (pd.read_csv(tmp_path / "again_counted.csv")["frame"] == "vehicle").all()


def test_a_rotated_csv_and_a_rotated_parquet_of_the_same_log_calibrate_and_refuse_alike(
    refused: Refused, made: Path, tmp_path: Path
) -> None:
    docs = {s: _calibrated(made / f"veh.{s}", tmp_path / f"{s}.json") for s in ("csv", "parquet")}
    for angle in ("roll_deg", "pitch_deg", "yaw_deg"):
        assert docs["csv"]["mounting"][angle] == pytest.approx(docs["parquet"]["mounting"][angle], abs=1e-6)
    words = {s: _frame(d)["value"].split(" ", 1)[0] for s, d in docs.items()}
    assert words["csv"] == words["parquet"] == "vehicle"

    def refusal(command: str, suffix: str) -> str:
        log, out = made / f"veh.{suffix}", tmp_path / ("o.csv" if command == "rotate" else "o.json")
        given = ["--calibration", str(made / "r.json")] if command == "rotate" else []
        err = refused([command, str(log), *given, "-o", str(out)], out).replace(str(log), "LOG")
        return re.sub(r" \(calibration from [^)]*\)", "", err)  # what a Parquet file records of the calibration

    for command in ("rotate", "triad"):
        said = {s: refusal(command, s) for s in ("csv", "parquet")}
        assert said["csv"] == said["parquet"] and "LOG: expected samples in the sensor's frame" in said["csv"]


def test_a_fleet_sets_a_rotated_csv_aside_as_it_does_a_rotated_parquet(
    refused: Refused, made: Path, tmp_path: Path
) -> None:
    folder = tmp_path / "logs"
    folder.mkdir()
    shutil.copy(made / "veh.csv", folder / "veh.csv")
    out = tmp_path / "fleet.parquet"
    err = refused(["fleet", str(folder), "--workers", "1", "-o", str(out)], out)
    assert f"no log; set aside 1 file(s) mountcal wrote, e.g. {folder / 'veh.csv'}" in err
    err = refused(["fleet", str(folder / "veh.csv"), "--workers", "1", "-o", str(out)], out)
    assert "a log already rotated into the vehicle frame" in err
