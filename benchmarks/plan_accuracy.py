"""Does `mountcal plan` predict what `calibrate` then achieves? Random plans against Monte Carlo.

Each plan draws a slope (2–10°), a per-sample noise (1–10 mg at 100 Hz), a model (with or without
an unknown bias, alternating), a dwell (15, 20 or 30 s) and targets (0.3–1.2× what 4 such stops
give, so that the plans have 4 to 24 stops); `make_plan` chooses the protocol. The planned session
is then simulated ``--runs`` times (random mounting, a 20 mg bias in a random direction for the
bias model) and calibrated with the matching fixed ``--model``; the predicted σ is compared with
the RMS error per angle. Acceptance: every ratio within 15 %.

The comparison is of the statistical part only: the simulated sensor has no scale, cross-axis or
bias-drift error, so the plans are made for a sensor without limits (systematic part zero, total =
statistical). That the total σ is what `calibrate` reports is checked in tests/test_plan.py.

    python benchmarks/plan_accuracy.py --plans 20 --runs 300 --markdown docs/plan-results.md
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from mountcal.core.conventions import G_N
from mountcal.estimate.sensor_errors import from_spec
from mountcal.io.sensor_spec import SensorSpec
from mountcal.sessions.plan import MIN_STOPS, Noise, Request, bound_of_headings, headings, make_plan, monte_carlo_rms

# the Monte Carlo draws no sensor errors: plan for a sensor without limits, so the prediction is the statistical part
NO_LIMITS = from_spec(SensorSpec(0.0, 0.0, 0.0, 0.0, "none (benchmark of the statistical part)", heading_deg=0.0))

TOLERANCE = 0.15


def random_request(rng: np.random.Generator, i: int) -> Request:
    """A dwell of 15, 20 or 30 s and targets 0.3–1.2× what 4 such stops give: plans of 4 to 24 stops."""
    terms = ("rotation", "slope", "bias") if i % 2 else ("rotation", "slope")
    noise = Noise(float(rng.uniform(1.0, 10.0)) * 1e-3 * G_N, 100.0, "benchmark")
    slope = round(float(rng.uniform(2.0, 10.0)), 1)
    stop_s = float(rng.choice([15.0, 20.0, 30.0]))
    shortest = bound_of_headings(headings(MIN_STOPS), slope, terms, noise.stop_sigma_mps2(stop_s - 4.0))
    target = {a: float(shortest[a]) * float(rng.uniform(0.3, 1.2)) for a in ("roll", "pitch", "yaw")}  # type: ignore[arg-type]
    return Request(target, noise, terms, slope_deg=slope, stop_s=stop_s, sensor=NO_LIMITS)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plans", type=int, default=20)
    ap.add_argument("--runs", type=int, default=300)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--markdown", default=None, help="also write the table here")
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    rows, worst, unreachable = [], 0.0, 0
    t0 = time.perf_counter()
    i = 0
    while len(rows) < args.plans:
        req = random_request(rng, i)
        i += 1
        plan = make_plan(req)
        if not plan.reachable:
            unreachable += 1
            continue
        mc = monte_carlo_rms(plan, args.runs, seed=int(rng.integers(2**31)))
        ratios = {a: mc[a] / float(plan.statistical_deg[a]) for a in mc}  # type: ignore[arg-type]
        worst = max(worst, *(abs(r - 1.0) for r in ratios.values()))
        cells = " | ".join(
            f"{plan.statistical_deg[a]:.4f} / {mc[a]:.4f} ({ratios[a]:.3f})" for a in ("roll", "pitch", "yaw")
        )
        rows.append(
            f"| {len(rows) + 1} | {'bias' if 'bias' in req.terms else 'none'} | {plan.slope_deg:g} | "
            f"{req.noise.sample_sigma_mps2 * 1e3 / G_N:.2f} | {plan.n_stops} × {plan.stop_s:g} s | {cells} |"
        )
        print(rows[-1], flush=True)
    lines = [
        f"`python benchmarks/plan_accuracy.py --plans {args.plans} --runs {args.runs} --seed {args.seed}` "
        f"({time.perf_counter() - t0:.0f} s)",
        "",
        "| # | bias | slope ° | noise mg | protocol | roll: predicted statistical / MC RMS (ratio) | pitch | yaw |",
        "|---|---|---|---|---|---|---|---|",
        *rows,
        "",
        f"Largest |MC RMS / predicted − 1|: {worst:.3f} (acceptance ≤ {TOLERANCE}); "
        f"{unreachable} drawn request(s) were not reachable and were redrawn. "
        f"Standard error of an RMS over {args.runs} runs ≈ {1 / np.sqrt(2 * args.runs):.3f}.",
    ]
    print("\n".join(lines[-1:]))
    if args.markdown:
        with open(args.markdown, "w", encoding="utf-8") as fh:
            fh.write("# Plan accuracy: predicted statistical σ against Monte Carlo\n\n" + "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
