"""The unit of a table's time column (mountcal.io.table.time_unit): stated by the name ``t_s``, the column
map, a Parquet type or ISO text; checked against the spacing; inferred and said where a map names none.
The tables are written by pandas and pyarrow themselves."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from mountcal.cli import main
from mountcal.core.errors import InputError
from mountcal.io.logs import iter_log, read_log
from mountcal.io.reader import LogOptions
from mountcal.io.table.layout import parse_columns
from mountcal.simulate.stops import simulate_parking_log

EPOCH = pd.Timestamp("2024-05-01T10:00:00")


@pytest.fixture(scope="module")
def frame() -> pd.DataFrame:
    """A parking session at 100 Hz, t_s in seconds from zero (mountcal's own columns)."""
    log = simulate_parking_log(seed=7, stop_s=20.0, drive_s=15.0, rate_hz=100.0)
    columns = {"t_s": log.t_s} | {f"a{c}": log.acc_s[:, i] for i, c in enumerate("xyz")}
    columns |= {f"g{c}": log.gyro_s[:, i] for i, c in enumerate("xyz")}
    return pd.DataFrame(columns | {"speed_mps": log.speed_mps, "heading_deg": log.heading_deg})


def _calibrate(path: Path, tmp_path: Path, *args: str) -> dict[str, object]:
    out = tmp_path / f"{path.stem}.json"
    assert main(["calibrate", str(path), "-o", str(out), *args]) == 0
    result: dict[str, object] = json.loads(out.read_text())
    return result


def _angles(result: dict[str, object]) -> np.ndarray:
    m = result["mounting"]
    assert isinstance(m, dict)
    return np.array([m["roll_deg"], m["pitch_deg"], result["slope_deg"]], dtype=float)


def _time_unit(result: dict[str, object]) -> dict[str, str]:
    prov = result["provenance"]
    assert isinstance(prov, dict)
    found = [c for c in prov["conventions"] if c["name"] == "time_unit"]
    assert len(found) == 1, prov["conventions"]
    return dict(found[0])


@pytest.fixture(scope="module")
def seconds(frame: pd.DataFrame, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, np.ndarray]:
    tmp = tmp_path_factory.mktemp("seconds")
    path = tmp / "seconds.csv"
    frame.to_csv(path, index=False, float_format="%.17g")
    return path, _angles(_calibrate(path, tmp))


@pytest.mark.parametrize(("unit", "factor"), [("ms", 1e3), ("ns", 1e9)])
def test_ms_or_ns_under_t_s_are_refused_naming_the_column_the_step_and_the_fix(
    frame: pd.DataFrame, tmp_path: Path, capsys: pytest.CaptureFixture[str], unit: str, factor: float
) -> None:
    table = frame.assign(t_s=np.round(frame["t_s"] * factor).astype(np.int64))
    path = tmp_path / f"{unit}.csv"
    table.to_csv(path, index=False)
    out = tmp_path / "r.json"
    assert main(["calibrate", str(path), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and not out.exists()
    assert "no parked period" not in err  # the old, wrong reason
    assert "time column t_s" in err and f"median step of {0.01 * factor:g}" in err
    assert f"in {unit} it would be 100 Hz" in err and f"--columns time=t_s:{unit},ax=ax" in err
    # the fix it names reads the table
    fix = err.split("--columns ")[1].rstrip().rstrip(".")
    assert main(["stops", str(path), "--columns", fix, "-o", str(tmp_path / "stops.csv")]) == 0


def test_a_map_without_a_time_unit_on_ms_infers_it_and_says_so(
    frame: pd.DataFrame, seconds: tuple[Path, np.ndarray], tmp_path: Path
) -> None:
    table = frame.rename(columns={"t_s": "timestamp"}).assign(timestamp=np.round(frame["t_s"] * 1e3).astype(np.int64))
    path = tmp_path / "ms_map.csv"
    table.to_csv(path, index=False, float_format="%.17g")
    columns = "time=timestamp,ax=ax,ay=ay,az=az,gx=gx,gy=gy,gz=gz,speed=speed_mps,heading=heading_deg"
    result = _calibrate(path, tmp_path, "--columns", columns)
    said = _time_unit(result)
    assert said["value"] == "ms" and said["how"] == "inferred" and "median step of 10" in said["by"]
    np.testing.assert_allclose(_angles(result), seconds[1], rtol=1e-9)


def test_chunks_of_an_inferred_unit_are_read_alike(frame: pd.DataFrame, tmp_path: Path) -> None:
    table = frame.rename(columns={"t_s": "stamp"}).assign(stamp=np.round(frame["t_s"] * 1e3).astype(np.int64))
    path = tmp_path / "ms.csv"
    table.to_csv(path, index=False)
    opts = LogOptions(columns=parse_columns("time=stamp,ax=ax,ay=ay,az=az"))
    chunks = list(iter_log(path, opts, max_samples=1000))
    assert len(chunks) > 5
    t = np.concatenate([c.t_s for c in chunks])
    np.testing.assert_allclose(t, frame["t_s"].to_numpy(), atol=1e-9)
    assert all(any(c.name == "time_unit" and c.value == "ms" for c in chunk.conventions) for chunk in chunks)


@pytest.mark.parametrize("zone", [None, "UTC", "Europe/Berlin"])
def test_a_parquet_timestamp_t_s_is_read_as_epoch_seconds_and_stated(
    frame: pd.DataFrame, seconds: tuple[Path, np.ndarray], tmp_path: Path, zone: str | None
) -> None:
    stamps = EPOCH + pd.to_timedelta(np.round(frame["t_s"] * 1e9).astype(np.int64), unit="ns")
    table = frame.assign(t_s=stamps if zone is None else stamps.dt.tz_localize("UTC").dt.tz_convert(zone))
    path = tmp_path / "stamped.parquet"
    table.to_parquet(path)  # pandas' writer: datetime64[ns] (with its zone)
    result = _calibrate(path, tmp_path)
    said = _time_unit(result)
    assert said["value"] == "timestamp" and said["how"] == "stated" and "type" in said["by"]
    epoch = (EPOCH - pd.Timestamp("1970-01-01")).total_seconds()
    got = read_log(path)
    np.testing.assert_allclose(got.t_s - epoch, frame["t_s"].to_numpy(), atol=1e-6)  # float seconds at 1.7e9
    np.testing.assert_allclose(_angles(result), seconds[1], atol=1e-3)  # the stops' edges move by < 1 µs


def test_a_pyarrow_timestamp_us_and_a_duration_read_as_seconds(frame: pd.DataFrame, tmp_path: Path) -> None:
    table = pa.Table.from_pandas(frame, preserve_index=False)
    micro = pa.array(np.round(frame["t_s"].to_numpy() * 1e6).astype(np.int64))
    stamped = table.set_column(0, "t_s", micro.cast(pa.timestamp("us")))
    pq.write_table(stamped, tmp_path / "us.parquet")
    lasting = table.set_column(0, "t_s", micro.cast(pa.duration("us")))
    pq.write_table(lasting, tmp_path / "duration.parquet")
    for name in ("us.parquet", "duration.parquet"):
        got = read_log(tmp_path / name)
        np.testing.assert_allclose(got.t_s, frame["t_s"].to_numpy(), atol=1e-9, err_msg=name)
        unit = next(c for c in got.conventions if c.name == "time_unit")
        assert unit.how == "stated" and unit.value in ("timestamp", "duration")


def test_iso_text_under_t_s_is_read_as_date_times(frame: pd.DataFrame, tmp_path: Path) -> None:
    stamps = EPOCH + pd.to_timedelta(np.round(frame["t_s"] * 1e9).astype(np.int64), unit="ns")
    path = tmp_path / "iso.csv"
    frame.assign(t_s=stamps.dt.strftime("%Y-%m-%dT%H:%M:%S.%f")).drop(columns=["gx", "gy", "gz"]).to_csv(
        path, index=False
    )
    got = read_log(path)
    epoch = (EPOCH - pd.Timestamp("1970-01-01")).total_seconds()
    np.testing.assert_allclose(got.t_s - epoch, frame["t_s"].to_numpy(), atol=1e-6)
    unit = next(c for c in got.conventions if c.name == "time_unit")
    assert unit.value == "iso" and "ISO-8601" in unit.by


def test_a_map_unit_against_the_columns_type_is_refused(frame: pd.DataFrame, tmp_path: Path) -> None:
    stamps = EPOCH + pd.to_timedelta(np.round(frame["t_s"] * 1e9).astype(np.int64), unit="ns")
    path = tmp_path / "stamped.parquet"
    frame.assign(t_s=stamps).to_parquet(path)
    with pytest.raises(InputError, match="timestamp type") as err:
        read_log(path, LogOptions(columns=parse_columns("time=t_s:ms,ax=ax,ay=ay,az=az")))
    assert "'time=t_s'" in str(err.value)  # the map without the unit (the type states it)


def test_slow_tables_and_gaps_raise_no_false_alarm(frame: pd.DataFrame, tmp_path: Path) -> None:
    gap = frame.assign(t_s=frame["t_s"] + np.where(frame.index >= len(frame) // 2, 600.0, 0.0))  # a 10-min gap
    jitter = frame.assign(t_s=frame["t_s"] + np.random.default_rng(1).uniform(0, 0.004, len(frame)))
    slow = frame.iloc[::20].assign(t_s=frame["t_s"].iloc[::20])  # 5 Hz
    for name, table in (("gap", gap), ("jitter", jitter), ("slow", slow)):
        path = tmp_path / f"{name}.csv"
        table.to_csv(path, index=False, float_format="%.17g")
        got = read_log(path)
        unit = next(c for c in got.conventions if c.name == "time_unit")
        assert unit.value == "s" and unit.how == "stated" and "checked" in unit.by, name


def test_a_genuine_slow_log_and_a_table_of_stops_are_read_in_seconds_and_their_spacing_said(
    frame: pd.DataFrame, tmp_path: Path
) -> None:
    """A name's unit is doubted only on a log's evidence: a 1 Hz log in seconds (telematics logs so; in ms it
    would be 1 kHz) and a short table of stop means two minutes apart are read in seconds, said as slow."""
    telematics = frame.iloc[::100].assign(t_s=np.arange(len(frame.iloc[::100]), dtype=float))  # 1 Hz
    stops = frame.iloc[:12].assign(t_s=120.0 * np.arange(12))  # 12 rows, 120 s apart
    for name, table, hz in (("telematics", telematics, "1 Hz"), ("stops", stops, "0.008333 Hz")):
        path = tmp_path / f"{name}.csv"
        table.to_csv(path, index=False, float_format="%.17g")
        got = read_log(path)
        unit = next(c for c in got.conventions if c.name == "time_unit")
        assert unit.value == "s" and unit.how == "stated", name
        assert f"its spacing: {hz}, slower than an IMU's; in ms it would be" in unit.by, (name, unit.by)
        assert got.t_s[1] - got.t_s[0] == pytest.approx(1.0 if name == "telematics" else 120.0)


def test_a_unit_the_user_states_in_the_map_is_read_as_stated(frame: pd.DataFrame, tmp_path: Path) -> None:
    """ms data read as ``time=t_s:s`` because the user says so: read in seconds, the spacing said beside it."""
    path = tmp_path / "ms.csv"
    frame.assign(t_s=np.round(frame["t_s"] * 1e3).astype(np.int64)).to_csv(path, index=False)
    got = read_log(path, LogOptions(columns=parse_columns("time=t_s:s,ax=ax,ay=ay,az=az")))
    unit = next(c for c in got.conventions if c.name == "time_unit")
    assert unit.value == "s" and "in ms it would be 100 Hz" in unit.by
    assert got.t_s[1] - got.t_s[0] == pytest.approx(10.0)


def test_an_unstated_unit_the_spacing_cannot_settle_is_asked_for(frame: pd.DataFrame, tmp_path: Path) -> None:
    slow = frame.iloc[::20].rename(columns={"t_s": "time"})  # 5 Hz in s, or 5 kHz in ms
    path = tmp_path / "slow.csv"
    slow.to_csv(path, index=False, float_format="%.17g")
    with pytest.raises(InputError, match="the unit of the time column time") as err:
        read_log(path, LogOptions(columns=parse_columns("time=time,ax=ax,ay=ay,az=az")))
    assert "s or ms (5 Hz, 5000 Hz)" in str(err.value) and "time=time:ms" in str(err.value)
    got = read_log(path, LogOptions(columns=parse_columns("time=time:s,ax=ax,ay=ay,az=az")))  # stated: read
    assert got.t_s[1] - got.t_s[0] == pytest.approx(0.2)


def test_ms_without_a_gyro_is_not_taken_for_a_stop_table(
    frame: pd.DataFrame, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    table = frame[["t_s", "ax", "ay", "az"]].assign(t_s=np.round(frame["t_s"] * 1e3).astype(np.int64))
    path = tmp_path / "ms.csv"
    table.to_csv(path, index=False, float_format="%.17g")
    assert main(["calibrate", str(path), "-o", str(tmp_path / "r.json")]) == 2
    err = capsys.readouterr().err
    assert "samples at 100 Hz with t_s in ms" in err and "--columns time=t_s:ms,ax=ax,ay=ay,az=az" in err


def test_a_mapped_column_named_with_its_unit_states_it(frame: pd.DataFrame, tmp_path: Path) -> None:
    ms = np.round(frame["t_s"] * 1e3).astype(np.int64)
    path = tmp_path / "named.csv"
    frame.assign(stamp_ms=ms, t_s=ms).to_csv(path, index=False, float_format="%.17g")
    got = read_log(path, LogOptions(columns=parse_columns("time=stamp_ms,ax=ax,ay=ay,az=az")))
    unit = next(c for c in got.conventions if c.name == "time_unit")
    assert (unit.value, unit.how) == ("ms", "stated") and "column name stamp_ms" in unit.by
    np.testing.assert_allclose(got.t_s, frame["t_s"].to_numpy(), atol=1e-9)
    with pytest.raises(InputError, match="in ms it would be 100 Hz"):  # t_s mapped: its name says s
        read_log(path, LogOptions(columns=parse_columns("time=t_s,ax=ax,ay=ay,az=az")))


# --------------------------------------------------------------------------- times written as text


def _clock(seconds: np.ndarray, start: str, sep: str) -> list[str]:
    """Times of day as Physics Toolbox Sensor Suite writes them (``HH:MM:SS:mmm``; ``.``: a fraction)."""
    t = pd.Timestamp(start) + pd.to_timedelta(np.round(seconds * 1e3), unit="ms")
    return [f"{x:%H:%M:%S}{sep}{x.microsecond // 1000:03d}" for x in t]


@pytest.mark.parametrize(("start", "sep"), [("2024-05-01T10:00:00", ":"), ("2024-05-01T23:58:00", ".")])
def test_times_of_day_are_read_as_seconds_since_midnight_carried_over_it(
    frame: pd.DataFrame, seconds: tuple[Path, np.ndarray], tmp_path: Path, start: str, sep: str
) -> None:
    """Physics Toolbox Sensor Suite's g-force export with its ``HH:MM:SS:mmm`` times (and one starting two
    minutes before midnight, as ``HH:MM:SS.fff``): the angles of the table in seconds. Before: refused, "no
    row with numbers" (the times read as numbers); past midnight the day after would have sorted first."""
    table = pd.DataFrame(
        {"time": _clock(frame["t_s"].to_numpy(), start, sep)}
        | {f"gF{c}": frame[f"a{c}"] / 9.80665 for c in "xyz"}
        | {f"w{c}": frame[f"g{c}"] for c in "xyz"}
    )
    path = tmp_path / "ptss.csv"
    table.to_csv(path, index=False, float_format="%.17g")
    result = _calibrate(path, tmp_path)
    assert _time_unit(result)["value"] == "clock" and "time of day" in _time_unit(result)["by"]
    np.testing.assert_allclose(_angles(result), seconds[1], atol=0.02)
    got = read_log(path, LogOptions())  # the samples in their own order, past midnight too
    np.testing.assert_allclose(got.t_s - got.t_s[0], frame["t_s"] - frame["t_s"].iloc[0], atol=1.5e-3)


def test_time_text_that_is_no_date_time_is_refused_naming_it(
    frame: pd.DataFrame, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """MATLAB's default date-time text ('01-May-2024 10:00:00.000'). Before: refused, "no distinct times"."""
    text = (EPOCH + pd.to_timedelta(frame["t_s"], unit="s")).dt.strftime("%d-%b-%Y %H:%M:%S.%f").str[:-3]
    path = tmp_path / "matlab.csv"
    frame.assign(Timestamp=text).drop(columns="t_s").to_csv(path, index=False, float_format="%.17g")
    out = tmp_path / "r.json"
    assert main(["calibrate", str(path), "--columns", "time=Timestamp,ax=ax,ay=ay,az=az", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "'01-May-2024 10:00:00.000'" in err and "ISO-8601" in err and "no distinct times" not in err, err
    assert not out.exists()


def test_a_spreadsheets_serial_days_are_refused_as_such(
    frame: pd.DataFrame, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Unix seconds turned into a spreadsheet's serial days under t_s. Before: "no parked period found"
    (100 Hz read as 8.6 MHz), or with a protocol sheet "the log's clock has no date"."""
    days = (EPOCH.timestamp() + frame["t_s"]) / 86400.0 + 25569.0
    path = tmp_path / "days.csv"
    frame.assign(t_s=days).to_csv(path, index=False, float_format="%.17g")
    out = tmp_path / "r.json"
    assert main(["calibrate", str(path), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "serial days" in err and "100 Hz in days" in err and "no parked period" not in err, err
    assert not out.exists()
