"""The stop-table input, the result file and the command line, including bad input."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from mountcal.calibration.fit import calibrate
from mountcal.cli import main
from mountcal.core.errors import InputError, NotEnoughInformation
from mountcal.core.result import FORMAT_VERSION, Calibration
from mountcal.simulate.stops import simulate_preset
from mountcal.stops.table import StopTable, checked, read_stop_table, write_stop_table

REPO = Path(__file__).resolve().parents[1]
SAMPLE = REPO / "data" / "zhang2011_stops.csv"


@pytest.fixture
def stops_csv(tmp_path: Path) -> Path:
    table, _ = simulate_preset("zhang2011", seed=21)
    path = tmp_path / "stops.csv"
    write_stop_table(table, path)
    return path


def run_cli(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(args)
    out = capsys.readouterr()
    return code, out.out, out.err


def test_calibrate_writes_a_result_with_every_documented_field(
    stops_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "result.json"
    code, stdout, text = run_cli(["calibrate", str(stops_csv), "-o", str(out)], capsys)
    assert code == 0 and stdout == ""
    assert "roll" in text and "±" in text and "model: rotation, slope" in text
    doc = json.loads(out.read_text())
    for key in ("roll_deg", "pitch_deg", "yaw_deg"):
        assert isinstance(doc["mounting"][key], float)
        assert doc["uncertainty"][key] > 0
    assert doc["model"] == ["rotation", "slope"]
    assert doc["format_version"] == FORMAT_VERSION
    assert doc["conventions"]["euler"].startswith("rot_vs = Rz(yaw) Ry(pitch) Rx(roll)")
    assert [len(h) for h in doc["provenance"]["input_sha256"]] == [64]  # one file, its SHA-256
    assert doc["provenance"]["method"] == "full"
    fit = doc["fit"]
    assert fit["p_value"] is not None and fit["log10_p"] == pytest.approx(np.log10(fit["p_value"]), rel=1e-9)
    assert doc["slope_deg"] == pytest.approx(5.0, abs=0.1)
    assert doc["residual_rms_mps2"] > 0
    assert doc["observability"]["fisher_rank"] == 4


@pytest.mark.invalid_results  # a version from the future, refused on purpose
def test_result_round_trips_and_unknown_versions_are_refused(stops_csv: Path, tmp_path: Path) -> None:
    from mountcal.calibration.fit import calibrate

    cal = calibrate(read_stop_table(stops_csv))
    path = tmp_path / "r.json"
    cal.save(path)
    back = Calibration.load(path)
    assert (back.rot_vs.inv() * cal.rot_vs).magnitude() < 1e-12
    assert back.to_dict()["mounting"] == cal.to_dict()["mounting"]
    doc = json.loads(path.read_text())
    doc["format_version"] = FORMAT_VERSION + 1
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError, match="format_version"):
        Calibration.load(path)


def test_no_headings_writes_null_yaw_with_a_reason(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    table, _ = simulate_preset("zhang2011", headings="none", seed=2)
    src = tmp_path / "s.csv"
    write_stop_table(table, src)
    out = tmp_path / "r.json"
    code, _, text = run_cli(["calibrate", str(src), "-o", str(out)], capsys)
    assert code == 0 and "  yaw undetermined  " in text.splitlines()[0] and "yaw undetermined: no headings" in text
    doc = json.loads(out.read_text())
    assert doc["mounting"]["yaw_deg"] is None and doc["uncertainty"]["yaw_deg"] is None
    assert "no headings" in doc["yaw"]["reason"]


def test_paper_method_and_g_units(stops_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    df = pd.read_csv(stops_csv)
    df[["ax", "ay", "az", "sx", "sy", "sz"]] /= 9.80665
    in_g = tmp_path / "g.parquet"
    df.to_parquet(in_g)
    a = tmp_path / "a.json"
    b = tmp_path / "b.json"
    assert run_cli(["calibrate", str(stops_csv), "--method", "paper", "-o", str(a)], capsys)[0] == 0
    assert run_cli(["calibrate", str(in_g), "--unit", "g", "--method", "paper", "-o", str(b)], capsys)[0] == 0
    ma, mb = json.loads(a.read_text())["mounting"], json.loads(b.read_text())["mounting"]
    assert ma == pytest.approx(mb, abs=1e-9)


BAD_TABLES = {
    "missing column": (lambda df: df.drop(columns=["az"]), "no column az"),
    "NaN": (lambda df: df.assign(ay=df["ay"].where(df.index != 4)), "row 5 column ay"),
    "fewer than 3 stops": (lambda df: df.head(2), "at least 3 stops"),
    "one heading only": (lambda df: df.assign(beta_deg=30.0), "different headings"),
    "g given as m/s²": (lambda df: df.assign(ax=df.ax / 9.8, ay=df.ay / 9.8, az=df.az / 9.8), "add --unit g"),
    "not gravity": (lambda df: df.assign(az=df.az * 3), "magnitude near gravity"),
    "negative spread": (lambda df: df.assign(sx=-1.0), "sx, sy, sz: the spread of a stop's samples"),
}


@pytest.mark.parametrize("case", list(BAD_TABLES))
def test_bad_stop_tables_fail_clearly_without_output(
    case: str, stops_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    change, expected = BAD_TABLES[case]
    bad = tmp_path / "bad.csv"
    change(pd.read_csv(stops_csv)).to_csv(bad, index=False)
    before = bad.read_bytes()
    out = tmp_path / "result.json"
    code, text, err = run_cli(["calibrate", str(bad), "-o", str(out)], capsys)
    assert code != 0
    assert str(bad) in err and expected in err, err
    assert "Traceback" not in err and text == ""
    assert not out.exists()
    assert list(tmp_path.glob(".result.json*")) == []
    assert bad.read_bytes() == before


def test_g_units_without_the_flag_suggest_it(
    stops_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    df = pd.read_csv(stops_csv)
    df[["ax", "ay", "az"]] /= 9.80665
    p = tmp_path / "g.csv"
    df.to_csv(p, index=False)
    code, _, err = run_cli(["calibrate", str(p)], capsys)
    assert code == 2 and "add --unit g" in err


def test_unreadable_and_missing_files(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_cli(["calibrate", str(tmp_path / "nope.csv")], capsys)
    assert code == 2 and "nope.csv" in err and "Check the path" in err
    junk = tmp_path / "junk.parquet"
    junk.write_bytes(b"\x00\x01not parquet")
    code, _, err = run_cli(["calibrate", str(junk)], capsys)
    assert code == 2 and "junk.parquet" in err and "does not parse" in err


def test_output_never_overwrites_the_input(stops_csv: Path, capsys: pytest.CaptureFixture[str]) -> None:
    before = stops_csv.read_bytes()
    code, _, err = run_cli(["calibrate", str(stops_csv), "-o", str(stops_csv)], capsys)
    assert code == 2 and "never overwrites its input" in err
    assert stops_csv.read_bytes() == before


def test_simulate_then_calibrate_recovers_the_truth(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    stops, truth, res = tmp_path / "s.parquet", tmp_path / "t.json", tmp_path / "r.json"
    assert (
        main(
            [
                "simulate",
                "--roll",
                "-3",
                "--pitch",
                "2",
                "--yaw",
                "120",
                "--bias-mg",
                "10",
                "-15",
                "5",
                "--seed",
                "4",
                "-o",
                str(stops),
                "--truth",
                str(truth),
            ]
        )
        == 0
    )
    assert main(["calibrate", str(stops), "-o", str(res)]) == 0
    capsys.readouterr()
    t, r = json.loads(truth.read_text()), json.loads(res.read_text())
    assert r["model"] == ["rotation", "slope", "bias"]
    for key in ("roll_deg", "pitch_deg", "yaw_deg"):
        assert abs(r["mounting"][key] - t[key]) < 4 * r["uncertainty"][key]
    np.testing.assert_allclose(r["bias_mps2"], t["bias_mps2"], atol=4 * max(r["uncertainty"]["bias_mps2"]))


def test_bundled_sample_is_the_simulator_output(tmp_path: Path) -> None:
    """data/zhang2011_stops.csv is regenerated bit for bit by the command in data/README.md."""
    again = tmp_path / "again.csv"
    assert main(["simulate", "--preset", "zhang2011", "--seed", "2011", "-o", str(again)]) == 0
    assert again.read_bytes() == SAMPLE.read_bytes()


# --- the stop table in memory: the full covariance of each stop mean --------------------------------


def _correlated(seed: int = 4) -> StopTable:
    """A simulated table whose stop means have strongly correlated axes (vibration along one direction)."""
    table, _ = simulate_preset("zhang2011", seed=seed)
    rng = np.random.default_rng(seed)
    axes = Rotation.random(len(table), random_state=rng).as_matrix()
    spread = np.diag([4e-3, 5e-4, 5e-4]) ** 2  # one direction ten times noisier than the others
    cov = axes @ spread @ axes.transpose(0, 2, 1)
    noise = np.einsum("nij,nj->ni", np.linalg.cholesky(cov), rng.standard_normal((len(table), 3)))
    return replace(table, acc_s=table.acc_s + noise, cov_s=cov)


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_the_file_form_keeps_the_off_diagonal_covariance(tmp_path: Path, suffix: str) -> None:
    table = _correlated()
    path = tmp_path / f"stops{suffix}"
    write_stop_table(table, path)
    frame = pd.read_csv(path) if suffix == ".csv" else pd.read_parquet(path)
    assert {"sx", "sy", "sz", "n", "rxy", "rxz", "ryz"} <= set(frame.columns)
    back = read_stop_table(path)
    assert back.cov_s is not None and table.cov_s is not None
    np.testing.assert_allclose(back.cov_s, table.cov_s, rtol=1e-12, atol=0)
    assert abs(back.cov_s[:, 0, 1]).max() > 0.1 * np.sqrt(back.cov_s[:, 0, 0] * back.cov_s[:, 1, 1]).max()
    assert calibrate(back).fit.chi2 == pytest.approx(calibrate(table).fit.chi2, rel=1e-9)


def test_the_fit_weighs_by_the_full_covariance() -> None:
    """Turning the sensor frame turns the means and their covariances (Q C Qᵀ): χ² stays the same and
    the rotation turns with it only if the fit uses the whole matrix, not its diagonal."""
    table = _correlated()
    assert table.cov_s is not None
    q = Rotation.from_euler("xyz", [30.0, -50.0, 70.0], degrees=True)
    m = q.as_matrix()
    turned = replace(table, acc_s=table.acc_s @ m.T, cov_s=m @ table.cov_s @ m.T)
    a, b = calibrate(table), calibrate(turned)
    assert b.fit.chi2 == pytest.approx(a.fit.chi2, rel=1e-6)
    assert float(np.degrees(((b.rot_vs * q) * a.rot_vs.inv()).magnitude())) < 1e-6
    diagonal = np.zeros_like(table.cov_s)
    diagonal[:, [0, 1, 2], [0, 1, 2]] = table.cov_s[:, [0, 1, 2], [0, 1, 2]]
    assert calibrate(replace(table, cov_s=diagonal)).fit.chi2 != pytest.approx(a.fit.chi2, rel=1e-3)


def test_impossible_correlations_are_refused_naming_the_rows(tmp_path: Path) -> None:
    path = tmp_path / "stops.csv"
    write_stop_table(_correlated(), path)
    frame = pd.read_csv(path)
    frame.loc[2, "rxy"] = 1.5
    frame.to_csv(path, index=False)
    with pytest.raises(InputError, match="rows 3"):
        read_stop_table(path)
    frame.drop(columns=["rxz"]).to_csv(path, index=False)
    with pytest.raises(InputError, match="rxy, rxz, ryz together"):
        read_stop_table(path)


def test_a_stop_table_built_in_memory_is_checked_like_a_file() -> None:
    table = _correlated()
    assert checked(table) is table
    with pytest.raises(NotEnoughInformation, match="at least 3 stops"):
        checked(table.subset(np.arange(2)))
    with pytest.raises(InputError, match="near gravity"):
        checked(replace(table, acc_s=table.acc_s * 3.0))
    assert table.cov_s is not None
    flat = table.cov_s.copy()
    flat[1] = 0.0
    with pytest.raises(InputError, match="stops 2"):
        checked(replace(table, cov_s=flat))
