"""Parked periods in a log: detection, per-stop statistics, and the stop table they make.

A sample is *still* when, over a moving window, every accelerometer axis varies less than a
threshold, the angular rate (when logged) is small and the vehicle speed (when logged) is near
zero. Still runs longer than ``min_duration_s`` after trimming ``trim_s`` of settling at both ends
are stops. Each stop's mean gets an honest covariance: batch means account for correlated
vibration, and a quantised signal that does not dither is given its quantisation floor.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from mountcal.conventions import FloatArray
from mountcal.errors import NotEnoughInformation
from mountcal.io.samples import Channel, Samples

BATCHES = 10  # batch means for the variance of a stop mean
BLOCKS_PER_WINDOW = 40


@dataclass(frozen=True)
class StopDetection:
    """Thresholds of stop detection (defaults work on the CANedge car log in shared/data/real)."""

    window_s: float = 2.0
    max_acc_std_mps2: float = 0.12
    max_acc_std_with_speed_mps2: float = 0.3  # with a speed signal, stillness rests on it; idle vibration is allowed
    max_gyro_rad_s: float = 0.02
    max_speed_mps: float = 0.3
    min_duration_s: float = 8.0
    trim_s: float = 2.0


@dataclass(frozen=True)
class Stop:
    """One parked period: times in s on the log's clock, means in SI units, sensor frame."""

    t_start_s: float
    t_end_s: float
    n: int
    acc_mean_s: FloatArray  # shape (3,)
    acc_cov_mean_s: FloatArray  # shape (3, 3), covariance of the mean
    channels: dict[str, float]  # means of the auxiliary channels over the stop
    heading_std_deg: float | None = None

    @property
    def duration_s(self) -> float:
        return self.t_end_s - self.t_start_s


