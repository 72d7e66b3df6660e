"""Is `temperature` chosen on stop tables with a temperature column and a temperature effect?

Tables the suite does not hold, drawn at random per run: 8, 12, 16 or 24 stops; headings visited in order around
the circle, in a random order, or around the circle twice; the sensor cooling or warming linearly (by 8 to 25 °C,
from 25 to 50 °C); its bias drifting 0.3 to 1 mg/°C in a random direction, with a constant bias of 0 to 30 mg or
none; a random mounting within ±10° of roll and pitch on a 3° to 8° slope; stop noise 1 mg. Reported: how often
`--model auto` chooses `temperature`, how often the final residual test still names temperature when it was not
chosen (the loop stopping one step short), and the result's confidence; the issue's case (12 stops in heading
order while the sensor cools, no constant bias); and, as the guard's check, the suite's
case where the temperature rises and falls with the headings while the body leans (a heading pattern that no
stop can tell from a temperature drift): `temperature` must not be taken there.

    OMP_NUM_THREADS=1 PYTHONPATH=src python benchmarks/temperature_choice.py --runs 300
"""

from __future__ import annotations

import argparse
import time
from collections import Counter
from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation

from mountcal.calibration.fit import calibrate
from mountcal.core.conventions import G_N
from mountcal.simulate.stops import random_bias, simulate_preset, simulate_stops
from mountcal.stops.table import StopTable

MG = 1e-3 * G_N


def hidden_table(rng: np.random.Generator) -> tuple[StopTable, str]:
    n = int(rng.choice([8, 12, 16, 24]))
    order = str(rng.choice(["circle", "random", "twice"]))
    beta = np.arange(n) * 360.0 / n
    if order == "random":
        beta = rng.permutation(beta)
    elif order == "twice":
        beta = np.resize(np.arange(n // 2) * 720.0 / n, n)
    start = rng.uniform(25.0, 50.0)
    span = rng.uniform(8.0, 25.0) * rng.choice([-1.0, 1.0])
    bias = random_bias(rng.uniform(0.0, 30.0) * MG, rng) if rng.random() < 0.5 else None
    table, _ = simulate_stops(
        rot_vs=Rotation.from_euler("ZYX", [rng.uniform(-180, 180), *rng.uniform(-10, 10, 2)], degrees=True),
        slope_deg=rng.uniform(3.0, 8.0),
        beta_deg=beta,
        bias_mps2=bias,
        temperature_c=np.linspace(start, start + span, n),
        temp_coeff_mps2_per_c=random_bias(rng.uniform(0.3, 1.0) * MG, rng),
        temp_ref_c=start,
        seed=rng,
    )
    return table, f"{n} stops, {order}, {'cooling' if span < 0 else 'warming'}"


def cooling_around_the_circle(rng: np.random.Generator) -> StopTable:
    """The case of the issue: the paper's 12 stops in heading order while the sensor cools by 15 °C, its bias
    drifting 0.5 mg/°C in a random direction, no constant bias (about 80 % of the ramp is a heading harmonic)."""
    return simulate_stops(
        rot_vs=Rotation.from_euler("ZYX", [rng.uniform(-180, 180), *rng.uniform(-10, 10, 2)], degrees=True),
        beta_deg=np.arange(12) * 30.0,
        temperature_c=np.linspace(40.0, 25.0, 12),
        temp_coeff_mps2_per_c=random_bias(0.5 * MG, rng),
        temp_ref_c=30.0,
        seed=rng,
    )[0]


def lean_around_a_warm_up(rng: np.random.Generator, lean: float = 0.05) -> StopTable:
    """The guard's case (tests/test_effects.py): the paper's 12 stops in heading order while the sensor warms and
    cools again, the body leaning ``lean`` × the lateral slope (no term of the model, no temperature effect)."""
    temperature = np.interp(np.arange(12), [0, 6, 11], [20.0, 35.0, 22.0])
    table, truth = simulate_preset("zhang2011", seed=rng, temperature_c=temperature)
    f_v = truth.rot_vs.apply(table.acc_s)
    roll = lean * np.arcsin(np.clip(f_v[:, 1] / truth.g_mps2, -1.0, 1.0))
    leaned = Rotation.from_rotvec(np.column_stack([roll, np.zeros((12, 2))])).inv().apply(f_v)
    return replace(table, acc_s=truth.rot_vs.inv().apply(leaned))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--seed", type=int, default=25)
    args = ap.parse_args()
    t0 = time.perf_counter()
    rng = np.random.default_rng(args.seed)
    chosen = named = confident = 0
    by_layout: Counter[str] = Counter()
    chosen_by_layout: Counter[str] = Counter()
    for _ in range(args.runs):
        table, layout = hidden_table(rng)
        cal = calibrate(table)
        took = "temperature" in cal.model
        chosen += took
        confident += cal.confident
        named += (not took) and any(f.test == "temperature" for f in cal.unexplained)
        key = layout.split(",")[0] + "," + layout.split(",")[1]
        by_layout[key] += 1
        chosen_by_layout[key] += took
    cooling = [calibrate(cooling_around_the_circle(rng)) for _ in range(args.runs // 3)]
    guard = [lean_around_a_warm_up(rng) for _ in range(50)]
    taken = sum("temperature" in calibrate(t).model for t in guard)
    print("| tables | `temperature` chosen | not chosen, residual names temperature | confident |")
    print("|---|---|---|---|")
    print(
        f"| {args.runs} hidden tables (all layouts) | {chosen / args.runs:.1%} | {named / args.runs:.1%} | "
        f"{confident / args.runs:.1%} |"
    )
    for key in sorted(by_layout):
        print(f"| {key} ({by_layout[key]}) | {chosen_by_layout[key] / by_layout[key]:.0%} | | |")
    took = ["temperature" in c.model for c in cooling]
    left = [not t and any(f.test == "temperature" for f in c.unexplained) for t, c in zip(took, cooling, strict=True)]
    print(
        f"| the issue's case: 12 stops in heading order cooling 15 °C, 0.5 mg/°C, no bias ({len(cooling)}) | "
        f"{np.mean(took):.1%} | {np.mean(left):.1%} | {np.mean([c.confident for c in cooling]):.1%} |"
    )
    print(
        f"\nThe guard's case (temperature rising and falling with the headings, a lean): `temperature` taken in "
        f"{taken} of {len(guard)}.\n\n_{args.runs} runs, seed {args.seed}, {time.perf_counter() - t0:.0f} s._"
    )


if __name__ == "__main__":
    main()
