"""Model choice at scale: calibrate time of ``--model auto`` against a fixed model, 10² to 10⁵ stops.

The paper's scenario (docs/conventions.md §3) repeated around the circle until the table holds n stops, with
a 20 mg bias and the temperature logged (a 20 °C ramp, no drift): the loop has to add ``bias``,
then try ``temperature``, ``scale``, ``gravity`` and the outlier test against it and turn them
down. With ``three sites`` the stops also carry a site column (a, b, c in turn, all on the one
slope), which adds the ``site_slope`` and ``surface`` (random road tilt) candidates. The fixed
model is the true one (``rotation,slope,bias``). Times are the best of ``--repeat`` runs of
:func:`mountcal.calibration.fit.calibrate` on one core.

    OMP_NUM_THREADS=1 python benchmarks/model_choice.py --markdown docs/model-choice-results.md
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import numpy as np

from mountcal.calibration.fit import Options, calibrate
from mountcal.core.conventions import G_N
from mountcal.simulate.stops import ZHANG2011, simulate_stops
from mountcal.stops.table import StopTable

FIXED = "rotation,slope,bias"


def table_of(n: int, seed: int, sites: bool = False) -> StopTable:
    rng = np.random.default_rng(seed)
    beta = np.resize(np.asarray(ZHANG2011["beta_deg"], dtype=float), n)
    bias = rng.normal(size=3)
    table, _ = simulate_stops(
        beta_deg=beta,
        bias_mps2=20e-3 * G_N * bias / np.linalg.norm(bias),
        temperature_c=np.linspace(20.0, 40.0, n),
        seed=rng,
    )
    return replace(table, site=np.array(["a", "b", "c"])[np.arange(n) % 3]) if sites else table


def best_time(table: StopTable, model: str, repeat: int) -> tuple[float, tuple[str, ...]]:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        cal = calibrate(table, Options(model=model))
        times.append(time.perf_counter() - t0)
    return min(times), cal.model


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="100,1000,10000,100000", help="comma-separated numbers of stops")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--markdown", default=None)
    args = ap.parse_args()
    lines = [
        f"| stops | table | fixed `{FIXED}` (s) | auto (s) | auto / fixed | model chosen |",
        "|---|---|---|---|---|---|",
    ]
    print("\n".join(lines), flush=True)
    for n in (int(s) for s in args.sizes.split(",")):
        for sites in (False, True):
            table = table_of(n, args.seed, sites)
            fixed, _ = best_time(table, FIXED, args.repeat)
            auto, model = best_time(table, "auto", args.repeat)
            kind = "three sites" if sites else "one place"
            lines.append(f"| {n} | {kind} | {fixed:.3f} | {auto:.3f} | {auto / fixed:.1f} | {', '.join(model)} |")
            print(lines[-1], flush=True)
    if args.markdown:
        with open(args.markdown, "w", encoding="utf-8") as fh:
            fh.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
