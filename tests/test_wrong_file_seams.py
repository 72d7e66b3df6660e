"""A file that is not what the option or argument expects, given to the newer commands as to the old.

- A log (binary: MCAP, Parquet) given where a JSON or TOML document is expected (``report``, ``export``,
  ``rotate --calibration``, ``--triad``, ``--sensor-spec``): refused naming what the file is — before, a
  large one was refused as a JSON "nested 2678 levels deep" naming MOUNTCAL_MAX_DEPTH as the fix (its
  binary bytes counted as brackets), a small one as "not UTF-8: save it as UTF-8".
- A stop table given where a log of samples is expected (``rotate``, ``stops``, ``inspect``,
  ``plan --from-log``): refused naming it a stop table and the command that takes it — before, ``rotate``
  wrote its 12 rows as 12 "vehicle-frame samples", ``stops`` and ``plan`` said no parked period was
  found, ``inspect`` listed it as a 0.01 Hz sample stream.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from mcap.writer import Writer
from tests.conftest import Refused

from mountcal.cli import main
from mountcal.simulate.stops import simulate_stops


@pytest.fixture
def binary_mcap(tmp_path: Path) -> Path:
    """An MCAP of 1 MB of binary payload (as a log's CDR messages are): its bytes include [ and {."""
    path = tmp_path / "drive.mcap"
    payload = np.random.default_rng(3).normal(size=(128, 1024)).astype(np.float64)
    with path.open("wb") as f:
        w = Writer(f)
        w.start()
        schema = w.register_schema("blob", "jsonschema", b"{}")
        channel = w.register_channel("/imu", "cdr", schema)
        for i, row in enumerate(payload):
            w.add_message(channel, log_time=i * 10**7, publish_time=i * 10**7, data=row.tobytes())
        w.finish()
    return path


def _document_refusals(log: Path, result: Path, tmp: Path) -> list[tuple[list[str], Path]]:
    stops = str(result.parent / "s.csv")  # the stop table the result was calibrated from
    html, js, veh, csv = (tmp / n for n in ("out.html", "out.json", "out.parquet", "out.csv"))
    return [
        (["report", str(log), "-o", str(html)], html),
        (["export", str(log), "--to", "json", "-o", str(js)], js),
        (["rotate", str(log), "--calibration", str(log), "-o", str(veh)], veh),
        (["calibrate", stops, "--triad", str(log), "-o", str(js)], js),
        (["calibrate", stops, "--sensor-spec", str(log), "-o", str(js)], js),
        (["plan", "--noise", "1", "--target", "roll=0.5", "--triad", str(log), "-o", str(csv)], csv),
    ]


def test_an_mcap_given_for_a_json_document_is_named_an_mcap_log(
    binary_mcap: Path, result: Path, tmp_path: Path, refused: Refused
) -> None:
    for argv, output in _document_refusals(binary_mcap, result, tmp_path):
        err = refused(argv, output)
        assert "an MCAP log" in err, (argv, err)
        assert "MOUNTCAL_MAX_DEPTH" not in err and "UTF-8" not in err, (argv, err)


def test_a_parquet_table_given_as_a_calibration_is_named_a_parquet_table(
    result: Path, tmp_path: Path, refused: Refused
) -> None:
    table = tmp_path / "log.json"  # a Parquet named for what the option expects
    pq.write_table(pa.table({"t_s": np.arange(1000.0), "ax": np.zeros(1000)}), table)
    err = refused(["export", str(table), "--to", "json", "-o", str(tmp_path / "e.json")], tmp_path / "e.json")
    assert "a Parquet table" in err and "UTF-8" not in err


def test_a_text_document_in_another_encoding_is_still_told_to_be_saved_as_utf8(
    tmp_path: Path, refused: Refused
) -> None:
    spec = tmp_path / "spec.toml"
    spec.write_bytes("# Beschleunigungssensor, Genauigkeit \xb1 3 %\nscale = 0.03\n".encode("latin-1"))
    stops = tmp_path / "s.csv"
    assert main(["simulate", "-q", "-o", str(stops)]) == 0
    out = tmp_path / "r.json"
    err = refused(["calibrate", str(stops), "--sensor-spec", str(spec), "-o", str(out)], out)
    assert "UTF-8" in err


@pytest.fixture
def stop_table(tmp_path: Path) -> Path:
    """A stop table as mountcal stops writes one (t_s among its columns), written with pandas."""
    table, _ = simulate_stops(5.0, 6.0, 7.0, slope_deg=5.0, seed=1)
    frame = table.to_frame()
    frame["t_s"] = 1714557600.0 + 60.0 * np.arange(len(frame))
    path = tmp_path / "stops.csv"
    frame.to_csv(path, index=False)
    return path


def test_a_stop_table_given_where_a_log_is_expected_is_refused_naming_calibrate(
    stop_table: Path, result: Path, tmp_path: Path, refused: Refused
) -> None:
    cases = [
        (["rotate", str(stop_table), "--calibration", str(result), "-o", str(tmp_path / "v.parquet")], "v.parquet"),
        (["stops", str(stop_table), "-o", str(tmp_path / "st.csv")], "st.csv"),
        (["inspect", str(stop_table)], "none"),
        (["plan", "--target", "roll=0.5", "--from-log", str(stop_table), "-o", str(tmp_path / "p.csv")], "p.csv"),
    ]
    for argv, name in cases:
        err = refused(argv, tmp_path / name)
        assert "a stop table" in err and "beta_deg" in err and "mountcal calibrate" in err, (argv, err)


def test_the_stop_table_still_calibrates_and_a_column_map_still_reads_it_as_samples(
    stop_table: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["calibrate", "-q", str(stop_table), "-o", str(tmp_path / "r.json")]) == 0
    capsys.readouterr()
    assert main(["inspect", str(stop_table), "--columns", "time=t_s,ax=ax,ay=ay,az=az"]) == 0  # said: samples
    assert "12 msgs" in capsys.readouterr().err
    assert len(pd.read_csv(stop_table)) == 12


@pytest.mark.invalid_results
def test_a_result_cut_short_or_empty_is_said_to_be_so(result: Path, tmp_path: Path, refused: Refused) -> None:
    """A JSON document that ends before its JSON does (an interrupted copy) was "invalid JSON (Expecting value:
    line 10 column 16 (char 500)). Fix or re-export the file."; an empty one "Expecting value: line 1 column 1"."""
    raw = result.read_bytes()
    cut, empty = tmp_path / "cut.json", tmp_path / "empty.json"
    cut.write_bytes(raw[: len(raw) // 2])
    empty.write_bytes(b"")
    out = tmp_path / "e.json"
    err = refused(["export", str(cut), "--to", "json", "-o", str(out)], out)
    assert f"ends at byte {len(raw) // 2}" in err and "cut short" in err, err
    err = refused(["report", str(empty), "-o", str(tmp_path / "r.html")], tmp_path / "r.html")
    assert "an empty file (0 bytes)" in err, err
    broken = tmp_path / "broken.json"  # not cut: a mistake inside is still said as the parser says it
    broken.write_bytes(raw.replace(b'"confident"', b'"confident', 1))
    err = refused(["export", str(broken), "--to", "json", "-o", str(out)], out)
    assert "invalid JSON" in err and "cut short" not in err, err
