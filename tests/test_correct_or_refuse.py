"""Issue 11's reproductions (estimator side): correct, or a clear refusal — never a traceback or a confident mirror."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from mountcal.calibration.fit import Options, calibrate
from mountcal.cli import main
from mountcal.core.errors import InputError, NotEnoughInformation
from mountcal.loop import terms
from mountcal.simulate.stops import simulate_stops
from mountcal.stops.table import read_stop_table, write_stop_table

REPO = Path(__file__).resolve().parents[1]


def _finite_json(path: Path) -> dict:
    """The document, parsed by a reader that refuses NaN and ±Infinity."""

    def refuse(token: str) -> None:
        raise AssertionError(f"non-finite number {token} in {path}")

    return json.loads(path.read_text(encoding="utf-8"), parse_constant=refuse)


def test_minimal_stop_table_writes_a_finite_result_with_null_statistics(tmp_path: Path) -> None:
    """Repro 1: only beta_deg, ax, ay, az → a written result; the χ² test that cannot exist is null with a reason."""
    full_table = pd.read_csv(REPO / "data" / "zhang2011_stops.csv")
    minimal = tmp_path / "s.csv"
    full_table[["beta_deg", "ax", "ay", "az"]].to_csv(minimal, index=False)
    out = tmp_path / "r.json"
    assert main(["calibrate", str(minimal), "-o", str(out)]) == 0
    doc = _finite_json(out)
    chi2 = next(d for d in doc["diagnostics"] if d["test"] == "chi2")
    assert chi2["statistic"] is None and chi2["p_value"] is None and chi2["log10_p"] is None
    assert "noise is unknown" in chi2["reason"]
    assert doc["fit"]["p_value"] is None and doc["fit"]["noise_scale_mps2"] > 0


def test_an_underflowing_p_value_is_written_as_a_finite_log(tmp_path: Path) -> None:
    """Repro 1b: a few stops with a tiny sx and large residuals: p underflows, log10_p stays finite."""
    table, _ = simulate_stops(slope_deg=5.0, noise_g=0.001, seed=4, samples_per_stop=1000)
    df = table.to_frame()
    df.loc[[2, 7], ["ax", "ay"]] += 0.5  # two stops far off their prediction ...
    df[["sx", "sy", "sz"]] = 1e-5  # ... with a claimed spread of 1 µm/s² per sample
    path = tmp_path / "tight.csv"
    df.to_csv(path, index=False)
    out = tmp_path / "r.json"
    assert main(["calibrate", str(path), "-o", str(out)]) == 0
    doc = _finite_json(out)
    logs = [d["log10_p"] for d in doc["diagnostics"] if d["log10_p"] is not None]
    assert min(logs) < -308  # the probability itself underflowed to 0 ...
    assert all(np.isfinite(logs))  # ... and its log is still a number
    assert doc["confident"] is False


@pytest.mark.parametrize("seed", range(1, 31))
def test_no_headings_small_slope_never_returns_the_mirror(seed: int) -> None:
    """Repro 2: roll −7°, pitch −2°, slope 1.5°, no headings: the mirror (roll ≈ 173°, slope ≈ 178°) is unphysical."""
    table, _ = simulate_stops(-7.0, -2.0, 7.0, slope_deg=1.5, headings="none", noise_g=0.005, seed=seed)
    cal = calibrate(table)
    assert 0.0 <= cal.slope_deg < 90.0  # type: ignore[operator]
    up_s = cal.rot_vs.inv().apply([0.0, 0.0, 1.0])
    assert up_s @ table.acc_s.mean(axis=0) > 0  # the sensor reads +g along the vehicle's up
    if cal.confident:
        assert abs(cal.roll_deg + 7.0) < 5 * cal.roll_sigma_deg + 0.5
        assert abs(cal.pitch_deg + 2.0) < 5 * cal.pitch_sigma_deg + 0.5


def test_the_mirror_repro_through_the_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    stops = tmp_path / "s.csv"
    args = ["--roll", "-7", "--pitch", "-2", "--slope", "1.5", "--headings", "none", "--noise-g", "0.005"]
    assert main(["simulate", *args, "--seed", "3", "-o", str(stops)]) == 0
    capsys.readouterr()
    assert main(["calibrate", str(stops)]) == 0
    out = capsys.readouterr().err.splitlines()[0]  # the answer line
    roll = float(re.search(r"roll (-?[\d.]+) ± [\d.]+°", out).group(1))  # type: ignore[union-attr]
    slope = float(re.search(r"slope (-?[\d.]+) ± [\d.]+°", out).group(1))  # type: ignore[union-attr]
    assert abs(roll + 7.0) < 1.0 and abs(slope - 1.5) < 1.0


def test_with_headings_an_upside_down_fit_is_not_confident() -> None:
    """Stops that only fit with −g up (one sensor axis negated: a left-handed triad) are never confident."""
    table, _ = simulate_stops(4.0, -3.0, 20.0, slope_deg=8.0, noise_g=0.0005, seed=2)
    from dataclasses import replace

    flipped = replace(table, acc_s=table.acc_s * np.array([1.0, 1.0, -1.0]))  # z negated: reads −g up
    try:
        cal = calibrate(flipped)
    except (NotEnoughInformation, InputError):
        return  # a refusal is a correct answer
    assert 0.0 <= cal.slope_deg < 90.0 or cal.slope_deg is None  # type: ignore[operator]
    assert not cal.confident


def test_a_term_whose_column_is_missing_is_refused_with_that_reason(tmp_path: Path) -> None:
    """Repro 6a: --model …,temperature on a table without temperature_c: an InputError naming the column."""
    table = read_stop_table(REPO / "data" / "zhang2011_stops.csv")
    with pytest.raises(InputError, match="temperature_c"):
        calibrate(table, Options(model="rotation,slope,bias,temperature"))
    with pytest.raises(InputError, match="site"):
        calibrate(table, Options(model="rotation,slope,site_slope"))


def test_a_term_the_stops_cannot_separate_is_refused_with_the_true_reason() -> None:
    """Repro 6b: --model rotation,slope,scale on a 5° slope: refused as inseparable, not as 'level ground'."""
    table, _ = simulate_stops(slope_deg=5.0, seed=1)
    with pytest.raises(NotEnoughInformation) as err:
        calibrate(table, Options(model="rotation,slope,scale"))
    message = str(err.value)
    assert "scale" in message and "confounded" in message and "level ground" not in message


def test_a_constant_temperature_is_refused() -> None:
    table, _ = simulate_stops(slope_deg=5.0, seed=1, temperature_c=np.full(12, 21.0))
    with pytest.raises(NotEnoughInformation, match="span"):
        calibrate(table, Options(model="rotation,slope,bias,temperature"))


def test_separable_fixed_terms_still_fit() -> None:
    temps = np.linspace(5.0, 35.0, 12)
    table, _ = simulate_stops(slope_deg=10.0, seed=1, temperature_c=temps, temp_coeff_mps2_per_c=np.full(3, 1e-3))
    cal = calibrate(table, Options(model="rotation,slope,bias,temperature"))
    k = cal.effect("temperature_mps2_per_c")
    assert k is not None and all(s is not None and s > 0 for s in k.sigma)
    np.testing.assert_allclose(k.value, 1e-3, atol=5 * max(s or 0.0 for s in k.sigma))


def test_the_terms_are_listed_one_way_everywhere(capsys: pytest.CaptureFixture[str]) -> None:
    """The help, the parse error and docs/commands.md come from mountcal.loop.terms (one description)."""
    with pytest.raises(SystemExit):
        main(["calibrate", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert " ".join(terms.help_text().split()) in help_text
    with pytest.raises(InputError) as err:  # refused when the options are built, before any fit
        calibrate(read_stop_table(REPO / "data" / "zhang2011_stops.csv"), Options(model="rotation,slope,wind"))
    assert terms.help_text() in str(err.value) and "wind" in str(err.value)
    assert terms.markdown_list() in (REPO / "docs" / "commands.md").read_text(encoding="utf-8")


def test_write_stop_table_round_trip_keeps_the_minimal_columns(tmp_path: Path) -> None:
    table, _ = simulate_stops(seed=5)
    path = tmp_path / "t.csv"
    write_stop_table(table, path)
    assert {"beta_deg", "ax", "ay", "az"} <= set(pd.read_csv(path).columns)


def test_a_model_that_leaves_no_values_to_estimate_the_noise_is_refused(tmp_path: Path) -> None:
    """3 stops without headings or noise columns: 9 values, and rotation, slope, bias has 9 parameters."""
    table, _ = simulate_stops(beta_deg=[0.0, 120.0, 240.0], slope_deg=10.0, seed=1)
    path, out = tmp_path / "three.csv", tmp_path / "r.json"
    table.to_frame()[["ax", "ay", "az"]].to_csv(path, index=False)
    assert main(["calibrate", str(path), "--model", "rotation,slope,bias", "-o", str(out)]) == 3
    assert not out.exists()
    assert main(["calibrate", str(path), "-o", str(out)]) == 0
    _finite_json(out)


def test_an_impossible_latitude_is_refused(tmp_path: Path) -> None:
    """Local gravity comes from the latitude: 95° N is a typo to report, not a gravity to compute."""
    df = pd.read_csv(REPO / "data" / "zhang2011_stops.csv")
    df["lat_deg"] = 95.0
    path = tmp_path / "lat.csv"
    df.to_csv(path, index=False)
    with pytest.raises(InputError, match=r"lat_deg: a latitude, a finite number in \[-90, 90\] °"):
        read_stop_table(path)


@pytest.mark.parametrize("columns", [["sx"], ["sx", "sz", "n"], ["n"]])
def test_noise_columns_given_in_part_are_refused_not_ignored(tmp_path: Path, columns: list[str]) -> None:
    df = pd.read_csv(REPO / "data" / "zhang2011_stops.csv")[["beta_deg", "ax", "ay", "az", *columns]]
    path = tmp_path / "part.csv"
    df.to_csv(path, index=False)
    with pytest.raises(InputError, match="together"):
        read_stop_table(path)
