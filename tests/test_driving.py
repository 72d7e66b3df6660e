"""Yaw from driving: the simulator's physics, recovery of the truth with an honest σ, the clock
offset, the combination with parked stops, the CLI, and the real drives (comma2k19, CANedge)."""

from __future__ import annotations

import dataclasses
import glob
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mountcal import calibrate, simulate_preset
from mountcal.apply.rotate_log import to_frame
from mountcal.calibration.with_driving import combine
from mountcal.cli import main
from mountcal.core.conventions import G_N, angles_from_rot_vs, rot_vs_from_angles
from mountcal.core.errors import NotEnoughInformation
from mountcal.core.result import Calibration
from mountcal.estimate.driving import estimate_driving
from mountcal.estimate.driving_options import DrivingOptions
from mountcal.io.samples import Channel, Samples
from mountcal.simulate.drive import simulate_drive


@pytest.fixture(scope="module")
def drive():  # type: ignore[no-untyped-def]
    """A 20-minute mixed drive, 100 Hz IMU, CAN speed at 50 Hz lagging by 0.08 s."""
    return simulate_drive(roll_deg=5.0, pitch_deg=6.0, yaw_deg=7.0, seed=3)


def x_axis_error_deg(est: Rotation, truth: Rotation) -> float:
    """Angle about the vehicle z axis from the true to the estimated vehicle x axis."""
    x = est.apply(truth.inv().apply([1.0, 0.0, 0.0]))
    return float(np.degrees(np.arctan2(x[1], x[0])))


# --------------------------------------------------------------------------- the simulator's physics


def test_simulated_drive_obeys_the_sign_conventions(drive) -> None:  # type: ignore[no-untyped-def]
    parked = drive.speed_true_mps == 0.0
    # At rest the specific force is +g up (tilted only by the road's grade and cross slope).
    assert np.allclose(np.linalg.norm(drive.f_v[parked], axis=1), G_N, atol=1e-6)
    assert np.all(drive.f_v[parked, 2] > 0.99 * G_N)
    # Driving forward, x is the direction of travel: f_x = dv/dt + g·sin(grade) (suspension pitch aside).
    moving = drive.speed_true_mps > 3.0
    expected = drive.acc_long_mps2 + G_N * np.sin(drive.grade_rad)
    assert np.corrcoef(drive.f_v[moving, 0], expected[moving])[0, 1] > 0.99
    # A left turn (counter-clockwise, ω_z > 0) pushes the specific force to the left (+y): v·ω.
    turning = moving & (drive.omega_v[:, 2] > 0.1)
    assert np.all(drive.f_v[turning, 1] > 0.0)
    # The IMU reads R_vsᵀ f_v (+ noise): its mean agrees with the rotated truth.
    assert np.allclose(drive.acc_s.mean(axis=0), drive.truth.rot_vs.inv().apply(drive.f_v).mean(axis=0), atol=0.01)


def test_a_forward_acceleration_seen_by_a_sensor_yawed_left_gives_positive_yaw() -> None:
    """Yaw +φ maps sensor to vehicle by Rz(φ): a sensor turned left sees forward thrust at −φ."""
    drive = simulate_drive(0.0, 0.0, 20.0, duration_s=600.0, seed=5)
    fit = estimate_driving(drive.to_samples())
    assert fit.yaw_deg is not None
    assert fit.yaw_deg == pytest.approx(20.0, abs=0.5)


# --------------------------------------------------------------------------- accuracy and σ


def test_yaw_from_a_20_minute_drive_is_within_0_3_degrees_and_its_sigma_covers_the_error(drive) -> None:  # type: ignore[no-untyped-def]
    fit = estimate_driving(drive.to_samples())
    roll, pitch, yaw = drive.truth.angles_deg
    assert fit.yaw_deg is not None and fit.yaw_sigma_deg is not None
    assert abs(fit.yaw_deg - yaw) < 0.3
    assert abs(fit.yaw_deg - yaw) < 3.0 * fit.yaw_sigma_deg
    err_z = x_axis_error_deg(fit.rot_vs, drive.truth.rot_vs)
    sigma_z = fit.rotation_sigma_deg[2]
    assert sigma_z is not None and abs(err_z) < 3.0 * sigma_z
    # Roll and pitch from the mean gravity: the road's crown (2 %, 1.15°) is inside their σ.
    assert abs(fit.roll_deg - roll) < 2.0 * fit.roll_sigma_deg
    assert abs(fit.pitch_deg - pitch) < 2.0 * fit.pitch_sigma_deg
    assert fit.n_segments >= 20 and fit.usable_s > 400.0


