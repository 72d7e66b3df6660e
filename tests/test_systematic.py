"""Systematic (Type B) uncertainty: the sensor's limits through the final fit, beside and inside the σ."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from mountcal.calibration.fit import Options, calibrate
from mountcal.cli import main
from mountcal.core.conventions import G_N
from mountcal.core.result import Calibration
from mountcal.estimate import full
from mountcal.io.sensor_spec import DEFAULT, SensorSpec, read_spec
from mountcal.loop import systematic
from mountcal.simulate.stops import simulate_stops
from mountcal.stops.table import StopTable, write_stop_table

BIAS_ONLY = SensorSpec(
    scale=0.0, cross_axis=0.0, bias_mps2=0.5, bias_tempco_mps2_per_c=0.0, heading_deg=0.0, source="test: bias only"
)
SENSOR_ONLY = replace(DEFAULT, heading_deg=0.0, source="test: the default sensor, exact headings")


@pytest.fixture(scope="module")
def table() -> StopTable:
    return simulate_stops(12.0, -4.0, 33.0, slope_deg=7.0, noise_g=0.002, seed=11)[0]


def _parts(cal: Calibration, key: str) -> tuple[float, float]:
    assert cal.systematic is not None
    stat, sys = cal.systematic.statistical[key], cal.systematic.systematic[key]
    assert stat is not None and sys is not None
    return stat, sys


def test_the_sigma_fields_hold_the_root_sum_of_squares_of_both_parts(table: StopTable) -> None:
    cal = calibrate(table)
    for key in ("roll_deg", "pitch_deg", "yaw_deg", "slope_deg"):
        stat, sys = _parts(cal, key)
        assert getattr(cal, key.replace("_deg", "_sigma_deg")) == pytest.approx(np.hypot(stat, sys), rel=1e-12)
        assert sys > 0  # the default class: one slope cannot see scale and cross-axis


def test_duplicating_stops_shrinks_only_the_statistical_part(table: StopTable) -> None:
    opts = Options(model="rotation,slope,bias", spec=SENSOR_ONLY)
    a, b = calibrate(table, opts), calibrate(table.subset(np.repeat(np.arange(len(table)), 2)), opts)
    for key in ("roll_deg", "pitch_deg", "yaw_deg"):
        (sa, ya), (sb, yb) = _parts(a, key), _parts(b, key)
        assert sb == pytest.approx(sa / np.sqrt(2), rel=1e-6)
        assert yb == pytest.approx(ya, rel=0.01)  # only what the residual sees of the errors narrows


def test_an_error_the_model_fits_contributes_nothing(table: StopTable) -> None:
    fitted = calibrate(table, Options(model="rotation,slope,bias", spec=BIAS_ONLY))
    unfitted = calibrate(table, Options(model="rotation,slope", spec=BIAS_ONLY))
    for key in ("roll_deg", "pitch_deg", "yaw_deg", "slope_deg"):
        assert _parts(fitted, key)[1] == pytest.approx(0.0, abs=1e-9)
    assert _parts(unfitted, "roll_deg")[1] > 1e-3  # the same bias, not fitted, moves the tilt
    assert fitted.systematic is not None and "bias_x" not in fitted.systematic.propagated


def test_a_common_heading_error_moves_yaw_one_for_one_and_the_total_sigma_covers_its_limit(table: StopTable) -> None:
    """Yaw is read against the headings: turning every heading by δ turns yaw by δ and leaves no residual, so
    only the headings' stated limit can bound it (the default ±1°, or heading_deg in the spec)."""
    assert table.beta_rad is not None
    delta = 0.7
    turned = replace(table, beta_rad=table.beta_rad + np.radians(delta))
    a, b = calibrate(table), calibrate(turned)
    assert a.yaw_deg is not None and b.yaw_deg is not None and a.yaw_sigma_deg is not None
    assert abs(abs(b.yaw_deg - a.yaw_deg) - delta) < 1e-3 * delta
    assert (a.roll_deg, a.pitch_deg, a.fit.chi2) == pytest.approx((b.roll_deg, b.pitch_deg, b.fit.chi2), rel=1e-6)
    stat, sys = _parts(a, "yaw_deg")
    assert sys >= 1.0 / np.sqrt(3) and a.yaw_sigma_deg > delta / 2  # the common part alone: u = 1°/√3
    assert a.systematic is not None and "heading" in a.systematic.propagated
    assert any("headings are known against the fall line (±1.0°)" in n for n in a.notes)
    exact = calibrate(table, Options(spec=SENSOR_ONLY))
    assert _parts(exact, "yaw_deg")[1] < 0.5 * sys and _parts(exact, "yaw_deg")[0] == pytest.approx(stat, rel=1e-9)
    assert exact.systematic is not None and "heading" not in exact.systematic.propagated


def test_headings_that_do_not_set_yaw_add_nothing(table: StopTable) -> None:
    for headings in ("relative", "none"):  # yaw is not determined from them: nothing for their error to move
        cal = calibrate(replace(table, headings=headings))
        assert cal.yaw_deg is None and cal.systematic is not None and "heading" not in cal.systematic.propagated


