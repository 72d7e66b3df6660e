"""The closing-the-loop findings on the real recordings in ../shared/data/real, as Markdown.

    python benchmarks/real_data.py > docs/real-data-results.md

Each section: what the data are, the residual of the first model, the effect it traces to, the
evidence, and the error (or residual) before and after. docs/real-data.md interprets the output.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from mountcal.calibration.pipeline import LogJob, calibrate_job
from mountcal.core.conventions import G_N, normal_gravity
from mountcal.estimate import sphere
from mountcal.io.can.files import read_frames
from mountcal.io.logs import read_log
from mountcal.io.reader import LogOptions
from mountcal.io.samples import Samples
from mountcal.stops.detect import StopDetection, detect_stops

REAL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"


def canedge_car(real: Path) -> str:
    base = real / "canedge"
    out = ["## CANedge car (3BA199E2), drives 00000164 and 00000165", ""]
    for drives in (("00000165",), ("00000164", "00000165")):
        files = sorted(str(p) for d in drives for p in (base / "3BA199E2_car_DK_2021-07-26" / d).glob("*.MF4"))
        job = LogJob(paths=tuple(files), log=LogOptions(dbc=str(base / "dbc" / "gnss.dbc"), channel=2), use="stops")
        done = calibrate_job(job)
        cal = done.calibration
        out += [
            f"### drive(s) {' + '.join(drives)}: {len(files)} files, {len(done.samples)} IMU samples, "
            f"{len(done.table)} stops ({done.stops.heading_source})",
            "",
            "| step | reason | χ² / dof | residual RMS (m/s²) | roll (°) | pitch (°) | slope (°) |",
            "|---|---|---|---|---|---|---|",
        ]
        for s in cal.model_steps:
            a = s.angles
            out.append(
                f"| {s.added} | {s.reason} | {s.chi2:.1f} / {s.dof} | {s.residual_rms_mps2:.3f} | "
                f"{_pm(a.roll_deg, a.roll_sigma_deg)} | {_pm(a.pitch_deg, a.pitch_sigma_deg)} | "
                f"{_pm(a.slope_deg, a.slope_sigma_deg)} |"
            )
        out += [
            "",
            f"Final: model `{', '.join(cal.model)}`, confident: {cal.confident}; unexplained: "
            + ("; ".join(f"{u.what} ({u.size})" for u in cal.unexplained) or "none"),
            "",
            "Declined: " + "; ".join(f"{d.effect}: {d.why}" for d in cal.model_selection.declined),
            "",
        ]
        if len(drives) == 1:
            out += ["Stop table:", "", _markdown(done.stops.table.to_frame()), ""]
    return "\n".join(out)


def boat(real: Path) -> str:
    base = real / "canedge"
    f = next((base / "94C49784_boat_static_nmea2000_2021-05-10").glob("*.MF4"))
    s = read_log([str(f)], LogOptions(dbc=str(base / "dbc" / "gnss.dbc"), channel=2))
    fr = read_frames(f, channel=1)
    ids = fr.arbitration_id.astype(np.int64)
    pf, ps, dp = (ids >> 16) & 0xFF, (ids >> 8) & 0xFF, (ids >> 24) & 1
    pgn = np.where(pf >= 240, (dp << 16) | (pf << 8) | ps, (dp << 16) | (pf << 8))
    att = fr.data[pgn == 127257, :8]  # NMEA 2000 Attitude: SID, yaw, pitch, roll (int16, 1e-4 rad)
    t_att = fr.t_s[pgn == 127257]
    pitch_b = np.degrees(att[:, 3:5].copy().view("<i2")[:, 0] * 1e-4)
    roll_b = np.degrees(att[:, 5:7].copy().view("<i2")[:, 0] * 1e-4)
    lat = float(np.mean(s.channels["lat_deg"].value))
    g = normal_gravity(lat)
    acc = s.acc_s
    norm = np.linalg.norm(acc, axis=1)
    # 1-s means on a common clock: the logger's IMU against the boat's attitude sensor
    edges = np.arange(max(s.t_s[0], t_att[0]), min(s.t_s[-1], t_att[-1]), 1.0)
    idx = np.digitize(s.t_s, edges)
    ok = (idx > 0) & (idx < len(edges))
    a1 = np.array([acc[ok & (idx == k)].mean(axis=0) for k in range(1, len(edges))])
    jdx = np.digitize(t_att, edges)
    r1 = np.array([roll_b[jdx == k].mean() for k in range(1, len(edges))])
    p1 = np.array([pitch_b[jdx == k].mean() for k in range(1, len(edges))])
    roll_l = np.degrees(np.arctan2(a1[:, 1], a1[:, 2]))
    pitch_l = np.degrees(np.arctan2(-a1[:, 0], np.hypot(a1[:, 1], a1[:, 2])))
    half = len(r1) // 2
    lines = [
        "## CANedge boat (94C49784): logger IMU against the boat's own attitude sensor (NMEA 2000 PGN 127257)",
        "",
        f"{len(s)} IMU samples over {s.t_s[-1] - s.t_s[0]:.0f} s; {len(t_att)} attitude messages. Local gravity "
        f"{g:.5f} m/s² (WGS 84 at {lat:.3f}°).",
        "",
        f"- Norm check: mean |a| = {norm.mean():.4f} m/s² against g = {g:.4f}: offset {norm.mean() - g:+.4f} m/s² "
        f"({(norm.mean() - g) / G_N * 1e3:+.0f} mg), std of 1-s means {np.linalg.norm(a1, axis=1).std():.4f} m/s².",
        f"- Boat attitude (sensor): roll {r1.mean():+.3f}° ± {r1.std():.3f}° (std over time), pitch {p1.mean():+.3f}° "
        f"± {p1.std():.3f}°.",
        f"- Logger tilt from its mean gravity: roll {roll_l.mean():+.3f}°, pitch {pitch_l.mean():+.3f}°.",
        "",
    ]
    lines += [
        "Mounting of the logger in the boat (roll and pitch offsets), fitted on the first half of the record "
        "and checked on the second half (1-s means):",
        "",
        "| | roll: RMS of logger − boat (°) | pitch: RMS of logger − boat (°) |",
        "|---|---|---|",
    ]
    for name, dr, dp_ in (
        ("before (logger axes taken as boat axes)", 0.0, 0.0),
        (
            "after (offsets from the first half)",
            float(np.mean(roll_l[:half] - r1[:half])),
            float(np.mean(pitch_l[:half] - p1[:half])),
        ),
    ):
        er = roll_l[half:] - r1[half:] - dr
        ep = pitch_l[half:] - p1[half:] - dp_
        lines.append(f"| {name} | {np.sqrt(np.mean(er**2)):.3f} | {np.sqrt(np.mean(ep**2)):.3f} |")
    slope_r = np.polyfit(r1, roll_l, 1)[0]
    lines += [
        "",
        f"Offsets: roll {np.mean(roll_l[:half] - r1[:half]):+.3f}°, pitch {np.mean(pitch_l[:half] - p1[:half]):+.3f}°; "
        f"regression slope of logger roll on boat roll over time: {slope_r:.3f} (1 means the two see the same "
        "motion).",
        "",
    ]
    return "\n".join(lines)


def multi_position(real: Path) -> str:
    out = ["## Multi-position sessions: bias, scale and cross-axis (the M matrix)", ""]
    df = pd.read_csv(real / "imucal-ferraris" / "example_ferraris_session.csv")
    ferraris = Samples(
        df["n_samples"].to_numpy(float) / 102.4,
        df[["acc_x", "acc_y", "acc_z"]].to_numpy(float),
        np.radians(df[["gyr_x", "gyr_y", "gyr_z"]].to_numpy(float)),
    )
    raw = np.loadtxt(real / "imu_tk-xsens" / "xsens_acc.mat")
    counts = raw[:, 1:] - 32768.0
    k = 9.81744 / np.median(np.linalg.norm(counts[:3000], axis=1))  # the first 50 s are static
    xsens = Samples(raw[:, 0], counts * k)
    for name, samples, g, cfg, note in (
        (
            "imucal Ferraris session (NilsPod-type IMU, m/s²)",
            ferraris,
            9.81,
            StopDetection(window_s=1.0, max_acc_std_mps2=0.1, max_gyro_rad_s=0.05, min_duration_s=2.0, trim_s=0.5),
            "g = 9.81 m/s² as the imucal tutorial uses",
        ),
        (
            "IMU-TK Xsens session (raw counts, scaled so the first static interval reads g)",
            xsens,
            9.81744,
            StopDetection(window_s=1.0, max_acc_std_mps2=0.05, min_duration_s=1.0, trim_s=0.3),
            "g = 9.81744 m/s² as the IMU-TK test app uses; scale terms are relative to the rough count scale",
        ),
    ):
        stops = detect_stops(samples, cfg)
        acc = np.array([s.acc_mean_s for s in stops])
        cov = np.array([s.acc_cov_mean_s for s in stops])
        out += [
            f"### {name}",
            "",
            f"{len(stops)} static stops detected; {note}.",
            "",
            "| step | χ² / dof | RMS of |a| − g (mm/s²) | bias (m/s²) | scale | cross-axis |",
            "|---|---|---|---|---|---|",
        ]
        for f, why in sphere.loop(acc, g, cov):
            v, sg = dict(zip(f.names, f.values, strict=True)), dict(zip(f.names, f.sigma(), strict=True))
            shown = {
                prefix: ", ".join(f"{v[n]:+.4f}±{sg[n]:.4f}" for n in f.names if n.startswith(prefix)) or "—"
                for prefix in ("bias", "scale", "cross")
            }
            out.append(
                f"| {why} | {f.chi2:.1f} / {f.dof} | {np.sqrt(np.mean(f.residual_mps2**2)) * 1e3:.2f} | "
                f"{shown['bias']} | {shown['scale']} | {shown['cross']} |"
            )
        out.append("")
    return "\n".join(out)


def _markdown(df: pd.DataFrame) -> str:
    cols = list(df.columns)
    rows = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    rows += [
        "| " + " | ".join(f"{v:.4g}" if isinstance(v, float) else str(v) for v in r) + " |"
        for r in df.itertuples(index=False)
    ]
    return "\n".join(rows)


def _pm(v: float | None, s: float | None) -> str:
    return "—" if v is None else (f"{v:.2f}" if s is None else f"{v:.2f} ± {s:.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--real", default=str(REAL))
    args = ap.parse_args()
    real = Path(args.real)
    if not real.is_dir():
        raise SystemExit(f"real recordings not found at {real}")
    print("\n\n".join([canedge_car(real), boat(real), multi_position(real)]))


if __name__ == "__main__":
    main()
