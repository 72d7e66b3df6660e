"""Each stop's own heading error, with and without its noise model (``heading_scatter``, docs/effects.md).

The paper's session (12 stops 30° apart, 1 mg noise) on slopes of 5° and 12°, every stop's given heading off by
an independent error, uniform within ±limit. For each case, over ``--runs`` sessions: how many answers are
confident, how often the step is taken, the σ it finds, and the yaw's error against its σ (the largest |error|/σ
and the RMS of error/σ: honest σ keep the RMS near or below 1). ``--without`` runs the loop without the step,
as mountcal was before it (for the before/after table in docs/effects.md).

    python benchmarks/heading_scatter.py --runs 40
"""

from __future__ import annotations

import argparse
import re
from dataclasses import replace

import numpy as np

from mountcal.calibration.fit import calibrate
from mountcal.loop import heading_scatter
from mountcal.simulate.stops import simulate_preset

LIMITS_DEG = (0.0, 0.5, 1.0, 2.0)
SLOPES_DEG = (5.0, 12.0)


def run(limit_deg: float, slope_deg: float, runs: int) -> str:
    rng = np.random.default_rng(int(100 * limit_deg + slope_deg))
    confident = taken = 0
    z, found = [], []
    for _ in range(runs):
        table, truth = simulate_preset("zhang2011", seed=rng, slope_deg=slope_deg)
        off = np.radians(rng.uniform(-limit_deg, limit_deg, len(table)))
        cal = calibrate(replace(table, beta_rad=table.beta_rad + off))  # type: ignore[operator]
        confident += cal.confident
        yaw_err = (cal.yaw_deg - truth.angles_deg[2] + 180.0) % 360.0 - 180.0  # type: ignore[operator]
        z.append(yaw_err / cal.yaw_sigma_deg)  # type: ignore[operator]
        if heading_scatter.NAME in cal.model:
            taken += 1
            step = next(s for s in cal.model_steps if s.added == heading_scatter.NAME)
            found.append(float(re.search(r"off by ([0-9.e+-]+)°", step.reason).group(1)))  # type: ignore[union-attr]
    z_arr = np.abs(np.array(z))
    sigma = f"{np.median(found):.2f}°" if found else "—"
    true = f"{limit_deg / np.sqrt(3):.2f}°"
    return (
        f"| ±{limit_deg:g}° | {slope_deg:g}° | {confident}/{runs} | {taken}/{runs} | {sigma} ({true}) | "
        f"{z_arr.max():.2f} | {np.sqrt(np.mean(z_arr**2)):.2f} |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=40)
    parser.add_argument("--without", action="store_true", help="the loop without the heading_scatter step")
    args = parser.parse_args()
    if args.without:
        heading_scatter.candidate = lambda table: False  # type: ignore[assignment]
    print("| headings off by | slope | confident | step taken | σ_h found, median (true) | max |yaw err|/σ | RMS |")
    print("|---|---|---|---|---|---|---|")
    for slope in SLOPES_DEG:
        for limit in LIMITS_DEG:
            print(run(limit, slope, args.runs), flush=True)


if __name__ == "__main__":
    main()
