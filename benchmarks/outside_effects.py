"""Effects the library does not model: when one moves an estimate beyond 2σ, is the result flagged?

Nine physically motivated effect types, two invented after those were measured and one after the
step tests (a slope that changes mid-session), none of them a term of the model (docs/effects.md,
"Unexplained structure"), each at three strengths, added to the same noisy session as a clean run.
Two session layouts alternate so that no single geometry is tuned to: the paper's 12 stops 30° apart
on a 5° slope with 1 mg noise, and 24 stops at random headings on a 3° slope with 0.5 mg noise. The
mounting is random in every run; the stop table logs time and temperature (a warm-up and cool-down,
20 → 35 → 22 °C) but no position.

For each type and strength: the fraction of runs in which the effect moves roll, pitch, yaw or
slope beyond 2σ of the σ the result reports — the total (statistical ⊕ systematic; the sessions
give no sensor spec, so the default class applies), and beside it the statistical part alone —
against the clean run of the same noise ("moved by the effect") and against the truth ("off the
truth", which a clean run also is by chance), and among those the fraction flagged (``confident``
false or ``unexplained`` non-empty). The clean runs give the false-alarm rate.

    OMP_NUM_THREADS=1 python benchmarks/outside_effects.py --runs 200 --seed 15 \
        --markdown docs/outside-effects-results.md

With ``--slope-reference-sigma 0.02`` every calibration is also given the session's slope measured
apart (the true slope plus its own error; docs/effects.md, "A slope reference").
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from mountcal.calibration.fit import Options, calibrate
from mountcal.core.conventions import G_N, FloatArray, specific_force_v
from mountcal.core.result import Calibration
from mountcal.loop.slope_reference import SlopeReference
from mountcal.simulate.stops import Truth, simulate_stops
from mountcal.stops.table import StopTable

MG = 1e-3 * G_N
ESTIMATES = ("roll", "pitch", "yaw", "slope")


@dataclass(frozen=True)
class Session:
    """A clean simulated session and what the effects need to know about it."""

    table: StopTable
    truth: Truth
    u_s: FloatArray  # noise-free specific force in the sensor frame, m/s², shape (n, 3)
    f_v: FloatArray  # the same in the vehicle frame


Effect = Callable[[Session, float, np.random.Generator], StopTable]


def _add(s: Session, delta_s: FloatArray) -> StopTable:
    return replace(s.table, acc_s=s.table.acc_s + delta_s)


def _from_vehicle(s: Session, f_v: FloatArray) -> StopTable:
    """The stops reading the specific force ``f_v`` (vehicle frame, per stop) instead of the clean one."""
    return _add(s, s.truth.rot_vs.inv().apply(f_v) - s.u_s)


def _later(n: int, rng: np.random.Generator) -> np.ndarray:
    """True from a random stop in the middle half of the session on."""
    return np.arange(n) >= rng.integers(n // 4, 3 * n // 4)


def measured_slope(s: Session, sigma_deg: float, rng: np.random.Generator) -> SlopeReference:
    """The session's slope measured apart from the sensor: the true one plus an error of ``sigma_deg`` (1σ)."""
    return SlopeReference(max(s.truth.slope_deg + rng.normal(0.0, sigma_deg), 0.0), sigma_deg)


def _sign3(rng: np.random.Generator) -> FloatArray:
    return rng.choice([-1.0, 1.0], 3)


def nonlinearity(s: Session, k: float, rng: np.random.Generator) -> StopTable:
    """Per-axis quadratic nonlinearity: a_i += k_i a_i²/g, k in mg/g² (|k_i| = k, random signs)."""
    return _add(s, _sign3(rng) * k * MG * (s.u_s / s.truth.g_mps2) ** 2)


def g_misalignment(s: Session, k: float, rng: np.random.Generator) -> StopTable:
    """The sensing axes tilt with the lateral load (a compliant bracket): θ = k·(u_x, u_y, 0)/g, k in mrad/g."""
    theta = 1e-3 * k * np.column_stack([s.u_s[:, 1], -s.u_s[:, 0], np.zeros(len(s.u_s))]) / s.truth.g_mps2
    return _add(s, np.cross(theta * rng.choice([-1.0, 1.0]), s.u_s))


def suspension(s: Session, k: float, rng: np.random.Generator) -> StopTable:
    """The body leans downhill on a cross slope, relative to the road: extra roll = k·(lateral slope); pitch stiff."""
    lean = k * np.arcsin(np.clip(s.f_v[:, 1] / s.truth.g_mps2, -1.0, 1.0))
    leaned = Rotation.from_rotvec(np.column_stack([lean, np.zeros((len(lean), 2))])).inv().apply(s.f_v)
    return _from_vehicle(s, leaned)


