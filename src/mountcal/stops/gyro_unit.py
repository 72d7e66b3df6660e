"""The gyro's unit, checked by what it reads while the accelerometer and the speed say how the sensor moves.

Every format states angular rates in rad/s (sensor_msgs/Imu, mountcal's table columns ``gx, gy, gz``), or says
its unit (a column map's ``gx=COL:deg/s``, a CAN mapping's ``[units] gyro``, a DBC's unit). A driver or a DBC
that gets it wrong hands over deg/s: numbers 57.3 times too large. The stops still come out (the accelerometer
makes them) but the gyro's stillness test rejects many, and a refusal would blame the parking. Two signs
tell deg/s apart from rad/s, measured on the blocks stop detection already computed (:mod:`mountcal.stops.detect`):

- **At rest.** Where the accelerometer is still (its moving std under the stillness threshold, the speed near
  zero) for :data:`MIN_REST_S` or more, a MEMS gyro in rad/s spreads about 0.001–0.01 rad/s per sample at
  100–200 Hz; engine idle shakes it less than it shakes the accelerometer in m/s² (a rotational vibration of
  0.05 rad/s at 25 Hz moves a point 0.5 m off its axis by ~4 m/s²). The project's real recordings spread
  0.001–0.02 rad/s at rest, 0.03–0.46 times the accelerometer's spread in m/s². A spread beyond
  :data:`REST_SPREAD_MAX_RAD_S` (5 times the noisiest MEMS) that also exceeds the accelerometer's
  (:data:`REST_RATIO_MIN`) is no gyro at rest in rad/s, and divided by 57.3 it is an ordinary one: deg/s.
- **Driving.** At :data:`ROAD_SPEED_MPS` or more, a road vehicle yaws below ~1 rad/s (a car's tightest turn at
  walking pace); a rate above :data:`ROAD_RATE_MAX_RAD_S` held for :data:`MIN_FAST_S` would need a turn of
  radius under 1 m. Hand-rotated sensors (a triad session) turn faster, but carry no speed, so they are not
  judged by this sign.
- **Tilting** (any motion, with or without a speed). Between consecutive 1-s means, the gyro's rate about the
  horizontal axes (its bias, the median, taken out) turns gravity by an angle the accelerometer sees as the change
  of its direction, plus what linear accelerations add: on the real recordings the gyro predicts 0.26–0.36 times
  the change the accelerometer sees (RMS) in vehicles, 0.83 times in a session turned by hand. Read in deg/s as
  rad/s it predicts 15–47 times it. A prediction over
  :data:`TILT_RATIO_MIN` times the accelerometer's, and over :data:`TILT_MIN_DEG` per second (at rest a gyro's
  noise predicts a tenth of a degree, which an accelerometer's quiet means can make a large ratio of), that is
  ordinary divided by 57.3, is deg/s — on a highway minute too, where neither sign above is seen.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mountcal.core.conventions import FloatArray
from mountcal.core.errors import InputError
from mountcal.core.option_names import option
from mountcal.io.table.layout import CHANNELS
from mountcal.stops.near_misses import Criterion

DEG_PER_RAD = math.degrees(1.0)  # 57.3: the factor a deg/s gyro read as rad/s is too large by
REST_SPREAD_MAX_RAD_S = 0.05  # a gyro at rest spreads less (MEMS: 0.001–0.01 rad/s per sample at 100–200 Hz)
REST_RATIO_MIN = 1.0  # at rest a gyro in rad/s spreads less than the accelerometer in m/s² (real logs: ≤ 0.46)
ORDINARY_REST_RAD_S = 0.01  # the noisiest MEMS gyro at rest: a larger spread makes deg/s a suspicion
MIN_REST_S = 10.0  # still time the rest sign needs (a stop's worth)
ROAD_SPEED_MPS = 3.0
ROAD_RATE_MAX_RAD_S = 3.0  # no road vehicle yaws this fast at speed (a car: below ~1 rad/s)
ORDINARY_ROAD_RAD_S = 1.5  # the same rate divided by 57.3 must be one a vehicle has
MIN_FAST_S = 2.0
ACC_STILL_MAX_MPS2 = 0.3  # the rest sign's accelerometer stillness, however far a user relaxed --max-acc-std
TILT_BLOCK_S = 1.0  # the means whose change of direction the tilt sign compares
TILT_MIN_PAIRS = 20  # consecutive means it needs
TILT_RATIO_MIN = 3.0  # the gyro's predicted tilt change over the accelerometer's (rad/s: 0.26–0.83; deg/s: 15–47)
TILT_MIN_DEG = 5.0  # RMS predicted tilt change per mean: no vehicle's gyro shows it while its gravity stays put


@dataclass(frozen=True)
class GyroLook:
    """What the gyro read where the accelerometer and the speed say how the sensor moved (rates as read, "rad/s")."""

    rest_s: float  # time the accelerometer (and the speed) found still
    spread: float  # median over that time of the gyro's moving std (largest axis)
    acc_spread: float  # the same of the accelerometer's, m/s²
    fast_s: float  # time at ≥ ROAD_SPEED_MPS with a rate beyond ROAD_RATE_MAX_RAD_S
    fast_rate: float  # median rate over that time
    periods: int  # still periods (accelerometer and speed) long enough for a stop
    rejected: int  # of those, the ones the gyro's thresholds left without a stop
    gyro_std_limit: float
    gyro_rate_limit: float
    tilt_gyro_deg: float = 0.0  # RMS tilt change between consecutive 1-s means the gyro predicts (rates as read)
    tilt_acc_deg: float = 0.0  # RMS change of the accelerometer's direction between the same means
    tilt_pairs: int = 0  # consecutive means compared

    @property
    def at_rest(self) -> bool:
        """The rest sign: a spread no gyro at rest has in rad/s, larger than the accelerometer's, ordinary in deg/s."""
        return (
            self.rest_s >= MIN_REST_S
            and REST_SPREAD_MAX_RAD_S < self.spread <= REST_SPREAD_MAX_RAD_S * DEG_PER_RAD
            and self.spread >= REST_RATIO_MIN * self.acc_spread
        )

    @property
    def driving(self) -> bool:
        """The driving sign: rates at speed no road vehicle has in rad/s, ordinary in deg/s."""
        return self.fast_s >= MIN_FAST_S and self.fast_rate <= ORDINARY_ROAD_RAD_S * DEG_PER_RAD

    @property
    def tilting(self) -> bool:
        """The tilt sign: the gyro turns gravity many times further than the accelerometer sees it turn, and the
        same numbers as deg/s turn it as far as an ordinary drive does."""
        return (
            self.tilt_pairs >= TILT_MIN_PAIRS
            and self.tilt_gyro_deg >= TILT_MIN_DEG
            and self.tilt_gyro_deg >= TILT_RATIO_MIN * self.tilt_acc_deg
            and self.tilt_gyro_deg / DEG_PER_RAD <= TILT_RATIO_MIN * self.tilt_acc_deg
        )

    def evidence(self) -> str:
        """What shows the gyro is in deg/s (empty when nothing does)."""
        signs = []
        if self.at_rest:
            signs.append(
                f"a spread of {self.spread:.3g} rad/s about its mean over {self.rest_s:.0f} s that the accelerometer "
                f"found still ({self.spread / max(self.acc_spread, 1e-12):.3g} times the accelerometer's "
                f"{self.acc_spread:.3g} m/s²): no gyro at rest spreads over {REST_SPREAD_MAX_RAD_S:g} rad/s, while "
                f"{self.spread / DEG_PER_RAD:.2g} rad/s (the same numbers as deg/s) is ordinary"
            )
        if self.driving:
            signs.append(
                f"rates of {self.fast_rate:.3g} rad/s for {self.fast_s:.0f} s at ≥ {ROAD_SPEED_MPS:g} m/s, which no "
                f"road vehicle turns at (over {ROAD_RATE_MAX_RAD_S:g} rad/s), while {self.fast_rate / DEG_PER_RAD:.2g} "
                "rad/s (the same numbers as deg/s) is ordinary"
            )
        if self.tilting:
            signs.append(
                f"rates that turn gravity by {self.tilt_gyro_deg:.3g}° from one second's mean to the next (RMS over "
                f"{self.tilt_pairs} s, about the horizontal axes), where the accelerometer sees it turn "
                f"{self.tilt_acc_deg:.3g}°: {self.tilt_gyro_deg / max(self.tilt_acc_deg, 1e-12):.3g} times further "
                f"(a gyro in rad/s predicts less than it sees: 0.3–0.8 times on the real recordings), while "
                f"{self.tilt_gyro_deg / DEG_PER_RAD:.2g}° (the same numbers as deg/s) fits"
            )
        return "; and ".join(signs)

    def rejection(self, source: str, channels: Iterable[str] = ()) -> str:
        """A sentence for a refusal of too few stops: the still periods the gyro rejected, and the suspicion."""
        if not self.rejected:
            return ""
        said = (
            f"the gyro rejected {self.rejected} of the {self.periods} periods the accelerometer found still long "
            f"enough for a stop (gyro moving std < {self.gyro_std_limit:.3g} rad/s, {option('max_gyro_std')}; rate "
            f"within {self.gyro_rate_limit:.3g} rad/s of its bias, {option('max_gyro_rate')})"
        )
        if self.rest_s > 0 and self.spread > ORDINARY_REST_RAD_S:
            return (
                f"{said}. At rest the gyro spreads {self.spread:.3g} rad/s, more than a gyro at rest in rad/s "
                f"(≤ {ORDINARY_REST_RAD_S:g}): if it is logged in deg/s, {fix(source, channels)} Otherwise relax "
                "those thresholds."
            )
        return f"{said}: the vehicle rocked or turned while parked, or relax those thresholds."


