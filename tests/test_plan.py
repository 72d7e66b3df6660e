"""`mountcal plan`: the σ it predicts is what `calibrate` reports and achieves; the sheet is one `calibrate` reads."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mountcal.calibration.fit import Options, calibrate
from mountcal.cli import main
from mountcal.core.conventions import G_N
from mountcal.estimate.sensor_errors import SensorErrors, from_spec
from mountcal.io.reader import LogOptions
from mountcal.io.samples import Samples
from mountcal.io.sensor_spec import DEFAULT, read_spec
from mountcal.sessions.plan import Noise, Request, bound_of_headings, make_plan, monte_carlo_rms, noise_from_log
from mountcal.simulate.stops import simulate_parking_log, simulate_stops
from mountcal.stops.headings import read_protocol, tabulate

TARGET = {"roll": 0.1, "pitch": 0.1, "yaw": 0.5}
# a calibrated sensor: limits far below what the stops resolve, so the plan is the bound alone
TIGHT_SPEC = "scale = 1e-5\ncross_axis = 1e-5\nbias_mg = 0.01\nbias_tempco_mg_per_c = 0.0\nheading_deg = 0.0\n"


def tight(tmp_path: Path) -> SensorErrors:
    path = tmp_path / "tight.toml"
    path.write_text(TIGHT_SPEC, encoding="utf-8")
    return from_spec(read_spec(path))


@pytest.mark.parametrize(
    ("terms", "slope", "noise_mg"),
    [(("rotation", "slope"), 3.0, 8.0), (("rotation", "slope", "bias"), 6.0, 4.0)],
)
def test_predicted_sigma_is_the_monte_carlo_rms_of_calibrate(
    terms: tuple[str, ...], slope: float, noise_mg: float, tmp_path: Path
) -> None:
    noise = Noise(noise_mg * 1e-3 * G_N, 100.0, "test")
    plan = make_plan(Request(TARGET, noise, terms, slope_deg=slope, sensor=tight(tmp_path)))
    assert plan.reachable
    mc = monte_carlo_rms(plan, runs=250, seed=7)  # no sensor errors simulated: the statistical part
    for angle, rms in mc.items():
        # 250 runs: the RMS itself scatters by ≈ 4.5 % (1σ); 15 % is the acceptance of issue 17.
        assert rms == pytest.approx(plan.statistical_deg[angle], rel=0.15), angle
        # with a tight spec the total is the statistical part: the plan is as before the systematic part
        assert plan.sigma_deg[angle] == pytest.approx(plan.statistical_deg[angle], rel=0.01), angle


def test_the_plan_is_the_smallest_that_reaches_the_target(tmp_path: Path) -> None:
    target = {"roll": 0.05, "pitch": 0.05, "yaw": 0.5}
    noise = Noise(6e-3 * G_N, 100.0, "test")
    req = Request(target, noise, ("rotation", "slope", "bias"), slope_deg=3.0, stop_s=30.0, sensor=tight(tmp_path))
    plan = make_plan(req)
    assert plan.reachable and plan.n_stops > 4
    assert all(plan.sigma_deg[a] <= t for a, t in target.items())  # type: ignore[operator]
    one_fewer = plan.n_stops - 1
    stop_sigma = noise.stop_sigma_mps2(30.0 - 4.0)
    smaller = bound_of_headings(np.arange(one_fewer) * 360.0 / one_fewer, 3.0, plan.request.terms, stop_sigma)
    assert any(smaller[a] > t for a, t in target.items())  # type: ignore[operator]
    # headings evenly spaced around the circle, in driving order
    assert np.allclose(np.diff(plan.beta_deg), 360.0 / plan.n_stops)


def test_yaw_on_a_half_degree_slope_is_refused_with_the_reason(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sheet, spec = tmp_path / "plan.csv", tmp_path / "tight.toml"
    spec.write_text(TIGHT_SPEC, encoding="utf-8")  # the statistical part alone falls short, not the spec
    argv = ["plan", "--target", "yaw=0.2", "--noise", "10", "--slope-deg", "0.5", "--max-stops", "8", "--stop-s", "30"]
    code = main([*argv, "--sensor-spec", str(spec), "-o", str(sheet)])
    out = capsys.readouterr().err
    assert code == 3
    assert "not reachable, because yaw reaches at best" in out and "needs a slope of ≥" in out
    assert not sheet.exists()


def test_a_yaw_target_below_the_headings_limit_is_refused_naming_them(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    spec = tmp_path / "headings.toml"
    spec.write_text(TIGHT_SPEC.replace("heading_deg = 0.0", "heading_deg = 2.0"), encoding="utf-8")
    argv = ["plan", "--target", "yaw=0.5", "--noise", "1", "--slope-deg", "10", "--sensor-spec", str(spec)]
    code = main([*argv, "-o", str(tmp_path / "plan.csv")])
    out = capsys.readouterr().err
    assert code == 3 and "headings' ±2.0° against the fall line" in out
    spec.write_text(TIGHT_SPEC.replace("heading_deg = 0.0", "heading_deg = 0.2"), encoding="utf-8")
    assert main([*argv, "-o", str(tmp_path / "plan.csv")]) == 0  # 0.2/√3 ≈ 0.12° leaves room


def test_calibrate_reads_the_sheet_and_finds_every_planned_stop(tmp_path: Path) -> None:
    sheet, spec = tmp_path / "plan.csv", tmp_path / "tight.toml"
    spec.write_text(TIGHT_SPEC, encoding="utf-8")
    code = main(["plan", "--target", "roll=0.05,pitch=0.05,yaw=0.3", "--noise", "5", "--slope-deg", "4",
                 "--stop-s", "20", "--sensor-spec", str(spec), "-o", str(sheet)])  # fmt: skip
    assert code == 0
    protocol = read_protocol(str(sheet))
    # a session driven to the plan: stops at the planned headings, dwell and drive time, clock from 0
    log = simulate_parking_log(slope_deg=4.0, beta_deg=tuple(protocol["beta_deg"]), stop_s=20.0, drive_s=60.0, seed=2)
    found = tabulate(Samples(log.t_s, log.acc_s, log.gyro_s), protocol=protocol)
    assert found.heading_source == "protocol sheet" and found.unmatched_protocol_rows == 0
    assert found.table.beta_rad is not None
    assert np.allclose(np.degrees(found.table.beta_rad), protocol["beta_deg"])


def test_noise_from_a_log_is_the_simulated_white_noise(tmp_path: Path) -> None:
    from mountcal.io import writers as export

    log = simulate_parking_log(noise_mps2=0.04, rate_hz=100.0, seed=5)
    path = tmp_path / "parked.mcap"
    export.write_log(path, log)
    noise = noise_from_log([str(path)], LogOptions())
    assert noise.rate_hz == pytest.approx(100.0, rel=1e-3)
    # batch means (9 dof per stop, median of 12 stops) and the never-below-independent floor: ≈ +0–15 %
    assert 0.04 * 0.9 < noise.sample_sigma_mps2 < 0.04 * 1.2


def test_a_target_below_the_default_class_systematic_part_is_refused_with_the_reason(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sheet = tmp_path / "plan.csv"
    # 0.05° is reached in a few stops statistically (above, with a tight spec), never with ±3 % scale, ±2 % cross-axis
    code = main(["plan", "--target", "roll=0.05,pitch=0.05,yaw=0.3", "--noise", "5", "--slope-deg", "4",
                 "--max-stops", "24", "-o", str(sheet)])  # fmt: skip
    out = capsys.readouterr().err
    assert code == 3 and not sheet.exists()
    assert "systematic part" in out and "cannot be reached by any number of stops or dwell" in out
    assert "default class" in out and "triad" in out and "two slopes" in out
    plan = make_plan(Request({"roll": 0.05}, Noise(5e-3 * G_N, 100.0, "test"), slope_deg=4.0))
    assert not plan.reachable
    assert plan.systematic_deg["roll"] > 0.05 > plan.statistical_deg["roll"]  # type: ignore[operator]


@pytest.mark.parametrize(
    ("terms", "slope", "spec"),
    [
        (("rotation", "slope", "bias"), 5.0, None),  # the default class: systematic dominates
        (("rotation", "slope"), 3.0, None),  # without a bias term the bias limit enters as well, bounded by the data
        (("rotation", "slope", "bias"), 5.0, "scale = 0.003\ncross_axis = 0.002\n"),  # both parts matter
    ],
)
def test_the_predicted_total_is_what_calibrate_reports_on_a_session_of_the_plan(
    terms: tuple[str, ...], slope: float, spec: str | None, tmp_path: Path
) -> None:
    noise = Noise(8e-3 * G_N, 100.0, "test")
    path = tmp_path / "spec.toml"
    path.write_text(spec or "", encoding="utf-8")
    sensor_spec = read_spec(path) if spec else DEFAULT
    req = Request(
        {"roll": 2.0, "pitch": 2.0}, noise, terms, slope_deg=slope, stop_s=20.0, sensor=from_spec(sensor_spec)
    )
    plan = make_plan(req)
    assert plan.reachable
    averaged = plan.stop_s - 2 * req.detection.trim_s
    for seed in range(3):
        table, _ = simulate_stops(
            2.0, -1.5, 30.0, slope_deg=plan.slope_deg, beta_deg=np.asarray(plan.beta_deg),
            noise_g=noise.stop_sigma_mps2(averaged) / G_N, samples_per_stop=int(noise.rate_hz * averaged), seed=seed,
        )  # fmt: skip
        cal = calibrate(table, Options(model=",".join(terms), spec=sensor_spec))
        assert cal.roll_sigma_deg == pytest.approx(plan.sigma_deg["roll"], rel=0.15), seed
        assert cal.pitch_sigma_deg == pytest.approx(plan.sigma_deg["pitch"], rel=0.15), seed