def bias_walk(s: Session, q: float, rng: np.random.Generator) -> StopTable:
    """A bias random walk across the session: steps of q mg (1σ per axis) between stops."""
    steps = rng.normal(0.0, q * MG, size=s.u_s.shape)
    walk = np.cumsum(steps, axis=0)
    return _add(s, walk - walk[len(walk) // 2])


def compass(s: Session, a: float, rng: np.random.Generator) -> StopTable:
    """The table's headings carry a compass deviation a·sin(β + φ), a in degrees."""
    beta = s.table.beta_rad + np.radians(a) * np.sin(s.table.beta_rad + rng.uniform(0, 2 * np.pi))  # type: ignore[operator]
    return replace(s.table, beta_rad=beta)


def heading_jitter(s: Session, a: float, rng: np.random.Generator) -> StopTable:
    """Each stop's heading is read with a random error of a degrees (1σ)."""
    return replace(s.table, beta_rad=s.table.beta_rad + np.radians(rng.normal(0.0, a, len(s.table))))  # type: ignore[operator]


def crowned_road(s: Session, c: float, rng: np.random.Generator) -> StopTable:
    """Parked left or right of a crowned road: an extra cross slope of ±c degrees, random side per stop."""
    side = rng.choice([-1.0, 1.0], len(s.table))
    crown = Rotation.from_rotvec(np.column_stack([np.radians(c) * side, np.zeros((len(side), 2))]))
    return _from_vehicle(s, crown.apply(s.f_v))


def rectification(s: Session, m: float, rng: np.random.Generator) -> StopTable:
    """Vibration rectification at the stops with the engine idling (a random third): m mg along a fixed axis."""
    idle = rng.random(len(s.table)) < 1 / 3
    axis = np.array([0.3, 0.3, 1.0]) * _sign3(rng)
    return _add(s, np.outer(idle, m * MG * axis / np.linalg.norm(axis)))


def hysteresis(s: Session, h: float, rng: np.random.Generator) -> StopTable:
    """Thermal hysteresis: the bias is ±h mg (a random direction) depending on whether the sensor warms or cools."""
    warming = np.sign(np.gradient(s.table.temperature_c))  # type: ignore[arg-type]
    direction = rng.normal(size=3)
    return _add(s, np.outer(warming, h * MG * direction / np.linalg.norm(direction)))


def heading_drift(s: Session, d: float, rng: np.random.Generator) -> StopTable:
    """Headings integrated from a gyro: an error growing linearly over the session to ±d degrees at its end."""
    t = np.asarray(s.table.t_s, float)
    error = np.radians(d) * rng.choice([-1.0, 1.0]) * (t - t[0]) / np.ptp(t)
    return replace(s.table, beta_rad=s.table.beta_rad + error)  # type: ignore[operator]


def bias_step(s: Session, b: float, rng: np.random.Generator) -> StopTable:
    """The sensor restarts once mid-session (a random stop in the middle half) with a new bias: a step of b mg."""
    later = _later(len(s.table), rng)
    direction = rng.normal(size=3)
    return _add(s, np.outer(later, b * MG * direction / np.linalg.norm(direction)))


def second_bay(s: Session, d: float, rng: np.random.Generator) -> StopTable:
    """The car moves to another bay mid-session (a random stop in the middle half): the slope changes by ±d degrees."""
    later = _later(len(s.table), rng)
    slope = np.radians(s.truth.slope_deg + d * rng.choice([-1.0, 1.0]) * later)
    beta = np.asarray(s.table.beta_rad, float)
    f_v = s.truth.g_mps2 * np.column_stack([np.sin(slope) * np.cos(beta), -np.sin(slope) * np.sin(beta), np.cos(slope)])
    return _from_vehicle(s, f_v)


EFFECTS: list[tuple[str, str, Effect, tuple[float, ...]]] = [
    ("quadratic nonlinearity", "mg/g²", nonlinearity, (5.0, 20.0, 60.0)),
    ("g-sensitive misalignment", "mrad/g", g_misalignment, (10.0, 30.0, 100.0)),
    ("suspension: body leans on a cross slope", "× lateral slope", suspension, (0.05, 0.15, 0.4)),
    ("bias random walk", "mg per stop", bias_walk, (0.3, 1.0, 3.0)),
    ("compass deviation (1β) in the headings", "°", compass, (1.0, 3.0, 8.0)),
    ("heading read with random error", "° 1σ", heading_jitter, (1.0, 3.0, 8.0)),
    ("crowned road: ± cross slope per stop", "°", crowned_road, (0.2, 0.5, 1.5)),
    ("vibration rectification at idling stops", "mg", rectification, (1.0, 3.0, 10.0)),
    ("thermal hysteresis of the bias", "mg", hysteresis, (0.5, 1.5, 5.0)),
    # two more, invented after the nine were measured (none a term of the model), so the figure is not fitted to them
    ("heading drift of an integrating gyro", "° at the end", heading_drift, (1.0, 3.0, 8.0)),
    ("bias step at a restart mid-session", "mg", bias_step, (0.5, 1.5, 5.0)),
    # invented after the step tests were built (a change of the road, not of the sensor)
    ("second bay mid-session: the slope changes", "°", second_bay, (0.2, 0.5, 1.5)),
]
NINE = 9
# On one slope its change of the stops lies 99.7–99.9 % inside the base model's span (docs/effects.md): no residual
# test can see it; the pooled figure is also given without it.
INSIDE_THE_SPAN = ("g-sensitive misalignment",)
LEAVES = "all types but the one inside the model's span"


def session(run: int, rng: np.random.Generator) -> Session:
    """The clean session of one run: the two layouts alternate."""
    if run % 2 == 0:
        beta, slope, noise = np.arange(12) * 30.0, 5.0, 0.001
    else:
        beta, slope, noise = rng.uniform(0.0, 360.0, 24), 3.0, 0.0005
    n = beta.size
    temperature = np.interp(np.arange(n), [0, n // 2, n - 1], [20.0, 35.0, 22.0])
    angles = rng.uniform(-10, 10), rng.uniform(-10, 10), rng.uniform(-180, 180)
    table, truth = simulate_stops(
        *angles, slope_deg=slope, beta_deg=beta, noise_g=noise, temperature_c=temperature, seed=rng
    )
    f_v = specific_force_v(np.radians(slope), np.radians(beta), truth.g_mps2)
    return Session(table, truth, truth.rot_vs.inv().apply(f_v), f_v)


def estimates(cal: Calibration) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Roll, pitch, yaw, slope, their σ as reported (the total) and the statistical part alone (NaN where not
    determined)."""
    est = np.array([cal.roll_deg, cal.pitch_deg, cal.yaw_deg, cal.slope_deg], dtype=float)
    sig = np.array([cal.roll_sigma_deg, cal.pitch_sigma_deg, cal.yaw_sigma_deg, cal.slope_sigma_deg], dtype=float)
    stat = (
        sig if cal.systematic is None else np.array([cal.systematic.statistical[f"{k}_deg"] for k in ESTIMATES], float)
    )
    return est, sig, stat


def beyond(est: FloatArray, ref: FloatArray, sig: FloatArray) -> bool:
    d = est - ref
    d[2] = (d[2] + 180.0) % 360.0 - 180.0
    return bool(np.any(np.abs(d) > 2.0 * sig))


def flagged(cal: Calibration) -> bool:
    return (not cal.confident) or bool(cal.unexplained)


VIEWS = ("total", "statistical")


def main(
    effects: list[tuple[str, str, Effect, tuple[float, ...]]] = EFFECTS,
    pooled: tuple[tuple[str, slice | list[int]], ...] | None = None,
    doc: str | None = __doc__,
) -> None:
    """Run ``effects`` (default: the benchmark's twelve) and print the tables; ``pooled`` the rows summed at the end."""
    if pooled is None:
        leaves = [i for i, (name, *_r) in enumerate(effects) if name not in INSIDE_THE_SPAN]
        pooled = (("the nine original types", slice(0, NINE)), ("all types", slice(None)), (LEAVES, leaves))
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--seed", type=int, default=15)
    ap.add_argument("--markdown", default=None)
    ap.add_argument(
        "--slope-reference-sigma",
        type=float,
        default=None,
        help="give every calibration the session's slope measured apart, to this 1σ in degrees (a slope reference)",
    )
    args = ap.parse_args()
    t0 = time.perf_counter()
    shape = (len(VIEWS), len(effects), 3, args.runs)
    moved, off = np.zeros(shape, bool), np.zeros(shape, bool)
    flag = np.zeros(shape[1:], bool)
    clean_flag, clean_off = np.zeros(args.runs, bool), np.zeros((len(VIEWS), args.runs), bool)
    fired: dict[str, int] = {}
    for r in range(args.runs):
        rng = np.random.default_rng([args.seed, r])
        s = session(r, rng)
        truth = np.array([*s.truth.angles_deg, s.truth.slope_deg])
        options = Options()
        if args.slope_reference_sigma is not None:  # its own generator: the sessions and effects stay the same
            own = np.random.default_rng([args.seed, r, 99])
            options = Options(slope_reference=measured_slope(s, args.slope_reference_sigma, own))
        clean = calibrate(s.table, options)
        ref, *ref_sig = estimates(clean)
        clean_flag[r] = flagged(clean)
        for v in range(len(VIEWS)):
            clean_off[v, r] = beyond(ref, truth, ref_sig[v])
        for i, (_, _, effect, strengths) in enumerate(effects):
            for j, strength in enumerate(strengths):
                cal = calibrate(effect(s, strength, np.random.default_rng([args.seed, r, i, j])), options)
                est, *sig = estimates(cal)
                flag[i, j, r] = flagged(cal)
                for v in range(len(VIEWS)):
                    moved[v, i, j, r], off[v, i, j, r] = beyond(est, ref, sig[v]), beyond(est, truth, sig[v])
                for u in cal.unexplained:
                    fired[u.test] = fired.get(u.test, 0) + 1
    reference = (
        ""
        if args.slope_reference_sigma is None
        else f" Every calibration is given the slope measured apart, ±{args.slope_reference_sigma:g}° (1σ)."
    )
    lines = [
        f"{args.runs} runs per row (the two layouts alternate), seed {args.seed}.{reference} "
        '"Moved": an estimate (roll, pitch, yaw or slope) beyond 2σ of the clean run of the same noise; '
        '"off": beyond 2σ of the truth. σ as the result reports it (the total: statistical ⊕ systematic of the '
        "default sensor class), and in brackets the statistical part alone (`cal.systematic.statistical`). "
        "The flag is the same in both views.",
        "",
        "| effect | strength | moved: total σ [statistical] | flagged when moved: total [statistical] | "
        "off the truth: total [statistical] | flagged when off: total [statistical] | flagged, all runs |",
        "|---|---|---|---|---|---|---|",
    ]
    for i, (name, unit, _, strengths) in enumerate(effects):
        for j, strength in enumerate(strengths):
            m, o, f = moved[:, i, j], off[:, i, j], flag[i, j]
            lines.append(
                f"| {name} | {strength:g} {unit} | {m[0].mean():.0%} [{m[1].mean():.0%}] | {share(f, m[0])} "
                f"[{share(f, m[1])}] | {o[0].mean():.0%} [{o[1].mean():.0%}] | {share(f, o[0])} [{share(f, o[1])}] | "
                f"{f.mean():.0%} |"
            )
    lines.append(
        f"| **no effect** | — | — | — | {clean_off[0].mean():.0%} [{clean_off[1].mean():.0%}] | "
        f"{share(clean_flag, clean_off[0])} [{share(clean_flag, clean_off[1])}] | **{clean_flag.mean():.1%}** |"
    )
    lines += ["", "| effect | flagged when moved beyond 2σ, total σ | the same, statistical σ |", "|---|---|---|"]
    for i, (name, *_rest) in enumerate(effects):
        lines.append(f"| {name} | {share(flag[i], moved[0, i])} | {share(flag[i], moved[1, i])} |")
    for label, sel in pooled:
        pooled = [share(flag[sel], moved[v, sel]) for v in range(len(VIEWS))]
        lines.append(f"| **{label}** | **{pooled[0]}** | **{pooled[1]}** |")
    lines += [
        "",
        f"Clean runs flagged: **{clean_flag.mean():.1%}** of {args.runs}.",
        "",
        "Tests that fired (Holm at 1 % over the family), over all runs with an effect: "
        + ", ".join(f"`{k}` {v}" for k, v in sorted(fired.items(), key=lambda kv: -kv[1]))
        + ".",
    ]
    write(lines, t0, args.markdown)


def share(hit: np.ndarray, among: np.ndarray) -> str:
    """The share of ``hit`` among the runs ``among``, with their count ("—" when there are none)."""
    return f"{hit[among].mean():.0%} of {among.sum()}" if among.any() else "—"


def write(lines: list[str], t0: float, markdown: str | None) -> None:
    """Print the tables with the time they took since ``t0``, and write them to ``markdown`` if given."""
    text = "\n".join(lines) + f"\n\n_{time.perf_counter() - t0:.0f} s._\n"
    print(text)
    if markdown:
        Path(markdown).write_text(text, encoding="utf-8")


if __name__ == "__main__":
    main()
