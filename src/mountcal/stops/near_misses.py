"""Parked periods that nearly became stops: which threshold failed, by how much, and the option that keeps each.

A driver who parked at a third heading and finds "park at more headings" in the refusal needs to know that the
log holds that stop and what dropped it: the speed crept to 0.42 m/s against a 0.3 m/s limit, or the still run
lasted 6.3 s after trimming against an 8 s minimum. :func:`near_misses` looks at the moving statistics stop
detection already computed, block by block (:mod:`mountcal.stops.detect`): a run of blocks where every criterion
is within ``NEAR`` times its threshold, that holds no stop, is a near miss when one option relaxed within that
factor (or the minimum duration down to ``MIN_KEEP_S``) would keep it; that option, the smallest relaxation that does,
is named. Whole-array work: a sliding maximum per criterion over the windows a stop needs, only inside the
nearly still periods.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from mountcal.core.conventions import FloatArray
from mountcal.core.option_names import option

NEAR = 3.0  # a threshold relaxed by more than this factor is another detector, not a near miss
MIN_KEEP_S = 3.0  # a shorter still run is no stop whatever the minimum duration
MIN_PERIOD_S = 4.0  # a nearly still period shorter than this is a pause, not a parking attempt
MAX_LISTED = 10


@dataclass(frozen=True)
class Criterion:
    """One stillness criterion, per block: the value a block has, and the threshold it must not exceed."""

    name: str  # what it measures, for the reader ("speed", "accelerometer moving std", ...)
    values: FloatArray  # per block
    limit: float
    key: str  # its option (mountcal.core.option_names)
    unit: str


@dataclass(frozen=True)
class NearMiss:
    """A parked period that did not become a stop: when, what failed and by how much, and the option that keeps it."""

    t_start_s: float
    t_end_s: float
    still_s: float  # the longest run passing every threshold inside it, after trimming (0 when none)
    failed: str  # which threshold, and by how much
    keep: str  # the one option (with its value) that keeps it

    def line(self) -> str:
        return (
            f"near miss at {self.t_start_s:.1f}–{self.t_end_s:.1f} s ({self.t_end_s - self.t_start_s:.1f} s nearly "
            f"still): {self.failed}; {self.keep} would keep it"
        )

    def to_dict(self) -> dict[str, float | str]:
        return {
            "t_start_s": self.t_start_s,
            "t_end_s": self.t_end_s,
            "still_s": self.still_s,
            "failed": self.failed,
            "keep": self.keep,
        }


def near_misses(
    t_start: FloatArray,
    t_end: FloatArray,
    criteria: list[Criterion],
    judged: np.ndarray,
    kept: list[tuple[float, float]],
    min_duration_s: float,
    trim_s: float,
) -> list[NearMiss]:
    """The near misses among the blocks (``t_start``/``t_end`` their times), in time order, at most ``MAX_LISTED``.

    ``kept`` are the spans of the stops found: a nearly still run that holds one is no near miss.
    """
    if t_start.size == 0:
        return []
    ok = np.array([c.values <= c.limit for c in criteria]) & judged  # (criteria, blocks)
    near = np.all([c.values <= NEAR * c.limit for c in criteria], axis=0) & judged
    block_s = float(np.median(np.diff(t_start))) if t_start.size > 1 else 0.0  # blocks abut: a block's share of time
    if block_s <= 0:
        return []
    need = max(int(np.ceil((min_duration_s + 2.0 * trim_s) / block_s)), 1)
    out = []
    for a, b in _runs(near):
        lo, hi = float(t_start[a]), float(t_end[b - 1])
        if hi - lo < MIN_PERIOD_S or any(k_lo < hi and lo < k_hi for k_lo, k_hi in kept):
            continue
        values = [c.values[a:b] for c in criteria]
        found = _best_option(ok[:, a:b], criteria, values, need, block_s, min_duration_s, trim_s)
        if found is not None:
            out.append(NearMiss(lo, hi, *found))
    return out[:MAX_LISTED]


def _best_option(
    ok: np.ndarray,
    criteria: list[Criterion],
    values: list[FloatArray],
    need: int,
    block_s: float,
    min_duration_s: float,
    trim_s: float,
) -> tuple[float, str, str] | None:
    """(still_s, failed, keep) of the smallest single relaxation that keeps the period, or None."""
    still = _longest(np.all(ok, axis=0)) * block_s - 2.0 * trim_s
    options: list[tuple[float, str, str]] = []  # (relative relaxation, failed, keep)
    if still >= MIN_KEEP_S:
        value = float(np.floor(still * 10.0) / 10.0)
        failed = (
            f"the still run lasts {value:g} s after trimming {trim_s:g} s at each end, under the "
            f"{option('min_stop')} of {min_duration_s:g} s"
        )
        options.append((min_duration_s / value, failed, option("min_stop", value)))
    if ok.shape[1] >= need:
        for i, c in enumerate(criteria):
            others = np.all(np.delete(ok, i, axis=0), axis=0)
            # the smallest threshold for which some window of `need` blocks passes: the least, over windows whose
            # other criteria pass, of the window's largest value
            window_max = sliding_window_view(values[i], need).max(axis=1)
            valid = sliding_window_view(others, need).all(axis=1)
            if not valid.any():
                continue
            required = float(window_max[valid].min())
            if required <= c.limit or required > NEAR * c.limit:
                continue
            value = float(f"{required * 1.05:.2g}")
            failed = f"the {c.name} reached {required:.3g} {c.unit}, over the {option(c.key)} of {c.limit:.3g} {c.unit}"
            options.append((value / c.limit, failed, option(c.key, value)))
    if not options:
        return None
    options.sort(key=lambda o: o[0])
    keep = options[0][2] + (f" (or {options[1][2]})" if len(options) > 1 else "")
    return max(still, 0.0), options[0][1], keep


def _longest(mask: np.ndarray) -> int:
    runs = _runs(mask)
    return max((b - a for a, b in runs), default=0)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(), strict=True))