def look(
    t_start: FloatArray,
    t_end: FloatArray,
    criteria: list[Criterion],
    judged: np.ndarray,
    need_s: float,
) -> GyroLook | None:
    """The gyro's readings per block of stop detection (``criteria`` by option key), or None without a gyro.

    ``need_s``: how long a still period must be to hold a stop (its minimum and the trims).
    """
    by = {c.key: c for c in criteria}
    g_std, g_rate, acc = by.get("max_gyro_std"), by.get("max_gyro_rate"), by["max_acc_std"]
    if g_std is None or g_rate is None or t_start.size == 0:
        return None
    block_s = float(np.median(np.diff(t_start))) if t_start.size > 1 else float(t_end[0] - t_start[0])
    still = (acc.values < min(acc.limit, ACC_STILL_MAX_MPS2)) & judged
    speed = by.get("max_speed")
    if speed is not None:
        still &= speed.values <= speed.limit
    gyro_still = still & (g_std.values < g_std.limit) & (g_rate.values < g_rate.limit)
    periods = rejected = 0
    for a, b in _runs(still):
        if float(t_end[b - 1] - t_start[a]) < need_s:
            continue
        periods += 1
        inside = [float(t_end[a + j - 1] - t_start[a + i]) for i, j in _runs(gyro_still[a:b])]
        rejected += max(inside, default=0.0) < need_s
    fast = np.zeros_like(judged) if speed is None else (speed.values >= ROAD_SPEED_MPS) & judged
    fast &= g_rate.values > ROAD_RATE_MAX_RAD_S
    return GyroLook(
        rest_s=float(still.sum()) * block_s,
        spread=float(np.median(g_std.values[still])) if still.any() else 0.0,
        acc_spread=float(np.median(acc.values[still])) if still.any() else 0.0,
        fast_s=float(fast.sum()) * block_s,
        fast_rate=float(np.median(g_rate.values[fast])) if fast.any() else 0.0,
        periods=periods,
        rejected=rejected,
        gyro_std_limit=g_std.limit,
        gyro_rate_limit=g_rate.limit,
    )


