"""The residual tests of yaw from driving: does each effect the driving model lacks get found (or does the σ
cover what it does to yaw), and how often is a clean drive flagged?

For each scenario, ``--runs`` 20-minute drives are simulated (:func:`mountcal.simulate.drive.simulate_drive`, a
random mounting within ±20° of roll and pitch, any yaw) with one effect, and
:func:`mountcal.estimate.driving.estimate_driving` is run on what the logger records. Per scenario:

- **found**: the test that names the effect fires (a finding of the family, Holm at 1 %; for the speed scale
  and the body's attitude, the effect's own estimate beyond 3σ and within 3σ of the truth);
- **covered**: the error of yaw about the vehicle z axis is within the reported 2σ (σ with the model-error
  term); for a remount, both mountings are;
- **found or covered**, the acceptance (≥ 90 %), and **flagged** (any finding; ≤ 5 % on clean drives);
- the error and σ of yaw, and the split-half z-scores (mean, SD, share beyond 2) — on clean drives these
  should be N(0, 1).

With ``--real DIR`` (``../shared/data/real``) it prints the tests on every real drive with a speed channel
instead: the comma2k19 RAV4 segment and the CANedge car's two drives.

    OMP_NUM_THREADS=1 PYTHONPATH=src python benchmarks/driving_residuals.py --runs 100
    OMP_NUM_THREADS=1 PYTHONPATH=src python benchmarks/driving_residuals.py --real ../shared/data/real
"""

from __future__ import annotations

import argparse
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from mountcal.core.driving_document import Comparison, Estimate
from mountcal.estimate.driving import DrivingFit, estimate_driving
from mountcal.io.samples import Channel, Samples
from mountcal.simulate.drive import PITCH_PER_ACC_RAD, ROLL_PER_ACC_RAD, simulate_drive

G = 9.80665


@dataclass(frozen=True)
class Scenario:
    name: str
    sim: dict[str, Any] = field(default_factory=dict)
    gyro: bool = True
    heading: bool = False
    found_by: tuple[str, ...] = ()  # the findings that name the effect
    kind: str = ""  # how else it is found: "scale", "body", "lateral_scale", "remount"


def cross_axis(c: float) -> np.ndarray:
    """A symmetric cross-axis coupling ``c`` between the sensor's x and y axes."""
    m = np.eye(3)
    m[0, 1] = m[1, 0] = c
    return m


SCENARIOS = [
    Scenario("clean drive, gyro, GNSS altitude (0.3 m noise)", sim={"altitude_noise_m": 0.3}),
    Scenario("clean drive, gyro, no altitude"),
    Scenario("clean drive, no gyro, heading channel 10 Hz", gyro=False, heading=True),
    Scenario(
        "horizontal cross-axis 2 % (sensor x–y)", sim={"scale_matrix": cross_axis(0.02)}, found_by=("driving_cues",)
    ),
    Scenario(
        "body pitch and roll under load ×3 (4.2°/g, 13.5°/g), gyro",
        sim={"pitch_per_acc_rad": 3 * PITCH_PER_ACC_RAD, "roll_per_acc_rad": 3 * ROLL_PER_ACC_RAD},
        kind="body",
    ),
    Scenario(
        "body roll under load ×3 (13.5°/g), no gyro, heading channel",
        sim={"roll_per_acc_rad": 3 * ROLL_PER_ACC_RAD},
        gyro=False,
        heading=True,
        kind="lateral_scale",
    ),
    Scenario("speed scale 1.05 (tyre radius)", sim={"speed_scale": 1.05}, kind="scale"),
    Scenario(
        "consumer IMU at 5 Hz (scale +3 %/−2 %, cross-axis 2 %), GNSS speed 1 Hz",
        sim={
            "rate_hz": 5.0,
            "speed_rate_hz": 1.0,
            "speed_noise_mps": 0.05,
            "speed_resolution_mps": 0.0,
            "speed_delay_s": 0.25,
            "scale_matrix": np.array([[1.03, 0.02, 0.0], [0.02, 0.98, 0.0], [0.0, 0.0, 1.0]]),
        },
        found_by=("driving_cues",),
    ),
    Scenario(
        "remount halfway: turned 3° about the vehicle z axis, 1° about y",
        found_by=("driving_halves_yaw", "driving_parts", "driving_halves_pitch", "driving_cues"),
        kind="remount",
    ),
]


