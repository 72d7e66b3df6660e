"""Closing the loop: library effects are found, absent ones are not added, foreign ones are flagged."""

from __future__ import annotations

import zlib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from tests.effect_plugin import Q_TRUE, install, quadratic

from mountcal.calibration.fit import Options, calibrate
from mountcal.cli import main
from mountcal.core.conventions import G_N
from mountcal.core.result import Calibration
from mountcal.estimate import full
from mountcal.loop.diagnose import leave_one_out, leave_one_out_refit
from mountcal.loop.model_choice import BASE, PROGRESS_STOPS, close_the_loop, with_surface
from mountcal.simulate.stops import random_bias, simulate_preset, simulate_stops
from mountcal.stops.table import StopTable, write_stop_table

MG = 1e-3 * G_N
RUNS = 12


def found(effect: str, make, runs: int = RUNS) -> int:  # type: ignore[no-untyped-def]
    """How many of ``runs`` simulated sessions add ``effect``. A run that does not add it must not be a
    confident answer: it is marked not confident and its residual findings name what was left."""
    rng = np.random.default_rng(zlib.crc32(effect.encode()))  # str hash() changes per process
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
        else:
            assert not cal.confident and cal.unexplained, (effect, cal.model)
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
    assert first.gravity_mps2 == G_N and second.added == "gravity"
    assert second.chi2 < first.chi2 / 3  # the wrong g left a large misfit


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
            assert cal.fit.excluded_stops == (bad + 1,)
            step = next(s for s in cal.model_steps if s.added == "outlier")
            assert f"stop {bad + 1}" in step.reason
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
    assert any(d.effect == "scale" and "confounded" in d.why for d in cal.model_selection.declined)


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
            assert all(u.what and u.size and u.p_value is not None for u in cal.unexplained)
    assert flagged >= RUNS - 1


def _lean_around_a_warm_up(rng: np.random.Generator, lean: float) -> StopTable:
    """The paper's 12 stops visited in order of heading while the sensor warms up and cools down again (so the
    temperature rises and falls around the circle, nearly as cos β), the body leaning ``lean`` × the lateral slope
    (no term of the model)."""
    temperature = np.interp(np.arange(12), [0, 6, 11], [20.0, 35.0, 22.0])
    table, truth = simulate_preset("zhang2011", seed=rng, temperature_c=temperature)
    f_v = truth.rot_vs.apply(table.acc_s)
    roll = lean * np.arcsin(np.clip(f_v[:, 1] / truth.g_mps2, -1.0, 1.0))
    leaned = Rotation.from_rotvec(np.column_stack([roll, np.zeros((12, 2))])).inv().apply(f_v)
    return replace(table, acc_s=truth.rot_vs.inv().apply(leaned))


def test_a_heading_pattern_is_not_taken_for_a_temperature_drift_that_follows_the_headings() -> None:
    rng = np.random.default_rng(15)
    refused = 0
    for _ in range(RUNS):
        cal = calibrate(_lean_around_a_warm_up(rng, 0.05))
        why = [d.why for d in cal.model_selection.declined if d.effect == "temperature"]
        refused += "temperature" not in cal.model and any("heading pattern" in w for w in why) and not cal.confident
    assert refused >= RUNS - 1


def _cooling(rng: np.random.Generator, n: int = 12) -> StopTable:
    """The circle of stops in heading order while the sensor cools linearly by 15 °C, its bias drifting 0.5 mg/°C in
    a random direction (no constant bias): a ramp of temperature, about 80 % of it a heading harmonic."""
    return simulate_stops(
        rot_vs=Rotation.from_euler("ZYX", [rng.uniform(-180, 180), *rng.uniform(-10, 10, 2)], degrees=True),
        beta_deg=np.arange(n) * 360.0 / n,
        temperature_c=np.linspace(40.0, 25.0, n),
        temp_coeff_mps2_per_c=random_bias(0.5 * MG, rng),
        temp_ref_c=30.0,
        seed=rng,
    )[0]


@pytest.mark.parametrize("n", [8, 12])
def test_a_linear_cooling_the_residual_names_is_taken_as_temperature(n: int) -> None:
    # Issue 25: the loop declined it as a heading pattern in about one run in four (the guard had little power on a
    # ramp), or excluded the hottest stop first, and the residual test named temperature after all.
    rng = np.random.default_rng(40 if n == 12 else 33)  # seeds where the loop before missed 5 and 6 of 12
    models = [calibrate(_cooling(rng, n)).model for _ in range(RUNS)]
    assert sum("temperature" in m for m in models) >= RUNS - 1


