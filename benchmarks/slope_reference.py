"""A slope reference against what lies inside the model's span on one slope.

Axes that tilt with the lateral load (a compliant bracket) and a common scale of the two horizontal
axes change only the size of the circle the stops trace: the stops read a steeper or flatter slope
and leave no residual (docs/effects.md, "What no residual can show"). With the slope measured apart
from the stops (``Options.slope_reference``, ``--slope-reference DEG SIGMA_DEG``) the fitted slope
is checked against it. For each strength: the share of runs in which the effect moves an estimate
beyond 2σ of the total σ against the clean run (as in benchmarks/outside_effects.py, same sessions),
and among those the share flagged without a reference and with one of 1σ 0.02° and 0.05° (a
surveyed bay; a digital inclinometer on the floor). The reference is the true slope plus its own
error. Clean runs give the false-alarm rate with each reference.

    OMP_NUM_THREADS=1 python benchmarks/slope_reference.py --runs 200 --seed 15 \
        --markdown docs/slope-reference-results.md
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from outside_effects import (
    Effect,
    Session,
    _add,
    beyond,
    estimates,
    flagged,
    g_misalignment,
    measured_slope,
    session,
    share,
    write,
)

from mountcal.calibration.fit import Options, calibrate
from mountcal.loop.slope_reference import SlopeReference
from mountcal.stops.table import StopTable

REFERENCE_SIGMAS = (0.02, 0.05)


def horizontal_scale(s: Session, percent: float, rng: np.random.Generator) -> StopTable:
    """The sensor's x and y axes read ``percent`` % too much (or too little: a random sign), z is right."""
    k = 1e-2 * percent * rng.choice([-1.0, 1.0])
    return _add(s, s.u_s * np.array([k, k, 0.0]))


EFFECTS: list[tuple[str, str, Effect, tuple[float, ...]]] = [
    ("g-sensitive misalignment", "mrad/g", g_misalignment, (10.0, 30.0, 100.0)),
    ("common scale of the horizontal axes", "%", horizontal_scale, (1.0, 3.0, 10.0)),
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--seed", type=int, default=15)
    ap.add_argument("--markdown", default=None)
    args = ap.parse_args()
    t0 = time.perf_counter()
    n_ref = 1 + len(REFERENCE_SIGMAS)
    moved = np.zeros((len(EFFECTS), 3, args.runs), bool)
    flag = np.zeros((n_ref, len(EFFECTS), 3, args.runs), bool)
    clean_flag = np.zeros((n_ref, args.runs), bool)
    for r in range(args.runs):
        rng = np.random.default_rng([args.seed, r])
        s = session(r, rng)
        refs: list[SlopeReference | None] = [None]
        refs += [measured_slope(s, sigma, rng) for sigma in REFERENCE_SIGMAS]
        clean = [calibrate(s.table, Options(slope_reference=ref)) for ref in refs]
        ref_est, *_ = estimates(clean[0])
        clean_flag[:, r] = [flagged(c) for c in clean]
        for i, (_, _, effect, strengths) in enumerate(EFFECTS):
            for j, strength in enumerate(strengths):
                table = effect(s, strength, np.random.default_rng([args.seed, r, i, j]))
                cals = [calibrate(table, Options(slope_reference=ref)) for ref in refs]
                est, sig, _ = estimates(cals[0])
                moved[i, j, r] = beyond(est, ref_est, sig)
                flag[:, i, j, r] = [flagged(c) for c in cals]

    heads = ["no reference", *(f"reference ±{s:g}° (1σ)" for s in REFERENCE_SIGMAS)]
    lines = [
        f"{args.runs} runs per row (the two layouts of benchmarks/outside_effects.py alternate), seed {args.seed}. "
        '"Moved": an estimate beyond 2σ (the total σ) of the clean run of the same noise; "flagged": not confident '
        "or structure unexplained.",
        "",
        "| effect | strength | moved | flagged when moved: " + " | ".join(heads) + " | flagged, all runs: "
        f"{heads[-1]} |",
        "|---|---|---|" + "---|" * len(heads) + "---|",
    ]
    for i, (name, unit, _, strengths) in enumerate(EFFECTS):
        for j, strength in enumerate(strengths):
            m = moved[i, j]
            cells = " | ".join(share(flag[k, i, j], m) for k in range(n_ref))
            lines.append(f"| {name} | {strength:g} {unit} | {m.mean():.0%} | {cells} | {flag[-1, i, j].mean():.0%} |")
    lines += ["", "| effect | " + " | ".join(heads) + " |", "|---|" + "---|" * len(heads)]
    for i, (name, *_r) in enumerate(EFFECTS):
        lines.append(
            f"| {name}, flagged when moved | " + " | ".join(share(flag[k, i], moved[i]) for k in range(n_ref)) + " |"
        )
    lines.append(
        "| **clean runs flagged** | " + " | ".join(f"**{clean_flag[k].mean():.1%}**" for k in range(n_ref)) + " |"
    )
    write(lines, t0, args.markdown)


if __name__ == "__main__":
    main()
