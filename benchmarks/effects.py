"""Closing the loop in the paper's scenario: is each effect found, and does the error fall to the bound?

For each scenario of issue 4 — no effect; a 20 mg bias; 2 % scale with 1 % cross-axis; a bias
drift of 0.5 mg/°C over 20 °C; gravity 9.780 m/s² with the position known; one stop disturbed by
50 mg; and effects outside the library (a bias drifting with time, no temperature logged; a 3β
heading-dependent error) — over seeded runs: how often the expected term is in the chosen model,
the angle RMS error of the base model (before) and of the chosen model (after) beside the
Cramér–Rao bound of the true model, how often unexplained structure is flagged, and coverage.

    python benchmarks/effects.py --runs 200 --markdown docs/effects-results.md
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from mountcal.calibration.fit import calibrate
from mountcal.core.conventions import G_N
from mountcal.estimate import bound
from mountcal.simulate.stops import ZHANG2011, Truth, random_bias, simulate_stops
from mountcal.stops.table import StopTable

MG = 1e-3 * G_N
ANGLES = ("roll", "pitch", "yaw")


@dataclass(frozen=True)
class Scenario:
    name: str
    expect: str | None  # the model term that should appear ("" for none expected, None for outside the library)
    make: Callable[[np.random.Generator], dict[str, object]]
    true_terms: tuple[str, ...]


def _scale(rng: np.random.Generator) -> dict[str, object]:
    e = np.diag(rng.choice([-1.0, 1.0], 3) * 0.02)
    cross = rng.choice([-1.0, 1.0], 3) * 0.01
    e[0, 1] = e[1, 0] = cross[0]
    e[0, 2] = e[2, 0] = cross[1]
    e[1, 2] = e[2, 1] = cross[2]
    return {"scale_matrix": np.eye(3) + e}


def _temperature(rng: np.random.Generator) -> dict[str, object]:
    return {
        "temperature_c": np.linspace(20.0, 40.0, 12),
        "temp_coeff_mps2_per_c": random_bias(0.5 * MG, rng),
        "temp_ref_c": 20.0,
    }


def _disturbed(rng: np.random.Generator) -> dict[str, object]:
    d = np.zeros((12, 3))
    d[rng.integers(12)] = random_bias(50 * MG, rng)
    return {"disturbance_mps2": d}


def _time_drift(rng: np.random.Generator) -> dict[str, object]:
    # A bias that drifts 15 mg over the session; the table logs time but no temperature.
    return {"disturbance_mps2": np.outer(np.linspace(-0.5, 0.5, 12), random_bias(15 * MG, rng))}


def _surfaces(rng: np.random.Generator) -> dict[str, object]:
    # Every stop on its own surface: an extra road tilt per stop of 0.3° (1σ), no site column.
    tilt = np.radians(rng.normal(0.0, 0.3, size=(12, 2)))
    return {"surface_tilt_rad": tilt}


SCENARIOS = [
    Scenario("no effect", "", lambda rng: {}, ("rotation", "slope")),
    Scenario("bias 20 mg", "bias", lambda rng: {"bias_mps2": random_bias(20 * MG, rng)}, ("rotation", "slope", "bias")),
    Scenario("scale 2 %, cross-axis 1 %", "scale", _scale, ("rotation", "slope", "scale")),
    Scenario(
        "temperature 0.5 mg/°C over 20 °C", "temperature", _temperature, ("rotation", "slope", "bias", "temperature")
    ),
    Scenario(
        "gravity 9.780, position known",
        "gravity",
        lambda rng: {"g_mps2": 9.780, "lat_deg": 0.0, "alt_m": 0.0},
        ("rotation", "slope"),
    ),
    Scenario("one stop disturbed by 50 mg", "outlier", _disturbed, ("rotation", "slope")),
    Scenario("outside the library: bias drifting with time", None, _time_drift, ("rotation", "slope")),
    Scenario("outside the library: each stop on its own surface (0.3° tilt)", None, _surfaces, ("rotation", "slope")),
]


def simulate(s: Scenario, rng: np.random.Generator) -> tuple[StopTable, Truth, dict[str, object]]:
    params = s.make(rng)
    tilt = params.pop("surface_tilt_rad", None)
    base = {k: v for k, v in ZHANG2011.items()}
    table, truth = simulate_stops(seed=rng, **{**base, **params})  # type: ignore[arg-type]
    if tilt is not None:  # tilt each stop's specific force about the vehicle x and y axes
        f_v = truth.rot_vs.apply(table.acc_s)
        tilted = np.array([Rotation.from_rotvec([tx, ty, 0.0]).apply(f) for (tx, ty), f in zip(tilt, f_v, strict=True)])
        table = replace(table, acc_s=truth.rot_vs.inv().apply(tilted))
    return table, truth, params


def true_bound(s: Scenario, table: StopTable, truth: Truth, params: dict[str, object]) -> dict[str, float | None]:
    sigma = ZHANG2011["noise_g"] * G_N  # type: ignore[operator]
    exact = replace(table, cov_s=np.broadcast_to(np.eye(3) * sigma**2, (len(table), 3, 3)).copy())
    if s.expect == "outlier":
        bad = np.flatnonzero(np.any(truth.disturbance_mps2 != 0, axis=1))  # type: ignore[arg-type]
        exact = exact.subset(np.setdiff1d(np.arange(len(table)), bad))
    e = truth.scale_matrix - np.eye(3)
    state = bound.true_state(
        truth.rot_vs,
        truth.slope_deg,
        truth.g_mps2,
        {
            "bias": truth.bias_mps2
            + truth.temp_coeff_mps2_per_c
            * (np.mean(table.temperature_c) - truth.temp_ref_c if table.temperature_c is not None else 0.0),
            "temperature": truth.temp_coeff_mps2_per_c,
            "scale": np.array([e[0, 0], e[1, 1], e[2, 2], e[0, 1], e[0, 2], e[1, 2]]),
        },
    )
    crb = bound.crb_deg(exact, state, s.true_terms, truth.g_mps2)
    return crb or {f"{a}_deg": None for a in (*ANGLES, "slope")}


def run(s: Scenario, runs: int, seed: int) -> dict[str, object]:
    rng = np.random.default_rng(seed)
    chosen: list[dict[str, object]] = []
    found = flagged = confident = 0
    before, after = np.zeros((runs, 3)), np.zeros((runs, 3))
    covered = np.zeros((runs, 3), dtype=bool)
    crb = None
    for r in range(runs):
        table, truth, params = simulate(s, rng)
        cal = calibrate(table)
        path = [(st.added, list(st.excluded_stops)) for st in cal.model_steps]
        chosen.append({"model": list(cal.model), "steps": path})
        true = np.array(truth.angles_deg)
        first = cal.model_steps[0].angles
        before[r] = np.array([first.roll_deg, first.pitch_deg, first.yaw_deg], dtype=float) - true
        after[r] = np.array([cal.roll_deg, cal.pitch_deg, cal.yaw_deg], dtype=float) - true
        sig = np.array([cal.roll_sigma_deg, cal.pitch_sigma_deg, cal.yaw_sigma_deg], dtype=float)
        covered[r] = np.abs(after[r]) <= 1.96 * sig
        expected_in = (s.expect in cal.model) if s.expect else (cal.model == ("rotation", "slope"))
        found += bool(expected_in) if s.expect is not None else 0
        flagged += bool(cal.unexplained)
        confident += cal.confident
        if crb is None:
            crb = true_bound(s, table, truth, params)
    return {
        "found": found / runs,
        "flagged": flagged / runs,
        "confident": confident / runs,
        "before": np.sqrt(np.mean(before**2, axis=0)),
        "after": np.sqrt(np.mean(after**2, axis=0)),
        "coverage": covered.mean(axis=0),
        "crb": crb,
        "chosen": chosen,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--seed", type=int, default=4)
    ap.add_argument("--markdown", default=None)
    ap.add_argument("--only", default=None, help="run the scenarios whose name contains this")
    ap.add_argument("--choices", default=None, help="write the model chosen in every run to this JSON file")
    args = ap.parse_args()
    t0 = time.perf_counter()
    lines = [
        f"{args.runs} runs per scenario, seed {args.seed}. Angles: roll / pitch / yaw, RMS error in degrees.",
        "",
        "| scenario | expected term found | unexplained flagged | confident | RMS before (base model) | "
        "RMS after (chosen model) | CRB of the true model | after / CRB | 95 % coverage after |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    choices: dict[str, object] = {}
    for i, s in enumerate(SCENARIOS):
        if args.only and args.only not in s.name:
            continue
        res = run(s, args.runs, args.seed + i)
        choices[s.name] = res["chosen"]
        crb = res["crb"]
        bound_v = np.array([np.nan if crb[f"{a}_deg"] is None else crb[f"{a}_deg"] for a in ANGLES])  # type: ignore[index]
        fmt = lambda v: " / ".join(f"{x:.3f}" for x in v)  # noqa: E731
        found = (
            "—"
            if s.expect is None
            else ("nothing added: " if s.expect == "" else f"`{s.expect}`: ") + f"{res['found']:.1%}"
        )
        ratio = res["after"] / bound_v  # type: ignore[operator]
        lines.append(
            f"| {s.name} | {found} | {res['flagged']:.1%} | {res['confident']:.1%} | {fmt(res['before'])} | "
            f"{fmt(res['after'])} | {fmt(bound_v) if np.all(np.isfinite(bound_v)) else 'singular'} | "
            f"{fmt(ratio) if np.all(np.isfinite(ratio)) else '—'} | "
            f"{' / '.join(f'{c:.0%}' for c in res['coverage'])} |"
        )  # type: ignore[union-attr]
        print(lines[-1], flush=True)
    text = "\n".join(lines) + f"\n\n_{time.perf_counter() - t0:.0f} s._\n"
    if args.markdown:
        with open(args.markdown, "w", encoding="utf-8") as fh:
            fh.write(text)
    if args.choices:
        with open(args.choices, "w", encoding="utf-8") as fh:
            json.dump(choices, fh, indent=1)


if __name__ == "__main__":
    main()