@pytest.mark.parametrize("pair", [(0, 2), (1, 2), (0, 1)])
def test_the_systematic_part_is_the_shift_a_real_fit_makes_for_a_cross_axis_error(pair: tuple[int, int]) -> None:
    """A cross-axis coupling c in a (nearly noise-free) session moves the fitted angles by what K A δ predicts."""
    c = 0.003
    e = np.eye(3)
    e[pair] = e[pair[::-1]] = c
    clean, _ = simulate_stops(3.0, -2.0, 20.0, slope_deg=6.0, noise_g=1e-7, seed=2)
    skewed, _ = simulate_stops(3.0, -2.0, 20.0, slope_deg=6.0, noise_g=1e-7, seed=2, scale_matrix=e)
    # spec: this one coupling, with a limit a such that its standard uncertainty a/√3 is c
    names = {(0, 1): "cross_xy", (0, 2): "cross_xz", (1, 2): "cross_yz"}
    opts = Options(model="rotation,slope,bias", gravity_mps2=G_N)
    a, b = calibrate(clean, opts), calibrate(skewed, opts)
    errors = systematic.SensorErrors((names[pair],), np.array([[c**2]]), "test", {})
    # assessed on an ordinary session (1 mg noise) with the coupling: where its residual sees nothing of it the
    # limit stands, where it sees it (xy) the limit narrows and what it sees counts in full
    noisy, _ = simulate_stops(3.0, -2.0, 20.0, slope_deg=6.0, noise_g=1e-3, seed=2, scale_matrix=e)
    f = full.fit(noisy, ("rotation", "slope", "bias"), G_N)
    cov, used, _, _ = systematic.propagate(noisy, f.state, f.names, f.terms, f.state.g_mps2, errors)
    assert used == (names[pair],)
    predicted = systematic.angle_sigmas(cov, f.names, f.state.rot_vs, yaw=True, slope=True)
    for key in ("roll_deg", "pitch_deg", "yaw_deg"):
        shift = abs(getattr(b, key) - getattr(a, key))
        assert predicted[key] == pytest.approx(shift, rel=0.1, abs=0.01 * np.degrees(c))  # second order: c²


def test_a_large_systematic_part_withdraws_confidence_and_says_so(table: StopTable) -> None:
    loose = SensorSpec(scale=0.2, cross_axis=0.2, source="test: a loose sensor")
    cal = calibrate(table, Options(model="rotation,slope,bias", spec=loose))
    assert not cal.confident
    assert any("dominated by sensor errors" in n for n in cal.notes)
    assert any("uncertain by" in n for n in cal.notes)
    tight = calibrate(table, Options(model="rotation,slope,bias", spec=BIAS_ONLY))
    assert tight.confident and not any("dominated" in n for n in tight.notes)


def test_the_default_class_is_stated_in_the_result_and_a_spec_replaces_it(table: StopTable, tmp_path: Path) -> None:
    cal = calibrate(table)
    assert cal.systematic is not None and cal.systematic.default_spec
    assert any("default class" in n for n in cal.notes)
    spec = tmp_path / "sensor.toml"
    spec.write_text("scale = 0.01\ncross_axis = 0.005\nbias_mg = 20\n", encoding="utf-8")
    read = read_spec(spec)
    assert read.scale == 0.01 and read.bias_mps2 == pytest.approx(20 * 9.80665e-3)
    assert read.bias_tempco_mps2_per_c == DEFAULT.bias_tempco_mps2_per_c  # not given: the default's
    own = calibrate(table, Options(spec=read))
    assert own.systematic is not None and not own.systematic.default_spec
    assert not any("default class" in n for n in own.notes)
    assert _parts(own, "roll_deg")[1] < _parts(cal, "roll_deg")[1]


def test_the_result_file_keeps_both_parts(table: StopTable, tmp_path: Path) -> None:
    cal = calibrate(table)
    cal.save(tmp_path / "r.json")
    back = Calibration.load(tmp_path / "r.json")
    assert back.systematic == cal.systematic
    doc = json.loads((tmp_path / "r.json").read_text(encoding="utf-8"))
    assert doc["systematic"]["dominant"] is True
    assert doc["uncertainty"]["roll_deg"] == pytest.approx(np.hypot(*_parts(cal, "roll_deg")))


def test_cli_summary_shows_both_parts_and_refuses_a_bad_spec(
    table: StopTable, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    stops = tmp_path / "stops.csv"
    write_stop_table(replace(table, cov_s=None), stops)
    assert main(["calibrate", str(stops)]) == 0
    out = capsys.readouterr().err
    assert "σ statistical / systematic" in out and "default class" in out
    bad = tmp_path / "bad.toml"
    bad.write_text("scale = 3\n", encoding="utf-8")  # a percentage where a fraction belongs
    assert main(["calibrate", str(stops), "--sensor-spec", str(bad)]) != 0
    err = capsys.readouterr().err
    assert "bad.toml" in err and "Traceback" not in err
    bad.write_text("heading_deg = 180\n", encoding="utf-8")  # a heading, not a limit
    assert main(["calibrate", str(stops), "--sensor-spec", str(bad)]) != 0
    err = capsys.readouterr().err
    assert "heading_deg" in err and "at most 90" in err and "Traceback" not in err
    good = tmp_path / "survey.toml"
    good.write_text("heading_deg = 0.1\n", encoding="utf-8")  # surveyed marks: yaw's systematic part shrinks
    assert main(["calibrate", str(stops), "--sensor-spec", str(good), "-o", str(tmp_path / "r.json")]) == 0
    surveyed = Calibration.load(tmp_path / "r.json")
    assert surveyed.systematic is not None and surveyed.systematic.limits.heading_deg == 0.1
    assert _parts(surveyed, "yaw_deg")[1] < _parts(calibrate(table), "yaw_deg")[1] / 2