def tilt_look(t_s: FloatArray, acc: FloatArray, gyro: FloatArray) -> tuple[float, float, int]:
    """(RMS tilt change in degrees the gyro predicts between consecutive :data:`TILT_BLOCK_S` means, RMS change of
    the accelerometer's direction between them, the number of pairs) of time-ordered samples.

    The gyro's bias is its median mean; its rate about the accelerometer's direction (the vertical) turns nothing
    the accelerometer can see, so only the part about the horizontal axes counts, less what follows the vertical
    rate (on simulated drives with the accelerometer's z reversed, 0.45–0.51 times what the accelerometer sees
    once taken out, 0.62–1.47 before)."""
    if t_s.size < 2:
        return 0.0, 0.0, 0
    # the blocks that hold samples, numbered in order (times far apart leave no empty block to count)
    seconds, block = np.unique(np.floor((t_s - t_s[0]) / TILT_BLOCK_S), return_inverse=True)
    count = np.bincount(block)
    full = np.flatnonzero(count >= 5)
    if full.size < 2:
        return 0.0, 0.0, 0
    mean_acc = np.stack([np.bincount(block, acc[:, i])[full] for i in range(3)], axis=1) / count[full, None]
    mean_gyro = np.stack([np.bincount(block, gyro[:, i])[full] for i in range(3)], axis=1) / count[full, None]
    mean_gyro -= np.median(mean_gyro, axis=0)
    norm = np.linalg.norm(mean_acc, axis=1)
    pair = (np.diff(seconds[full]) == 1) & (norm[1:] > 0) & (norm[:-1] > 0)
    if not pair.any():
        return 0.0, 0.0, 0
    up = mean_acc / np.maximum(norm, 1e-300)[:, None]
    seen = np.arccos(np.clip(np.sum(up[1:] * up[:-1], axis=1), -1.0, 1.0))[pair]
    rate = 0.5 * (mean_gyro[1:] + mean_gyro[:-1])
    about_up = np.sum(rate * up[:-1], axis=1)
    horizontal = rate - about_up[:, None] * up[:-1]
    # the part that follows the rate about the vertical is the vertical seen from axes the accelerometer's disagree
    # with (one accelerometer axis reversed, a DBC sign: its "up" leans from the gyro's, and the turns leak into
    # the horizontal): taken out, so that only a gyro scaled as a whole shows this sign
    horizontal -= about_up[:, None] * (horizontal.T @ about_up) / max(float(about_up @ about_up), 1e-300)
    turned = np.linalg.norm(horizontal, axis=1)[pair] * TILT_BLOCK_S
    return _rms_deg(turned), _rms_deg(seen), int(pair.sum())


