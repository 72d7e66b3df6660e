"""Recovery of a known truth by the paper's method and the full estimator (docs/conventions.md §3–5)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy import stats
from scipy.spatial.transform import Rotation

from mountcal.calibration.fit import Options, calibrate
from mountcal.core.conventions import G_N, rot_vs_from_angles
from mountcal.core.result import Calibration
from mountcal.estimate.paper import opposite_pairs
from mountcal.simulate.stops import Truth, random_bias, simulate_preset, simulate_stops

CHI2_3_99_99 = stats.chi2.ppf(0.9999, 3)


def rotation_error_mahalanobis(cal: Calibration, truth: Truth) -> float:
    """δ with R_true = exp([δ]) R̂, weighed by the reported covariance about the vehicle axes."""
    delta = (truth.rot_vs * cal.rot_vs.inv()).as_rotvec()
    sig = np.radians([s if s is not None else np.inf for s in cal.rotation_sigma_deg])
    return float(np.sum((delta / sig) ** 2))


@pytest.mark.parametrize("method", ["paper", "full"])
def test_noise_free_stops_give_the_truth_exactly(method: str) -> None:
    table, _truth = simulate_preset("zhang2011", noise_g=0.0, seed=0)
    cal = calibrate(table, Options(method=method, model="rotation,slope"))  # type: ignore[arg-type]
    np.testing.assert_allclose([cal.roll_deg, cal.pitch_deg, cal.yaw_deg, cal.slope_deg], [5, 6, 7, 5], atol=1e-7)


def test_noise_free_stops_with_bias_give_the_bias() -> None:
    bias = np.array([0.1, -0.2, 0.15])
    table, _ = simulate_preset("zhang2011", noise_g=0.0, bias_mps2=bias, seed=0)
    cal = calibrate(table, Options(model="rotation,slope,bias"))
    np.testing.assert_allclose([cal.roll_deg, cal.pitch_deg, cal.yaw_deg, cal.slope_deg], [5, 6, 7, 5], atol=1e-7)
    assert cal.bias_mps2 is not None
    np.testing.assert_allclose(cal.bias_mps2, bias, atol=1e-9)


def test_paper_method_fails_step_2_honestly_with_a_vertical_bias() -> None:
    table, _ = simulate_preset("zhang2011", bias_mps2=np.array([0.0, 0.0, 0.05]), seed=1)
    cal = calibrate(table, Options(method="paper"))
    assert cal.slope_deg is None and cal.slope_sigma_deg is None
    assert any("step 2 failed" in n for n in cal.notes)
    full = calibrate(table, Options(model="rotation,slope,bias"))
    assert full.slope_deg == pytest.approx(5.0, abs=5 * full.slope_sigma_deg)  # type: ignore[arg-type]


def test_opposite_pairs_use_each_stop_once() -> None:
    pairs = opposite_pairs(np.radians([0, 180, 30, 210, 90, 0.5]))
    assert pairs == [(0, 1), (2, 3)]


def test_paper_scenario_monte_carlo_reaches_the_bound() -> None:
    """A small Monte Carlo (the full one is benchmarks/accuracy.py): RMS within 25 % of the CRB."""
    rng = np.random.default_rng(7)
    err = []
    crb = None
    for _ in range(150):
        table, _truth = simulate_preset("zhang2011", seed=rng)
        cal = calibrate(table, Options(model="rotation,slope"))
        err.append([cal.roll_deg - 5, cal.pitch_deg - 6, cal.yaw_deg - 7, cal.slope_deg - 5])  # type: ignore[operator]
        assert cal.observability is not None
        crb = cal.observability.crb_1sigma["rotation,slope"]
    rms = np.sqrt(np.mean(np.square(err), axis=0))
    assert crb is not None
    bound = np.array([crb.roll_deg, crb.pitch_deg, crb.yaw_deg, crb.slope_deg], dtype=float)
    np.testing.assert_allclose(bound, [0.0166, 0.0166, 0.19, 0.0166], rtol=0.05)
    assert np.all(rms / bound > 0.75) and np.all(rms / bound < 1.25), rms / bound


@given(st.integers(0, 2**31 - 1))
def test_any_orientation_is_recovered_to_the_bound(seed: int) -> None:
    rot = Rotation.random(random_state=seed)
    table, truth = simulate_stops(rot_vs=rot, slope_deg=5.0, seed=seed)
    cal = calibrate(table, Options(model="rotation,slope"))
    assert rotation_error_mahalanobis(cal, truth) < CHI2_3_99_99
    assert np.degrees((truth.rot_vs * cal.rot_vs.inv()).magnitude()) < 1.0  # bound scale: ≈ 0.2°


@pytest.mark.parametrize(
    ("name", "rot", "gravity_axis"),
    [
        ("on its side, gravity on +x", rot_vs_from_angles(0.3, -np.pi / 2, 0.2), [1, 0, 0]),
        ("on its side, gravity on +y", rot_vs_from_angles(np.pi / 2, 0.0, 1.0), [0, 1, 0]),
        ("upside down", rot_vs_from_angles(np.pi, 0.0, -0.5), [0, 0, -1]),
    ],
)
@pytest.mark.parametrize("model", ["rotation,slope", "rotation,slope,bias"])
def test_extreme_mountings(name: str, rot: Rotation, gravity_axis: list[float], model: str) -> None:
    table, truth = simulate_stops(rot_vs=rot, slope_deg=5.0, seed=11)
    assert np.dot(table.acc_s.mean(axis=0) / G_N, gravity_axis) > 0.99, name
    cal = calibrate(table, Options(model=model))
    assert rotation_error_mahalanobis(cal, truth) < CHI2_3_99_99
    if "gravity on +x" in name:
        assert any("not separately meaningful" in n for n in cal.notes)


def test_missing_headings_give_null_yaw_and_good_tilt() -> None:
    table, _truth = simulate_preset("zhang2011", headings="none", seed=3)
    cal = calibrate(table)
    assert cal.yaw_deg is None and cal.yaw_sigma_deg is None and cal.yaw_reason
    assert "no headings" in cal.yaw_reason
    assert abs(cal.roll_deg - 5) < 4 * cal.roll_sigma_deg
    assert abs(cal.pitch_deg - 6) < 4 * cal.pitch_sigma_deg
    assert cal.slope_deg == pytest.approx(5.0, abs=4 * cal.slope_sigma_deg)  # type: ignore[arg-type]
    assert cal.rotation_sigma_deg[2] is None
    assert cal.to_dict()["mounting"]["yaw_deg"] is None


@pytest.mark.parametrize("method", ["full", "paper"])
def test_relative_headings_give_null_yaw(method: str) -> None:
    table, _ = simulate_preset("zhang2011", headings="relative", heading_offset_deg=37.0, seed=4)
    cal = calibrate(table, Options(method=method))  # type: ignore[arg-type]
    assert cal.yaw_deg is None and cal.yaw_reason is not None and "relative" in cal.yaw_reason
    assert abs(cal.roll_deg - 5) < 4 * cal.roll_sigma_deg
    assert abs(cal.pitch_deg - 6) < 4 * cal.pitch_sigma_deg


def test_relative_headings_leave_roll_and_pitch_as_with_true_headings() -> None:
    a, _ = simulate_preset("zhang2011", seed=5)
    b, _ = simulate_preset("zhang2011", headings="relative", heading_offset_deg=-80.0, seed=5)
    ca, cb = calibrate(a), calibrate(b)
    assert cb.roll_deg == pytest.approx(ca.roll_deg, abs=1e-6)
    assert cb.pitch_deg == pytest.approx(ca.pitch_deg, abs=1e-6)


def test_a_tiny_slope_leaves_yaw_undetermined() -> None:
    table, _ = simulate_preset("zhang2011", slope_deg=0.05, seed=6)
    cal = calibrate(table)
    assert cal.yaw_deg is None and "too small" in (cal.yaw_reason or "")
    assert abs(cal.roll_deg - 5) < 4 * cal.roll_sigma_deg


def test_unknown_noise_is_estimated_from_the_residuals() -> None:
    from dataclasses import replace

    table, _ = simulate_preset("zhang2011", seed=8)
    cal = calibrate(replace(table, cov_s=None))
    assert cal.fit.noise_scale_mps2 == pytest.approx(0.001 * G_N, rel=0.4)
    assert cal.systematic is not None  # the statistical part: the total adds the sensor's systematic part
    assert cal.systematic.statistical["roll_deg"] == pytest.approx(0.0166, rel=0.4)
    assert any("F(3," in d.why for d in cal.model_selection.declined if d.effect == "bias")


def test_auto_model_fits_a_20mg_bias_and_no_phantom_one() -> None:
    """Over 60 seeded sessions each way (the benchmark runs 2000): ≥ 93 % right decisions."""
    rng = np.random.default_rng(12)
    fitted_when_present = fitted_when_absent = 0
    for _ in range(60):
        with_bias, truth = simulate_preset("zhang2011", seed=rng, bias_mps2=random_bias(0.02 * G_N, rng))
        cal = calibrate(with_bias)
        if cal.model == ("rotation", "slope", "bias"):
            fitted_when_present += 1
            assert cal.bias_mps2 is not None and cal.bias_sigma_mps2 is not None
            assert np.all(np.abs(cal.bias_mps2 - truth.bias_mps2) < 5 * cal.bias_sigma_mps2)
        clean, _ = simulate_preset("zhang2011", seed=rng)
        fitted_when_absent += "bias" in calibrate(clean).model
    assert fitted_when_present >= 56 and fitted_when_absent <= 4


def test_level_ground_does_not_fit_a_bias_it_cannot_separate() -> None:
    table, _ = simulate_preset("zhang2011", slope_deg=0.05, bias_mps2=np.array([0.0, 0.2, 0.0]), seed=2)
    cal = calibrate(table)
    assert "bias" not in cal.model
    assert any(d.effect == "bias" and "not separable" in d.why for d in cal.model_selection.declined), (
        cal.model_selection.declined
    )


def test_crb_report_matches_model_md_section_5() -> None:
    table, _ = simulate_preset("zhang2011", seed=9)
    obs = calibrate(table).observability
    assert obs is not None
    crb = obs.crb_1sigma["rotation,slope,bias"]
    assert crb is not None
    np.testing.assert_allclose(
        [crb.roll_deg, crb.pitch_deg, crb.yaw_deg],
        [0.27, 0.27, 0.19],
        rtol=0.06,
    )
    assert obs.fisher_rank == 4


def test_stop_weights_follow_the_stop_covariance() -> None:
    """A stop with a 100× larger covariance barely moves the estimate when it is disturbed."""
    from dataclasses import replace

    table, _ = simulate_preset("zhang2011", noise_g=1e-7, seed=0)
    acc = table.acc_s.copy()
    acc[3] += [0.3, 0.0, 0.0]
    cov = table.cov_s.copy()  # type: ignore[union-attr]
    cov[3] *= 1e4
    weighted = calibrate(replace(table, acc_s=acc, cov_s=cov), Options(model="rotation,slope"))
    unweighted = calibrate(replace(table, acc_s=acc, cov_s=None), Options(model="rotation,slope"))
    assert abs(weighted.yaw_deg - 7) < 0.05 < abs(unweighted.yaw_deg - 7)  # type: ignore[operator]


@pytest.mark.parametrize("headings", ["uphill", "none"])
def test_the_jacobian_of_every_registered_effect_matches_finite_differences(headings: str) -> None:
    """The chain rule through the effects (gravity and scale scale the earlier columns) against central
    differences of the residual along each parameter, at a point where every effect is non-zero."""
    from dataclasses import replace as with_

    from mountcal.estimate import effects as registry
    from mountcal.estimate import full as ml

    rng = np.random.default_rng(3)
    temperature = np.linspace(15.0, 35.0, 12)
    table, _ = simulate_stops(temperature_c=temperature, headings=headings, seed=rng)  # type: ignore[arg-type]
    table = with_(table, site=np.array(["a", "b", "c"] * 4))
    terms = ("rotation", "slope", *registry.registered())
    model = ml.StaticModel(table, terms, 9.81)
    start = ml.adapt(ml.initial_state(table, 9.81), table, terms, 9.81)
    state = model.retract(start, 1e-2 * rng.normal(size=len(model.names)))  # every effect away from its start
    moved = [np.all(v != s) for v, s in zip(state.values.values(), start.values.values(), strict=True) if v.size]
    assert len(moved) == len(registry.registered()) - 1 and all(moved)  # site_slope's α are the base slopes
    jac = model.jacobian(state)
    h = 1e-6
    for k in range(len(model.names)):
        step = np.zeros(len(model.names))
        step[k] = h
        numeric = (model.residual(model.retract(state, step)) - model.residual(model.retract(state, -step))) / (2 * h)
        assert np.allclose(jac[:, k], numeric, rtol=1e-4, atol=1e-6 * np.abs(jac).max()), model.names[k]
