"""Per-vehicle consensus, disagreeing logs and remount detection, on simulated calibrations."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from mountcal.calibration.fit import calibrate
from mountcal.core.conventions import rot_vs_from_angles
from mountcal.fleet.agreement import (
    angles_with_sigma,
    consensus,
    find_change_points,
    information,
    segment_consensus,
    tangent_residuals,
)
from mountcal.fleet.vehicles import analyse_fleet
from mountcal.fleet.worker import calibration_record
from mountcal.simulate.stops import simulate_stops

TRUTH = (5.0, 6.0, 7.0)


def _log_rows(vehicle: str, angles: list[tuple[float, float, float]], seed: int, **sim: object) -> list[dict]:
    """One calibrated, simulated stop table per mounting in ``angles`` (time order = list order)."""
    rows = []
    for i, (roll, pitch, yaw) in enumerate(angles):
        table, _ = simulate_stops(roll, pitch, yaw, noise_g=0.001, seed=seed + i, **sim)  # type: ignore[arg-type]
        rec = calibration_record(calibrate(table))
        rec.update(
            vehicle_id=vehicle,
            log=f"{vehicle}/log_{i}.csv",
            status="ok",
            start_time=pd.Timestamp("2024-05-01", tz="UTC") + pd.Timedelta(days=i),
        )
        rows.append(rec)
    return rows


def _mounting(i: int, n: int, change_at: int | None, change: tuple[float, float, float]) -> tuple[float, float, float]:
    if change_at is None or i < change_at:
        return TRUTH
    return tuple(a + d for a, d in zip(TRUTH, change, strict=True))  # type: ignore[return-value]


def test_a_2deg_remount_half_way_is_flagged_at_the_right_log_and_a_steady_vehicle_is_not() -> None:
    n = 10
    rows = _log_rows("moved", [_mounting(i, n, 5, (2.0, 0.0, 0.0)) for i in range(n)], seed=100)
    rows += _log_rows("steady", [_mounting(i, n, None, (0, 0, 0)) for i in range(n)], seed=200)
    logs, vehicles = analyse_fleet(pd.DataFrame(rows))

    moved = vehicles[vehicles["vehicle_id"] == "moved"].reset_index(drop=True)
    assert list(moved["segment"]) == [0, 1]
    assert list(moved["remount"]) == [False, True]
    assert moved.loc[1, "remount_log"] == "moved/log_5.csv"
    assert moved.loc[1, "remount_p_value"] < 1e-3
    change, sigma = moved.loc[1, "remount_change_deg"], moved.loc[1, "remount_change_sigma_deg"]
    assert abs(change - 2.0) < 4 * sigma + 1e-3, (change, sigma)
    assert abs(moved.loc[1, "remount_change_x_deg"] - 2.0) < 0.1  # a change of roll is a rotation about x
    flagged = logs[logs["flags"].map(lambda f: "remount" in f)]
    assert list(flagged["log"]) == ["moved/log_5.csv"]
    assert list(logs.loc[logs["vehicle_id"] == "moved", "segment"]) == [0] * 5 + [1] * 5

    steady = vehicles[vehicles["vehicle_id"] == "steady"]
    assert len(steady) == 1 and not steady["remount"].iloc[0]
    assert steady["n_disagreeing"].iloc[0] == 0
    for angle, value in zip(("roll", "pitch", "yaw"), TRUTH, strict=True):
        est, sig = steady[f"{angle}_deg"].iloc[0], steady[f"{angle}_sigma_deg"].iloc[0]
        assert abs(est - value) < 4 * sig, (angle, est, sig)


@pytest.mark.parametrize("seed", range(4))
def test_steady_vehicles_raise_no_false_remount(seed: int) -> None:
    rows = _log_rows("steady", [TRUTH] * 12, seed=1000 * seed)
    _, vehicles = analyse_fleet(pd.DataFrame(rows))
    assert len(vehicles) == 1 and not vehicles["remount"].iloc[0]
    assert vehicles["p_value"].iloc[0] > 1e-3


def test_a_remount_is_placed_by_start_time_not_by_file_name() -> None:
    rows = _log_rows("v", [_mounting(i, 8, 3, (0.0, 2.0, 0.0)) for i in range(8)], seed=7)
    for i, row in enumerate(rows):
        row["log"] = f"v/log_{7 - i}.csv"  # names run backwards in time
    _, vehicles = analyse_fleet(pd.DataFrame(rows))
    assert vehicles["order"].iloc[0] == "start_time"
    assert vehicles.loc[vehicles["remount"], "remount_log"].tolist() == ["v/log_4.csv"]


def test_a_single_outlier_log_is_flagged_as_disagreeing_not_as_two_remounts() -> None:
    angles = [TRUTH] * 9
    angles[4] = (TRUTH[0] + 1.0, TRUTH[1], TRUTH[2])
    logs, vehicles = analyse_fleet(pd.DataFrame(_log_rows("v", angles, seed=11)))
    assert len(vehicles) == 1 and not vehicles["remount"].iloc[0]
    assert vehicles["disagreeing_logs"].iloc[0] == ["v/log_4.csv"]
    assert vehicles["n_used"].iloc[0] == 8
    row = logs[logs["log"] == "v/log_4.csv"].iloc[0]
    assert "disagrees_with_consensus" in row["flags"] and not row["in_consensus"]
    assert row["consensus_p_value"] < 1e-3
    assert abs(vehicles["roll_deg"].iloc[0] - TRUTH[0]) < 4 * vehicles["roll_sigma_deg"].iloc[0]


def test_without_headings_yaw_stays_undetermined_and_tilt_remounts_are_still_found() -> None:
    angles = [_mounting(i, 8, 4, (0.0, 2.0, 0.0)) for i in range(8)]
    rows = _log_rows("v", angles, seed=3, headings="none")
    assert all(r["yaw_deg"] is None and r["rot_sigma_z_deg"] is None for r in rows)
    _, vehicles = analyse_fleet(pd.DataFrame(rows))
    assert vehicles["remount"].tolist() == [False, True]
    assert vehicles["yaw_deg"].isna().all() and vehicles["yaw_sigma_deg"].isna().all()
    assert all("no log of this mounting period determined yaw" in r for r in vehicles["yaw_reason"])
    assert np.isnan(vehicles["remount_change_z_deg"].iloc[1])
    assert abs(vehicles["remount_change_deg"].iloc[1] - 2.0) < 0.1


def test_a_vehicle_whose_logs_all_failed_has_no_calibration_and_says_why() -> None:
    rows = _log_rows("good", [TRUTH] * 3, seed=5)
    rows += [
        {"vehicle_id": "bad", "log": f"bad/{i}.csv", "status": "failed", "error": "x", "flags": []} for i in range(2)
    ]
    frame = pd.DataFrame(rows)
    logs, vehicles = analyse_fleet(frame)
    bad = vehicles[vehicles["vehicle_id"] == "bad"].iloc[0]
    assert bad["status"] == "no calibration" and bad["reason"] == "all 2 logs failed"
    assert bad["n_failed_vehicle"] == 2
    assert logs.loc[logs["vehicle_id"] == "bad", "segment"].isna().all()


def test_consensus_is_the_inverse_variance_weighted_mean_for_small_differences() -> None:
    base = rot_vs_from_angles(*np.radians(TRUTH))
    offsets = 1e-5 * np.array([[1.0, -2.0, 3.0], [-2.0, 1.0, 0.0], [0.0, 3.0, -1.0]])  # rad: linear regime
    sigma_deg = np.array([[0.01, 0.02, 0.1], [0.02, 0.02, 0.2], [0.04, 0.01, 0.1]])
    rot = Rotation.from_rotvec(offsets) * base
    cons = consensus(rot, information(sigma_deg))
    w = 1.0 / sigma_deg**2
    expected = (w * offsets).sum(axis=0) / w.sum(axis=0)
    got = (cons.rot_vs * base.inv()).as_rotvec()
    np.testing.assert_allclose(got, expected, atol=1e-9)  # second-order (BCH) terms are ~1e-10
    np.testing.assert_allclose(np.sqrt(np.diag(cons.cov_rad2)), np.radians(1.0 / np.sqrt(w.sum(axis=0))), rtol=1e-12)
    assert cons.dof == 6


def test_a_log_without_yaw_informs_tilt_only() -> None:
    base = rot_vs_from_angles(*np.radians(TRUTH))
    yaw_only = Rotation.from_euler("z", 30, degrees=True) * base  # the same tilt, another yaw
    rot = Rotation.concatenate([base, yaw_only])
    sigma = np.array([[0.1, 0.1, 0.5], [0.1, 0.1, np.nan]])
    cons = consensus(rot, information(sigma))
    assert (cons.rot_vs * base.inv()).magnitude() < 1e-10  # the yaw-less log does not pull yaw
    np.testing.assert_allclose(cons.residual_rad[1], 0.0, atol=1e-12)
    angles, sig = angles_with_sigma(cons)
    np.testing.assert_allclose(angles, TRUTH, atol=1e-8)
    assert sig[2] is not None and abs(sig[2] - 0.5) < 1e-3  # yaw's σ is the σ about z (plus tilt coupling)


def test_tangent_residuals_of_a_tilt_follow_the_vehicle_axes() -> None:
    base = rot_vs_from_angles(*np.radians(TRUTH))
    for axis in range(3):
        d = np.zeros(3)
        d[axis] = 0.01
        rot = Rotation.concatenate([Rotation.from_rotvec(d) * base])
        full = tangent_residuals(rot, base, np.array([True]))[0]
        tilt = tangent_residuals(rot, base, np.array([False]))[0]
        np.testing.assert_allclose(full, d, atol=1e-12)
        np.testing.assert_allclose(tilt, d * [1, 1, 0], atol=1e-12)


@given(
    st.lists(st.floats(-0.05, 0.05), min_size=9, max_size=9),
    st.floats(-np.pi, np.pi),
    st.floats(-1.2, 1.2),
    st.floats(-np.pi, np.pi),
)
def test_consensus_follows_a_change_of_the_sensor_frame(
    offsets: list[float], yaw: float, pitch: float, roll: float
) -> None:
    """R_i → R_i·Q for all logs (the sensor re-labelled) moves the consensus to R̄·Q and nothing else."""
    base = rot_vs_from_angles(0.1, 0.2, 0.3)
    rot = Rotation.from_rotvec(np.reshape(offsets, (3, 3))) * base
    info = information(np.array([[0.1, 0.2, 0.3], [0.2, 0.1, 0.5], [0.3, 0.3, 0.2]]))
    q = Rotation.from_euler("ZYX", [yaw, pitch, roll])
    a, b = consensus(rot, info), consensus(rot * q, info)
    assert ((a.rot_vs * q).inv() * b.rot_vs).magnitude() < 1e-9
    assert abs(a.chi2 - b.chi2) < 1e-6 * max(1.0, a.chi2)


def test_a_big_remount_and_a_second_one_are_both_found() -> None:
    angles = [TRUTH] * 4 + [(TRUTH[0], TRUTH[1], TRUTH[2] + 90.0)] * 4 + [(TRUTH[0] - 3.0, TRUTH[1], TRUTH[2])] * 4
    rot = Rotation.from_euler("ZYX", [[y, p, r] for r, p, y in angles], degrees=True)
    info = information(np.full((12, 3), 0.05))
    points, outliers = find_change_points(rot, info)
    assert [c.index for c in points] == [4, 8] and outliers == []


def test_a_period_s_consensus_kept_from_the_split_search_is_the_one_it_would_compute() -> None:
    angles = [TRUTH] * 5 + [(TRUTH[0] + 2.0, TRUTH[1], TRUTH[2])] * 5
    rot = Rotation.from_euler("ZYX", [[y, p + 0.01 * i, r] for i, (r, p, y) in enumerate(angles)], degrees=True)
    info = information(np.full((10, 3), 0.05))
    runs: dict = {}
    points, _ = find_change_points(rot, info, runs=runs)
    assert [c.index for c in points] == [5] and {(0, 10), (0, 5), (5, 10)} <= set(runs)
    for a, b in ((0, 5), (5, 10)):  # the kept consensus gives the very numbers a fresh one gives
        kept, fresh = segment_consensus(rot[a:b], info[a:b], of_all=runs[a, b]), segment_consensus(rot[a:b], info[a:b])
        assert np.array_equal(kept[0].rot_vs.as_quat(), fresh[0].rot_vs.as_quat())
        assert np.array_equal(kept[2], fresh[2], equal_nan=True) and kept[4] == fresh[4]


def test_a_yaw_less_period_names_its_most_common_reason_the_first_by_name_on_a_tie() -> None:
    rows = _log_rows("v", [TRUTH] * 4, seed=21, headings="none")
    for row, reason in zip(rows, ["b: no turns", "a: no heading", None, "a: no heading"], strict=True):
        row["yaw_reason"] = reason
    _, vehicles = analyse_fleet(pd.DataFrame(rows))
    assert "(e.g. a: no heading)" in vehicles["yaw_reason"].iloc[0]
    rows[2]["yaw_reason"] = "b: no turns"  # a tie: the first by name, as pandas' mode orders it
    _, vehicles = analyse_fleet(pd.DataFrame(rows))
    assert "(e.g. a: no heading)" in vehicles["yaw_reason"].iloc[0]
    rows[0]["yaw_reason"] = rows[1]["yaw_reason"] = rows[3]["yaw_reason"] = None
    _, vehicles = analyse_fleet(pd.DataFrame(rows))
    assert "(e.g. b: no turns)" in vehicles["yaw_reason"].iloc[0]