def _rms_deg(angles_rad: FloatArray) -> float:
    return float(np.degrees(np.sqrt(np.mean(angles_rad * angles_rad))))


def refuse_degrees(found: GyroLook | None, source: str, channels: Iterable[str] = ()) -> None:
    """Refuse a gyro whose readings show deg/s where rad/s is stated (nothing when they do not)."""
    if found is None or not (found.at_rest or found.driving or found.tilting):
        return
    raise InputError(
        source,
        "angular rates in rad/s, the gyro's unit as the format, the columns or the mapping state it",
        f"numbers 57.3 times too large, as a gyro in deg/s reads: {found.evidence()}",
        f"The gyro is logged in deg/s: {fix(source, channels)}",
    )


def fix(source: str, channels: Iterable[str] = ()) -> str:
    """What states the gyro's unit for the input kind of ``source`` (its first file); ``channels``: the log's
    channel keys (``speed_mps``...), which a sample table's column map names too."""
    first = Path(source.split(" + ")[0])
    suffix = first.suffix.lower()
    if suffix in (".blf", ".asc", ".log", ".trc", ".mf4", ".mdf"):
        return (
            f'state it in the CAN mapping\'s [units] table, gyro = "deg/s" ({option("mapping")}), or correct the '
            "unit of the gyro signals in the DBC."
        )
    if suffix in (".mcap", ".bag", ".db3") or first.is_dir():
        return (
            "sensor_msgs/Imu's angular_velocity is rad/s (REP 103), and the driver that recorded this log "
            "publishes deg/s. mountcal has no option that rescales a recorded angular_velocity: set the driver to "
            "publish rad/s and record again, or write the samples to a sample table (t_s, ax, ay, az, gx, gy, gz) "
            f"and read it with {option('columns', table_map(channels))}."
        )
    if suffix in (".csv", ".parquet", ".pq"):
        return (
            f"give the table's columns with their units, {option('columns', table_map(channels))} (with a column map "
            'already: add :deg/s to its gx, gy, gz; a CAN log read with a DBC: the mapping\'s [units] gyro = "deg/s").'
        )
    return (
        f"state its unit: a table's column map (gx=COLUMN:deg/s, {option('columns')}), a CAN mapping's [units] "
        'gyro = "deg/s", or a driver that publishes rad/s.'
    )


def table_map(channels: Iterable[str] = ()) -> str:
    """A column map of mountcal's own columns with the gyro in deg/s: a map names every column it reads, so the
    log's channels too."""
    roles = {key: role for role, key in CHANNELS.items()}
    named = ",".join(f"{roles[c]}={c}" for c in channels if c in roles)
    return "time=t_s,ax=ax,ay=ay,az=az,gx=gx:deg/s,gy=gy:deg/s,gz=gz:deg/s" + (f",{named}" if named else "")


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(), strict=True))


__all__ = ["GyroLook", "fix", "look", "refuse_degrees", "tilt_look"]
