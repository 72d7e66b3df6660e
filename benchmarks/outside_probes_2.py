"""Probes, second batch: five more effect types the library does not model, invented after the slope
reference was built, run exactly as benchmarks/outside_effects.py runs its twelve (same sessions,
same "moved" and "flagged"). Written to look for weaknesses; nothing was changed after running them.

Two of the protocol (headings read off a compass rose to the nearest 5°, 10°, 20°; the stop means
quantised by a logger's resolution), two of the sensor (its temperature logged by a board thermistor
that lags the die; the bracket tilting as it warms), and one of the vehicle that lies inside the
model's span on one slope by construction (a soft suspension: the body leans downhill by the same
fraction of the slope in roll and in pitch, so the stops read a steeper slope and nothing else; with
``--slope-reference-sigma`` the reference sees it).

    OMP_NUM_THREADS=1 python benchmarks/outside_probes_2.py --runs 200 --seed 15 \
        --markdown docs/outside-probes-2-results.md
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from outside_effects import MG, Effect, Session, _add, _from_vehicle, main
from scipy.spatial.transform import Rotation

from mountcal.core.conventions import specific_force_v
from mountcal.stops.table import StopTable


def compass_rose(s: Session, q: float, rng: np.random.Generator) -> StopTable:
    """The headings are read off a compass rose to the nearest q degrees."""
    beta = np.degrees(np.asarray(s.table.beta_rad, float))
    return replace(s.table, beta_rad=np.radians(q * np.round(beta / q)))


def quantised_means(s: Session, q: float, rng: np.random.Generator) -> StopTable:
    """Each stop's mean is stuck on the logger's resolution of q mg (noise below one step does not dither it);
    the stop noise in the table stays what the sensor's is."""
    step = q * MG
    return replace(s.table, acc_s=step * np.round(s.table.acc_s / step))


def lagging_thermistor(s: Session, tau: float, rng: np.random.Generator) -> StopTable:
    """The bias drifts 0.5 mg/°C per axis (random signs, within the class's 0.86) with the die temperature, and the
    logged temperature is a board thermistor that follows the die with a lag of tau stops."""
    die = np.asarray(s.table.temperature_c, float)
    logged = np.empty_like(die)
    logged[0] = die[0]
    keep = np.exp(-1.0 / tau)
    for i in range(1, die.size):  # a first-order lag, stop to stop
        logged[i] = keep * logged[i - 1] + (1.0 - keep) * die[i]
    drift = rng.choice([-1.0, 1.0], 3) * 0.5 * MG
    table = _add(s, np.outer(die - 20.0, drift))
    return replace(table, temperature_c=logged)


def bracket_thermal_tilt(s: Session, k: float, rng: np.random.Generator) -> StopTable:
    """The bracket tilts k degrees per °C about a random horizontal sensor axis as it warms from 20 °C."""
    axis = np.append(rng.normal(size=2), 0.0)
    tilt = np.radians(k) * (np.asarray(s.table.temperature_c, float) - 20.0)
    turn = Rotation.from_rotvec(np.outer(tilt, axis / np.linalg.norm(axis)))
    return _add(s, turn.apply(s.u_s) - s.u_s)


def soft_suspension(s: Session, k: float, rng: np.random.Generator) -> StopTable:
    """The body leans downhill by k × the slope, in roll and in pitch alike: it stands on a slope (1 + k) α."""
    slope = np.radians(s.truth.slope_deg) * (1.0 + k)
    return _from_vehicle(s, specific_force_v(slope, np.asarray(s.table.beta_rad, float), s.truth.g_mps2))


PROBES: list[tuple[str, str, Effect, tuple[float, ...]]] = [
    ("headings read off a compass rose", "° steps", compass_rose, (5.0, 10.0, 20.0)),
    ("stop means quantised by the logger", "mg steps", quantised_means, (1.0, 4.0, 16.0)),
    ("temperature logged by a lagging thermistor", "stops of lag", lagging_thermistor, (1.0, 3.0, 8.0)),
    ("bracket tilting as it warms", "°/°C", bracket_thermal_tilt, (0.003, 0.01, 0.03)),
    ("soft suspension: the body leans downhill", "× slope", soft_suspension, (0.02, 0.05, 0.15)),
]

if __name__ == "__main__":
    main(
        PROBES,
        (("all five", slice(None)), ("all but the one inside the model's span", slice(0, 4))),
        __doc__,
    )
