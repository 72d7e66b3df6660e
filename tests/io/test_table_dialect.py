"""Tables as loggers, spreadsheets and phone apps write them, read the same way by every reader of a table
(the kind of the input, a sample table whole or in chunks, a stop table, a protocol sheet): ``;`` with
decimal commas, comment lines above the header, UTF-16 text, a units row under the header, and a time
column that restarts (recordings joined) or is out of order. The tables are written by pandas."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from mountcal.cli import main
from mountcal.simulate.stops import simulate_parking_log

T0 = 1714557600.0
TRUTH = (4.0, -3.0, 20.0)  # roll, pitch, yaw (deg)


@pytest.fixture(scope="module")
def session() -> tuple[pd.DataFrame, pd.DataFrame]:
    """A parking session at 50 Hz on a 6° slope (Unix times), and its protocol sheet."""
    log = simulate_parking_log(*TRUTH, slope_deg=6.0, seed=3, stop_s=20.0, drive_s=10.0, rate_hz=50.0)
    columns = {"t_s": log.t_s + T0} | {f"a{c}": log.acc_s[:, i] for i, c in enumerate("xyz")}
    columns |= {f"g{c}": log.gyro_s[:, i] for i, c in enumerate("xyz")}
    frame = pd.DataFrame(columns | {"speed_mps": log.speed_mps, "heading_deg": log.heading_deg})
    sheet = pd.DataFrame(
        [(a + T0, b + T0, c) for a, b, c in log.protocol], columns=["t_start_s", "t_end_s", "beta_deg"]
    )
    return frame, sheet


def _angles(out: Path) -> np.ndarray:
    m = json.loads(out.read_text())["mounting"]
    return np.array([m["roll_deg"], m["pitch_deg"], m["yaw_deg"]], dtype=float)


def _calibrated(path: Path, tmp_path: Path, *args: str) -> np.ndarray:
    out = tmp_path / f"{path.stem}.json"
    assert main(["calibrate", str(path), "-o", str(out), *args]) == 0
    return _angles(out)


def _written(session: tuple[pd.DataFrame, pd.DataFrame], tmp_path: Path) -> tuple[Path, Path]:
    """The session's log and protocol sheet, written as comma CSVs (the reference every dialect is read against)."""
    frame, sheet = session
    log, proto = tmp_path / "log.csv", tmp_path / "protocol.csv"
    frame.to_csv(log, index=False, float_format="%.17g")
    sheet.to_csv(proto, index=False, float_format="%.17g")
    return log, proto


def test_a_semicolon_table_with_decimal_commas_and_its_protocol_sheet_calibrate(
    session: tuple[pd.DataFrame, pd.DataFrame], tmp_path: Path
) -> None:
    """Only t_s, ax, ay, az (its kind told by its rows), ``;`` and decimal commas, as a German Excel writes
    them; the protocol sheet too. Before: refused as a stop table without ax, ay, az (the header read as one
    column 't_s;ax;ay;az'), and the sheet as having no t_start_s."""
    frame, sheet = session
    table, proto = tmp_path / "excel_de.csv", tmp_path / "protocol_de.csv"
    frame[["t_s", "ax", "ay", "az"]].to_csv(table, index=False, sep=";", decimal=",", float_format="%.10f")
    sheet.to_csv(proto, index=False, sep=";", decimal=",")
    assert np.allclose(_calibrated(table, tmp_path, "--protocol", str(proto)), TRUTH, atol=1.0)


def test_a_semicolon_stop_table_with_decimal_commas_calibrates_as_written(
    session: tuple[pd.DataFrame, pd.DataFrame], tmp_path: Path
) -> None:
    """A stop table `mountcal stops` wrote, saved by a spreadsheet with ``;`` and decimal commas: the same
    answer as the original. Before: refused, "no column ax, ay, az"."""
    log, proto = _written(session, tmp_path)
    stops = tmp_path / "stops.csv"
    assert main(["stops", str(log), "--protocol", str(proto), "-o", str(stops)]) == 0
    resaved = tmp_path / "stops_de.csv"
    pd.read_csv(stops).to_csv(resaved, index=False, sep=";", decimal=",", float_format="%.17g")
    assert np.allclose(_calibrated(resaved, tmp_path), _calibrated(stops, tmp_path), atol=1e-9)


