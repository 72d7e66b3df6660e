"""A triad calibration from a real multi-position session, feeding a simulated slope session.

For each real session in ../shared/data/real (IMU-TK's Xsens, imucal's Ferraris faces; see
real_sessions.py): ``mountcal triad`` fits it. Then, in every run, a sensor is drawn from what the
triad leaves uncertain — its values ± its covariance (Gaussian), and for terms the session could
not see (the couplings of the six faces) uniform within the spec's limits — and the paper's slope
session (docs/conventions.md §3) is simulated with it. ``mountcal calibrate --triad`` corrects the
stops and reports σ. Compared: the RMS error over the runs, the RMS of the reported σ, and the
bound — the Cramér–Rao bound of the slope session with the triad's covariance propagated through
the same gain (mountcal.loop.systematic), at the truth.

    python benchmarks/triad_accuracy.py --runs 1000 --markdown docs/triad-results.md
"""

from __future__ import annotations

import argparse
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import real_sessions
from accuracy import publish

from mountcal.calibration.fit import Options, calibrate
from mountcal.cli import main as cli
from mountcal.core.conventions import G_N
from mountcal.estimate import bound, full
from mountcal.estimate.triad import NAMES, Triad, load
from mountcal.io.sensor_spec import SensorSpec
from mountcal.loop.systematic import angle_sigmas, propagate
from mountcal.simulate.stops import simulate_preset

KEYS = ("roll_deg", "pitch_deg", "yaw_deg", "slope_deg")
MODEL = ("rotation", "slope")
SPEC = SensorSpec(  # the simulated headings are exact: no heading limit
    bias_tempco_mps2_per_c=0.0, source="the default class, no temperatures", heading_deg=0.0
)


def session_triads(work: Path) -> dict[str, Triad]:
    """Each real session fitted by `mountcal triad` (the command, as a user runs it)."""
    out = {}
    xsens = real_sessions.xsens_samples(work / "xsens.parquet")
    assert cli(["triad", str(xsens), "-o", str(work / "xsens_triad.json")]) == 0
    out["IMU-TK Xsens (hand-held, 34 stops)"] = load(work / "xsens_triad.json")
    faces = real_sessions.ferraris_stops(work / "faces.csv")
    assert cli(["triad", str(faces), "-o", str(work / "faces_triad.json")]) == 0
    out["imucal Ferraris (six faces)"] = load(work / "faces_triad.json")
    return out


def draw_sensor(triad: Triad, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A sensor (bias, I + E) drawn from what the triad leaves uncertain."""
    values = np.concatenate([triad.bias_mps2, triad.scale_e])
    fitted = [NAMES.index(n) for n in triad.fitted]
    x = values.copy()
    x[fitted] += rng.multivariate_normal(np.zeros(len(fitted)), triad.cov[np.ix_(fitted, fitted)])
    limits = {n: SPEC.cross_axis if n.startswith("cross") else SPEC.scale for n in NAMES[3:]}
    limits |= {n: SPEC.bias_mps2 for n in NAMES[:3]}
    for i, n in enumerate(NAMES):
        if n not in triad.fitted:
            x[i] += rng.uniform(-limits[n], limits[n])
    e = x[3:]
    return x[:3], np.eye(3) + np.array([[e[0], e[3], e[4]], [e[3], e[1], e[5]], [e[4], e[5], e[2]]])


def bound_deg(triad: Triad, noise_g: float) -> dict[str, float]:
    """CRB of the slope session and the triad's covariance through the gain, at the truth."""
    table, truth = simulate_preset("zhang2011", seed=0, noise_g=0.0)  # at the truth
    table = replace(table, cov_s=np.broadcast_to(np.eye(3) * (noise_g * G_N) ** 2, (len(table), 3, 3)).copy())
    state = bound.true_state(truth.rot_vs, truth.slope_deg, truth.g_mps2)
    crb = bound.crb_deg(table, state, MODEL, truth.g_mps2)
    assert crb is not None
    names = full.StaticModel(table, MODEL, truth.g_mps2).names
    # noise_scale = ∞: no residual narrows the limits. Over the sensors drawn, the narrowed limits plus the mean
    # the residual shows (what calibrate reports) average to this: E[Σ_post + μμᵀ] = Σ_δ
    cov, _, _, _ = propagate(table, state, names, MODEL, truth.g_mps2, triad.errors(SPEC), noise_scale=np.inf)
    sys = angle_sigmas(cov, names, state.rot_vs, yaw=True, slope=True)
    return {k: float(np.hypot(crb[k] or 0.0, sys[k] or 0.0)) for k in KEYS}


def run(triad: Triad, runs: int, noise_g: float, seed: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    err, sig = np.full((runs, 4), np.nan), np.full((runs, 4), np.nan)
    opts = Options(model=",".join(MODEL), gravity_mps2=G_N, spec=SPEC, triad=triad)
    for r in range(runs):
        bias, m = draw_sensor(triad, rng)
        table, truth = simulate_preset("zhang2011", seed=rng, noise_g=noise_g, bias_mps2=bias, scale_matrix=m)
        cal = calibrate(table, opts)
        err[r] = np.array([cal.roll_deg, cal.pitch_deg, cal.yaw_deg, cal.slope_deg], dtype=float) - [
            *truth.angles_deg,
            truth.slope_deg,
        ]
        sig[r] = [cal.roll_sigma_deg, cal.pitch_sigma_deg, cal.yaw_sigma_deg, cal.slope_sigma_deg]
    return {"err": err, "sig": sig}


def table_md(name: str, rows: list[tuple[float, dict[str, float], dict[str, np.ndarray]]], runs: int) -> str:
    lines = [
        f"### {name} ({runs} runs per row)",
        "",
        "| stop noise | | roll | pitch | yaw | slope |",
        "|---|---|---|---|---|---|",
    ]
    for noise_g, bnd, res in rows:
        rms = np.sqrt(np.nanmean(res["err"] ** 2, axis=0))
        rsig = np.sqrt(np.nanmean(res["sig"] ** 2, axis=0))
        cover = np.nanmean(np.abs(res["err"]) <= 1.96 * res["sig"], axis=0)
        b = np.array([bnd[k] for k in KEYS])
        lead = f"| {noise_g * 1e3:g} mg |"
        lines.append(lead + " bound (CRB ⊕ triad) | " + " | ".join(f"{x:.4f}°" for x in b) + " |")
        lines.append(
            "| | RMS error (÷ bound) | "
            + " | ".join(f"{x:.4f}° ({x / y:.2f})" for x, y in zip(rms, b, strict=True))
            + " |"
        )
        lines.append(
            "| | RMS reported σ (÷ bound) | "
            + " | ".join(f"{x:.4f}° ({x / y:.2f})" for x, y in zip(rsig, b, strict=True))
            + " |"
        )
        lines.append("| | 95 % coverage | " + " | ".join(f"{x:.1%}" for x in cover) + " |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=15)
    ap.add_argument("--markdown", default=None)
    args = ap.parse_args()
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        triads = session_triads(Path(tmp))
    parts = []
    for i, (name, triad) in enumerate(triads.items()):
        rows = [(n, bound_deg(triad, n), run(triad, args.runs, n, args.seed + i)) for n in (1e-3, 1e-4)]
        parts.append(table_md(name, rows, args.runs))
    publish(parts, t0, args.seed, args.markdown)


if __name__ == "__main__":
    main()
