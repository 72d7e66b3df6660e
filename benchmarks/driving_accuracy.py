"""Accuracy of yaw from driving on simulated 20-minute mixed drives, and whether its σ covers the error.

For each scenario, ``--seeds`` drives are simulated (:func:`mountcal.simulate.drive.simulate_drive`:
launches, braking, junction turns, curves, grades, crowned roads, suspension pitch and roll,
vibration and noise; speed on its own clock with a delay) with a random mounting, and
:func:`mountcal.estimate.driving.estimate_driving` is run on what a logger would record. Reported
per scenario: RMS and largest yaw error, the fraction within 0.3°, the coverage of the reported 1σ
and 2σ (about 68 % and 95 % for an honest σ), the mean σ, the error of the recovered clock offset
and its coverage, and the time per fit.

Run from the repository root::

    .venv/bin/python benchmarks/driving_accuracy.py --seeds 50

The error is measured on the rotation, as the angle about the vehicle z axis between the
estimated and the true vehicle x axis (``yaw`` as compared by the rotation, not the Euler angle),
and also on the Euler yaw against its reported σ.

With ``--real DIR`` (the folder of real recordings, ``../shared/data/real``) it instead runs the
real-data comparisons of ``docs/real-data-driving.md``: the comma2k19 RAV4 segment (phone rotated
into the vehicle frame against the car's own KINEMATICS accelerations, before and after) and the
CANedge car (yaw from driving on both drives, against the parked stops)::

    .venv/bin/python benchmarks/driving_accuracy.py --real ../shared/data/real
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from mountcal.estimate.driving import estimate_driving
from mountcal.io.samples import Channel, Samples
from mountcal.simulate.drive import simulate_drive


@dataclass(frozen=True)
class Scenario:
    name: str
    sim: dict[str, Any] = field(default_factory=dict)
    gyro: bool = True
    heading: bool = False
    heading_rate_hz: float | None = None
    mounting: str = "random"  # "random": roll, pitch within ±20°, any yaw; "sideways": pitch ≈ −85°


SCENARIOS = [
    Scenario("CAN speed 50 Hz, IMU 100 Hz, gyro"),
    Scenario(
        "IMU 200 Hz, 20 mg bias, gyro bias, speed 10 Hz ×1.02, delay 0.3 s",
        sim={"rate_hz": 200.0, "speed_rate_hz": 10.0, "speed_scale": 1.02, "speed_delay_s": 0.3, "bias_mg": 20.0},
    ),
    Scenario(
        "GNSS speed 1 Hz (σ 0.05 m/s), delay 0.5 s",
        sim={"speed_rate_hz": 1.0, "speed_noise_mps": 0.05, "speed_resolution_mps": 0.0, "speed_delay_s": 0.5},
    ),
    Scenario("logger on its side (pitch ≈ −85°)", mounting="sideways"),
    Scenario("no gyro, heading channel 10 Hz", gyro=False, heading=True, heading_rate_hz=10.0),
    Scenario("no gyro, no heading (straightness from lateral acceleration)", gyro=False),
]


def mounting(kind: str, rng: np.random.Generator) -> Rotation:
    if kind == "sideways":
        return Rotation.from_euler("ZYX", [rng.uniform(-180, 180), rng.uniform(-87, -83), rng.uniform(-180, 180)], True)
    return Rotation.from_euler("ZYX", [rng.uniform(-180, 180), rng.uniform(-20, 20), rng.uniform(-20, 20)], True)


def run(sc: Scenario, seed: int) -> dict[str, float]:
    rng = np.random.default_rng(1000 + seed)
    rot = mounting(sc.mounting, rng)
    sim = dict(sc.sim)
    bias_mg = sim.pop("bias_mg", 0.0)
    bias = rng.normal(size=3)
    bias *= bias_mg * 1e-3 * 9.80665 / np.linalg.norm(bias)
    gyro_bias = np.radians(rng.normal(0.0, 0.3, 3)) if bias_mg else None
    drive = simulate_drive(rot_vs=rot, bias_mps2=bias, gyro_bias_rad_s=gyro_bias, seed=seed, **sim)
    samples = drive.to_samples(gyro=sc.gyro)
    if sc.heading:
        step = max(1, round(1.0 / (sc.heading_rate_hz or 10.0) / np.median(np.diff(drive.t_s))))
        channels = dict(samples.channels)
        channels["heading_deg"] = Channel(drive.t_s[::step].copy(), drive.heading_deg[::step].copy())
        samples = Samples(samples.t_s, samples.acc_s, samples.gyro_s, channels, samples.source)
    t0 = time.perf_counter()
    fit = estimate_driving(samples)
    elapsed = time.perf_counter() - t0
    # Error about the vehicle z axis: where the estimate puts the true vehicle x axis.
    x_est = fit.rot_vs.apply(rot.inv().apply([1.0, 0.0, 0.0]))
    err_z = float(np.degrees(np.arctan2(x_est[1], x_est[0])))
    true_yaw = float(rot.as_euler("ZYX", degrees=True)[0])
    err_euler = float((fit.yaw_deg - true_yaw + 180.0) % 360.0 - 180.0) if fit.yaw_deg is not None else np.nan
    sz = fit.rotation_sigma_deg[2]
    stat = max(fit.yaw_sigma_hac_deg or 0.0, fit.yaw_sigma_jackknife_deg or 0.0)
    return {
        "err_z": err_z,
        "sigma_z": np.nan if sz is None else sz,
        "sigma_stat": stat if stat > 0 else np.nan,
        "err_euler": err_euler,
        "sigma_euler": np.nan if fit.yaw_sigma_deg is None else fit.yaw_sigma_deg,
        "offset_err": fit.time_offset_s + drive.truth.speed_delay_s,
        "offset_sigma": np.nan if fit.time_offset_sigma_s is None else fit.time_offset_sigma_s,
        "seconds": elapsed,
        "segments": fit.n_segments,
        "usable_s": fit.usable_s,
    }


def summarise(sc: Scenario, rows: list[dict[str, float]]) -> str:
    col = {k: np.array([r[k] for r in rows]) for k in rows[0]}
    ez, sz, st = col["err_z"], col["sigma_z"], col["sigma_stat"]
    ee, se = col["err_euler"], col["sigma_euler"]
    eo, so = col["offset_err"], col["offset_sigma"]
    return (
        f"| {sc.name} | {np.sqrt(np.mean(ez**2)):.3f} | {np.max(np.abs(ez)):.3f} | {np.mean(np.abs(ez) <= 0.3):.0%} | "
        f"{np.nanmean(st):.3f} | {np.mean(np.abs(ez) <= st):.0%} / {np.mean(np.abs(ez) <= 2 * st):.0%} | "
        f"{np.nanmean(sz):.3f} | {np.mean(np.abs(ez) <= sz):.0%} / {np.mean(np.abs(ez) <= 2 * sz):.0%} | "
        f"{np.sqrt(np.nanmean(ee**2)):.3f} | "
        f"{np.nanmean(np.abs(ee) <= se):.0%} / {np.nanmean(np.abs(ee) <= 2 * se):.0%} | "
        f"{np.sqrt(np.mean(eo**2)):.3f} | {np.nanmean(np.abs(eo) <= so):.0%} | {np.mean(col['usable_s']):.0f} | "
        f"{np.mean(col['seconds']):.2f} |"
    )


def boxcar(t: np.ndarray, x: np.ndarray, grid: np.ndarray, width_s: float) -> np.ndarray:
    """Means of x(t) over [g − w/2, g + w/2] for each g of the grid: exact integrals of the samples."""
    c = np.concatenate([[0.0], np.cumsum(0.5 * (x[1:] + x[:-1]) * np.diff(t))])
    return (np.interp(grid + width_s / 2, t, c) - np.interp(grid - width_s / 2, t, c)) / width_s


def real_comma2k19(root: Path, width_s: float) -> None:
    from mountcal.io.comma2k19 import KINEMATICS_TO_ISO, read_comma2k19

    seg = read_comma2k19(root / "comma2k19" / "rav4_2018-08-02--08-34-47_seg40")
    s, kin = seg.samples, seg.kinematics
    speed = s.channels["speed_mps"]
    grid = np.arange(speed.t_s[0] + 1.0, speed.t_s[-1] - 1.0, 0.5)
    dvdt = np.interp(grid + 0.5, speed.t_s, speed.value) - np.interp(grid - 0.5, speed.t_s, speed.value)
    print("## comma2k19 RAV4 segment\n")
    print(f"{len(s)} phone IMU samples, axis map {s.axis_map}; KINEMATICS frames: {kin['ACCEL_X'].t_s.size}")
    for name, ref, what in (
        ("ACCEL_X", dvdt, "d(speed)/dt"),
        ("ACCEL_Y", -speed_interp(speed, grid) * boxcar(s.t_s, s.gyro_s[:, 2], grid, 1.0), "−v·ω_z (phone gyro)"),
        ("YAW_RATE", boxcar(s.t_s, s.gyro_s[:, 2], grid, 1.0), "ω_z (phone gyro, up)"),
    ):
        r = np.corrcoef(boxcar(kin[name].t_s, kin[name].value, grid, 1.0), ref)[0, 1]
        print(f"- sign of {name}: correlation with {what} = {r:+.3f}")
    fit = estimate_driving(s)
    d = fit.to_dict()
    print(
        f"- calibrated from driving: roll {fit.roll_deg:.2f}° ± {fit.roll_sigma_deg:.2f}°, pitch {fit.pitch_deg:.2f}° "
        f"± {fit.pitch_sigma_deg:.2f}°, yaw {fit.yaw_deg:.2f}° ± {fit.yaw_sigma_deg:.2f}° "
        f"(Newey–West {d['sigma']['yaw_newey_west_deg']:.2f}°, jackknife {d['sigma']['yaw_jackknife_deg']:.2f}°); "
        f"{fit.n_intervals} intervals in {fit.n_segments} segments, {fit.usable_s:.0f} s of {fit.moving_s:.0f} s; "
        f"speed clock offset {fit.time_offset_s:+.3f} ± {fit.time_offset_sigma_s:.3f} s; speed scale "
        f"{fit.speed_scale:.3f}, correlation {fit.correlation:.3f}"
    )
    car = np.column_stack([KINEMATICS_TO_ISO[n] * kin[n].value for n in ("ACCEL_X", "ACCEL_Y")])
    t_k = kin["ACCEL_X"].t_s
    lo, hi = max(s.t_s[0], t_k[0]) + 2.0, min(s.t_s[-1], t_k[-1]) - 2.0
    rot = fit.rot_vs.as_matrix()
    fine = np.arange(lo, hi, 0.1)
    lags = np.arange(-0.5, 0.5001, 0.01)
    score = [
        sum(
            np.corrcoef(
                boxcar(s.t_s, (s.acc_s @ rot.T)[:, j], fine + lag, width_s), boxcar(t_k, car[:, j], fine, width_s)
            )[0, 1]
            for j in range(2)
        )
        for lag in lags
    ]
    lag = float(lags[int(np.argmax(score))])
    grid = np.arange(lo, hi, width_s)
    ref = np.column_stack([boxcar(t_k, car[:, j], grid, width_s) for j in range(2)])
    print(f"- phone clock against the car's: {lag:+.2f} s (largest correlation of {width_s:g} s means)\n")
    print(
        "| phone axes | RMS diff a_x | RMS diff a_y | RMS diff horizontal | mean diff (x, y) "
        "| RMS diff less means (x, y) |"
    )
    print("|---|---|---|---|---|---|")
    for name, acc in (
        ("taken as vehicle axes (before)", s.acc_s),
        ("rotated by the calibration (after)", s.acc_s @ rot.T),
    ):
        p = np.column_stack([boxcar(s.t_s, acc[:, j], grid + lag, width_s) for j in range(2)])
        diff = p - ref
        rms = np.sqrt(np.mean(diff**2, axis=0))
        print(
            f"| {name} | {rms[0]:.3f} | {rms[1]:.3f} | {np.sqrt(np.mean(np.sum(diff**2, axis=1))):.3f} | "
            f"({diff[:, 0].mean():+.3f}, {diff[:, 1].mean():+.3f}) | ({diff[:, 0].std():.3f}, {diff[:, 1].std():.3f}) |"
        )
    print()


def speed_interp(speed: Channel, grid: np.ndarray) -> np.ndarray:
    return np.interp(grid, speed.t_s, speed.value)


def real_canedge(root: Path) -> None:
    import glob

    from mountcal.calibration.pipeline import calibrate_log
    from mountcal.core.errors import NotEnoughInformation
    from mountcal.io.reader import LogOptions

    base = root / "canedge" / "3BA199E2_car_DK_2021-07-26"
    opts = LogOptions(dbc=str(root / "canedge" / "dbc" / "gnss.dbc"), channel=2)
    print("## CANedge car (3BA199E2), CAN channel 2, speed from gnss_speed\n")
    rows: dict[str, Any] = {}
    for drive in ("00000164", "00000165"):
        files = sorted(glob.glob(str(base / drive / "*.MF4")))
        driving = calibrate_log(files, log=opts, use="driving")
        both = calibrate_log(files, log=opts)
        try:
            stops = calibrate_log(files, log=opts, use="stops")
        except NotEnoughInformation as err:
            stops = None
            print(f"- {drive}: stops alone: {err}".replace(str(base) + "/", ""))
        rows[drive] = (stops, driving, both)
        d = driving.driving
        assert d is not None
        print(
            f"- {drive}: driving {d.usable_s:.0f} s usable of {d.moving_s:.0f} s in {d.n_segments} segments, "
            f"speed clock offset {d.time_offset_s:+.3f} ± {d.time_offset_sigma_s:.3f} s, "
            f"speed scale {d.speed_scale:.3f}, "
            f"correlation {d.correlation:.3f}; rotation σ about vehicle z {d.rotation_sigma_deg[2]:.3f}°; Euler "
            f"roll {d.roll_deg:.2f}° ± {d.roll_sigma_deg:.2f}°, pitch {d.pitch_deg:.2f}° ± {d.pitch_sigma_deg:.2f}°, "
            f"yaw {d.yaw_deg:.2f}° ± {d.yaw_sigma_deg:.2f}°; vehicle x axis in sensor coordinates "
            f"{np.round(d.rot_vs.inv().apply([1.0, 0.0, 0.0]), 4).tolist()}"
        )
        if stops is not None:
            st = stops.calibration
            print(
                f"- {drive}: stops alone ({len(stops.stops.table) if stops.stops is not None else 0} stops, "
                f"headings {st.fit.headings}): roll {st.roll_deg:.2f}° ± {st.roll_sigma_deg:.2f}°, pitch "
                f"{st.pitch_deg:.2f}° ± {st.pitch_sigma_deg:.2f}°, yaw {st.yaw_deg} ({st.yaw_reason})"
            )
            combination = both.calibration.fit.combination
            check = None if combination is None else combination.tilt_check
            zx = zy = float("nan")
            if check is not None:
                zx, zy = (float("inf") if z is None else z for z in (check.z_about_vehicle_x, check.z_about_vehicle_y))
            up_s = st.rot_vs.inv().apply([0.0, 0.0, 1.0])
            print(
                f"- {drive}: up axis, stops against mean gravity while driving: "
                f"{np.degrees(np.arccos(up_s @ d.up_driving_s)):.2f}° "
                f"apart (z = {zx:+.2f} about x, {zy:+.2f} about y)"
            )
            b = both.calibration
            print(
                f"- {drive}: stops + driving: yaw {b.yaw_deg:.2f}° ± {b.yaw_sigma_deg:.2f}° (rotation σ about z "
                f"{b.rotation_sigma_deg[2]:.3f}°), calibrated from {b.fit.calibrated_from}"
            )
    a, b = (rows[k][1].calibration.rot_vs for k in ("00000164", "00000165"))
    sa, sb = (rows[k][1].calibration.rotation_sigma_deg for k in ("00000164", "00000165"))
    rel = np.degrees((a * b.inv()).as_rotvec())
    print(
        f"- drive 164 against drive 165, driving alone: rotation difference about vehicle x, y, z = "
        f"{np.round(rel, 3).tolist()}°; about z z-score {rel[2] / np.hypot(sa[2], sb[2]):+.2f}; about y "
        f"{rel[1] / np.hypot(sa[1], sb[1]):+.2f}; about x {rel[0] / np.hypot(sa[0], sb[0]):+.2f}"
    )
    c = rows["00000165"][2].calibration.rot_vs
    rel2 = np.degrees((a * c.inv()).as_rotvec())
    print(
        "- drive 164 (driving) against drive 165 (stops + driving): about vehicle x, y, z = "
        f"{np.round(rel2, 3).tolist()}°\n"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=50, help="drives per scenario")
    parser.add_argument("--scenario", type=int, nargs="*", help="indices of the scenarios to run (default: all)")
    parser.add_argument("--real", type=Path, default=None, help="run the real-data comparisons on this folder")
    parser.add_argument("--width", type=float, default=1.0, help="matched boxcar width for comma2k19 (s)")
    args = parser.parse_args()
    if args.real is not None:
        real_comma2k19(args.real, args.width)
        real_canedge(args.real)
        return
    chosen = [SCENARIOS[i] for i in args.scenario] if args.scenario else SCENARIOS
    print(
        "| scenario | RMS err about z (°) | max | within 0.3° | mean statistical σ_z (°) | its 1σ / 2σ coverage | "
        "mean total σ_z (°) | its 1σ / 2σ coverage | RMS Euler yaw err (°) | Euler 1σ / 2σ coverage | "
        "RMS offset err (s) | offset 1σ coverage | usable s | s per fit |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for sc in chosen:
        rows = [run(sc, seed) for seed in range(args.seeds)]
        print(summarise(sc, rows), flush=True)


if __name__ == "__main__":
    main()