def mounting(rng: np.random.Generator) -> Rotation:
    return Rotation.from_euler("ZYX", [rng.uniform(-180, 180), rng.uniform(-20, 20), rng.uniform(-20, 20)], True)


def about_z(fit: DrivingFit, truth: Rotation) -> float:
    """Where the estimate puts the true vehicle x axis, as an angle about the vehicle z axis (deg)."""
    x = fit.rot_vs.apply(truth.inv().apply([1.0, 0.0, 0.0]))
    return float(np.degrees(np.arctan2(x[1], x[0])))


def run(sc: Scenario, seed: int) -> dict[str, Any]:
    rng = np.random.default_rng(5000 + seed)
    rot = mounting(rng)
    sim = dict(sc.sim)
    second = None
    if sc.kind == "remount":
        second = Rotation.from_euler("zy", [3.0, 1.0], degrees=True) * rot
        sim.update(remount_at_s=600.0, remount_rot_vs=second)
    drive = simulate_drive(rot_vs=rot, seed=seed, **sim)
    samples = drive.to_samples(gyro=sc.gyro)
    if sc.heading:
        channels = dict(samples.channels)
        channels["heading_deg"] = Channel(drive.t_s[::10].copy(), drive.heading_deg[::10].copy())
        samples = Samples(samples.t_s, samples.acc_s, samples.gyro_s, channels, samples.source)
    t0 = time.perf_counter()
    fit = estimate_driving(samples)
    seconds = time.perf_counter() - t0
    c = fit.consistency
    assert c is not None
    sigma = fit.rotation_sigma_deg[2] or np.nan
    errors = [about_z(fit, rot)] + ([] if second is None else [about_z(fit, second)])
    covered = all(abs(e) <= 2 * sigma for e in errors)
    findings = {f.test for f in fit.findings}
    found = bool(findings & set(sc.found_by))
    if sc.kind == "scale":
        s = c.speed_scale  # the speed reads 1.05 × true: the IMU's longitudinal is 1/1.05 × d(speed)/dt
        found = s.noted and s.value is not None and s.sigma is not None and abs(s.value - 1 / 1.05) <= 3 * s.sigma
    elif sc.kind == "body":
        truth = {
            "body_pitch": np.degrees(sc.sim["pitch_per_acc_rad"]) * G,
            "body_roll": np.degrees(sc.sim["roll_per_acc_rad"]) * G,
        }
        found = True
        for name, value in truth.items():
            e = c.effect(name)
            found &= e is not None and e.chosen and abs((e.value or 0.0) - value) <= 3 * (e.sigma or 0.0)
    elif sc.kind == "lateral_scale":
        e = c.effect("lateral_scale")
        found = e is not None and e.chosen
    h = c.halves
    z = {"yaw": h.yaw.z, "roll": h.roll_about_vehicle_x.z, "pitch": h.pitch_about_vehicle_y.z}
    return {
        "error": errors[0],
        "sigma": sigma,
        "covered": covered,
        "found": found,
        "flagged": bool(findings),
        "findings": sorted(findings),
        "z": z,
        "seconds": seconds,
    }


def summarise(sc: Scenario, rows: list[dict[str, Any]]) -> str:
    err = np.array([r["error"] for r in rows])
    sigma = np.array([r["sigma"] for r in rows])
    found = np.mean([r["found"] for r in rows])
    covered = np.mean([r["covered"] for r in rows])
    either = np.mean([r["found"] or r["covered"] for r in rows])
    flagged = np.mean([r["flagged"] for r in rows])
    zs = [f"{np.nanmean(v):+.2f} / {np.nanstd(v):.2f} / {np.nanmean(np.abs(v) > 2):.0%}" for v in _z(rows)]
    clean = not sc.found_by and not sc.kind
    named = Counter(t for r in rows for t in r["findings"])
    which = ", ".join(f"{t.removeprefix('driving_')} {k}" for t, k in named.most_common()) or "none"
    return (
        f"| {sc.name} | {'—' if clean else f'{found:.0%}'} | {covered:.0%} | {'—' if clean else f'{either:.0%}'} | "
        f"{flagged:.0%} | {np.sqrt(np.mean(err**2)):.3f} | {np.sqrt(np.mean(sigma**2)):.3f} | {' | '.join(zs)} | "
        f"{np.mean([r['seconds'] for r in rows]):.2f} | {which} |"
    )


