"""Strictly increasing sample times: duplicate stamps merged, out-of-order samples put in order.

Loggers often stamp samples in pairs (two IMU readings per CAN frame or per message) and clocks
sometimes step back. Everything downstream (stop detection, driving) divides by the sample step, so
the samples are made strictly increasing first, and what was changed is counted in
``Samples.dropped``.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from mountcal.core.errors import InputError
from mountcal.io.samples import Channel, FloatArray, Samples

MERGED = "samples merged (duplicate timestamp)"
REORDERED = "samples out of time order (put in order)"
CIRCULAR = ("heading_deg",)  # channels averaged as angles


def increasing_times(samples: Samples) -> Samples:
    """The samples with strictly increasing times: equal stamps averaged into one sample.

    The counts of merged and reordered samples are added to ``dropped`` (the merged samples are
    not lost: each merged sample is the mean of its group). Auxiliary channels get the same
    treatment (headings averaged as angles), counted under their own names.
    """
    samples = time_ordered(samples)
    t = samples.t_s
    if t.size < 2 or bool(np.all(np.diff(t) > 0)):
        return samples
    starts = np.flatnonzero(np.concatenate([[True], np.diff(t) > 0]))
    size = np.diff(np.append(starts, t.size)).astype(float)[:, None]

    def merge(x: FloatArray) -> FloatArray:
        return np.asarray(np.add.reduceat(x, starts, axis=0) / size, dtype=np.float64)

    dropped = dict(samples.dropped)
    _count(dropped, MERGED, t.size - starts.size)
    return replace(
        samples,
        t_s=t[starts],
        acc_s=merge(samples.acc_s),
        gyro_s=None if samples.gyro_s is None else merge(samples.gyro_s),
        dropped=dropped,
    )


RESTART_S = 10.0  # a clock stepping back further, for longer, is not jitter: a restart, or two recordings


def time_ordered(samples: Samples) -> Samples:
    """The samples in time order (stable), equal stamps kept; channels made strictly increasing.

    Statistics of the samples themselves (a quantised sensor's codes) need every sample as
    logged; only the order is fixed here, and counted.

    Raises
    ------
    InputError
        The clock steps back by more than 10 s and a run of samples behind it spans more than 10 s of its own:
        a restarted clock or two recordings in one file, whose samples put in order would interleave two
        stretches of the drive (stops would be searched in a mixture). A step back of a second (a clock
        synchronised, jitter) is put in order and counted, as before.
    """
    check_one_clock(samples.t_s, samples.source)
    dropped = dict(samples.dropped)
    channels = {}
    for key, ch in samples.channels.items():
        new_ch, merged, reordered = _channel(ch, circular=key in CIRCULAR)
        channels[key] = new_ch
        _count(dropped, f"{key}: {MERGED}", merged)
        _count(dropped, f"{key}: {REORDERED}", reordered)
    order, reordered = _order(samples.t_s)
    _count(dropped, REORDERED, reordered)
    if not reordered:
        return replace(samples, channels=channels, dropped=dropped) if dropped != samples.dropped else samples
    return replace(
        samples,
        t_s=samples.t_s[order],
        acc_s=samples.acc_s[order],
        gyro_s=None if samples.gyro_s is None else samples.gyro_s[order],
        channels=channels,
        dropped=dropped,
    )


def check_one_clock(t: FloatArray, source: str) -> None:
    """Refuse times whose clock restarts (see :func:`time_ordered`), naming where it steps back."""
    if t.size < 2:
        return
    latest = np.maximum.accumulate(t)
    behind = t < latest - RESTART_S
    if not behind.any():
        return
    # runs of consecutive samples behind: a restart is one long run, stray stamps are single samples
    edges = np.flatnonzero(np.diff(np.concatenate([[0], behind.astype(np.int8), [0]])))
    starts, ends = edges[::2], edges[1::2]
    spans = np.maximum.reduceat(np.where(behind, t, -np.inf), starts) - np.minimum.reduceat(
        np.where(behind, t, np.inf), starts
    )  # each run's span: a segment from a run's start to the next run's holds that run alone
    longest = int(np.argmax(spans))
    if spans[longest] <= RESTART_S:
        return  # stray stamps, or a short stretch: put in order and counted
    first, span = int(starts[longest]), float(spans[longest])
    step = float(latest[first - 1] - t[first])
    raise InputError(
        source,
        "sample times on one clock that runs forward (steps back under 10 s, or a few stray stamps, are put in order)",
        f"the clock stepping back by {step:.1f} s at sample {first + 1} (t = {latest[first - 1]:.3f} s → "
        f"{t[first]:.3f} s), and {int(ends[longest] - first)} samples over {span:.0f} s behind the times before it: a "
        "restarted clock, or two recordings in one file, whose samples put in order would interleave",
        "Split the log where its clock steps back and give each part on its own (their times overlap: they are "
        "not splits of one log), or fix the logger's time source.",
    )


def _order(t: FloatArray) -> tuple[np.ndarray, int]:
    """A stable time order and how many samples stepped back in time."""
    backwards = int(np.count_nonzero(np.diff(t) < 0))
    return (np.argsort(t, kind="stable") if backwards else np.arange(t.size)), backwards


def _channel(ch: Channel, circular: bool) -> tuple[Channel, int, int]:
    if ch.t_s.size < 2 or bool(np.all(np.diff(ch.t_s) > 0)):
        return ch, 0, 0
    order, reordered = _order(ch.t_s)
    ts = ch.t_s[order]
    starts = np.flatnonzero(np.concatenate([[True], np.diff(ts) > 0]))
    size = np.diff(np.append(starts, ts.size)).astype(float)
    v = ch.value[order]
    if circular:
        z = np.add.reduceat(np.exp(1j * np.radians(v)), starts) / size
        value = np.degrees(np.angle(z)) % 360.0
    else:
        value = np.add.reduceat(v, starts) / size
    return Channel(ts[starts], value), ts.size - starts.size, reordered


def _count(dropped: dict[str, int], key: str, k: int) -> None:
    if k:
        dropped[key] = dropped.get(key, 0) + k
