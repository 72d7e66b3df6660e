"""Parked periods in a log: detection, per-stop statistics, and the stop table they make.

A sample is *still* when, over a moving window, every accelerometer axis varies less than a
threshold, the angular rate (when logged) neither changes nor departs from the gyro's own bias,
and the vehicle speed (when logged) is near zero. The thresholds are set from the log itself: the
sensor's rest noise (the quietest windows), its quantisation step (a quantised axis at rest may
toggle between two codes) and the gyro bias (a constant rate is still, a changing one is not);
every one can be given instead. Still runs longer than ``min_duration_s`` after trimming
``trim_s`` of settling at both ends are stops; a run whose heading wanders more than
``max_heading_wander_deg`` is split into pieces that do not (too short a piece is dropped), and
both are counted. Each stop's mean gets an honest covariance: batch means account for correlated
vibration, and quantisation sets a floor that depends on how much the noise dithers it.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from mountcal.core.conventions import FloatArray
from mountcal.core.option_names import option
from mountcal.io.samples import Channel, Samples
from mountcal.io.timestamps import increasing_times, time_ordered
from mountcal.stops.gyro_unit import MIN_REST_S, GyroLook, look, refuse_degrees, tilt_look
from mountcal.stops.near_misses import Criterion, NearMiss, near_misses

BATCHES = 10  # batch means for the variance of a stop mean
BLOCKS_PER_WINDOW = 40
REST_QUANTILE = 2.0  # percent of the windows taken as the sensor at rest
REST_FACTOR = 3.0  # a still window spreads less than this many times the rest noise
ACC_STD_FLOOR = 0.12  # m/s²: without a speed signal, any parked vehicle is at least this still
ACC_STD_FLOOR_WITH_SPEED = 0.3  # with a speed signal stillness rests on it: idle vibration is allowed
GYRO_STD_FLOOR = 0.01  # rad/s (0.57 °/s): a parked vehicle rotates less, a pulling-off one more
GYRO_RATE_FLOOR = 0.02  # rad/s away from the gyro bias
LSB_SAMPLES = 65_536  # samples searched for the quantisation step
MIN_WINDOW_SAMPLES = 5  # fewer samples in a window measure no spread: nothing there is judged still
MAX_WINDOW_SPAN = 2.0  # a window spanning more than this many window lengths holds a gap in time


@dataclass(frozen=True)
class StopDetection:
    """Thresholds of stop detection; ``None`` means "set from the log" (see :class:`Thresholds`)."""

    window_s: float = 2.0
    max_acc_std_mps2: float | None = None  # moving std of each accelerometer axis
    max_gyro_std_rad_s: float | None = None  # moving std of each gyro axis: a changing rate is not still
    max_gyro_rad_s: float | None = None  # |moving mean rate − gyro bias|: a turn is not still
    max_speed_mps: float = 0.3
    min_duration_s: float = 8.0
    trim_s: float = 2.0
    max_heading_wander_deg: float = 10.0  # span of the (window-smoothed) heading within one stop


@dataclass(frozen=True)
class Thresholds:
    """The stillness thresholds used, with the sensor properties measured to set them."""

    acc_std_mps2: float
    acc_rest_noise_mps2: FloatArray  # shape (3,), moving std in the quietest windows
    acc_lsb_mps2: FloatArray  # shape (3,), quantisation step (0 when not quantised)
    gyro_std_rad_s: float | None = None
    gyro_rate_rad_s: float | None = None
    gyro_bias_rad_s: FloatArray | None = None
    gyro_rest_noise_rad_s: FloatArray | None = None
    gyro_lsb_rad_s: FloatArray | None = None
    speed_mps: float | None = None

    def lines(self) -> list[str]:
        """What the detector used, for the user (with the option that changes each)."""

        def vec(x: FloatArray, scale: float = 1.0) -> str:
            return "(" + ", ".join(f"{v * scale:.3g}" for v in x) + ")"

        out = [
            f"stillness: accelerometer moving std < {self.acc_std_mps2:.3g} m/s² ({option('max_acc_std')}; rest noise "
            f"{vec(self.acc_rest_noise_mps2)}, quantisation {vec(self.acc_lsb_mps2)} m/s²)"
        ]
        if self.gyro_std_rad_s is not None and self.gyro_rate_rad_s is not None and self.gyro_bias_rad_s is not None:
            assert self.gyro_rest_noise_rad_s is not None and self.gyro_lsb_rad_s is not None
            deg = float(np.degrees(1.0))
            out.append(
                f"stillness: gyro moving std < {self.gyro_std_rad_s:.3g} rad/s ({option('max_gyro_std')}) and rate "
                f"within {self.gyro_rate_rad_s:.3g} rad/s of the gyro bias {vec(self.gyro_bias_rad_s, deg)} °/s "
                f"({option('max_gyro_rate')}; rest noise {vec(self.gyro_rest_noise_rad_s, deg)} °/s, "
                f"quantisation {vec(self.gyro_lsb_rad_s, deg)} °/s)"
            )
        if self.speed_mps is not None:
            out.append(f"stillness: speed ≤ {self.speed_mps:g} m/s ({option('max_speed')})")
        return out


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
    acc_std_s: FloatArray = field(default_factory=lambda: np.full(3, np.nan))  # sample std of each axis

    @property
    def duration_s(self) -> float:
        return self.t_end_s - self.t_start_s


@dataclass(frozen=True)
class StillPeriod:
    """A still period that detection did not keep as a stop, and why (times on the log's clock, s)."""

    t_start_s: float
    t_end_s: float
    why: str


@dataclass(frozen=True)
class StopSearch:
    """The stops of a log, the thresholds that found them, what was changed or left out, and the parked periods
    that nearly became stops (:mod:`mountcal.stops.near_misses`)."""

    stops: list[Stop]
    thresholds: Thresholds
    counts: dict[str, int] = field(default_factory=dict)
    dropped: tuple[StillPeriod, ...] = ()
    near_misses: tuple[NearMiss, ...] = ()
    gyro: GyroLook | None = None  # what the gyro read where the accelerometer found the sensor still

    def gyro_rejection(self, source: str, channels: tuple[str, ...] = ()) -> str:
        """A sentence for a refusal of too few stops: the still periods the gyro rejected (empty when none)."""
        return "" if self.gyro is None else self.gyro.rejection(source, channels)

    def lines(self) -> list[str]:
        return self.thresholds.lines() + [f"{k}: {v}" for k, v in self.counts.items()] + self.near_miss_lines()

    def near_miss_lines(self) -> list[str]:
        return [m.line() for m in self.near_misses]


@dataclass(frozen=True)
class Blocks:
    """The moving statistics per block: its times, each criterion's values and threshold, and which are judged."""

    t_start_s: FloatArray
    t_end_s: FloatArray
    criteria: list[Criterion]
    judged: np.ndarray


def still_mask(samples: Samples, cfg: StopDetection) -> np.ndarray:
    """Boolean mask, shape (n,), of the samples that look parked (equal stamps allowed; in time order)."""
    gyro_lsb = None if samples.gyro_s is None else _lsb(samples.gyro_s)
    return _stillness(samples, cfg, _lsb(samples.acc_s), gyro_lsb)[0]


def _stillness(
    samples: Samples, cfg: StopDetection, acc_lsb: FloatArray, gyro_lsb: FloatArray | None
) -> tuple[np.ndarray, Thresholds, int, Blocks | None]:
    """The still mask, the thresholds it used, how many samples could not be judged (their
    window holds too few samples, or a gap in time: see :func:`_judged_blocks`), and the blocks' criteria.

    The moving statistics run on short blocks (≈ 1/40 of the window) rather than on every sample:
    stillness over seconds does not need the sample rate's resolution, and an hour at 200 Hz then
    costs a few milliseconds.
    """
    t, acc = samples.t_s, samples.acc_s
    n = len(samples)
    steps = np.diff(t)
    steps = steps[steps > 0]  # stamps in pairs have a median step of 0; find_stops merges them first
    if n < MIN_WINDOW_SAMPLES or steps.size == 0:
        return np.zeros(n, dtype=bool), Thresholds(cfg.max_acc_std_mps2 or ACC_STD_FLOOR, np.zeros(3), acc_lsb), n, None
    rate = 1.0 / float(np.median(steps))
    block = max(int(cfg.window_s * rate) // BLOCKS_PER_WINDOW, 1)
    starts = np.arange(0, n, block)
    count = np.diff(np.append(starts, n)).astype(float)[:, None]
    w = min(max(round(cfg.window_s * rate / block), 1), starts.size)  # a log shorter than the window: one window
    mc = moving_mean(count, w)
    judged = _judged_blocks(t, starts, count[:, 0], w, cfg.window_s)

    def moving(x: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Moving mean and std of each column over the window, per block."""
        m1 = moving_mean(np.add.reduceat(x, starts, axis=0), w) / mc
        m2 = moving_mean(np.add.reduceat(x * x, starts, axis=0), w) / mc
        var = m2 - m1**2
        return m1, np.sqrt(np.where(var > 1e-12 * (1.0 + m1**2), var, 0.0))  # below: rounding of m2 − m1²

    _, std = moving(acc)
    speed = samples.channels.get("speed_mps")
    has_speed = speed is not None and speed.t_s.size > 0
    measured = judged if judged.any() else slice(None)  # the rest noise of windows that measure one
    acc_rest = np.percentile(std[measured], REST_QUANTILE, axis=0)
    max_std = cfg.max_acc_std_mps2
    if max_std is None:  # above the rest noise, and above a quantised axis toggling between two codes (std ≤ q/2)
        floor = ACC_STD_FLOOR_WITH_SPEED if has_speed else ACC_STD_FLOOR
        max_std = max(floor, REST_FACTOR * float(acc_rest.max()), float(acc_lsb.max()))
    still = (std.max(axis=1) < max_std) & judged
    ends = np.minimum(starts + block - 1, n - 1)
    criteria = [Criterion("accelerometer moving std", std.max(axis=1), max_std, "max_acc_std", "m/s²")]
    if speed is not None and has_speed:
        # a block is still only if the speed is low at both of its ends
        v = np.maximum(np.abs(_hold(speed, t[starts])), np.abs(_hold(speed, t[ends])))
        still &= v <= cfg.max_speed_mps
        criteria.append(Criterion("speed", v, cfg.max_speed_mps, "max_speed", "m/s"))
    found = Thresholds(max_std, acc_rest, acc_lsb, speed_mps=cfg.max_speed_mps if has_speed else None)
    if samples.gyro_s is not None:
        g_mean, g_std = moving(samples.gyro_s)
        g_lsb = np.zeros(3) if gyro_lsb is None else gyro_lsb
        g_rest = np.percentile(g_std[measured], REST_QUANTILE, axis=0)
        max_g_std = cfg.max_gyro_std_rad_s
        if max_g_std is None:
            max_g_std = max(GYRO_STD_FLOOR, REST_FACTOR * float(g_rest.max()), float(g_lsb.max()))
        max_rate = cfg.max_gyro_rad_s
        if max_rate is None:
            max_rate = max(GYRO_RATE_FLOOR, 2.0 * float(g_lsb.max()))
        quiet = still & (g_std.max(axis=1) < max_g_std)
        bias = _gyro_bias(g_mean[quiet] if quiet.sum() >= w else g_mean, max_rate)
        rate = np.linalg.norm(g_mean - bias, axis=1)
        still &= (g_std.max(axis=1) < max_g_std) & (rate < max_rate)
        found = Thresholds(max_std, acc_rest, acc_lsb, max_g_std, max_rate, bias, g_rest, g_lsb, found.speed_mps)
        criteria += [
            Criterion("gyro moving std", g_std.max(axis=1), max_g_std, "max_gyro_std", "rad/s"),
            Criterion("angular rate off the gyro bias", rate, max_rate, "max_gyro_rate", "rad/s"),
        ]
    blocks = Blocks(t[starts], t[ends], criteria, judged)
    return np.repeat(still, count[:, 0].astype(int)), found, int(count[~judged, 0].sum()), blocks


def _judged_blocks(t: FloatArray, starts: np.ndarray, count: FloatArray, w: int, window_s: float) -> np.ndarray:
    """Blocks whose moving window (the ``w`` blocks :func:`moving_mean` averages for it) holds at
    least MIN_WINDOW_SAMPLES samples within MAX_WINDOW_SPAN window lengths of time.

    A window of one or two samples has no spread, and one across a gap in the log (a dropout, or
    damaged times) mixes moments the log does not connect: neither says the vehicle was still.
    """
    nb = starts.size
    first = np.clip(np.arange(nb) - (w - 1) // 2, 0, nb - w)
    last_block = first + w - 1
    last_sample = np.append(starts[1:], t.size) - 1
    span = t[last_sample[last_block]] - t[starts[first]]
    total = np.concatenate([[0.0], np.cumsum(count)])
    held = total[last_block + 1] - total[first]
    return np.asarray((held >= MIN_WINDOW_SAMPLES) & (span <= MAX_WINDOW_SPAN * window_s), dtype=np.bool_)


def _gyro_bias(rates: FloatArray, radius: float) -> FloatArray:
    """The gyro's rate at rest: the median of the densest cluster of quiet rates (rad/s).

    Quiet blocks (accelerometer and gyro steady) are stops, but also cruising straight and steady
    turns, whose rates differ. A rate shared by most quiet time is the bias; a plain median would
    take a turn's rate when turning fills more than half the quiet time.
    """
    _, inverse, counts = np.unique(np.floor(rates / radius), axis=0, return_inverse=True, return_counts=True)
    densest = rates[inverse.ravel() == int(np.argmax(counts))]
    centre = np.median(densest, axis=0)
    near = rates[np.linalg.norm(rates - centre, axis=1) < radius]
    return np.asarray(np.median(near, axis=0) if near.size else centre, dtype=np.float64)


def detect_stops(
    samples: Samples, cfg: StopDetection | None = None, windows: list[tuple[float, float]] | None = None
) -> list[Stop]:
    """The stops of a log, in time order (see :func:`find_stops` for the thresholds and counts)."""
    return find_stops(samples, cfg, windows).stops


def find_stops(
    samples: Samples, cfg: StopDetection | None = None, windows: list[tuple[float, float]] | None = None
) -> StopSearch:
    """The stops of a log, in time order, with the thresholds used and what was changed or dropped.

    Parameters
    ----------
    samples : Samples
        Times need not be strictly increasing: equal stamps are merged and counted.
    cfg : StopDetection, optional
    windows : list of (t_start_s, t_end_s), optional
        Restrict each stop to one of these intervals (a protocol sheet); the longest still run
        inside each interval is taken.
    """
    cfg = cfg or StopDetection()
    # the quantisation of the samples as logged: merging equal stamps averages codes into half steps
    acc_lsb = _lsb(samples.acc_s)
    gyro_lsb = None if samples.gyro_s is None else _lsb(samples.gyro_s)
    before = dict(samples.dropped)
    logged = time_ordered(samples)  # every sample as logged, for the stops' statistics
    samples = increasing_times(logged)  # equal stamps merged, for the moving windows and the runs
    counts = {k: v - before.get(k, 0) for k, v in samples.dropped.items() if v != before.get(k, 0)}
    still, thresholds, unjudged, blocks = _stillness(samples, cfg, acc_lsb, gyro_lsb)
    gyro = _gyro_look(blocks, cfg, samples)
    refuse_degrees(gyro, samples.source or "log", tuple(samples.channels))  # deg/s read as rad/s: the true reason
    if unjudged:
        counts[
            f"samples whose {cfg.window_s:g} s window holds fewer than {MIN_WINDOW_SAMPLES} samples or a gap "
            f"(spans over {MAX_WINDOW_SPAN * cfg.window_s:g} s): not judged still ({option('still_window')})"
        ] = unjudged
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
    heading = samples.channels.get("heading_deg")
    lsb = thresholds.acc_lsb_mps2
    stops = []
    dropped: list[StillPeriod] = []
    split = pieces_dropped = too_few = 0
    for i0, i1 in runs:
        pieces = [(float(t[i0]), float(t[i1 - 1]))]
        if heading is not None and heading.t_s.size:
            pieces = _steady_heading(heading, pieces[0], cfg.max_heading_wander_deg, cfg.window_s)
        found = []
        for p_lo, p_hi in pieces:
            lo, hi = p_lo + cfg.trim_s, p_hi - cfg.trim_s
            if hi - lo < cfg.min_duration_s:
                why = f"{max(hi - lo, 0.0):.3g} s once trimmed, under {option('min_stop')} {cfg.min_duration_s:g} s"
                dropped.append(StillPeriod(p_lo, p_hi, why))
                continue
            sel = slice(int(np.searchsorted(logged.t_s, lo)), int(np.searchsorted(logged.t_s, hi, side="right")))
            if sel.stop - sel.start < MIN_WINDOW_SAMPLES:  # sparse samples: the trimmed span holds too few
                too_few += 1
                dropped.append(StillPeriod(p_lo, p_hi, f"fewer than {MIN_WINDOW_SAMPLES} samples once trimmed"))
                continue
            found.append(_stop_stats(logged, sel, lsb))
        if windows is not None and len(found) > 1:  # one stop per protocol row: its longest steady piece
            longest = max(found, key=lambda s: s.duration_s)
            why = "not the longest steady piece in its protocol row"
            dropped += [StillPeriod(s.t_start_s, s.t_end_s, why) for s in found if s is not longest]
            found = [longest]
        stops += found
        if len(pieces) > 1:
            split += 1
            pieces_dropped += len(pieces) - len(found)
    if split:
        counts[
            f"still periods whose heading wandered > {cfg.max_heading_wander_deg:g}° "
            f"(split; {option('max_heading_wander')})"
        ] = split
        counts["pieces of those not kept as a stop (too short, or not the longest in a protocol row)"] = pieces_dropped
    if too_few:
        counts[f"still periods with fewer than {MIN_WINDOW_SAMPLES} samples once trimmed (not kept)"] = too_few
    missed: list[NearMiss] = []
    if blocks is not None and windows is None:  # with a protocol sheet the rows say where the stops are
        kept = [(stop.t_start_s - cfg.trim_s, stop.t_end_s + cfg.trim_s) for stop in stops]
        missed = near_misses(
            blocks.t_start_s, blocks.t_end_s, blocks.criteria, blocks.judged, kept, cfg.min_duration_s, cfg.trim_s
        )
    return StopSearch(stops, thresholds, counts, tuple(dropped), tuple(missed), gyro)


def _gyro_look(blocks: Blocks | None, cfg: StopDetection, samples: Samples) -> GyroLook | None:
    """What the gyro read (:func:`mountcal.stops.gyro_unit.look`), with the tilt it predicts against the
    accelerometer's (time-ordered ``samples``)."""
    if blocks is None or samples.gyro_s is None:
        return None
    need_s = cfg.min_duration_s + 2.0 * cfg.trim_s
    found = look(blocks.t_start_s, blocks.t_end_s, blocks.criteria, blocks.judged, need_s)
    if found is None:
        return None
    gyro_deg, acc_deg, pairs = tilt_look(samples.t_s, samples.acc_s, samples.gyro_s)
    return replace(found, tilt_gyro_deg=gyro_deg, tilt_acc_deg=acc_deg, tilt_pairs=pairs)


def checked_gyro(samples: Samples, cfg: StopDetection | None = None) -> FloatArray | None:
    """The samples' gyro, refused when logged in deg/s where its format or columns state rad/s
    (:mod:`mountcal.stops.gyro_unit`): what every stop search does, for a drive, which looks for no stops."""
    if samples.gyro_s is not None and len(samples) > 0:
        _checked_look(samples, cfg or StopDetection())
    return samples.gyro_s


def _checked_look(samples: Samples, cfg: StopDetection) -> GyroLook | None:
    assert samples.gyro_s is not None
    merged = increasing_times(time_ordered(samples))
    _, _, _, blocks = _stillness(merged, cfg, _lsb(samples.acc_s), _lsb(samples.gyro_s))
    found = _gyro_look(blocks, cfg, merged)
    refuse_degrees(found, samples.source or "log", tuple(samples.channels))
    return found


GYRO_LOOK_S = 900.0  # of a stream, the time looked at for the gyro's unit at most (a still period shows it)


@dataclass
class GyroUnitWatch:
    """:func:`checked_gyro` over a stream's chunks (``mountcal rotate``): a chunk is refused where it shows deg/s,
    until one holds a still period long enough to show rad/s or :data:`GYRO_LOOK_S` of the log were looked at —
    a deg/s gyro shows at its first still period, so a long log pays for one look, not one per chunk."""

    cfg: StopDetection = field(default_factory=StopDetection)
    looked_s: float = 0.0
    settled: bool = False

    @property
    def done(self) -> bool:
        return self.settled or self.looked_s >= GYRO_LOOK_S

    def look(self, samples: Samples) -> None:
        if self.done or len(samples) == 0:
            return
        if samples.gyro_s is None:
            self.settled = True
            return
        found = _checked_look(samples, self.cfg)
        self.settled = found is None or found.rest_s >= MIN_REST_S
        self.looked_s += float(samples.t_s[-1] - samples.t_s[0])


def _steady_heading(
    heading: Channel, span: tuple[float, float], limit_deg: float, window_s: float
) -> list[tuple[float, float]]:
    """``span`` cut into pieces over which the heading (smoothed over the window) stays within the limit."""
    lo, hi = span
    inside = (heading.t_s >= lo) & (heading.t_s <= hi)
    if np.count_nonzero(inside) < 2:
        return [span]
    ht = heading.t_s[inside]
    k = max(1, min(round(window_s / float(np.median(np.diff(ht)))), ht.size))
    h = moving_mean(np.degrees(np.unwrap(np.radians(heading.value[inside]))), k)
    if np.ptp(h) <= limit_deg:
        return [span]
    pieces = []
    a = 0
    while a < h.size:
        grow = np.maximum.accumulate(h[a:]) - np.minimum.accumulate(h[a:])
        over = np.flatnonzero(grow > limit_deg)
        b = a + int(over[0]) if over.size else h.size
        pieces.append((lo if a == 0 else float(ht[a]), hi if b == h.size else float(ht[b - 1])))
        a = b
    return pieces


def _stop_stats(samples: Samples, sel: slice, lsb: FloatArray) -> Stop:
    t, acc = samples.t_s[sel], samples.acc_s[sel]
    n = acc.shape[0]
    mean = acc.mean(axis=0)
    cov = _cov_of_mean(acc, lsb)
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
    std = acc.std(axis=0, ddof=1) if n > 1 else np.zeros(3)
    return Stop(float(t[0]), float(t[-1]), n, mean, cov, channels, heading_std, std)


def _lsb(x: FloatArray) -> FloatArray:
    """Quantisation step of each column (the smallest step between its values; 0 when it is not quantised).

    An axis that never changes borrows the others' step: a logger's axes share one resolution.
    """
    x = x[:: max(1, x.shape[0] // LSB_SAMPLES)]  # adjacent codes show up in any long stretch; sorting all is slow
    steps = np.zeros(x.shape[1])
    for j in range(x.shape[1]):
        d = np.diff(np.unique(x[:, j]))
        d = d[d > 1e-9 * max(1.0, float(np.abs(x[:, j]).max(initial=0.0)))]  # float noise is not a step
        steps[j] = d.min() if d.size else np.nan
    if np.all(np.isnan(steps)):
        return np.zeros(x.shape[1])
    return np.where(np.isnan(steps), np.nanmin(steps), steps)


def _cov_of_mean(acc: FloatArray, lsb: FloatArray) -> FloatArray:
    """Covariance of the mean of correlated, possibly quantised samples, shape (3, 3).

    Quantisation with step q biases a mean by up to q/2 when the noise does not dither it (a
    constant signal on one code says only that the truth lies within ±q/2: σ = q/√12), and by a
    vanishing amount when it does. Samples on two codes (a fraction p on the rarer one) leave a
    small noise unknown: the mean is then off by at most q·(½ − p), so the floor is
    ``min(q/√12, q·(½ − p))``. Samples on three or more codes are dithered by a noise σ (estimated
    as ``s² − q²/12``), and the mean of a quantised Gaussian is off by a term ∝ exp(−2π²σ²/q²)
    (Widrow's quantisation theorem): the floor is ``q/√12 · exp(−2π²σ²/q²)``.
    """
    n = acc.shape[0]
    k = BATCHES if n >= 10 * BATCHES else max(n // 2, 1)
    edges = np.linspace(0, n, k + 1).astype(int)
    batch = np.add.reduceat(acc, edges[:-1], axis=0) / np.diff(edges)[:, None]
    cov = np.cov(batch.T) / k if k > 1 else np.cov(acc.T) / n
    cov = np.atleast_2d(cov)
    if cov.shape != (3, 3):  # a single sample
        cov = np.zeros((3, 3))
    sample_var = acc.var(axis=0, ddof=1) if n > 1 else np.zeros(3)
    floor = np.zeros(3)
    for j, q in enumerate(np.asarray(lsb, dtype=float)):
        if q <= 0.1 * np.sqrt(sample_var[j]):  # many codes, dithered: the floor is exp(−400π²)-small
            continue
        _, counts = np.unique(np.round(acc[:, j] / q), return_counts=True)
        if counts.size <= 2:
            rare = counts.min() / n if counts.size == 2 else 0.0
            floor[j] = min(q / np.sqrt(12.0), q * (0.5 - rare)) ** 2
        else:
            noise_var = max(sample_var[j] - q**2 / 12.0, 0.0)
            floor[j] = q**2 / 12.0 * np.exp(-4.0 * np.pi**2 * noise_var / q**2)
    cov[np.diag_indices(3)] = np.maximum(np.diag(cov), floor)
    cov[np.diag_indices(3)] = np.maximum(np.diag(cov), sample_var / n)  # never less than independent samples
    return cov


def moving_mean(x: FloatArray, w: int) -> FloatArray:
    """Centred moving mean over ``w`` rows, the edges held; ``w`` is at most the number of rows."""
    w = max(min(w, x.shape[0]), 1)
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