def test_three_stops_without_headings_at_different_places_give_a_result_with_the_reason_not_a_failed_fit(
    tmp_path: Path,
) -> None:
    # Issue 25: `--headings none` on a 3-stop table (stops at different places) ended with exit 4 "no convergence
    # in 500 iterations": the random road tilt per stop left the refit adrift. It is now declined with the reason.
    rng = np.random.default_rng(23)
    table, _ = simulate_stops(
        rot_vs=Rotation.random(random_state=23),
        slope_deg=rng.uniform(1, 4),
        beta_deg=rng.uniform(0, 360, 3),
        bias_mps2=rng.normal(0, 0.5, 3),
        noise_g=0.0005,
        seed=23,
    )
    path = tmp_path / "three.csv"
    write_stop_table(replace(table, lat_deg=np.array([55.0, 55.01, 55.02]), lon_deg=np.full(3, 10.0)), path)
    out = tmp_path / "cal.json"
    assert main(["calibrate", str(path), "--headings", "none", "-o", str(out), "-q"]) == 0
    cal = Calibration.load(out)
    why = [d.why for d in cal.model_selection.declined if d.effect == "surface"]
    assert why and "its fit failed" in why[0] and "free parameter" in why[0]


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
    bias = next(e for e in doc["effects"] if e["name"] == "bias_mps2")
    assert np.all(np.abs(np.subtract(bias["value"], [0.1, -0.15, 0.12])) < 4 * np.array(bias["sigma"]))
    assert {d["test"] for d in doc["diagnostics"]} >= {"chi2", "harmonic_1beta", "harmonic_2beta", "norm"}


def test_fixed_models_accept_any_library_terms() -> None:
    table, _ = simulate_preset("zhang2011", seed=6, temperature_c=np.linspace(10, 30, 12))
    cal = calibrate(table, Options(model="rotation,slope,bias,temperature"))
    assert cal.model == ("rotation", "slope", "bias", "temperature")
    temperature = cal.effect("temperature_mps2_per_c")
    assert temperature is not None and (temperature.sigma[0] or 0.0) > 0


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
    rounds = [line for line in err.splitlines() if line.lstrip().startswith("model choice")]
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


# --- an effect added by one file, from outside the package -----------------------------------------