def test_the_clock_offset_of_the_speed_channel_is_found(drive) -> None:  # type: ignore[no-untyped-def]
    fit = estimate_driving(drive.to_samples())
    assert fit.time_offset_searched and fit.time_offset_sigma_s is not None
    assert fit.time_offset_s == pytest.approx(-drive.truth.speed_delay_s, abs=max(3 * fit.time_offset_sigma_s, 0.02))


def test_a_big_offset_beyond_the_search_is_found_by_the_wider_search_and_said() -> None:
    drive = simulate_drive(duration_s=600.0, speed_delay_s=3.0, seed=4)
    fit = estimate_driving(drive.to_samples(), DrivingOptions(max_time_offset_s=1.0))
    assert fit.time_offset_s == pytest.approx(-3.0, abs=0.05)
    assert any("3.0 s apart, beyond the ±1 s searched first" in n for n in fit.notes)


def test_an_offset_beyond_the_wider_search_is_flagged_at_its_limit() -> None:
    drive = simulate_drive(duration_s=600.0, speed_delay_s=40.0, seed=4)
    fit = estimate_driving(drive.to_samples())
    assert any("search limit" in n for n in fit.notes)


def test_a_known_offset_is_used_as_given(drive) -> None:  # type: ignore[no-untyped-def]
    fit = estimate_driving(drive.to_samples(), DrivingOptions(time_offset_s=-0.08))
    assert not fit.time_offset_searched and fit.time_offset_s == -0.08


def test_without_a_gyro_a_heading_channel_gives_straightness(drive) -> None:  # type: ignore[no-untyped-def]
    s = drive.to_samples(gyro=False, heading=True)
    fit = estimate_driving(s)
    assert fit.straightness_source == "heading channel"
    assert fit.yaw_sigma_deg is not None and fit.yaw_deg is not None
    assert abs(fit.yaw_deg - 7.0) < 3.0 * fit.yaw_sigma_deg
    bare = estimate_driving(drive.to_samples(gyro=False))
    assert bare.straightness_source.startswith("lateral acceleration")
    assert bare.yaw_sigma_deg is not None and bare.yaw_deg is not None
    assert abs(bare.yaw_deg - 7.0) < 3.0 * bare.yaw_sigma_deg


def test_a_bias_and_a_wrong_speed_scale_do_not_bias_yaw() -> None:
    bias = np.array([0.15, -0.2, 0.1])  # ~ 25 mg
    drive = simulate_drive(yaw_deg=-12.0, bias_mps2=bias, speed_scale=1.03, rate_hz=200.0, seed=8)
    fit = estimate_driving(drive.to_samples())
    assert fit.speed_scale == pytest.approx(1 / 1.03, abs=0.02)
    assert fit.rotation_sigma_deg[2] is not None
    assert abs(x_axis_error_deg(fit.rot_vs, drive.truth.rot_vs)) < 3.0 * fit.rotation_sigma_deg[2]


# --------------------------------------------------------------------------- what the data cannot tell


def test_no_speed_channel_is_not_enough_information(drive) -> None:  # type: ignore[no-untyped-def]
    s = drive.to_samples()
    with pytest.raises(NotEnoughInformation, match="speed"):
        estimate_driving(dataclasses.replace(s, channels={}))


def test_standing_still_is_not_enough_information() -> None:
    t = np.arange(0.0, 300.0, 0.01)
    acc = np.tile([0.0, 0.0, G_N], (t.size, 1)) + np.random.default_rng(0).normal(0, 0.05, (t.size, 3))
    s = Samples(t, acc, None, {"speed_mps": Channel(t[::10], np.zeros(t[::10].size))})
    with pytest.raises(NotEnoughInformation, match="no driving"):
        estimate_driving(s)


def test_cruising_without_speed_changes_leaves_yaw_undetermined_with_the_reason() -> None:
    drive = simulate_drive(duration_s=400.0, seed=2)
    s = drive.to_samples()
    speed = s.channels["speed_mps"]
    steady = Channel(speed.t_s, np.full(speed.t_s.size, 15.0))  # a speed channel that never changes
    fit = estimate_driving(dataclasses.replace(s, channels={"speed_mps": steady}), DrivingOptions(time_offset_s=0.0))
    assert fit.yaw_deg is None and fit.yaw_sigma_deg is None
    assert fit.yaw_reason is not None and "speed changes" in fit.yaw_reason


# --------------------------------------------------------------------------- with parked stops