def test_comment_lines_above_the_header_are_read_past(
    session: tuple[pd.DataFrame, pd.DataFrame], tmp_path: Path
) -> None:
    """A logger's preamble (``# …`` lines) above mountcal's own columns. Before: refused, its columns said
    to be '# logger v1.2'."""
    frame, sheet = session
    table, proto = tmp_path / "preamble.csv", tmp_path / "protocol.csv"
    table.write_text("# logger v1.2, serial 0042\n# rate 50 Hz\n" + frame.to_csv(index=False, float_format="%.17g"))
    sheet.to_csv(proto, index=False, float_format="%.17g")
    assert np.allclose(_calibrated(table, tmp_path, "--protocol", str(proto)), TRUTH, atol=1.0)


@pytest.mark.parametrize("kind", ["samples", "stops"])
def test_utf16_text_is_refused_as_such(
    session: tuple[pd.DataFrame, pd.DataFrame], tmp_path: Path, capsys: pytest.CaptureFixture[str], kind: str
) -> None:
    """A spreadsheet's "Unicode text" (UTF-16 with a byte-order mark). Before: refused as a file cut short
    (its last line break is two bytes) or as a UnicodeDecodeError, neither the reason."""
    frame, _ = session
    path = tmp_path / f"{kind}_utf16.csv"
    table = frame if kind == "samples" else frame.iloc[::500][["ax", "ay", "az"]].assign(beta_deg=30.0)
    table.to_csv(path, index=False, encoding="utf-16")
    args = ["--input-kind", "stop-table"] if kind == "stops" else []
    assert main(["calibrate", str(path), "-o", str(tmp_path / "r.json"), *args]) == 2
    err = capsys.readouterr().err
    assert "UTF-16" in err and "UTF-8" in err and str(path) in err, err
    assert not (tmp_path / "r.json").exists()


def test_a_units_row_under_the_header_is_a_row_dropped_and_counted(
    session: tuple[pd.DataFrame, pd.DataFrame], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A units row ('s,m/s2,…') under mountcal's own columns. Before: a traceback (ValueError: could not
    convert string to float: 's')."""
    frame, sheet = session
    head, rows = frame.to_csv(index=False, float_format="%.17g").split("\n", 1)
    table, proto = tmp_path / "units_row.csv", tmp_path / "protocol.csv"
    table.write_text(f"{head}\ns,m/s2,m/s2,m/s2,rad/s,rad/s,rad/s,m/s,deg\n{rows}")
    sheet.to_csv(proto, index=False, float_format="%.17g")
    out = tmp_path / "r.json"
    assert main(["calibrate", str(table), "--protocol", str(proto), "-o", str(out)]) == 0
    assert np.allclose(_angles(out), TRUTH, atol=1.0)
    assert "dropped rows with missing or non-numeric values: 1" in capsys.readouterr().err


def _joined(frame: pd.DataFrame) -> pd.DataFrame:
    """Two recordings, each counting from its own start, one after the other in one table."""
    joined = frame.copy()
    half = len(joined) // 2
    t = joined["t_s"].to_numpy() - T0
    t[half:] -= t[half]
    return joined.assign(t_s=t)


@pytest.mark.parametrize("command", ["calibrate", "stops"])
@pytest.mark.parametrize("mapped", [False, True])
def test_recordings_joined_in_one_table_are_refused_naming_the_row(
    session: tuple[pd.DataFrame, pd.DataFrame],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    command: str,
    mapped: bool,
) -> None:
    """Sorting by time interleaved the two recordings. Before: `stops` wrote 6 stops of the mixture (exit 0)
    and `calibrate` answered from them (not confident, for a structure the residual could not name)."""
    frame, _ = session
    joined = _joined(frame)
    path = tmp_path / "joined.csv"
    args: list[str] = []
    if mapped:
        joined = joined.rename(columns={"t_s": "time"})
        args = ["--columns", "time=time:s,ax=ax,ay=ay,az=az,gx=gx,gy=gy,gz=gz,speed=speed_mps"]
    joined.to_csv(path, index=False, float_format="%.17g")
    out = tmp_path / ("r.json" if command == "calibrate" else "stops.csv")
    assert main([command, str(path), "-o", str(out), *args]) == 2
    err = capsys.readouterr().err
    row = len(joined) // 2 + 1
    assert f"data row {row}" in err and "joined" in err and str(path) in err, err
    assert not out.exists()


def test_rows_out_of_order_are_sorted_and_said(
    session: tuple[pd.DataFrame, pd.DataFrame], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Rows shuffled (a spreadsheet sorted by another column): put in time order, the count said — they were
    sorted before too, silently."""
    frame, sheet = session
    table, proto = tmp_path / "shuffled.csv", tmp_path / "protocol.csv"
    frame.sample(frac=1.0, random_state=0).to_csv(table, index=False, float_format="%.17g")
    sheet.to_csv(proto, index=False, float_format="%.17g")
    out = tmp_path / "r.json"
    assert main(["calibrate", str(table), "--protocol", str(proto), "-o", str(out)]) == 0
    assert np.allclose(_angles(out), TRUTH, atol=1.0)
    err = capsys.readouterr().err  # the samples' own count (the channels' were said before too)
    assert re.search(r"read \d+ samples from 1 file\(s\); dropped samples out of time order \(put in order\): \d+", err)


