"""Triad calibration: `mountcal triad` on real multi-position sessions and imucal's JSON; `calibrate --triad`."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from mountcal.calibration.fit import Options, calibrate
from mountcal.cli import main
from mountcal.core.conventions import G_N
from mountcal.estimate.triad import NAMES, Triad, load
from mountcal.simulate.stops import simulate_stops

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import real_sessions

needs_xsens = pytest.mark.skipif(not real_sessions.XSENS.is_dir(), reason="../shared/data/real/imu_tk-xsens absent")
needs_ferraris = pytest.mark.skipif(
    not real_sessions.FERRARIS.is_dir(), reason="../shared/data/real/imucal-ferraris absent"
)


def _fitted(inputs: Path, tmp_path: Path) -> Triad:
    """``mountcal triad`` run on a session, its output read back."""
    assert main(["triad", str(inputs), "-o", str(tmp_path / "t.json")]) == 0
    return load(tmp_path / "t.json")


def _triad(scale_e: tuple[float, ...], sigma: float) -> Triad:
    return Triad(np.array([0.3, -0.2, 0.5]), np.array(scale_e), np.eye(9) * sigma**2, "test")


@pytest.mark.real_data
@needs_xsens
def test_the_hand_held_session_gives_every_term_and_a_calibrated_sensor_reads_g(tmp_path: Path) -> None:
    session = real_sessions.xsens_samples(tmp_path / "xsens.parquet")
    triad = _fitted(session, tmp_path)
    assert triad.fitted == NAMES  # 34 orientations separate bias, scale and cross-axis
    sigma = np.sqrt(np.diag(triad.cov))
    assert np.all(sigma[:3] < 0.01) and np.all(sigma[3:] < 1e-3)
    # the stops read as the calibrated sensor reads them: |a| = g far better than raw
    from mountcal.estimate.triad import session_stops

    acc, _, _ = session_stops([str(session)], "mps2")
    raw = np.abs(np.linalg.norm(acc, axis=1) - G_N)
    fixed = np.abs(np.linalg.norm((acc - triad.bias_mps2) @ np.linalg.inv(triad.matrix).T, axis=1) - G_N)
    assert np.sqrt(np.mean(fixed**2)) < 0.01 * np.sqrt(np.mean(raw**2))


@pytest.mark.real_data
@needs_ferraris
def test_six_faces_give_bias_and_scale_and_leave_the_couplings_to_the_spec(tmp_path: Path) -> None:
    triad = _fitted(real_sessions.ferraris_stops(tmp_path / "faces.csv"), tmp_path)
    assert triad.fitted == NAMES[:6]
    errors = triad.errors(Options().spec)
    i = errors.names.index("cross_xz")
    assert np.sqrt(errors.cov[i, i]) == pytest.approx(Options().spec.cross_axis / np.sqrt(3))


@pytest.mark.real_data
@needs_ferraris
def test_imucal_json_written_by_imucal_is_read_and_checked_against_its_session(tmp_path: Path) -> None:
    pytest.importorskip("imucal")
    cal = real_sessions.imucal_json(tmp_path / "imucal.json")
    faces = real_sessions.ferraris_stops(tmp_path / "faces.csv")
    out = tmp_path / "t.json"
    # imucal's gravity is 9.81: with mountcal's 9.80665 its scales differ by 0.035 %, ~9σ of this session
    assert main(["triad", str(faces), "-o", str(out), "--imucal", str(cal)]) != 0
    assert not out.exists()
    assert main(["triad", str(faces), "-o", str(out), "--imucal", str(cal), "--gravity", "9.81"]) == 0
    triad = load(out)
    doc = json.loads(cal.read_text(encoding="utf-8"))
    np.testing.assert_allclose(triad.bias_mps2, doc["b_a"], rtol=1e-12)
    m = np.array(doc["K_a"]) @ np.array(doc["R_a"])
    # the symmetric part: I + E = (M Mᵀ)^½ (the rotation goes to the mounting)
    w, v = np.linalg.eigh(m @ m.T)
    np.testing.assert_allclose(triad.matrix, (v * np.sqrt(w)) @ v.T, atol=1e-12)


def test_calibrate_with_the_triad_finds_the_uncorrected_sensor_s_mounting_and_carries_its_covariance() -> None:
    e = (0.03, -0.02, 0.025, 0.015, -0.01, 0.012)
    triad = _triad(e, 1e-4)
    table, truth = simulate_stops(
        4.0, -3.0, 25.0, slope_deg=6.0, noise_g=1e-4, seed=3, bias_mps2=triad.bias_mps2, scale_matrix=triad.matrix
    )
    with_triad = calibrate(table, Options(model="rotation,slope", triad=triad))
    without = calibrate(table, Options(model="rotation,slope"))
    err_with = abs(with_triad.roll_deg - truth.angles_deg[0])
    err_without = abs(without.roll_deg - truth.angles_deg[0])
    assert err_with < 3 * with_triad.roll_sigma_deg and err_without > 10 * err_with
    part = with_triad.systematic
    assert part is not None and "triad" in part.source and not part.default_spec
    assert part.systematic["roll_deg"] is not None and part.systematic["roll_deg"] > 0
    # a triad ten times less certain: what the slope cannot see of it grows tenfold, what it sees is narrowed
    looser = calibrate(table, Options(model="rotation,slope", triad=_triad(e, 1e-3)))
    assert looser.systematic is not None and looser.systematic.systematic["roll_deg"] > 2 * part.systematic["roll_deg"]


def test_a_file_that_is_not_a_triad_is_refused_naming_it(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    table, _ = simulate_stops(seed=1)
    from mountcal.stops.table import write_stop_table

    stops = tmp_path / "stops.csv"
    write_stop_table(table, stops)
    bad = tmp_path / "imucal_like.json"
    bad.write_text(json.dumps({"cal_type": "Ferraris", "K_a": [[1, 0, 0]]}), encoding="utf-8")
    assert main(["calibrate", str(stops), "--triad", str(bad)]) != 0
    err = capsys.readouterr().err
    assert "imucal_like.json" in err and "mountcal triad" in err and "Traceback" not in err
    nan_cov = _triad((0.0,) * 6, 1e-3).to_dict()
    nan_cov["covariance"][0][0] = -1.0  # not a covariance
    bad.write_text(json.dumps(nan_cov), encoding="utf-8")
    assert main(["calibrate", str(stops), "--triad", str(bad)]) != 0


def test_triad_refuses_a_session_in_one_orientation(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    table, _ = simulate_stops(slope_deg=2.0, seed=4)  # a vehicle's stops: gravity near one sensor axis
    from mountcal.stops.table import write_stop_table

    stops = tmp_path / "stops.csv"
    write_stop_table(table, stops)
    out = tmp_path / "t.json"
    assert main(["triad", str(stops), "-o", str(out)]) != 0
    assert "orientations" in capsys.readouterr().err and not out.exists()


def test_cli_calibrate_with_triad_writes_both_parts(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from mountcal.stops.table import write_stop_table

    triad = _triad((0.02, -0.01, 0.015, 0.01, -0.005, 0.008), 2e-4)
    table, truth = simulate_stops(seed=5, bias_mps2=triad.bias_mps2, scale_matrix=triad.matrix)
    write_stop_table(table, tmp_path / "stops.csv")
    triad.save(tmp_path / "triad.json")
    out = tmp_path / "r.json"
    assert (
        main(["calibrate", str(tmp_path / "stops.csv"), "--triad", str(tmp_path / "triad.json"), "-o", str(out)]) == 0
    )
    assert "triad calibration" in capsys.readouterr().err
    doc = json.loads(out.read_text(encoding="utf-8"))
    assert "triad" in doc["systematic"]["source"] and doc["systematic"]["default_spec"] is False
    assert abs(doc["mounting"]["roll_deg"] - truth.angles_deg[0]) < 3 * doc["uncertainty"]["roll_deg"]


def test_a_triad_file_naming_an_unknown_parameter_is_refused_naming_it(tmp_path: Path) -> None:
    from mountcal.core.errors import InputError

    doc = _triad((0.0,) * 6, 1e-3).to_dict()
    doc["fitted"] = ["bias_x", "bias_y", "scale_q"]  # not a parameter of the triad model
    path = tmp_path / "odd.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    with pytest.raises(InputError) as err:
        load(path)
    text = str(err.value)
    assert "odd.json" in text and "'scale_q'" in text and all(n in text for n in NAMES)
    doc["fitted"] = list(NAMES[:6])  # a known subset still loads
    path.write_text(json.dumps(doc), encoding="utf-8")
    assert load(path).fitted == NAMES[:6]
