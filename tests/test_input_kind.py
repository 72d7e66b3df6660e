"""One decision of what an input is — stop table or log, and which log — made by every command the
same way, from the name where it settles it and from the content where it does not (issue 23,
reproduction 5): said in the log and in the result; an undecidable table refused with the option
and the columns that settle it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from mountcal.calibration.pipeline import LogJob
from mountcal.cli import main
from mountcal.core.errors import InputError
from mountcal.estimate.triad import session_stops
from mountcal.fleet.inputs import FleetJob
from mountcal.fleet.worker import run_job
from mountcal.io.kind import input_kind
from mountcal.simulate.stops import simulate_parking_log
from mountcal.stops.table import read_stop_table

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "data"
COMMA = "comma2k19/rav4_2018-08-02--08-34-47_seg40"


@pytest.fixture
def timed_stops(tmp_path: Path) -> Path:
    """The reproduction: a stop table with t_s and temperature_c, without beta_deg or noise columns
    (one row per stop, a minute apart), as a user exports one without headings."""
    table = read_stop_table(DATA / "zhang2011_stops.csv")
    n = len(table)
    frame = pd.DataFrame(
        {
            "t_s": 1000.0 + 60.0 * np.arange(n),
            "ax": table.acc_s[:, 0],
            "ay": table.acc_s[:, 1],
            "az": table.acc_s[:, 2],
            "temperature_c": 20.0 + 0.1 * np.arange(n),
        }
    )
    path = tmp_path / "stops.csv"
    frame.to_csv(path, index=False)
    return path


@pytest.fixture
def sample_table(tmp_path: Path) -> Path:
    log = simulate_parking_log(seed=2, stop_s=20.0, rate_hz=50.0)
    path = tmp_path / "log.csv"
    pd.DataFrame({"t_s": log.t_s, "ax": log.acc_s[:, 0], "ay": log.acc_s[:, 1], "az": log.acc_s[:, 2]}).to_csv(
        path, index=False
    )
    return path


def test_a_timed_stop_table_without_headings_or_noise_is_a_stop_table_by_its_rows(
    timed_stops: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    kind = input_kind([timed_stops])
    assert kind.stop_table and "by its rows" in kind.why and "60 s apart" in kind.why
    out = tmp_path / "r.json"
    assert main(["calibrate", str(timed_stops), "--headings", "none", "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert "no parked period" not in err
    assert "input: a stop table (CSV), by its rows" in err
    result = json.loads(out.read_text())
    assert result["provenance"]["input_kind"].startswith("a stop table (CSV), by its rows")
    # the same table as triad and fleet see it: the one decision
    acc, _, _ = session_stops([str(timed_stops)], "mps2")
    assert acc.shape == (12, 3)
    record = run_job(FleetJob("v", str(timed_stops), LogJob(paths=(str(timed_stops),)), headings="none"))
    assert record["status"] == "ok" and record["input_kind"] == "stop table", record


def test_a_sample_table_is_a_log_by_its_rows_and_columns(sample_table: Path, tmp_path: Path) -> None:
    kind = input_kind([sample_table])
    assert not kind.stop_table and "per second" in kind.why
    with_gyro = tmp_path / "gyro.csv"
    frame = pd.read_csv(sample_table).head(5)
    frame.assign(gx=0.0, gy=0.0, gz=0.0).to_csv(with_gyro, index=False)
    assert input_kind([with_gyro]).why == "by its columns gx, gy, gz"
    assert input_kind([DATA / "zhang2011_stops.csv"]).why.startswith("by its columns beta_deg")


def test_a_table_its_columns_and_rows_do_not_settle_is_refused_naming_the_option(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "few.csv"
    pd.DataFrame({"t_s": [0.0, 1.0, 2.0], "ax": [0.0] * 3, "ay": [0.0] * 3, "az": [9.8] * 3}).to_csv(path, index=False)
    with pytest.raises(InputError, match="--input-kind stop-table or --input-kind log") as err:
        input_kind([path])
    assert "beta_deg" in str(err.value) and "gx, gy, gz" in str(err.value)
    assert main(["calibrate", str(path)]) == 2
    assert "--input-kind" in capsys.readouterr().err
    assert input_kind([path], declared="stop-table").stop_table
    assert not input_kind([path], declared="log").stop_table
    both = tmp_path / "both.csv"
    pd.DataFrame({"beta_deg": [0.0], "ax": [0.0], "ay": [0.0], "az": [9.8], "gx": [0.0]}).to_csv(both, index=False)
    with pytest.raises(InputError, match="both: beta_deg"):
        input_kind([both])


def test_a_stop_table_cannot_be_joined_with_logs_and_names_are_kinds(timed_stops: Path, sample_table: Path) -> None:
    with pytest.raises(InputError, match=r"a stop table .* among 2 files"):
        input_kind([sample_table, timed_stops])
    assert input_kind([DATA / "parking.blf"]).sentence == "a CAN log (BLF), by its suffix .blf"
    assert input_kind([DATA / "parking.mcap"]).what == "an MCAP log"
    assert input_kind([sample_table], dbc=True).sentence == "a CAN log (CSV), a CSV read with a DBC"
    assert input_kind(["-"]).stop_table


@pytest.mark.real_data
def test_calibrate_reads_a_comma2k19_folder_as_the_other_commands_do(
    real_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = real_data / COMMA
    kind = input_kind([folder])
    assert not kind.stop_table and kind.why == "by the folder's layout"
    out = tmp_path / "r.json"
    code = main(["calibrate", str(folder), "-o", str(out)])
    err = capsys.readouterr().err
    assert "Is a directory" not in err and "Traceback" not in err
    assert code in (0, 3), err  # a calibration, or a reason the minute of highway does not support one
    if code == 0:
        provenance = json.loads(out.read_text())["provenance"]
        assert provenance["input_kind"].startswith("a comma2k19 segment folder")
        assert len(provenance["input_sha256"][0]) == 64  # the folder's files, hashed


def test_a_fleet_worker_flags_a_cut_stop_table_read_in_part(timed_stops: Path, tmp_path: Path) -> None:
    from mountcal.io.reader import LogOptions

    cut = tmp_path / "cut.csv"
    cut.write_bytes(timed_stops.read_bytes()[:-4])  # the last row loses its last digits and line break
    job = LogJob(paths=(str(cut),), log=LogOptions(allow_truncated=True))
    record = run_job(FleetJob("v", str(cut), job, headings="none"))
    assert record["status"] == "ok" and "input_incomplete" in record["flags"], record
    refused = run_job(FleetJob("v", str(cut), LogJob(paths=(str(cut),)), headings="none"))
    assert refused["status"] == "failed" and "ends at byte" in refused["error"]