def _suggested(err: str) -> str:
    """The column map a refusal names (quoted for a shell: the names hold spaces)."""
    found = re.search(r"--columns '([^']+)'", err)
    assert found is not None, err
    return found.group(1)


def test_units_in_column_names_are_named_back_as_the_column_map_that_reads_them(
    session: tuple[pd.DataFrame, pd.DataFrame], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A logger's headers with their units ('time (s)', 'ax [g]', 'gyro_x (dps)', 'speed (km/h)'): refused —
    the roles are the names' guess — naming the map the names say, which reads the table right. Before:
    refused with a generic example map ('time=ts:ms,ax=acc_x:g,…'), none of the table's columns in it."""
    frame, sheet = session
    table = pd.DataFrame(
        {"time (s)": frame["t_s"]}
        | {f"a{c} [g]": frame[f"a{c}"] / 9.80665 for c in "xyz"}
        | {f"gyro_{c} (dps)": np.degrees(frame[f"g{c}"]) for c in "xyz"}
        | {"speed (km/h)": frame["speed_mps"] * 3.6}
    )
    path, proto = tmp_path / "named_units.csv", tmp_path / "protocol.csv"
    table.to_csv(path, index=False, float_format="%.17g")
    sheet.to_csv(proto, index=False, float_format="%.17g")
    out = tmp_path / "r.json"
    assert main(["calibrate", str(path), "--protocol", str(proto), "-o", str(out)]) == 2
    columns = _suggested(capsys.readouterr().err)
    assert columns == (
        "time=time (s):s,ax=ax [g]:g,ay=ay [g]:g,az=az [g]:g,"
        "gx=gyro_x (dps):dps,gy=gyro_y (dps):dps,gz=gyro_z (dps):dps,speed=speed (km/h):km/h"
    )
    assert main(["calibrate", str(path), "--protocol", str(proto), "--columns", columns, "-o", str(out)]) == 0
    assert np.allclose(_angles(out), TRUTH, atol=1.0)


def test_a_unit_in_a_column_name_the_values_contradict_is_refused_when_given(
    session: tuple[pd.DataFrame, pd.DataFrame], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Headers saying g over values in m/s²: the map the names say is refused where it is given (the
    acceleration 9.8 g), never answered."""
    frame, _ = session
    table = frame[["t_s", "ax", "ay", "az"]].rename(columns={f"a{c}": f"a{c} [g]" for c in "xyz"})
    path = tmp_path / "says_g.csv"
    table.to_csv(path, index=False, float_format="%.17g")
    out = tmp_path / "r.json"
    assert main(["calibrate", str(path), "-o", str(out)]) == 2
    columns = _suggested(capsys.readouterr().err)
    assert main(["calibrate", str(path), "--columns", columns, "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "near 1 g" in err and "m/s2" in err and not out.exists(), err


def test_a_rotated_csv_with_a_comment_line_above_its_header_is_still_known_rotated(
    session: tuple[pd.DataFrame, pd.DataFrame], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`mountcal rotate -o x.csv`'s output with a line '# …' added above its header, rotated again: refused as
    already in the vehicle frame. Once comment lines were read past, the column frame was read from the
    header's line on (its value 'frame' among 'vehicle') and refused for that."""
    log, proto = _written(session, tmp_path)
    result = tmp_path / "r.json"
    assert main(["calibrate", str(log), "--protocol", str(proto), "-o", str(result)]) == 0
    rotated = tmp_path / "vehicle.csv"
    assert main(["rotate", str(log), "--calibration", str(result), "-o", str(rotated)]) == 0
    noted = tmp_path / "vehicle_noted.csv"
    noted.write_text("# rotated by mountcal, checked by hand\n" + rotated.read_text())
    capsys.readouterr()
    again = tmp_path / "again.csv"
    assert main(["rotate", str(noted), "--calibration", str(result), "-o", str(again)]) == 2
    err = capsys.readouterr().err
    assert "already put in the vehicle frame" in err and "'frame'" not in err, err
    assert not again.exists()


def test_a_stop_tables_columns_not_read_are_named(
    session: tuple[pd.DataFrame, pd.DataFrame], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A stop table from `mountcal stops` whose beta_deg a spreadsheet user renamed 'beta': yaw is not
    determined (no β read) and the note names the column left unread. Before: 'heading_reference: none',
    the column 'beta' never mentioned."""
    log, proto = _written(session, tmp_path)
    stops = tmp_path / "stops.csv"
    assert main(["stops", str(log), "--protocol", str(proto), "-o", str(stops)]) == 0
    renamed = tmp_path / "renamed.csv"
    pd.read_csv(stops).rename(columns={"beta_deg": "beta"}).to_csv(renamed, index=False, float_format="%.17g")
    capsys.readouterr()
    out = tmp_path / "r.json"
    assert main(["calibrate", str(renamed), "-o", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["mounting"]["yaw_deg"] is None
    assert any("columns not read: 'beta'" in n for n in result["notes"]), result["notes"]
    assert "columns not read: 'beta'" in capsys.readouterr().err


def test_rotate_refuses_recordings_joined_in_one_table_whatever_reader_reads_it(
    session: tuple[pd.DataFrame, pd.DataFrame], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Recordings joined in one table, rotated: from the comma file (the chunked native reader) and from the same
    table saved with ';' and decimal commas (the chunked reader of a dialect or column map) alike, refused where
    the clock steps back, with no file written. Before: the second sorted each chunk by time, interleaving the two
    recordings in the file it wrote (exit 0)."""
    log, proto = _written(session, tmp_path)
    result = tmp_path / "r.json"
    assert main(["calibrate", str(log), "--protocol", str(proto), "-o", str(result)]) == 0
    joined = _joined(session[0])
    comma, semicolon = tmp_path / "joined.csv", tmp_path / "joined_de.csv"
    joined.to_csv(comma, index=False, float_format="%.17g")
    joined.to_csv(semicolon, index=False, sep=";", decimal=",", float_format="%.17g")
    capsys.readouterr()
    for path in (comma, semicolon):
        out = tmp_path / f"{path.stem}_vehicle.csv"
        assert main(["rotate", str(path), "--calibration", str(result), "-o", str(out)]) == 2
        err = capsys.readouterr().err
        assert str(path) in err and "steps back" in err and "Split the log" in err, err
        assert not out.exists()


def test_times_in_32_bit_floats_coarser_than_the_samples_are_refused(
    session: tuple[pd.DataFrame, pd.DataFrame], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Unix seconds stored as float32 in a Parquet file (128 s resolution): refused naming the type. Before:
    "no parked period found". Seconds from the start as float32 (resolution 0.03 ms) read as before."""
    frame, _ = session
    coarse, fine = tmp_path / "coarse.parquet", tmp_path / "fine.parquet"
    frame.assign(t_s=frame["t_s"].astype(np.float32)).to_parquet(coarse, index=False)
    frame.assign(t_s=(frame["t_s"] - T0).astype(np.float32)).to_parquet(fine, index=False)
    out = tmp_path / "r.json"
    assert main(["calibrate", str(coarse), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "32-bit floats" in err and "resolution is 128" in err and "no parked period" not in err, err
    assert not out.exists()
    assert np.allclose(_calibrated(fine, tmp_path)[:2], TRUTH[:2], atol=1.0)


def test_raw_counts_under_mountcals_own_names_are_refused_naming_their_unit(
    session: tuple[pd.DataFrame, pd.DataFrame], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A 16-bit accelerometer's counts (2048 per g) under ax, ay, az: every row outside the physical range.
    Before: refused, "no row with numbers in all of them" (they are numbers). The map it names reads them."""
    frame, sheet = session
    counts = frame.assign(**{f"a{c}": np.round(frame[f"a{c}"] / 9.80665 * 2048) for c in "xyz"})
    path, proto = tmp_path / "counts.csv", tmp_path / "protocol.csv"
    counts.to_csv(path, index=False, float_format="%.17g")
    sheet.to_csv(proto, index=False, float_format="%.17g")
    out = tmp_path / "r.json"
    assert main(["calibrate", str(path), "--protocol", str(proto), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "no row with numbers" not in err and "g/2048" in err and not out.exists(), err
    columns = err.split("--columns ")[1].split()[0].rstrip(".")
    assert main(["calibrate", str(path), "--protocol", str(proto), "--columns", columns, "-o", str(out)]) == 0
    assert np.allclose(_angles(out), TRUTH, atol=1.0)
