"""Properties of `mountcal calibrate` on inputs a user can write, and metamorphic relations.

The property (issue 11): every run either writes a result that is valid JSON with finite numbers,
loads back and is right when marked confident (tilt within 10°, yaw within 5σ) — or exits non-zero
with a message. Never a traceback. The cases are benchmarks/fuzz.py's, drawn here by hypothesis
(a small profile; the long run is `python benchmarks/fuzz.py`).

The metamorphic relations do not trust the simulator's model: they compare two runs of the
estimator on inputs that must give related answers.
"""

from __future__ import annotations

import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from mountcal.calibration.fit import Options, calibrate
from mountcal.cli import main
from mountcal.core.conventions import G_N
from mountcal.core.result import Calibration
from mountcal.simulate.stops import simulate_stops
from mountcal.stops.table import OPTIONAL, StopTable

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import fuzz

unit_quaternions = st.tuples(*[st.floats(-1, 1) for _ in range(4)]).filter(lambda q: 0.1 < np.linalg.norm(q))
stop_cases = st.builds(
    fuzz.StopCase,
    n=st.one_of(st.integers(3, 14), st.integers(15, 200)),
    columns=st.lists(st.sampled_from(OPTIONAL), unique=True).map(tuple),
    unit=st.sampled_from(["mps2", "g"]),
    headings=st.sampled_from(fuzz.HEADINGS),
    quat_xyzw=unit_quaternions.map(lambda q: tuple(float(v) for v in np.asarray(q) / np.linalg.norm(q))),
    noise_mg=st.floats(0.1, 20.0),
    slope_deg=st.floats(0.5, 30.0),
    even_headings=st.booleans(),
    heading_offset_deg=st.floats(-180.0, 180.0),
    seed=st.integers(0, 2**31 - 1),
    model=st.one_of(st.just("auto"), st.sampled_from(fuzz.MODELS)),
    method=st.sampled_from(["full", "full", "paper"]),
    parquet=st.booleans(),
    slope_reference=st.one_of(
        st.none(),
        st.tuples(  # an offset from the true slope (beyond ±10: the value itself), and its σ
            st.one_of(st.floats(-3.0, 3.0), st.sampled_from([90.0, 1e9, float("nan")])),
            st.sampled_from([0.01, 0.05, 0.5, 0.0, -0.1, float("inf")]),
        ),
    ),
)