def _z(rows: list[dict[str, Any]]) -> list[np.ndarray]:
    return [
        np.array([np.nan if r["z"][k] is None else r["z"][k] for r in rows], dtype=float)
        for k in ("yaw", "roll", "pitch")
    ]


HEADER = (
    "| scenario | found | 2σ covers the yaw error | found or covered | flagged | RMS yaw err about z (°) "
    "| RMS σ_z (°) | halves z yaw: mean / SD / beyond 2 | halves z roll | halves z pitch | s per fit "
    "| findings (runs) |\n"
    "|---|---|---|---|---|---|---|---|---|---|---|---|"
)


def real(root: Path) -> None:
    import glob

    from mountcal.io.comma2k19 import read_comma2k19
    from mountcal.io.logs import read_log
    from mountcal.io.reader import LogOptions
    from mountcal.io.timestamps import increasing_times

    drives: list[tuple[str, Samples]] = [
        (
            "comma2k19 RAV4 seg40 (1 min, highway)",
            read_comma2k19(root / "comma2k19" / "rav4_2018-08-02--08-34-47_seg40").samples,
        )
    ]
    car = root / "canedge" / "3BA199E2_car_DK_2021-07-26"
    opts = LogOptions(dbc=str(root / "canedge" / "dbc" / "gnss.dbc"), channel=2)
    for d in ("00000164", "00000165"):
        drives.append((f"CANedge car drive {d[-3:]}", read_log(sorted(glob.glob(str(car / d / "*.MF4"))), opts)))
    print(
        "| drive | yaw about z ± σ | halves z: yaw / roll / pitch / clock | parts χ² (dof), p | cues: longitudinal, "
        "lateral, Δ, z | left/right z | accel/brake z | speed scale (EIV) ± σ [OLS both ways] | findings |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for name, samples in drives:
        fit = estimate_driving(increasing_times(samples))
        c = fit.consistency
        assert c is not None
        h = c.halves

        def z(x: Comparison) -> str:
            return "—" if x.z is None else f"{x.z:+.2f}"

        def est(e: Estimate | None) -> str:
            return "—" if e is None else f"{e.value:.2f}°" + ("" if e.sigma is None else f" ± {e.sigma:.2f}°")

        cue = c.cues.comparison
        parts = c.parts
        s = c.speed_scale
        print(
            f"| {name} | {fit.yaw_deg:.2f}° ± {fit.rotation_sigma_deg[2]:.3f}° | {z(h.yaw)} / "
            f"{z(h.roll_about_vehicle_x)} / {z(h.pitch_about_vehicle_y)} / {z(h.clock_offset)} | "
            + ("—" if parts.chi2 is None else f"{parts.chi2:.2f} ({parts.dof}), {parts.p_value:.2f}")
            + f" | {est(cue.one)}, {est(cue.two)}, "
            + ("—" if cue.difference is None else f"{cue.difference:+.2f}°")
            + f", {z(cue)} | {z(c.left_right)} | {z(c.accelerating_braking)} | "
            + ("—" if s.value is None else f"{s.value:.3f}")
            + ("" if s.sigma is None else f" ± {s.sigma:.3f}")
            + f" [{s.imu_on_speed or float('nan'):.3f}, {s.speed_on_imu or float('nan'):.3f}] | "
            f"{', '.join(c.findings) or 'none'} |"
        )
        for e in c.effects:
            print(
                f"  - {name}: {e.name}: {e.why}"
                + (f" ({e.changes} {e.before:.3f} → {e.after:.3f})" if e.changes else "")
            )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=50, help="drives per scenario")
    ap.add_argument("--scenario", type=int, nargs="*", help="indices of the scenarios to run (default: all)")
    ap.add_argument("--real", type=Path, default=None, help="run the tests on the real drives in this folder")
    args = ap.parse_args()
    if args.real is not None:
        real(args.real)
        return
    chosen = [SCENARIOS[i] for i in args.scenario] if args.scenario else SCENARIOS
    t0 = time.perf_counter()
    print(HEADER, flush=True)
    for sc in chosen:
        rows = [run(sc, seed) for seed in range(args.runs)]
        print(summarise(sc, rows), flush=True)
    print(f"\n_{args.runs} drives per scenario, {time.perf_counter() - t0:.0f} s._")


if __name__ == "__main__":
    main()