@pytest.fixture(scope="module")
def plugin_env(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """A folder with one module and its distribution metadata, put on PYTHONPATH: nothing else edited."""
    return install(tmp_path_factory.mktemp("plugin")).env


def _mountcal(env: dict[str, str], *args: str, code: int = 0) -> str:
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-m", "mountcal", *args], env=env, capture_output=True, text=True)
    assert done.returncode == code, done.stderr
    return done.stdout + done.stderr


def test_an_effect_added_by_one_file_is_fitted_chosen_applied_and_used_by_the_fleet(
    plugin_env: dict[str, str], tmp_path: Path
) -> None:
    import pandas as pd

    from mountcal.core.result import Calibration

    table, truth = simulate_stops(slope_deg=10.0, beta_deg=np.arange(0.0, 360.0, 15.0), seed=3)
    table = replace(table, acc_s=quadratic(table.acc_s))
    stops = tmp_path / "car" / "stops.csv"
    stops.parent.mkdir()
    write_stop_table(table, stops)
    refused = _mountcal(plugin_env, "calibrate", str(stops), "--model", "rotation,slope,nonsense", code=2)
    assert "quadratic" in refused  # the refusal lists the installed effects

    for model in ("rotation,slope,quadratic", "auto"):
        out = tmp_path / f"{model.replace(',', '_')}.json"
        _mountcal(plugin_env, "calibrate", str(stops), "--model", model, "-o", str(out))
        cal = Calibration.load(out)
        assert "quadratic" in cal.model, model
        fitted = cal.effect("quadratic_per_mps2")
        assert fitted is not None, model
        assert np.all(np.abs(np.array(fitted.value) - Q_TRUE) < 5 * np.array(fitted.sigma, dtype=float)), model
        for est, true in zip((cal.roll_deg, cal.pitch_deg, cal.yaw_deg), truth.angles_deg, strict=True):
            assert abs(est - true) < 0.1  # type: ignore[operator]

    # rotate undoes the fitted nonlinearity before rotating: samples of known vehicle-frame force come out right
    f_v = np.array([[0.0, 0.0, G_N], [1.5, -1.0, 9.6], [-2.0, 1.8, 9.5]] * 4)
    acc_s = quadratic(truth.rot_vs.inv().apply(f_v))
    log = tmp_path / "drive.csv"
    pd.DataFrame({"t_s": np.arange(len(f_v)) * 0.01, "ax": acc_s[:, 0], "ay": acc_s[:, 1], "az": acc_s[:, 2]}).to_csv(
        log, index=False, float_format="%.15g"
    )
    rotated = tmp_path / "vehicle.csv"
    _mountcal(plugin_env, "rotate", str(log), "--calibration", str(tmp_path / "auto.json"), "-o", str(rotated))
    acc_v = pd.read_csv(rotated)[["ax", "ay", "az"]].to_numpy()
    assert np.max(np.abs(acc_v - f_v)) < 0.02  # the fit's own error: mrad × g
    uncorrected = truth.rot_vs.apply(acc_s)
    assert np.max(np.abs(uncorrected - f_v)) > 0.15  # what leaving the nonlinearity in would cost

    fleet_out = tmp_path / "fleet.parquet"
    _mountcal(plugin_env, "fleet", str(stops.parent), "-o", str(fleet_out), "-q", "--workers", "1")
    logs = pd.read_parquet(fleet_out)
    assert "quadratic" in logs["model"].iloc[0].split(",")


# --- two slopes: scale and cross-axis become observable ---------------------------------------------

SCALE_2_1 = np.eye(3) + np.array([[0.02, -0.01, 0.01], [-0.01, -0.02, 0.01], [0.01, 0.01, 0.02]])


def _on_slopes(slopes_deg: tuple[float, ...], scale: np.ndarray | None, seed: int) -> tuple[StopTable, object]:
    rng = np.random.default_rng(seed)
    parts = [simulate_stops(slope_deg=a, scale_matrix=scale, seed=rng) for a in slopes_deg]
    arrays = {k: np.concatenate([getattr(t, k) for t, _ in parts]) for k in ("acc_s", "beta_rad", "cov_s", "t_s")}
    site = np.repeat([f"s{k}" for k in range(len(slopes_deg))], len(parts[0][0]))
    return replace(parts[0][0], site=site, **arrays), parts[0][1]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_two_slopes_separate_scale_and_cross_axis_and_the_loop_fits_them(seed: int) -> None:
    table, truth = _on_slopes((5.0, 10.0), SCALE_2_1, seed)
    cal = calibrate(table)
    assert "scale" in cal.model
    scale = cal.effect("scale")
    assert scale is not None
    fitted = dict(zip(scale.components, zip(scale.value, scale.sigma, strict=True), strict=True))
    assert abs(fitted["scale_xx"][0] - 0.02) < 5 * (fitted["scale_xx"][1] or 0.0)
    assert abs(fitted["cross_xy"][0] + 0.01) < 5 * (fitted["cross_xy"][1] or 0.0)
    for est, sig, true in zip(
        (cal.roll_deg, cal.pitch_deg, cal.yaw_deg),
        (cal.roll_sigma_deg, cal.pitch_sigma_deg, cal.yaw_sigma_deg),
        truth.angles_deg,  # type: ignore[attr-defined]
        strict=True,
    ):
        assert abs(est - true) < 5 * sig  # type: ignore[operator]
    clean = calibrate(_on_slopes((5.0, 10.0), None, seed)[0])
    assert set(clean.model) <= {"rotation", "slope", "site_slope"}


def test_observability_names_the_protocol_that_would_separate_scale() -> None:
    one, _ = simulate_stops(seed=4)
    verdicts = {v.effect: v for v in calibrate(one, Options(model="rotation,slope")).observability.separability}
    assert not verdicts["scale"].separable
    assert "two slopes of different inclination" in verdicts["scale"].why
    assert "three slopes" in verdicts["scale with bias"].why
    assert verdicts["bias"].separable
    # equal inclinations in different directions are the same cone of gravity in the vehicle frame: no help
    same, _ = _on_slopes((5.0, 5.0), SCALE_2_1, 4)
    assert "scale" not in calibrate(same).model


def test_rotate_undoes_a_fitted_scale_matrix_and_back() -> None:
    from mountcal.apply.rotate import acc_to_sensor, acc_to_vehicle

    table, truth = _on_slopes((5.0, 10.0), SCALE_2_1, 0)
    cal = calibrate(table)
    assert "scale" in cal.model
    # near gravity, where two slopes determine the matrix well (the horizontal scales only to ~2 %, 1σ)
    f_v = np.array([[0.0, 0.0, G_N], [0.3, -0.2, 9.8], [-0.2, 0.3, 9.8]])
    acc_s = truth.rot_vs.inv().apply(f_v) @ SCALE_2_1.T  # type: ignore[attr-defined]
    acc_v = acc_to_vehicle(acc_s, cal)
    assert np.max(np.abs(acc_v - f_v)) < 0.01  # the scale error (0.2 m/s² on the vertical) removed
    assert np.max(np.abs(cal.rot_vs.apply(acc_s) - f_v)) > 0.1
    assert np.allclose(acc_to_sensor(acc_v, cal), acc_s, atol=1e-12)


def test_an_effect_that_cannot_be_loaded_is_refused_by_name(tmp_path: Path) -> None:
    import os
    import subprocess
    import sys

    info = tmp_path / "mc_broken-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: mc-broken\nVersion: 0.1\n", encoding="utf-8")
    (info / "entry_points.txt").write_text("[mountcal.effects]\nbroken = mc_missing:Broken\n", encoding="utf-8")
    table, _ = simulate_stops(seed=1)
    write_stop_table(table, tmp_path / "stops.csv")
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(tmp_path), str(Path(__file__).resolve().parents[1] / "src")]),
    }
    done = subprocess.run(
        [sys.executable, "-m", "mountcal", "calibrate", str(tmp_path / "stops.csv")],
        env=env,
        capture_output=True,
        text=True,
    )
    assert done.returncode != 0
    assert "plugin 'broken' (mc_missing:Broken)" in done.stderr and "mc-broken" in done.stderr
    assert "Traceback" not in done.stderr