def static_like(truth: Rotation, yaw_deg: float | None, yaw_sigma_deg: float | None) -> Calibration:
    """A stops-only calibration with the drive's true tilt and a chosen yaw (None: not determined)."""
    base = calibrate(simulate_preset("zhang2011", seed=0)[0])
    roll, pitch, _ = angles_from_rot_vs(truth)
    rot = rot_vs_from_angles(roll, pitch, float(np.radians(yaw_deg or 0.0)))
    return dataclasses.replace(
        base,
        rot_vs=rot,
        roll_deg=float(np.degrees(roll)),
        pitch_deg=float(np.degrees(pitch)),
        yaw_deg=yaw_deg,
        yaw_sigma_deg=yaw_sigma_deg,
        yaw_reason=None if yaw_deg is not None else "headings are relative",
        rotation_sigma_deg=(0.02, 0.02, yaw_sigma_deg),
        bias_mps2=None,
        bias_sigma_mps2=None,
    )


def test_driving_and_stops_agreeing_are_combined_by_inverse_variance(drive) -> None:  # type: ignore[no-untyped-def]
    static = static_like(drive.truth.rot_vs, 7.1, 0.2)
    fit = estimate_driving(drive.to_samples(), tilt_from=static)
    cal = combine(static, fit)
    c = cal.fit.combination
    assert c is not None and c.agree and c.z is not None and abs(c.z) <= 2.0
    s_d = fit.rotation_sigma_deg[2]
    assert s_d is not None and cal.rotation_sigma_deg[2] is not None
    assert cal.rotation_sigma_deg[2] < min(0.2, s_d)
    assert cal.yaw_deg is not None and fit.yaw_deg is not None
    assert min(7.1, fit.yaw_deg) <= cal.yaw_deg <= max(7.1, fit.yaw_deg)
    assert cal.roll_deg == pytest.approx(static.roll_deg) and cal.pitch_deg == pytest.approx(static.pitch_deg)
    assert any("agree" in n for n in cal.notes)
    Calibration.from_dict(cal.to_dict())  # the result JSON stays valid


def test_a_disagreement_beyond_the_uncertainties_is_reported(drive) -> None:  # type: ignore[no-untyped-def]
    static = static_like(drive.truth.rot_vs, 9.0, 0.2)  # 2° off
    cal = combine(static, estimate_driving(drive.to_samples(), tilt_from=static))
    c = cal.fit.combination
    assert c is not None and not c.agree and c.disagreement is not None  # beyond 3σ: a finding, not combined
    assert c.disagreement.statistic is not None and c.disagreement.statistic > 5
    assert any("DISAGREE" in n for n in cal.notes) and not cal.confident
    assert cal.yaw_deg == static.yaw_deg and cal.rot_vs.approx_equal(static.rot_vs)


def test_stops_without_yaw_take_the_yaw_from_driving(drive) -> None:  # type: ignore[no-untyped-def]
    static = static_like(drive.truth.rot_vs, None, None)
    cal = combine(static, estimate_driving(drive.to_samples(), tilt_from=static))
    assert cal.yaw_deg is not None and cal.yaw_reason is None
    assert cal.yaw_deg == pytest.approx(7.0, abs=0.3)
    assert cal.fit.calibrated_from == "stops + driving"


# --------------------------------------------------------------------------- the CLI


def test_calibrate_a_drive_log_uses_what_it_supports_and_says_so(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    drive,  # type: ignore[no-untyped-def]
) -> None:
    log = tmp_path / "drive.parquet"
    to_frame(drive.to_samples()).to_parquet(log, index=False)
    # The drive waits at junctions: parked stops (no headings) give the tilt, driving the yaw.
    assert main(["calibrate", str(log)]) == 0
    assert "calibrated from: stops + driving" in capsys.readouterr().err  # status goes to stderr
    out = tmp_path / "result.json"
    assert main(["calibrate", str(log), "--use", "driving", "-o", str(out)]) == 0
    captured = capsys.readouterr()
    assert "calibrated from: driving" in captured.err and "driving method" in captured.err  # status, summary
    assert captured.out == ""  # the result went to -o
    cal = Calibration.load(out)
    assert cal.method == "driving" and cal.yaw_deg == pytest.approx(7.0, abs=0.3)
    assert cal.fit.driving is not None and cal.fit.driving.segments > 10 and cal.slope_deg is None


def test_a_slope_reference_with_a_result_from_driving_says_it_was_not_checked(
    tmp_path: Path,
    drive,  # type: ignore[no-untyped-def]
) -> None:
    log = tmp_path / "drive.parquet"
    to_frame(drive.to_samples()).to_parquet(log, index=False)
    out = tmp_path / "result.json"
    assert main(["calibrate", str(log), "--use", "driving", "--slope-reference", "3", "0.05", "-o", str(out)]) == 0
    cal = Calibration.load(out)
    assert cal.slope_deg is None and any("--slope-reference was not checked" in n for n in cal.notes)


