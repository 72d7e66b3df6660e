"""Coverage of the total σ (statistical + systematic) when the sensor has random errors within its spec.

The paper's scenario (docs/conventions.md §3; benchmarks/accuracy.py) with, in every run, a new
random sensor: scale errors uniform in ±scale, symmetric cross-axis couplings uniform in
±cross_axis and a bias uniform in ±bias per axis — the rectangular distributions the spec stands
for — and headings off the fall line by a common error and each stop's own, both uniform in
±heading_deg. ``mountcal calibrate`` (``--model auto``) is given that spec. Reported: 95 % coverage of the
total σ and of the statistical part alone, RMS error against the mean total σ, how often the
result is confident and says its error is dominated by the systematic part.

    python benchmarks/systematic.py --runs 500 --markdown docs/systematic-results.md
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import numpy as np
from accuracy import publish

from mountcal.calibration.fit import Options, calibrate
from mountcal.core.conventions import G_N
from mountcal.io.sensor_spec import SensorSpec
from mountcal.simulate.stops import simulate_preset

KEYS = ("roll_deg", "pitch_deg", "yaw_deg", "slope_deg")


def random_sensor(spec: SensorSpec, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """A sensor drawn uniformly within the spec's limits."""
    e = np.diag(rng.uniform(-spec.scale, spec.scale, 3))
    xy, xz, yz = rng.uniform(-spec.cross_axis, spec.cross_axis, 3)
    e[0, 1] = e[1, 0] = xy
    e[0, 2] = e[2, 0] = xz
    e[1, 2] = e[2, 1] = yz
    return {"scale_matrix": np.eye(3) + e, "bias_mps2": rng.uniform(-spec.bias_mps2, spec.bias_mps2, 3)}


def run(spec: SensorSpec, runs: int, seed: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    err, total, stat = (np.full((runs, 4), np.nan) for _ in range(3))
    confident, dominant = np.zeros(runs, bool), np.zeros(runs, bool)
    for r in range(runs):
        table, truth = simulate_preset("zhang2011", seed=rng, **random_sensor(spec, rng))  # type: ignore[arg-type]
        assert table.beta_rad is not None  # the headings logged: the true ones, off by what the spec allows
        off = rng.uniform(-1, 1) + rng.uniform(-1, 1, len(table))
        table = replace(table, beta_rad=table.beta_rad + np.radians(spec.heading_deg * off))
        cal = calibrate(table, Options(spec=spec))
        assert cal.systematic is not None
        err[r] = np.array([cal.roll_deg, cal.pitch_deg, cal.yaw_deg, cal.slope_deg], dtype=float) - [
            *truth.angles_deg,
            truth.slope_deg,
        ]
        total[r] = [cal.roll_sigma_deg, cal.pitch_sigma_deg, cal.yaw_sigma_deg, cal.slope_sigma_deg]
        stat[r] = [cal.systematic.statistical[k] for k in KEYS]
        confident[r], dominant[r] = cal.confident, cal.systematic.dominant
    return {"err": err, "total": total, "stat": stat, "confident": confident, "dominant": dominant}


def table_md(spec: SensorSpec, res: dict[str, np.ndarray], runs: int) -> str:
    e, t, s = res["err"], res["total"], res["stat"]
    ok = np.isfinite(e) & np.isfinite(t)

    def col(f: np.ndarray) -> list[float]:
        return [float(np.mean(np.abs(e[ok[:, j], j]) <= 1.96 * f[ok[:, j], j])) for j in range(4)]

    rms = [float(np.sqrt(np.mean(e[ok[:, j], j] ** 2))) for j in range(4)]
    mean_t = [float(np.sqrt(np.mean(t[ok[:, j], j] ** 2))) for j in range(4)]
    lim = (
        f"scale ±{spec.scale:.1%}, cross-axis ±{spec.cross_axis:.1%}, bias ±{spec.bias_mps2 / G_N * 1e3:.0f} mg, "
        f"headings ±{spec.heading_deg:g}°"
    )
    return "\n".join(
        [
            f"### Random sensor within {lim} ({runs} runs)",
            "",
            "| | roll | pitch | yaw | slope |",
            "|---|---|---|---|---|",
            "| RMS error | " + " | ".join(f"{x:.4f}°" for x in rms) + " |",
            "| RMS of the total σ | " + " | ".join(f"{x:.4f}°" for x in mean_t) + " |",
            "| 95 % coverage, total σ | " + " | ".join(f"{x:.1%}" for x in col(t)) + " |",
            "| 95 % coverage, statistical σ alone | " + " | ".join(f"{x:.1%}" for x in col(s)) + " |",
            "",
            f"Confident: {res['confident'].mean():.1%} of runs; 'dominated by the systematic part' said in "
            f"{res['dominant'].mean():.1%}; runs without a value: {int((~ok).any(axis=1).sum())}.",
        ]
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=500)
    ap.add_argument("--seed", type=int, default=15)
    ap.add_argument("--markdown", default=None)
    args = ap.parse_args()
    t0 = time.perf_counter()
    specs = [
        SensorSpec(scale=0.02, cross_axis=0.01, bias_mps2=0.020 * G_N, bias_tempco_mps2_per_c=0.0, source="issue 15"),
        SensorSpec(bias_tempco_mps2_per_c=0.0, source="the default class (no temperatures in these runs)"),
    ]
    parts = [table_md(spec, run(spec, args.runs, args.seed + i), args.runs) for i, spec in enumerate(specs)]
    publish(parts, t0, args.seed, args.markdown)


if __name__ == "__main__":
    main()
