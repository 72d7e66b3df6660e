"""Closing the loop: library effects are found, absent ones are not added, foreign ones are flagged."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mountcal.calibrate import Options, calibrate
from mountcal.cli import main
from mountcal.conventions import G_N
from mountcal.diagnose import leave_one_out, leave_one_out_refit
from mountcal.effects import BASE, PROGRESS_STOPS, close_the_loop, with_surface
from mountcal.estimate import full
from mountcal.simulate.stops import random_bias, simulate_preset, simulate_stops
from mountcal.stoptable import StopTable, write_stop_table

MG = 1e-3 * G_N
RUNS = 12


def found(effect: str, make, runs: int = RUNS) -> int:  # type: ignore[no-untyped-def]
    rng = np.random.default_rng(hash(effect) % 2**32)
    hits = 0
    for _ in range(runs):
        table, truth = make(rng)
        cal = calibrate(table)
        hits += effect in cal.model
        if effect in cal.model:  # and the angles are right within their (honest) σ
            for est, sig, true in zip(
                (cal.roll_deg, cal.pitch_deg, cal.yaw_deg),
                (cal.roll_sigma_deg, cal.pitch_sigma_deg, cal.yaw_sigma_deg),
                truth.angles_deg,
                strict=True,
            ):
                assert abs(est - true) < 5 * sig  # type: ignore[operator]
    return hits


def test_a_20mg_bias_is_found() -> None:
    assert (
        found("bias", lambda rng: simulate_preset("zhang2011", seed=rng, bias_mps2=random_bias(20 * MG, rng)))
        >= RUNS - 1
    )


def test_a_temperature_drift_is_found_with_its_offset() -> None:
    def make(rng):  # type: ignore[no-untyped-def]
        return simulate_preset(
            "zhang2011",
            seed=rng,
            temperature_c=np.linspace(20, 40, 12),
            temp_coeff_mps2_per_c=random_bias(0.5 * MG, rng),
            temp_ref_c=20.0,
        )

    assert found("temperature", make) >= RUNS - 1


def test_local_gravity_from_the_position_is_applied_and_shown() -> None:
    table, _ = simulate_preset("zhang2011", seed=1, g_mps2=9.780, lat_deg=0.0, alt_m=0.0)
    cal = calibrate(table)
    assert "gravity" in cal.model and cal.gravity_mps2 == pytest.approx(9.7803, abs=1e-4)
    first, second = cal.model_steps[:2]
    assert first["gravity_mps2"] == G_N and second["added"] == "gravity"
    assert second["chi2"] < first["chi2"] / 3  # the wrong g left a large misfit


def test_a_disturbed_stop_is_excluded_with_its_reason() -> None:
    rng = np.random.default_rng(3)
    hits = 0
    for _ in range(RUNS):
        d = np.zeros((12, 3))
        bad = int(rng.integers(12))
        d[bad] = random_bias(50 * MG, rng)
        cal = calibrate(simulate_preset("zhang2011", seed=rng, disturbance_mps2=d)[0])
        if "outlier" in cal.model:
            hits += 1
            assert cal.fit["excluded_stops"] == [bad + 1]
            step = next(s for s in cal.model_steps if s["added"] == "outlier")
            assert f"stop {bad + 1}" in step["reason"]
    assert hits >= RUNS - 1


def test_nothing_is_added_when_nothing_is_there() -> None:
    rng = np.random.default_rng(5)
    plain = sum(
        calibrate(simulate_preset("zhang2011", seed=rng)[0]).model == ("rotation", "slope") for _ in range(2 * RUNS)
    )
    assert plain >= 2 * RUNS - 2


def test_scale_on_one_slope_is_declared_confounded_not_fitted() -> None:
    e = np.array([[0.02, 0.01, 0.01], [0.01, -0.02, 0.01], [0.01, 0.01, 0.02]])
    table, _ = simulate_preset("zhang2011", seed=2, scale_matrix=np.eye(3) + e)
    cal = calibrate(table)
    assert "scale" not in cal.model
    assert any(d["effect"] == "scale" and "confounded" in d["why"] for d in cal.model_selection["declined"])


@pytest.mark.parametrize("kind", ["time drift", "own surfaces"])
def test_an_effect_outside_the_library_is_flagged_and_not_confident(kind: str) -> None:
    rng = np.random.default_rng(11)
    flagged = 0
    for _ in range(RUNS):
        if kind == "time drift":  # a bias drifting 15 mg over the session, no temperature logged
            table, _ = simulate_preset(
                "zhang2011", seed=rng, disturbance_mps2=np.outer(np.linspace(-0.5, 0.5, 12), random_bias(15 * MG, rng))
            )
        else:  # every stop on its own surface: 0.3° of extra road tilt, no site column
            table, truth = simulate_preset("zhang2011", seed=rng)
            tilt = Rotation.from_rotvec(np.column_stack([np.radians(rng.normal(0, 0.3, (12, 2))), np.zeros(12)]))
            f_v = truth.rot_vs.apply(table.acc_s)
            table = replace(table, acc_s=truth.rot_vs.inv().apply(tilt.apply(f_v)))
        cal = calibrate(table)
        if cal.unexplained:
            flagged += 1
            assert not cal.confident
            assert any("not confident" in n for n in cal.notes)
            assert all({"what", "size", "p_value"} <= set(u) for u in cal.unexplained)
    assert flagged >= RUNS - 1


def test_the_result_carries_the_before_after_table() -> None:
    table, _ = simulate_preset("zhang2011", seed=4, bias_mps2=np.array([0.1, -0.15, 0.12]))
    doc = calibrate(table).to_dict()
    steps = doc["model_steps"]
    assert [s["added"] for s in steps] == ["start", "bias"]
    assert steps[1]["moved"]["roll_deg"] == pytest.approx(
        steps[1]["angles"]["roll_deg"] - steps[0]["angles"]["roll_deg"]
    )
    assert steps[1]["chi2"] < steps[0]["chi2"]
    assert doc["unexplained"] == [] and doc["confident"] is True
    bias = doc["effects"]["bias_mps2"]
    assert np.all(np.abs(np.subtract(bias["value"], [0.1, -0.15, 0.12])) < 4 * np.array(bias["sigma"]))
    assert {d["test"] for d in doc["diagnostics"]} >= {"chi2", "harmonic_1beta", "harmonic_2beta", "norm"}


def test_fixed_models_accept_any_library_terms() -> None:
    table, _ = simulate_preset("zhang2011", seed=6, temperature_c=np.linspace(10, 30, 12))
    cal = calibrate(table, Options(model="rotation,slope,bias,temperature"))
    assert cal.model == ("rotation", "slope", "bias", "temperature")
    assert cal.effects["temperature_mps2_per_c"]["sigma"][0] > 0


def _moderate_table(case: str) -> tuple[StopTable, tuple[str, ...]]:
    """48 stops (the circle four times) with the effect the fitted model carries."""
    rng = np.random.default_rng(sum(map(ord, case)))
    beta = np.resize(np.arange(0.0, 360.0, 30.0), 48)
    bias = random_bias(20 * MG, rng)
    if case == "bias, stop noise known":
        return simulate_stops(beta_deg=beta, bias_mps2=bias, seed=rng)[0], (*BASE, "bias")
    if case == "bias, stop noise unknown":
        table = simulate_stops(beta_deg=beta, bias_mps2=bias, seed=rng)[0]
        return replace(table, cov_s=None), (*BASE, "bias")
    if case == "headings fitted per stop":
        return simulate_stops(beta_deg=beta, headings="none", seed=rng)[0], BASE
    temp = np.linspace(10.0, 35.0, 48)
    table = simulate_stops(
        beta_deg=beta, bias_mps2=bias, temperature_c=temp, temp_coeff_mps2_per_c=random_bias(0.5 * MG, rng), seed=rng
    )[0]
    return table, (*BASE, "bias", "temperature")


@pytest.mark.parametrize(
    "case",
    ["bias, stop noise known", "bias, stop noise unknown", "headings fitted per stop", "temperature drift"],
)
def test_closed_form_leave_one_out_matches_a_refit_per_stop(case: str) -> None:
    table, terms = _moderate_table(case)
    fit = full.fit(table, terms, G_N)
    d2, press = leave_one_out(table, fit)
    d2_refit, press_refit = leave_one_out_refit(table, fit)
    # Exact for the linearised model; the model's curvature over one stop's pull on the
    # parameters is what is left (≤ 1e-3 relative here).
    np.testing.assert_allclose(d2, d2_refit, rtol=5e-3)
    np.testing.assert_allclose(press, press_refit, rtol=5e-3)
    assert np.all(np.isfinite(d2)) and np.all(press > 0)


def test_a_stop_that_alone_sets_a_parameter_is_not_judged_by_the_others() -> None:
    table, _ = simulate_stops(beta_deg=np.resize(np.arange(0.0, 360.0, 30.0), 25), seed=8)
    site = np.array(["a"] * 12 + ["b"] * 12 + ["c"])  # site c: one stop, its own slope
    table = replace(table, site=site)
    d2, press = leave_one_out(table, full.fit(table, (*BASE, "site_slope"), G_N))
    assert np.isnan(d2[-1]) and np.isnan(press[-1])
    assert np.all(np.isfinite(d2[:-1])) and np.all(np.isfinite(press[:-1]))


def test_a_long_model_choice_reports_its_rounds_on_stderr_not_stdout(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    beta = np.resize(np.arange(0.0, 360.0, 30.0), PROGRESS_STOPS)
    table, _ = simulate_stops(beta_deg=beta, bias_mps2=random_bias(20 * MG, np.random.default_rng(2)), seed=2)
    src = tmp_path / "stops.csv"
    write_stop_table(table, src)
    assert main(["calibrate", str(src), "-o", str(tmp_path / "cal.json")]) == 0
    out, err = capsys.readouterr()
    assert "model choice" not in out
    rounds = [line for line in err.splitlines() if line.startswith("mountcal: model choice")]
    assert any(f"on {PROGRESS_STOPS} stops, round 1" in line for line in rounds)
    assert any("round 1: bias added" in line for line in rounds)
    assert "nothing more to add" in rounds[-1]


def _at_three_sites(tilt_deg: float, seed: int) -> StopTable:
    """48 stops at three sites (a, b, c in turn), each stop on a road tilted by ``tilt_deg`` (1σ)."""
    rng = np.random.default_rng(seed)
    table, truth = simulate_stops(beta_deg=np.resize(np.arange(0.0, 360.0, 30.0), 48), seed=rng)
    tilt = Rotation.from_rotvec(np.column_stack([np.radians(rng.normal(0, tilt_deg, (48, 2))), np.zeros(48)]))
    acc = truth.rot_vs.inv().apply(tilt.apply(truth.rot_vs.apply(table.acc_s)))
    return replace(table, acc_s=acc, site=np.array(["a", "b", "c"])[np.arange(48) % 3])


def test_the_road_tilt_found_is_the_profile_likelihoods_optimum() -> None:
    table = _at_three_sites(0.2, seed=21)
    loop = close_the_loop(table, G_N, gravity_known=False, alpha=1e-3)
    step = next(s for s in loop.steps if s.added == "surface")
    prev = loop.steps[loop.steps.index(step) - 1]
    extra = step.table.cov_s - prev.table.cov_s  # type: ignore[operator]
    log_sigma = np.log(np.sqrt(np.trace(extra[0]) / 2) / G_N)
    assert 0.1 < np.degrees(np.exp(log_sigma)) < 0.4
    # The reference: refit the mean model on a grid of road tilts around it, no shortcut.
    grid = log_sigma + np.linspace(-0.1, 0.1, 41)
    profile = []
    for x in grid:
        widened = with_surface(prev.table, prev.fit.state.rot_vs, float(np.exp(x)), G_N)
        f = full.fit(widened, prev.terms, G_N, prev.fit.state)
        profile.append(f.chi2 + np.sum(np.linalg.slogdet(widened.cov_s)[1]))
    assert abs(grid[int(np.argmin(profile))] - log_sigma) <= 0.01  # the old search's tolerance


def test_no_road_tilt_is_added_when_the_stops_share_one_surface() -> None:
    assert sum("surface" in calibrate(_at_three_sites(0.0, seed=s)).model for s in range(6)) == 0
