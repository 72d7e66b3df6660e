"""A slope measured apart from the stops, checked against theirs (mountcal.loop.slope_reference)."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from mountcal.calibration.fit import Options, calibrate
from mountcal.cli import main
from mountcal.core.conventions import specific_force_v
from mountcal.core.errors import InputError
from mountcal.loop.slope_reference import TEST, SlopeReference, check
from mountcal.simulate.stops import simulate_stops
from mountcal.stops.table import StopTable


def _finding(cal):  # type: ignore[no-untyped-def]
    return next(d for d in cal.diagnostics if d.test == TEST)


def _compliant(table: StopTable, truth, k: float) -> StopTable:  # type: ignore[no-untyped-def]
    """The axes tilt with the lateral load by k rad/g (a compliant bracket): the horizontal reads (1 + k) too big."""
    f_v = specific_force_v(np.radians(truth.slope_deg), np.radians(truth.beta_deg), truth.g_mps2)
    u_s = truth.rot_vs.inv().apply(f_v)
    theta = k * np.column_stack([-u_s[:, 1], u_s[:, 0], np.zeros(len(u_s))]) / truth.g_mps2
    return replace(table, acc_s=table.acc_s + np.cross(theta, u_s))


@pytest.mark.parametrize("noise_known", [True, False])
def test_the_check_fires_at_its_nominal_rate_on_clean_sessions(noise_known: bool) -> None:
    rng = np.random.default_rng(11)
    p = []
    for _ in range(150):
        angles = rng.uniform(-20, 20), rng.uniform(-20, 20), rng.uniform(-180, 180)
        table, truth = simulate_stops(
            *angles, slope_deg=rng.uniform(2, 8), seed=int(rng.integers(1 << 30)), samples_per_stop=200
        )
        if not noise_known:
            table = replace(table, cov_s=None)
        sigma = 0.02
        ref = SlopeReference(truth.slope_deg + rng.normal(0.0, sigma), sigma)
        p.append(_finding(calibrate(table, Options(slope_reference=ref))).p_value)
    rate = np.mean(np.array(p) < 0.05)
    assert 0.015 <= rate <= 0.10, rate  # nominal 5 %; the binomial 1σ on 150 draws is 1.8 %


def test_a_compliant_mount_no_residual_shows_is_flagged_against_the_reference() -> None:
    table, truth = simulate_stops(12.0, -7.0, 140.0, slope_deg=4.0, seed=5)
    bent = _compliant(table, truth, 0.05)  # 50 mrad/g: the stops read a slope 5 % too steep
    alone = calibrate(bent)
    assert alone.confident and not alone.unexplained  # nothing in the stops shows it ...
    assert alone.slope_deg - truth.slope_deg > 5 * alone.systematic.statistical["slope_deg"]  # ... yet it moved
    ref = SlopeReference(truth.slope_deg, 0.02)
    cal = calibrate(bent, Options(slope_reference=ref))
    assert not cal.confident
    assert [u.test for u in cal.unexplained] == [TEST]
    assert cal.slope_deg - truth.slope_deg == pytest.approx(0.05 * truth.slope_deg, rel=0.2)
    notes = " ".join(cal.notes)
    assert "suspension" in notes and "compliant mount" in notes and "triad" in notes  # causes, and one way out
    # the same session, not bent: the reference agrees
    fine = calibrate(table, Options(slope_reference=ref))
    assert fine.confident and _finding(fine).p_value > 0.01


def test_the_check_does_not_depend_on_the_order_of_the_stops() -> None:
    table, truth = simulate_stops(3.0, 2.0, -30.0, slope_deg=5.0, seed=8)
    ref = Options(slope_reference=SlopeReference(truth.slope_deg + 0.05, 0.03))
    order = np.random.default_rng(2).permutation(len(table))
    a, b = (_finding(calibrate(t, ref)) for t in (table, table.subset(order)))
    assert a.statistic == pytest.approx(b.statistic, rel=1e-6) and a.p_value == pytest.approx(b.p_value, rel=1e-6)


@pytest.mark.parametrize(
    ("slope", "sigma"), [(float("nan"), 0.02), (5.0, 0.0), (5.0, -0.1), (90.0, 0.02), (-1.0, 0.02), (5.0, np.inf)]
)
def test_a_reference_that_is_no_slope_is_refused(slope: float, sigma: float) -> None:
    with pytest.raises(InputError, match="slope_reference"):
        SlopeReference(slope, sigma)


def test_a_reference_the_fit_cannot_check_is_refused() -> None:
    table, _ = simulate_stops(seed=1)
    ref = SlopeReference(5.0, 0.02)
    with pytest.raises(InputError, match="method"):
        calibrate(table, Options(method="paper", slope_reference=ref))
    sites = replace(table, site=np.array(["a", "b"] * (len(table) // 2)))
    with pytest.raises(InputError, match="2 sites"):
        calibrate(sites, Options(slope_reference=ref))


def test_the_command_line_checks_the_reference_and_refuses_a_bad_one(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    table, truth = simulate_stops(seed=4)
    stops = tmp_path / "stops.csv"
    table.to_frame().to_csv(stops, index=False)
    out = tmp_path / "r.json"
    assert main(["calibrate", str(stops), "--slope-reference", f"{truth.slope_deg}", "0.02", "-o", str(out)]) == 0
    tests = [d["test"] for d in json.loads(out.read_text())["diagnostics"]]
    assert TEST in tests
    bad = tmp_path / "bad.json"
    with pytest.raises(SystemExit) as stop:  # the parser refuses it: the option's range (mountcal.core.ranges)
        main(["calibrate", str(stops), "--slope-reference", "5", "0", "-o", str(bad)])
    err = capsys.readouterr().err
    assert stop.value.code == 2 and "--slope-reference" in err and "Traceback" not in err and not bad.exists()


def test_a_model_without_one_slope_gives_no_test_and_says_why() -> None:
    found = check(None, None, SlopeReference(5.0, 0.02), None)
    assert found.p_value is None and found.reason is not None and "no test" in found.reason
