"""Residual tests: calibrated under the model (each test, and the family), and each sees its own structure."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mountcal.calibrate import calibrate
from mountcal.conventions import G_N
from mountcal.diagnose import FAMILY_ALPHA, analyse, unexplained
from mountcal.effects import BASE
from mountcal.estimate import full
from mountcal.result import Finding
from mountcal.simulate.stops import simulate_stops
from mountcal.stoptable import StopTable

MG = 1e-3 * G_N


def clean(rng: np.random.Generator, n: int = 12, **kw: object) -> StopTable:
    beta = np.arange(n) * 360.0 / n
    angles = rng.uniform(-10, 10), rng.uniform(-10, 10), rng.uniform(-180, 180)
    temperature = np.interp(np.arange(n), [0, n // 2, n - 1], [20.0, 35.0, 22.0])
    table, _ = simulate_stops(*angles, beta_deg=beta, temperature_c=temperature, seed=rng, **kw)  # type: ignore[arg-type]
    return table


def p_values(table: StopTable, terms: tuple[str, ...] = BASE) -> dict[str, float]:
    fit = full.fit(table, terms, G_N)
    return {f.test: f.p_value for f in analyse(table, fit) if f.p_value is not None}


@pytest.mark.parametrize("noise_known", [True, False])
def test_every_test_fires_at_its_nominal_rate_under_the_model(noise_known: bool) -> None:
    # 300 clean sessions: a test whose null is right rejects ~5 % at p < 0.05 (binomial sd 1.3 %);
    # one that ignored what the fit absorbs, or the estimated noise, would be far off.
    rng = np.random.default_rng(5 if noise_known else 6)
    runs = 300
    low: dict[str, int] = {}
    for _ in range(runs):
        table = clean(rng)
        if not noise_known:
            table = replace(table, cov_s=None)
        for test, p in p_values(table).items():
            low[test] = low.get(test, 0) + (p < 0.05)
    expected = {"harmonic_2beta", "harmonic_3beta", "drift", "temperature", "norm", "variance_heading", "single_stop"}
    expected |= {"stop_norm", "stop_heading", "hysteresis"}
    assert expected | ({"chi2"} if noise_known else set()) <= set(low)
    for test, k in low.items():
        assert 0.015 <= k / runs <= 0.095, (test, k / runs)


def test_clean_sessions_are_rarely_flagged_and_stay_confident() -> None:
    rng = np.random.default_rng(8)
    runs = 200
    flagged = sum(bool(calibrate(clean(rng)).unexplained) for _ in range(runs))
    assert flagged / runs <= 0.03  # the family is held at 1 %; 3 % is > 3 binomial sd above it


def test_holm_rejects_step_down_at_the_family_level() -> None:
    def f(name: str, p: float | None) -> Finding:
        return Finding(name, name, "", None if p is None else 1.0, 1, p, None if p is None else np.log10(p))

    findings = [f("a", 0.003), f("b", 0.0011), f("c", 0.2), f("d", None), f("e", 0.0049)]
    # four tests with p-values: 0.0011 ≤ 0.01/4, 0.003 ≤ 0.01/3, 0.0049 ≤ 0.01/2, 0.2 > 0.01/1
    assert [x.test for x in unexplained(findings, 0.01)] == ["b", "a", "e"]
    # 0.0011 ≤ 0.005/4, then 0.003 > 0.005/3 stops the procedure (0.0049 is not reached)
    assert [x.test for x in unexplained(findings, 0.005)] == ["b"]
    assert unexplained(findings, 0.001) == []
    assert FAMILY_ALPHA <= 0.05


def test_a_direction_the_model_absorbs_is_not_a_test() -> None:
    rng = np.random.default_rng(9)
    table = clean(rng)
    fit = full.fit(table, (*BASE, "gravity"), G_N)
    norm = next(f for f in analyse(table, fit) if f.test == "norm")
    assert norm.p_value is None and norm.dof == 0 and norm.reason


def test_the_gravity_direction_is_tested_only_where_it_is_not_the_harmonics_again() -> None:
    rng = np.random.default_rng(10)
    one = clean(rng)
    assert "gravity_quadratic" not in p_values(one)
    # Two sites on slopes of 3° and 12°: the gravity direction spans a wider cone than one circle.
    a, _ = simulate_stops(2, 3, 4, slope_deg=3.0, beta_deg=np.arange(12) * 30.0, seed=rng)
    b, _ = simulate_stops(2, 3, 4, slope_deg=12.0, beta_deg=np.arange(12) * 30.0, seed=rng)
    two = StopTable(
        acc_s=np.vstack([a.acc_s, b.acc_s]),
        beta_rad=np.concatenate([a.beta_rad, b.beta_rad]),  # type: ignore[list-item]
        cov_s=np.concatenate([a.cov_s, b.cov_s]),  # type: ignore[list-item]
        site=np.array(["a"] * 12 + ["b"] * 12),
    )
    assert "gravity_quadratic" in p_values(two, (*BASE, "site_slope"))
    # A per-axis quadratic nonlinearity of 100 mg/g² there is seen as one.
    u = two.acc_s / G_N
    bent = replace(two, acc_s=two.acc_s + 100 * MG * np.array([1.0, -1.0, 1.0]) * u**2)
    assert p_values(bent, (*BASE, "site_slope"))["gravity_quadratic"] < 1e-4


def _flags(table: StopTable) -> set[str]:
    cal = calibrate(table)
    assert not cal.confident or not cal.unexplained
    return {u.test for u in cal.unexplained}


def test_each_structure_is_seen_by_its_own_test() -> None:
    rng = np.random.default_rng(11)
    n = 24
    beta = np.radians(np.arange(n) * 15.0)
    # 3 mg along sensor x varying as 2β: a heading-dependent body tilt or an elliptical slope
    table = clean(rng, n)
    assert "harmonic_2beta" in _flags(replace(table, acc_s=table.acc_s + np.outer(np.cos(2 * beta), [3 * MG, 0, 0])))
    # a bias random walk of 2 mg per stop: slow drift
    table = clean(rng, n)
    walk = np.cumsum(rng.normal(0, 2 * MG, (n, 3)), axis=0)
    assert "drift" in _flags(replace(table, acc_s=table.acc_s + walk - walk.mean(axis=0)))
    # a bias of ±4 mg as the sensor warms or cools: thermal hysteresis
    table = clean(rng, n)
    warming = np.sign(np.gradient(table.temperature_c))  # type: ignore[arg-type]
    assert "hysteresis" in _flags(replace(table, acc_s=table.acc_s + np.outer(warming, [0, 4 * MG, 0])))


def test_scatter_that_varies_with_heading_is_seen() -> None:
    rng = np.random.default_rng(12)
    n = 48
    table = clean(rng, n, noise_g=0.0005)
    beta = table.beta_rad
    hits = 0
    for _ in range(5):
        extra = (1.0 + np.cos(beta))[:, None] * rng.normal(0, 2 * MG, (n, 3))  # type: ignore[index]
        hits += p_values(replace(table, acc_s=table.acc_s + extra))["variance_heading"] < 0.01
    assert hits >= 4


def test_the_worst_stop_is_judged_against_all_the_stops() -> None:
    rng = np.random.default_rng(13)
    table = clean(rng)
    hit = table.acc_s.copy()
    hit[4] += [0, 0, 8 * MG]  # 8σ along z on one stop, the loop not run (fixed base model)
    p = p_values(replace(table, acc_s=hit))["single_stop"]
    assert p < 1e-6
    assert p_values(table)["single_stop"] > 1e-3


@pytest.mark.parametrize("terms", [BASE, (*BASE, "bias"), (*BASE, "bias", "gravity")])
def test_the_per_stop_tests_equal_the_dense_projection(terms: tuple[str, ...]) -> None:
    # The O(n p²) form against the plain one: project the n one-stop directions off the Jacobian.
    from mountcal.diagnose import _outside, _span

    rng = np.random.default_rng(14)
    table = clean(rng, 18)
    fit = full.fit(table, terms, G_N)
    model = full.StaticModel(table, terms, G_N)
    r, basis = model.residual(fit.state), _span(model.jacobian(fit.state))
    u = model.predict(fit.state)
    v = np.einsum("nij,nj->ni", model.whiten, u / np.linalg.norm(u, axis=1, keepdims=True))
    dense = np.zeros((3 * len(table), len(table)))
    for i, vi in enumerate(v):
        dense[3 * i : 3 * i + 3, i] = vi
    q = _outside(dense, basis)
    found = next(f for f in analyse(table, fit) if f.test == "stop_norm")
    assert found.dof == q.shape[1]
    assert found.statistic == pytest.approx(float(np.sum((q.T @ r) ** 2)), rel=1e-5)  # r ⟂ J to the fit's tolerance
