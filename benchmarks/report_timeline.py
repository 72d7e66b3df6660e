"""Cost of the report's log over time against the log's length: the min/max envelope, the figure as
SVG, its size, and whether a one-sample spike survives — beside drawing every sample.

Logs are synthetic arrays (no reader is timed): three accelerometer axes at ``--rate`` Hz with noise
and slow swings, a speed channel at 50 Hz, 12 stops, and one sample of +40 m/s² on x (a pothole) at
a time that is not a multiple of any stride. For each length:

- ``timeline``: :func:`mountcal.outputs.report.timeline.timeline` (the envelope of acc and speed);
- ``figure``: :func:`mountcal.outputs.report.figures.log_over_time` rendered to inline SVG, as the
  report embeds it; its size in bytes;
- ``spike``: whether the drawn envelope holds the spike;
- ``every sample`` (lengths up to ``--baseline-hours`` only): the same axes drawn with
  ``Axes.plot`` of all samples (matplotlib's own path simplification on, as by default), to SVG —
  what the report would cost without the envelope.

Each measurement is the median of ``--runs`` runs in this process. Run from the repository root::

    .venv/bin/python benchmarks/report_timeline.py --hours 0.25 1 5 --runs 3
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable

import numpy as np

from mountcal.io.samples import Channel, Samples
from mountcal.outputs.report import figures
from mountcal.outputs.report.embed import figure_html
from mountcal.outputs.report.timeline import timeline
from mountcal.stops.table import StopTable

SPIKE_MPS2 = 40.0


def log(hours: float, rate_hz: float) -> tuple[Samples, StopTable]:
    n = int(hours * 3600.0 * rate_hz)
    rng = np.random.default_rng(0)
    t = np.arange(n) / rate_hz
    acc = rng.normal(0.0, 0.15, (n, 3)) + np.array([0.3, -0.2, 9.8])
    acc[:, 0] += np.sin(t / 40.0)
    acc[n // 2 + 7, 0] = SPIKE_MPS2
    ts = t[:: max(1, int(rate_hz // 50))]
    speed = Channel(ts, 15.0 * np.abs(np.sin(ts / 300.0)))
    starts = np.linspace(0.05, 0.9, 12) * t[-1]
    table = StopTable(
        acc_s=np.tile([0.3, -0.2, 9.8], (12, 1)), t_s=starts, duration_s=np.full(12, 20.0), source="bench"
    )
    return Samples(t, acc, None, {"speed_mps": speed}, source="bench"), table


def median_s(run: Callable[[], object], runs: int) -> float:
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def every_sample_svg(samples: Samples) -> int:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9.0, 4.2), layout="constrained")
    ax = fig.add_subplot()
    for k in range(3):
        ax.plot(samples.t_s, samples.acc_s[:, k], lw=0.6)
    return len(figure_html(fig, "every sample", "svg", 1))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--hours", type=float, nargs="+", default=[0.25, 1.0, 5.0])
    p.add_argument("--rate", type=float, default=200.0, help="accelerometer rate, Hz")
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--baseline-hours", type=float, default=0.25, help="draw every sample up to this length")
    args = p.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f}; {args.rate:g} Hz; median of {args.runs} runs")
    print("| log | samples | timeline (s) | figure → SVG (s) | SVG bytes | spike drawn | every sample: s, bytes |")
    print("|---|---|---|---|---|---|---|")
    for hours in args.hours:
        samples, table = log(hours, args.rate)
        tl = timeline(samples, table)
        t_build = median_s(lambda s=samples, tb=table: timeline(s, tb), args.runs)
        html = figure_html(figures.log_over_time(tl), "log", "svg", 1)
        t_draw = median_s(lambda tl=tl: figure_html(figures.log_over_time(tl), "log", "svg", 1), args.runs)
        spike = bool(np.nanmax(tl.acc_mps2.high[:, 0]) == SPIKE_MPS2)
        base = "—"
        if hours <= args.baseline_hours:
            start = time.perf_counter()
            size = every_sample_svg(samples)
            base = f"{time.perf_counter() - start:.2f} s, {size:,}"
        print(
            f"| {hours:g} h | {len(samples):,} | {t_build:.3f} | {t_draw:.2f} | {len(html):,} | {spike} | {base} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
