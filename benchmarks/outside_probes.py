"""Probes: six more effect types the library does not model, invented after the step tests were built,
run exactly as benchmarks/outside_effects.py runs its twelve (same sessions, same "moved" and "flagged").

They were written to look for weaknesses, not to be passed: nothing was changed after running them.
Two are of the sensor (a scale factor that changes with temperature; the bracket slipping mid-session),
four of the vehicle and the protocol (the body pitching when the driver gets out at some stops; a slow
tyre leak rolling the body over the session; a second operator reading the headings with another
offset from a stop on; a car park that is not a plane).

    OMP_NUM_THREADS=1 python benchmarks/outside_probes.py --runs 200 --seed 15 \
        --markdown docs/outside-probes-results.md
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from outside_effects import Effect, Session, _add, _from_vehicle, _later, _sign3, main
from scipy.spatial.transform import Rotation

from mountcal.stops.table import StopTable


def _body_turned(s: Session, rotvec: np.ndarray) -> StopTable:
    """The stops with the body turned by ``rotvec`` (n, 3) relative to the road, in the vehicle frame."""
    return _from_vehicle(s, Rotation.from_rotvec(rotvec).apply(s.f_v))


def scale_tc(s: Session, k: float, rng: np.random.Generator) -> StopTable:
    """Each axis's scale factor changes by k %/°C (random signs) from 20 °C: a_i += k_i (T − 20) a_i."""
    t = np.asarray(s.table.temperature_c, float) - 20.0
    return _add(s, (_sign3(rng) * k * 1e-2)[None, :] * t[:, None] * s.u_s)


def driver_out(s: Session, d: float, rng: np.random.Generator) -> StopTable:
    """The body pitches by d degrees at a random third of the stops (the driver got out)."""
    out = rng.random(len(s.table)) < 1 / 3
    return _body_turned(s, np.outer(out * np.radians(d), [0.0, 1.0, 0.0]))


def tyre_leak(s: Session, d: float, rng: np.random.Generator) -> StopTable:
    """The body rolls linearly in time to ±d degrees at the session's end (a slow tyre leak)."""
    t = np.asarray(s.table.t_s, float)
    roll = np.radians(d) * rng.choice([-1.0, 1.0]) * (t - t[0]) / np.ptp(t)
    return _body_turned(s, np.outer(roll, [1.0, 0.0, 0.0]))


def second_operator(s: Session, d: float, rng: np.random.Generator) -> StopTable:
    """From a stop in the middle half on, the headings are read d degrees off (another operator, another mark)."""
    later = _later(len(s.table), rng)
    return replace(s.table, beta_rad=s.table.beta_rad + np.radians(d) * rng.choice([-1.0, 1.0]) * later)  # type: ignore[operator]


def bracket_slip(s: Session, d: float, rng: np.random.Generator) -> StopTable:
    """From a stop in the middle half on, the sensor is turned by d degrees about a random axis (it slipped)."""
    axis = rng.normal(size=3)
    later = _later(len(s.table), rng)
    turn = Rotation.from_rotvec(np.outer(later * np.radians(d), axis / np.linalg.norm(axis)))
    return _add(s, turn.apply(s.u_s) - s.u_s)


def warped_car_park(s: Session, d: float, rng: np.random.Generator) -> StopTable:
    """The ground is not a plane: each stop's ground is tilted by up to d degrees, a smooth function of where
    on the circle it stands (3β and 2β, random phases)."""
    beta = np.asarray(s.table.beta_rad, float)
    phase = rng.uniform(0.0, 2 * np.pi, 2)
    tilt = np.column_stack([np.sin(3 * beta + phase[0]), np.cos(2 * beta + phase[1]), np.zeros_like(beta)])
    return _body_turned(s, np.radians(d) * tilt)


PROBES: list[tuple[str, str, Effect, tuple[float, ...]]] = [
    ("scale factor changing with temperature", "%/°C", scale_tc, (0.02, 0.1, 0.3)),
    ("body pitches at a third of the stops (driver out)", "°", driver_out, (0.1, 0.3, 1.0)),
    ("body rolls over the session (slow tyre leak)", "° at the end", tyre_leak, (0.2, 0.5, 1.5)),
    ("headings read with another offset from a stop on", "°", second_operator, (1.0, 3.0, 8.0)),
    ("bracket slips mid-session", "°", bracket_slip, (0.1, 0.3, 1.0)),
    ("car park not a plane", "°", warped_car_park, (0.1, 0.3, 1.0)),
]

if __name__ == "__main__":
    main(PROBES, (("all six probes", slice(None)), ("all but the scale factor", slice(1, None))), __doc__)
