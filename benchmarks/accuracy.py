"""Monte Carlo accuracy of the paper's method and the full estimator in the paper's scenario.

docs/conventions.md §3 (γ = 5°, θ = 6°, φ = 7°, α = 5°, 12 headings 30° apart, stop noise 0.001 g per axis),
without a bias and with an unknown 20 mg bias in a random direction. For each: RMS error of roll,
pitch, yaw and slope beside the Cramér–Rao bound, coverage of the ±1.96σ intervals, and how often
``--model auto`` fits the bias.

    python benchmarks/accuracy.py --runs 2000 --markdown docs/accuracy-results.md
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import numpy as np

from mountcal.calibration.fit import BASE, WITH_OFFSET, Options, calibrate
from mountcal.core.conventions import G_N
from mountcal.core.result import Calibration
from mountcal.estimate import bound
from mountcal.estimate.bound import true_state
from mountcal.simulate.stops import ZHANG2011, random_bias, simulate_preset

QUANTITIES = ("roll", "pitch", "yaw", "slope")
BIAS_MPS2 = 0.020 * G_N


def crb_deg(terms: tuple[str, ...]) -> dict[str, float]:
    """The Cramér–Rao bound at the truth with the true stop noise (no estimation involved)."""
    table, truth = simulate_preset("zhang2011", seed=0)
    sigma = ZHANG2011["noise_g"] * G_N  # type: ignore[operator]
    table = replace(table, cov_s=np.broadcast_to(np.eye(3) * sigma**2, (len(table), 3, 3)).copy())
    state = true_state(truth.rot_vs, truth.slope_deg, truth.g_mps2)
    crb = bound.crb_deg(table, state, terms, truth.g_mps2)
    assert crb is not None
    return {q: float(crb[f"{q}_deg"]) for q in QUANTITIES}  # type: ignore[arg-type]


def run(runs: int, with_bias: bool, seed: int) -> dict[str, dict[str, np.ndarray]]:
    """Errors (deg) and 1σ (deg) per estimator and quantity; plus auto's bias decisions."""
    rng = np.random.default_rng(seed)
    fixed = "rotation,slope,bias" if with_bias else "rotation,slope"
    estimators = {
        "paper": Options(method="paper", model="rotation,slope"),
        f"full ({fixed})": Options(model=fixed),
        "full (auto)": Options(model="auto"),
    }
    err = {k: np.full((runs, 4), np.nan) for k in estimators}
    sig = {k: np.full((runs, 4), np.nan) for k in estimators}
    auto_bias = np.zeros(runs, dtype=bool)
    for r in range(runs):
        bias = random_bias(BIAS_MPS2, rng) if with_bias else None
        table, truth = simulate_preset("zhang2011", seed=rng, bias_mps2=bias)
        true = np.array([*truth.angles_deg, truth.slope_deg])
        for name, opts in estimators.items():
            cal = calibrate(table, opts)
            est = np.array([cal.roll_deg, cal.pitch_deg, cal.yaw_deg, cal.slope_deg], dtype=float)
            err[name][r] = est - true
            sig[name][r] = statistical_sigma(cal)
            if name == "full (auto)":
                auto_bias[r] = "bias" in cal.model
    return {"err": err, "sig": sig, "auto_bias": auto_bias}  # type: ignore[dict-item]


def statistical_sigma(cal: Calibration) -> np.ndarray:
    """The statistical part of roll, pitch, yaw and slope σ: the part the Cramér–Rao bound speaks of.

    The result's σ fields hold the total (with the sensor's systematic part, docs/accuracy.md); these
    simulations have no sensor error, so their coverage is that of the statistical part.
    """
    keys = ("roll_deg", "pitch_deg", "yaw_deg", "slope_deg")
    if cal.systematic is not None:
        return np.array([cal.systematic.statistical[k] for k in keys], dtype=float)
    return np.array([cal.roll_sigma_deg, cal.pitch_sigma_deg, cal.yaw_sigma_deg, cal.slope_sigma_deg], dtype=float)


def table_md(title: str, res: dict, crb: dict[str, float], runs: int) -> str:  # type: ignore[type-arg]
    lines = [
        f"### {title} ({runs} runs)",
        "",
        "| estimator | roll RMS | pitch RMS | yaw RMS | slope RMS | 95 % coverage roll / pitch / yaw / slope |",
        "|---|---|---|---|---|---|",
    ]
    lines.append("| Cramér–Rao bound | " + " | ".join(f"{crb[q]:.4f}°" for q in QUANTITIES) + " | — |")
    for name in res["err"]:
        e, s = res["err"][name], res["sig"][name]
        ok = np.isfinite(e)
        rms = [np.sqrt(np.mean(e[ok[:, j], j] ** 2)) for j in range(4)]
        cov = [np.mean(np.abs(e[ok[:, j], j]) <= 1.96 * s[ok[:, j], j]) for j in range(4)]
        ratio = [rms[j] / crb[q] for j, q in enumerate(QUANTITIES)]
        failed = (~ok).any(axis=0).sum()
        cells = [f"{rms[j]:.4f}° ({ratio[j]:.2f}×)" for j in range(4)]
        note = f" ({(~ok[:, 3]).sum()} runs without slope)" if failed else ""
        lines.append(f"| {name}{note} | " + " | ".join(cells) + " | " + " / ".join(f"{c:.1%}" for c in cov) + " |")
    lines.append("")
    lines.append(f"`--model auto` fitted the bias in {res['auto_bias'].mean():.1%} of runs.")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=20110101)
    ap.add_argument("--markdown", default=None, help="also write the tables to this file")
    args = ap.parse_args()
    t0 = time.perf_counter()
    parts = []
    for with_bias, crb_terms, title in (
        (False, BASE, "No bias; CRB of rotation,slope"),
        (True, WITH_OFFSET, "Unknown 20 mg bias; CRB of rotation,slope,bias"),
    ):
        res = run(args.runs, with_bias, args.seed + with_bias)
        parts.append(table_md(title, res, crb_deg(crb_terms), args.runs))
    publish(parts, t0, args.seed, args.markdown)


def publish(parts: list[str], t0: float, seed: int, markdown: str | None) -> None:
    """Print the tables with the time and seed, and write them to ``markdown`` when given."""
    text = "\n\n".join(parts) + f"\n\n_{time.perf_counter() - t0:.0f} s, seed {seed}._\n"
    print(text)
    if markdown:
        with open(markdown, "w", encoding="utf-8") as fh:
            fh.write(text)


if __name__ == "__main__":
    main()