def still_mask(samples: Samples, cfg: StopDetection) -> np.ndarray:
    """Boolean mask, shape (n,), of the samples that look parked.

    The moving statistics run on short blocks (≈ 1/40 of the window) rather than on every sample:
    stillness over seconds does not need the sample rate's resolution, and an hour at 200 Hz then
    costs a few milliseconds.
    """
    t, acc = samples.t_s, samples.acc_s
    n = len(samples)
    if n < 3:
        return np.zeros(n, dtype=bool)
    rate = 1.0 / float(np.median(np.diff(t)))
    block = max(int(cfg.window_s * rate) // BLOCKS_PER_WINDOW, 1)
    starts = np.arange(0, n, block)
    count = np.diff(np.append(starts, n)).astype(float)[:, None]
    s1 = np.add.reduceat(acc, starts, axis=0)
    s2 = np.add.reduceat(acc * acc, starts, axis=0)
    w = max(round(cfg.window_s * rate / block), 1)
    m1, m2, mc = _moving_mean(s1, w), _moving_mean(s2, w), _moving_mean(count, w)
    std = np.sqrt(np.clip(m2 / mc - (m1 / mc) ** 2, 0.0, None))
    speed = samples.channels.get("speed_mps")
    has_speed = speed is not None and speed.t_s.size > 0
    max_std = cfg.max_acc_std_with_speed_mps2 if has_speed else cfg.max_acc_std_mps2
    still = std.max(axis=1) < max_std
    if samples.gyro_s is not None:
        rate_sum = np.add.reduceat(np.linalg.norm(samples.gyro_s, axis=1), starts)[:, None]
        still &= (_moving_mean(rate_sum, w) / mc)[:, 0] < cfg.max_gyro_rad_s
    if speed is not None and has_speed:
        # a block is still only if the speed is low at both of its ends
        still &= np.abs(_hold(speed, t[starts])) <= cfg.max_speed_mps
        still &= np.abs(_hold(speed, t[np.minimum(starts + block - 1, n - 1)])) <= cfg.max_speed_mps
    return np.repeat(still, count[:, 0].astype(int))


def detect_stops(
    samples: Samples, cfg: StopDetection | None = None, windows: list[tuple[float, float]] | None = None
) -> list[Stop]:
    """The stops of a log, in time order.

    Parameters
    ----------
    samples : Samples
    cfg : StopDetection, optional
    windows : list of (t_start_s, t_end_s), optional
        Restrict each stop to one of these intervals (a protocol sheet); the longest still run
        inside each interval is taken.
    """
    cfg = cfg or StopDetection()
    still = still_mask(samples, cfg)
    runs = _runs(still)
    t = samples.t_s
    if windows is not None:
        chosen = []
        for lo, hi in windows:
            a, b = int(np.searchsorted(t, lo)), int(np.searchsorted(t, hi, side="right"))
            cand = [(a + i, a + j) for i, j in _runs(still[a:b])]
            if cand:
                chosen.append(max(cand, key=lambda r: t[r[1] - 1] - t[r[0]]))
        runs = chosen
    stops = []
    for i0, i1 in runs:
        lo, hi = t[i0] + cfg.trim_s, t[i1 - 1] - cfg.trim_s
        if hi - lo < cfg.min_duration_s:
            continue
        sel = slice(int(np.searchsorted(t, lo)), int(np.searchsorted(t, hi, side="right")))
        stops.append(_stop_stats(samples, sel))
    return stops


def stop_frame(stops: list[Stop], beta_deg: FloatArray | None = None) -> pd.DataFrame:
    """The stop table (the columns :mod:`mountcal.stoptable` reads) of detected stops.

    ``sx, sy, sz`` are written so that ``s²/n`` is the variance of each stop mean.
    """
    if not stops:
        raise NotEnoughInformation("no stops to tabulate")
    acc = np.array([s.acc_mean_s for s in stops])
    n = np.array([s.n for s in stops])
    var = np.array([np.diag(s.acc_cov_mean_s) for s in stops])
    df = pd.DataFrame({"ax": acc[:, 0], "ay": acc[:, 1], "az": acc[:, 2]})
    if beta_deg is not None:
        df.insert(0, "beta_deg", np.asarray(beta_deg) % 360.0)
    df["sx"], df["sy"], df["sz"] = (np.sqrt(var[:, k] * n) for k in range(3))
    df["n"] = n
    df["t_s"] = [s.t_start_s for s in stops]
    df["duration_s"] = [s.duration_s for s in stops]
    for key in ("temperature_c", "lat_deg", "lon_deg", "alt_m", "heading_deg"):
        values = [s.channels.get(key, np.nan) for s in stops]
        if np.any(np.isfinite(values)):
            df[key] = values
    return df


def beta_from_heading(heading_deg: FloatArray, uphill_azimuth_deg: float) -> FloatArray:
    """β (counter-clockwise from uphill) from compass headings (clockwise from north)."""
    return (uphill_azimuth_deg - np.asarray(heading_deg, dtype=float)) % 360.0


def _stop_stats(samples: Samples, sel: slice) -> Stop:
    t, acc = samples.t_s[sel], samples.acc_s[sel]
    n = acc.shape[0]
    mean = acc.mean(axis=0)
    cov = _cov_of_mean(acc)
    channels: dict[str, float] = {}
    heading_std = None
    for key, ch in samples.channels.items():
        inside = (ch.t_s >= t[0]) & (ch.t_s <= t[-1])
        if not inside.any():
            continue
        v = ch.value[inside]
        if key == "heading_deg":
            z = np.exp(1j * np.radians(v)).mean()
            channels[key] = float(np.degrees(np.angle(z)) % 360.0)
            heading_std = abs(float(np.degrees(np.sqrt(max(-2.0 * np.log(min(max(abs(z), 1e-12), 1.0)), 0.0)))))
        else:
            channels[key] = float(np.mean(v))
    return Stop(float(t[0]), float(t[-1]), n, mean, cov, channels, heading_std)


def _cov_of_mean(acc: FloatArray) -> FloatArray:
    """Covariance of the mean of correlated, possibly quantised samples, shape (3, 3)."""
    n = acc.shape[0]
    k = BATCHES if n >= 10 * BATCHES else max(n // 2, 1)
    edges = np.linspace(0, n, k + 1).astype(int)
    batch = np.add.reduceat(acc, edges[:-1], axis=0) / np.diff(edges)[:, None]
    cov = np.cov(batch.T) / k if k > 1 else np.cov(acc.T) / n
    cov = np.atleast_2d(cov)
    # A quantised axis that does not dither averages to a level, not to the truth: σ ≥ q/√12.
    # Logger axes share one resolution, so an axis stuck on a single level borrows the others' q.
    spacing = [np.diff(np.unique(acc[:, j])) for j in range(3)]
    steps = np.concatenate(spacing)
    q_all = float(steps.min()) if steps.size else 0.0
    floor = np.zeros(3)
    for j in range(3):
        q = float(spacing[j].min()) if spacing[j].size else q_all
        if acc[:, j].std() < q:
            floor[j] = q**2 / 12.0
    cov[np.diag_indices(3)] = np.maximum(np.diag(cov), floor)
    sample_floor = np.diag(np.cov(acc.T)) / n  # never claim less than independent samples would
    cov[np.diag_indices(3)] = np.maximum(np.diag(cov), sample_floor)
    return cov


def _moving_mean(x: FloatArray, w: int) -> FloatArray:
    c = np.cumsum(np.concatenate([np.zeros((1, *x.shape[1:])), x]), axis=0)
    m = (c[w:] - c[:-w]) / w
    pad_lo = (w - 1) // 2
    pad_hi = x.shape[0] - m.shape[0] - pad_lo
    return np.concatenate([np.repeat(m[:1], pad_lo, 0), m, np.repeat(m[-1:], pad_hi, 0)])


def _hold(ch: Channel, t: FloatArray) -> FloatArray:
    """The channel's latest value at each time t (its first value before it starts)."""
    idx = np.clip(np.searchsorted(ch.t_s, t, side="right") - 1, 0, ch.t_s.size - 1)
    return ch.value[idx]


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) index pairs of the true runs of a boolean mask."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(), strict=True))


@dataclass(frozen=True)
class StopTableFromLog:
    """The stop table of a log and how its headings were found."""

    frame: pd.DataFrame
    headings: str  # "uphill", "relative" or "none"
    heading_source: str
    unmatched_protocol_rows: int = 0


def read_protocol(path: str) -> pd.DataFrame:
    """A protocol sheet: CSV ``t_start_s, t_end_s, beta_deg`` (times on the log's clock)."""
    from mountcal.errors import InputError
    from mountcal.paths import input_file

    input_file(path, "a protocol sheet CSV")  # not a FIFO or a device: reading ends
    try:
        df = pd.read_csv(path, comment="#", skipinitialspace=True)
    except (OSError, ValueError) as err:
        raise InputError(
            path,
            "a protocol sheet CSV (t_start_s, t_end_s, beta_deg)",
            f"an unreadable file ({err})",
            "Check the path and the format.",
        ) from err
    missing = [c for c in ("t_start_s", "t_end_s", "beta_deg") if c not in df.columns]
    values = None if missing else df[["t_start_s", "t_end_s", "beta_deg"]].apply(pd.to_numeric, errors="coerce")
    if missing or values is None or not np.all(np.isfinite(values.to_numpy())):
        raise InputError(
            path,
            "columns t_start_s, t_end_s, beta_deg with numbers in every row",
            f"missing columns {missing}" if missing else "empty or non-numeric cells",
            "Write one row per stop.",
        )
    return values


def tabulate(
    samples: Samples,
    cfg: StopDetection | None = None,
    protocol: pd.DataFrame | None = None,
    uphill_azimuth_deg: float | None = None,
) -> StopTableFromLog:
    """Detect the stops of a log and attach their headings β.

    β comes from the protocol sheet when given; else from the log's heading channel and the
    slope's uphill azimuth; a heading channel alone gives relative headings; nothing gives none.
    """
    where = samples.source or "log"
    if protocol is not None:
        windows = list(zip(protocol["t_start_s"], protocol["t_end_s"], strict=True))
        stops = detect_stops(samples, cfg, windows=windows)
        kept = [i for i, (lo, hi) in enumerate(windows) if any(lo <= s.t_start_s and s.t_end_s <= hi for s in stops)]
        if not stops:
            raise NotEnoughInformation(
                f"{where}: no parked period found inside any protocol interval. Check that "
                "the sheet's times are on the log's clock, or relax the stop thresholds."
            )
        beta = protocol["beta_deg"].to_numpy()[kept]
        return StopTableFromLog(stop_frame(stops, beta), "uphill", "protocol sheet", len(windows) - len(kept))
    stops = detect_stops(samples, cfg)
    if not stops:
        raise NotEnoughInformation(
            f"{where}: no parked period found (no still run ≥ "
            f"{(cfg or StopDetection()).min_duration_s:g} s). Relax --min-stop-s or the "
            "stillness thresholds, or check that the log holds parked periods."
        )
    heading = np.array([s.channels.get("heading_deg", np.nan) for s in stops])
    if np.all(np.isfinite(heading)):
        if uphill_azimuth_deg is not None:
            return StopTableFromLog(
                stop_frame(stops, beta_from_heading(heading, uphill_azimuth_deg)),
                "uphill",
                f"heading channel with uphill azimuth {uphill_azimuth_deg:g}°",
            )
        return StopTableFromLog(
            stop_frame(stops, beta_from_heading(heading, 0.0)),
            "relative",
            "heading channel without the uphill azimuth (relative)",
        )
    return StopTableFromLog(stop_frame(stops), "none", "none")
