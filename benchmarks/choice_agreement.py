"""The model chosen in every seeded run on tables larger than the effects benchmark's 12 stops.

Scenarios at 48 and 200 stops (the circle of 12 headings repeated): no effect; a 20 mg and a 2 mg
bias; a 0.2 mg/°C drift over 20 °C with a 5 mg bias; two stops disturbed by 20 and 10 mg; and
stops at three sites (12, 48 and 200 stops) each on a road tilted by 0, 0.1° or 0.3° (1σ), where
``site_slope`` and ``surface`` are candidates. Writes the path of every run, for
``compare_choices.py`` between two versions of the library:

    PYTHONPATH=/tmp/mountcal-old/src python benchmarks/choice_agreement.py old.json
    PYTHONPATH=src python benchmarks/choice_agreement.py new.json
    python benchmarks/compare_choices.py old.json new.json
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation

from mountcal.calibration.fit import calibrate
from mountcal.core.conventions import G_N
from mountcal.simulate.stops import random_bias, simulate_stops
from mountcal.stops.table import StopTable

MG = 1e-3 * G_N


def effect_table(name: str, n: int, rng: np.random.Generator) -> StopTable:
    kw: dict[str, object] = {}
    if name.startswith("bias"):
        kw["bias_mps2"] = random_bias((20 if name == "bias 20 mg" else 2) * MG, rng)
    if name == "temperature":
        kw.update(
            temperature_c=np.linspace(20, 40, n),
            temp_coeff_mps2_per_c=random_bias(0.2 * MG, rng),
            bias_mps2=random_bias(5 * MG, rng),
        )
    if name == "two disturbed stops":
        d = np.zeros((n, 3))
        d[rng.integers(n)] = random_bias(20 * MG, rng)
        d[rng.integers(n)] = random_bias(10 * MG, rng)
        kw["disturbance_mps2"] = d
    beta = np.resize(np.arange(0.0, 360.0, 30.0), n)
    return simulate_stops(beta_deg=beta, seed=rng, **kw)[0]  # type: ignore[arg-type]


def site_table(tilt_deg: float, n: int, rng: np.random.Generator) -> StopTable:
    table, truth = simulate_stops(beta_deg=np.resize(np.arange(0.0, 360.0, 30.0), n), seed=rng)
    if tilt_deg:
        tilt = Rotation.from_rotvec(np.column_stack([np.radians(rng.normal(0, tilt_deg, (n, 2))), np.zeros(n)]))
        table = replace(table, acc_s=truth.rot_vs.inv().apply(tilt.apply(truth.rot_vs.apply(table.acc_s))))
    return replace(table, site=np.array(["a", "b", "c"])[np.arange(n) % 3])


def path(table: StopTable) -> dict[str, object]:
    cal = calibrate(table)
    return {
        "model": list(cal.model),
        "steps": [(s.added, list(s.excluded_stops)) for s in cal.model_steps],
        "reasons": [s.reason for s in cal.model_steps],
        "angles_deg": [cal.roll_deg, cal.pitch_deg, cal.yaw_deg],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("output")
    args = ap.parse_args()
    out: dict[str, list[dict[str, object]]] = {}
    for n, runs in ((48, 40), (200, 10)):
        for name in ("no effect", "bias 20 mg", "bias 2 mg", "temperature", "two disturbed stops"):
            rng = np.random.default_rng(n + len(name))
            out[f"{n} stops, {name}"] = [path(effect_table(name, n, rng)) for _ in range(runs)]
            print(f"{n} stops, {name}", flush=True)
    for n, runs in ((12, 30), (48, 15), (200, 3)):
        for tilt in (0.0, 0.1, 0.3):
            rng = np.random.default_rng(n * 7 + int(tilt * 10))
            out[f"{n} stops at three sites, road tilt {tilt}°"] = [path(site_table(tilt, n, rng)) for _ in range(runs)]
            print(f"{n} stops at three sites, road tilt {tilt}°", flush=True)
    with open(args.output, "w", encoding="utf-8") as fh:
        json.dump(out, fh, indent=1)


if __name__ == "__main__":
    main()