@settings(max_examples=12, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(case=stop_cases)
def test_calibrate_is_correct_or_refuses(case: fuzz.StopCase, tmp_path: Path) -> None:
    kind, detail = fuzz.run_stop_case(case, tmp_path)
    assert kind in ("ok", "refused"), f"{kind}: {detail}"


@pytest.mark.invalid_results  # the judge must see an invalid result
def test_the_judge_catches_what_it_must(tmp_path: Path) -> None:
    """The oracle itself can fail: a NaN, a missing reason, a confident wrong tilt are each caught."""
    table, truth = simulate_stops(seed=3)
    doc = calibrate(table).to_dict()
    out = tmp_path / "r.json"
    out.write_text(json.dumps(doc), encoding="utf-8")
    assert fuzz.judge(0, "", out, truth.rot_vs, "uphill") == ("ok", "")
    out.write_text(json.dumps({**doc, "residual_rms_mps2": float("nan")}), encoding="utf-8")
    assert fuzz.judge(0, "", out, truth.rot_vs, "uphill")[0] == "nonfinite"
    out.write_text(json.dumps(doc), encoding="utf-8")
    wrong = Rotation.from_euler("x", 15, degrees=True) * truth.rot_vs
    assert fuzz.judge(0, "", out, wrong, "uphill")[0] == "wrong_confident"
    assert fuzz.judge(None, "Traceback ...\nValueError: x\n", out, None, "uphill")[0] == "traceback"
    bad = {**doc, "diagnostics": [{"test": "chi2", "statistic": None}]}
    out.write_text(json.dumps(bad), encoding="utf-8")
    assert fuzz.judge(0, "", out, None, "uphill")[0] == "invalid"


# --- metamorphic relations ----------------------------------------------------------------------


@pytest.fixture(scope="module")
def known_noise() -> StopTable:
    table, _ = simulate_stops(12.0, -4.0, 33.0, slope_deg=7.0, noise_g=0.002, seed=11)
    return table


def _close(a: Rotation, b: Rotation, deg: float = 1e-6) -> bool:
    return float(np.degrees((a * b.inv()).magnitude())) < deg


FIXED = Options(model="rotation,slope,bias")


def test_permuting_the_stops_changes_nothing(known_noise: StopTable) -> None:
    order = np.random.default_rng(0).permutation(len(known_noise))
    a = calibrate(known_noise, FIXED)
    b = calibrate(known_noise.subset(order), FIXED)
    assert _close(a.rot_vs, b.rot_vs)
    for key in ("roll_sigma_deg", "pitch_sigma_deg", "yaw_sigma_deg", "slope_deg", "slope_sigma_deg"):
        assert getattr(a, key) == pytest.approx(getattr(b, key), rel=1e-6)


@pytest.mark.parametrize("seed", [1, 2])
def test_rotating_every_sample_composes_with_the_answer(known_noise: StopTable, seed: int) -> None:
    """Samples a' = Q a (the sensor turned by Qᵀ) give R' = R Qᵀ, the same σ, and the bias turned by Q."""
    q = Rotation.random(random_state=seed)
    qm = q.as_matrix()
    turned = replace(known_noise, acc_s=q.apply(known_noise.acc_s), cov_s=qm @ known_noise.cov_s @ qm.T)
    a, b = calibrate(known_noise, FIXED), calibrate(turned, FIXED)
    assert _close(b.rot_vs, a.rot_vs * q.inv())
    assert _stat_rotation(b) == pytest.approx(_stat_rotation(a), rel=1e-5)  # the spec turns with the sensor
    np.testing.assert_allclose(b.bias_mps2, q.apply(a.bias_mps2), atol=1e-8)  # type: ignore[arg-type]


def test_adding_a_constant_to_every_heading_shifts_yaw_by_it(known_noise: StopTable) -> None:
    """β + c for the same samples: R' = Rz(−c) R (the uphill reference turned by c), σ unchanged."""
    c = np.radians(40.0)
    shifted = replace(known_noise, beta_rad=known_noise.beta_rad + c)  # type: ignore[operator]
    a, b = calibrate(known_noise, FIXED), calibrate(shifted, FIXED)
    assert _close(b.rot_vs, Rotation.from_euler("z", -c) * a.rot_vs)
    assert b.yaw_sigma_deg == pytest.approx(a.yaw_sigma_deg, rel=1e-5)


def _cli(args: list[str], out: Path) -> dict:
    assert main(["calibrate", *args, "-o", str(out)]) == 0
    return json.loads(out.read_text(encoding="utf-8"))


def test_unit_g_equals_mps2(known_noise: StopTable, tmp_path: Path) -> None:
    df = known_noise.to_frame()
    df.to_csv(tmp_path / "mps2.csv", index=False, float_format="%.17g")
    in_g = df.copy()
    in_g[["ax", "ay", "az", "sx", "sy", "sz"]] /= G_N
    in_g.to_csv(tmp_path / "g.csv", index=False, float_format="%.17g")
    a = _cli([str(tmp_path / "mps2.csv")], tmp_path / "a.json")
    b = _cli([str(tmp_path / "g.csv"), "--unit", "g"], tmp_path / "b.json")
    np.testing.assert_allclose(a["rotation"]["matrix_vs"], b["rotation"]["matrix_vs"], atol=1e-9)
    for key in ("roll_deg", "pitch_deg", "yaw_deg", "slope_deg"):
        assert a["uncertainty"][key] == pytest.approx(b["uncertainty"][key], rel=1e-6)
    assert a["model"] == b["model"]


RIGHT_HANDED = [((1, 0, 2), (1, -1, 1)), ((2, 0, 1), (1, 1, 1)), ((0, 1, 2), (-1, -1, 1)), ((2, 1, 0), (-1, 1, 1))]


@pytest.mark.parametrize(("perm", "signs"), RIGHT_HANDED)
def test_swapping_and_negating_axes_gives_the_composed_mounting(
    known_noise: StopTable, tmp_path: Path, perm: tuple[int, int, int], signs: tuple[int, int, int]
) -> None:
    """Columns re-labelled by a right-handed signed permutation P: a' = P a, so R' = R Pᵀ (through the CLI)."""
    p = np.zeros((3, 3))
    p[np.arange(3), perm] = signs
    assert np.linalg.det(p) == pytest.approx(1.0)
    df = known_noise.to_frame()
    moved = df.copy()
    moved[["ax", "ay", "az"]] = df[["ax", "ay", "az"]].to_numpy() @ p.T
    moved[["sx", "sy", "sz"]] = df[["sx", "sy", "sz"]].to_numpy()[:, list(perm)]
    df.to_csv(tmp_path / "a.csv", index=False, float_format="%.17g")
    moved.to_csv(tmp_path / "b.csv", index=False, float_format="%.17g")
    a = _cli([str(tmp_path / "a.csv"), "--model", "rotation,slope,bias"], tmp_path / "a.json")
    b = _cli([str(tmp_path / "b.csv"), "--model", "rotation,slope,bias"], tmp_path / "b.json")
    ra, rb = Calibration.from_dict(a).rot_vs, Calibration.from_dict(b).rot_vs
    assert _close(rb, ra * Rotation.from_matrix(p).inv())
    assert b["uncertainty"]["rotation_about_vehicle_xyz_deg"] == pytest.approx(
        a["uncertainty"]["rotation_about_vehicle_xyz_deg"], rel=1e-5
    )


def _doubled(table: StopTable) -> StopTable:
    return table.subset(np.repeat(np.arange(len(table)), 2))


def _stat_rotation(cal: Calibration) -> list[float | None]:
    """The statistical part of the σ about the vehicle axes (the fields hold the total)."""
    assert cal.systematic is not None
    return [cal.systematic.statistical[f"rotation_{a}_deg"] for a in "xyz"]


def test_duplicating_every_stop_shrinks_sigma_by_sqrt2_when_the_table_gives_the_noise(known_noise: StopTable) -> None:
    a, b = calibrate(known_noise, FIXED), calibrate(_doubled(known_noise), FIXED)
    assert _close(a.rot_vs, b.rot_vs)
    assert b.slope_deg == pytest.approx(a.slope_deg, abs=1e-7)
    for sa, sb in zip(_stat_rotation(a), _stat_rotation(b), strict=True):
        assert sb == pytest.approx(sa / np.sqrt(2), rel=1e-6)  # type: ignore[operator]


def test_duplicating_every_stop_with_noise_from_the_residuals(known_noise: StopTable) -> None:
    """σ̂² = χ²/dof: duplicates double χ² and the information, but dof goes from 3n−p to 6n−p, so
    σ shrinks by √((3n−p)/(6n−p)) — a little less than √2, as it must for a noise estimated from
    the same residuals counted twice."""
    unknown = replace(known_noise, cov_s=None)
    opts = Options(model="rotation,slope")
    a, b = calibrate(unknown, opts), calibrate(_doubled(unknown), opts)
    assert _close(a.rot_vs, b.rot_vs)
    n, p = len(unknown), 4  # rotation (3) and slope
    ratio = np.sqrt((3 * n - p) / (6 * n - p))
    for sa, sb in zip(_stat_rotation(a), _stat_rotation(b), strict=True):
        assert sb == pytest.approx(sa * ratio, rel=1e-6)  # type: ignore[operator]
    assert a.fit.noise_scale_mps2 is not None
    assert b.fit.noise_scale_mps2 == pytest.approx(a.fit.noise_scale_mps2 * np.sqrt(2) * ratio, rel=1e-6)


def test_no_headings_and_a_sensor_upside_down_read_the_physical_branch() -> None:
    """Any orientation (here a box upside down, yawed), no headings: slope in [0°, 90°) and +g up."""
    rot = Rotation.from_euler("xyz", [178.0, 3.0, -120.0], degrees=True)
    for seed in range(5):
        table, _ = simulate_stops(rot_vs=rot, slope_deg=2.0, headings="none", noise_g=0.003, seed=seed)
        cal = calibrate(table)
        assert 0 <= cal.slope_deg < 90  # type: ignore[operator]
        up_error = np.degrees(np.arccos(np.clip(cal.rot_vs.inv().apply([0, 0, 1]) @ rot.inv().apply([0, 0, 1]), -1, 1)))
        assert up_error < 10 or not cal.confident


def test_minimal_columns_table_from_frame_round_trip(tmp_path: Path) -> None:
    table, _ = simulate_stops(seed=8)
    df = table.to_frame()[["ax", "ay", "az"]]
    df.to_csv(tmp_path / "m.csv", index=False)
    assert main(["calibrate", str(tmp_path / "m.csv"), "-o", str(tmp_path / "m.json")]) == 0
    assert fuzz.check_document(tmp_path / "m.json") is None
    assert pd.read_csv(tmp_path / "m.csv").shape == (12, 3)