def test_a_log_with_neither_stops_nor_speed_says_both_reasons(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    short = simulate_drive(duration_s=60.0, seed=6).to_samples()
    log = tmp_path / "short.csv"
    to_frame(dataclasses.replace(short, channels={})).to_csv(log, index=False)
    assert main(["calibrate", str(log), "-o", str(tmp_path / "r.json")]) == 3
    err = capsys.readouterr().err
    assert "neither" in err and "parked" in err and "speed" in err
    assert not (tmp_path / "r.json").exists()


# --------------------------------------------------------------------------- real drives


@pytest.mark.real_data
def test_comma2k19_phone_matches_the_cars_own_accelerations_better_after_calibration(real_data: Path) -> None:
    from mountcal.io.comma2k19 import KINEMATICS_TO_ISO, read_comma2k19

    seg = read_comma2k19(real_data / "comma2k19" / "rav4_2018-08-02--08-34-47_seg40")
    s = seg.samples
    assert s.axis_map == "x,-y,-z" and s.acc_s.mean(axis=0)[2] > 9.0  # gravity up in the sensor frame
    kin = seg.kinematics
    assert {k: kin[k].t_s.size for k in kin} == {"ACCEL_X": 4974, "ACCEL_Y": 4974, "YAW_RATE": 4974}
    # The car's signs (KINEMATICS_TO_ISO): ACCEL_X against d(speed)/dt, YAW_RATE against the phone's yaw rate.
    speed = s.channels["speed_mps"]
    grid = np.arange(speed.t_s[0] + 1, speed.t_s[-1] - 1, 0.5)
    dvdt = (np.interp(grid + 0.5, speed.t_s, speed.value) - np.interp(grid - 0.5, speed.t_s, speed.value)) / 1.0
    ax = np.interp(grid, kin["ACCEL_X"].t_s, kin["ACCEL_X"].value)
    assert np.sign(np.corrcoef(ax, dvdt)[0, 1]) == KINEMATICS_TO_ISO["ACCEL_X"]
    fit = estimate_driving(s)
    assert fit.yaw_deg is not None and fit.yaw_sigma_deg is not None and fit.yaw_sigma_deg < 1.5
    rot = fit.rot_vs.as_matrix()
    before = _rms_vs_car(s.acc_s, s.t_s, kin)
    after = _rms_vs_car(s.acc_s @ rot.T, s.t_s, kin)
    assert after < before


def _rms_vs_car(acc_v: np.ndarray, t_s: np.ndarray, kin: dict[str, Channel]) -> float:
    """RMS of the horizontal difference to the car's (ISO-signed) KINEMATICS, 1 s means on a 0.5 s grid."""
    from mountcal.io.comma2k19 import KINEMATICS_TO_ISO

    grid = np.arange(max(t_s[0], kin["ACCEL_X"].t_s[0]) + 1, min(t_s[-1], kin["ACCEL_X"].t_s[-1]) - 1, 0.5)

    def mean_1s(t: np.ndarray, x: np.ndarray) -> np.ndarray:
        c = np.concatenate([[0.0], np.cumsum(0.5 * (x[1:] + x[:-1]) * np.diff(t))])
        return (np.interp(grid + 0.5, t, c) - np.interp(grid - 0.5, t, c)) / 1.0

    diff = [
        mean_1s(t_s, acc_v[:, j]) - KINEMATICS_TO_ISO[name] * mean_1s(kin[name].t_s, kin[name].value)
        for j, name in enumerate(("ACCEL_X", "ACCEL_Y"))
    ]
    return float(np.sqrt(np.mean(np.square(diff))))


@pytest.mark.real_data
def test_canedge_car_two_drives_give_the_same_yaw_from_driving_within_sigma(real_data: Path) -> None:
    from mountcal.io.logs import read_log
    from mountcal.io.reader import LogOptions

    car = real_data / "canedge" / "3BA199E2_car_DK_2021-07-26"
    opts = LogOptions(dbc=str(real_data / "canedge" / "dbc" / "gnss.dbc"), channel=2)
    fits = [
        estimate_driving(read_log(sorted(glob.glob(str(car / d / "*.MF4"))), opts)) for d in ("00000164", "00000165")
    ]
    # Compare rotations, not Euler angles (the logger lies on its side: pitch ≈ −85°, gimbal lock).
    relative = fits[0].rot_vs * fits[1].rot_vs.inv()
    about_z = float(np.degrees(relative.as_rotvec()[2]))
    sz = [f.rotation_sigma_deg[2] for f in fits]
    assert all(s is not None for s in sz)
    assert abs(about_z) < 3.0 * float(np.hypot(*sz))  # type: ignore[arg-type]
    assert all(abs(f.pitch_deg + 85.0) < 3.0 for f in fits)
