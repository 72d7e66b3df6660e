"""A stop's heading where the heading channel has none at rest.

A course over ground is the direction of motion: at rest it is undefined, and receivers and apps leave it
empty (an iPhone's bearing of −1, an RMC sentence's empty field) or hold one value (0°, or the last course)
at every stop. Read at rest, such a channel gives no stop a heading, or every stop the same one, although
the vehicle turned between them — and the stops were tabulated without headings, or refused as parked at
one heading. The course in the seconds before each stop, while the vehicle still moved, is the direction it
drove in: the vehicle's heading at the stop when it drove in forwards (a stop entered in reverse reads half
a turn off, which the fit sets aside and names, :mod:`mountcal.loop.half_turn`). A vehicle still turns as it
slows into a spot, and a course below a walking pace is noise: the course is taken at the last moment the
vehicle moved at :data:`MOVING_MPS` or faster, and carried to the stop by the gyro's turn about the stop's up
axis since then (its bias taken from the stop itself). That reading is taken only where the at-rest one fails,
and said (convention ``heading_at_stops``); a stop with no course before it (the log began there) is set aside
and counted.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from mountcal.core.conventions import FloatArray
from mountcal.core.result import Convention
from mountcal.io.samples import Channel, Samples
from mountcal.stops.detect import Stop

APPROACH_S = 15.0  # the course is looked for this long before a stop's still run
MOVING_MPS = 2.0  # ... where the vehicle moved at least this fast (a receiver's course at a crawl is noise)
ONE_VALUE_DEG = 0.5  # at-rest headings closer than this at every stop are one held value
TURNED_DEG = 60.0  # ... when the courses before the stops spread wider than this


@dataclass(frozen=True)
class StopHeadings:
    """The stops with the headings to use (``channels["heading_deg"]``), and how they were read."""

    stops: list[Stop]
    convention: Convention | None  # None: read at rest, as the channel gives them
    missing: str | None  # why no stop has a heading (None when they all have one)


def stop_headings(stops: list[Stop], samples: Samples, trim_s: float) -> StopHeadings:
    """Each stop's heading at rest where the channel gives one that moves with the vehicle; else the course before it.

    ``trim_s``: the settling trimmed off the still run at each end (the stop starts that long after the halt).
    """
    heading, speed = samples.channels.get("heading_deg"), samples.channels.get("speed_mps")
    if heading is None or not stops:
        return StopHeadings(stops, None, None)
    at_rest = np.array([s.channels.get("heading_deg", np.nan) for s in stops])
    empty, held = ~np.isfinite(at_rest), _one_value(at_rest)
    if not empty.any() and not held:  # a heading at every stop that moves with the vehicle: read at rest
        return StopHeadings(stops, None, None)
    placeholder = float(np.nanmedian(at_rest)) if held else None
    before = np.array([_course_before(samples, heading, speed, s, s.t_start_s - trim_s, placeholder) for s in stops])
    if not empty.any() and _spread_deg(before) <= TURNED_DEG:  # one value, and the vehicle did not turn either
        return StopHeadings(stops, None, None)
    why = (
        f"empty at {int(empty.sum())} of {len(stops)} stops"
        if empty.any()
        else f"one value ({at_rest[0]:.1f}°) at every stop while the courses before them spread "
        f"{_spread_deg(before):.0f}°"
    )
    has = np.isfinite(before)
    if has.sum() < 3:
        return StopHeadings(
            stops,
            None,
            f"the heading channel at rest is {why}, and fewer than 3 stops have a course "
            "while moving before them to take instead",
        )
    carried = "carried to the stop by the gyro's turn, " if samples.gyro_s is not None else ""
    convention = Convention(
        "heading_at_stops",
        "course before the stop",
        "inferred",
        f"the heading channel at rest ({why}), as a course over ground is: each stop's heading is the last course "
        f"at ≥ {MOVING_MPS:g} m/s in the {APPROACH_S:g} s before it, {carried}a stop entered in reverse reading half "
        "a turn off"
        + (f"; {int((~has).sum())} stop(s) without a course before them set aside" if not has.all() else ""),
    )
    turned = [
        replace(s, channels={**s.channels, "heading_deg": float(h)})
        for s, h, ok in zip(stops, before, has, strict=True)
        if ok
    ]
    return StopHeadings(turned, convention, None)


def _course_before(
    samples: Samples, heading: Channel, speed: Channel | None, stop: Stop, t_halt: float, placeholder: float | None
) -> float:
    """The channel's last finite value in the ``APPROACH_S`` before ``t_halt`` while moving, turned by the gyro's
    yaw since then (NaN if there is none); without a speed, the values that are the at-rest ``placeholder`` are
    left out instead."""
    lo, hi = np.searchsorted(heading.t_s, [t_halt - APPROACH_S, t_halt])  # the window alone, not the whole log
    t, value = heading.t_s[lo:hi], heading.value[lo:hi]
    inside = np.isfinite(value)
    if speed is not None and speed.t_s.size >= 2:
        inside &= np.interp(t, speed.t_s, speed.value, left=np.nan, right=np.nan) >= MOVING_MPS
    elif placeholder is not None:
        inside &= np.abs((value - placeholder + 180.0) % 360.0 - 180.0) >= ONE_VALUE_DEG
    if not inside.any():
        return float("nan")
    last = int(np.flatnonzero(inside)[-1])
    return float((value[last] - np.degrees(_turn_since(samples, stop, t[last]))) % 360.0)


def _turn_since(samples: Samples, stop: Stop, t_from: float) -> float:
    """The vehicle's turn (rad, counter-clockwise seen from above) from ``t_from`` to the stop's start, from the gyro
    about the stop's up axis less its rate at rest during the stop; 0 without a gyro."""
    if samples.gyro_s is None:
        return 0.0
    up = stop.acc_mean_s / np.linalg.norm(stop.acc_mean_s)  # at rest the specific force points up
    t = samples.t_s
    a, b, c = np.searchsorted(t, [t_from, stop.t_start_s, stop.t_end_s])
    if b - a < 2 or c - b < 2:
        return 0.0
    rate = samples.gyro_s[a:b] @ up - float(np.mean(samples.gyro_s[b:c] @ up))
    return float(np.sum(0.5 * (rate[1:] + rate[:-1]) * np.diff(t[a:b])))


def _one_value(deg: FloatArray) -> bool:
    finite = deg[np.isfinite(deg)]
    return finite.size >= 3 and _spread_deg(finite) < ONE_VALUE_DEG


def _spread_deg(deg: FloatArray) -> float:
    """The widest angle between two of the headings (the circle's span they cover)."""
    finite = np.sort(np.asarray(deg, dtype=float)[np.isfinite(deg)] % 360.0)
    if finite.size < 2:
        return 0.0
    gaps = np.diff(np.append(finite, finite[0] + 360.0))
    return float(360.0 - gaps.max())
