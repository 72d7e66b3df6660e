"""The unit a CAN log's accelerometer was read in, checked by gravity, and the units its signals were read in, stated.

Every reader of CAN data (a log read whole or in chunks, a live bus) passes its samples through both: a DBC or
mapping stating the wrong unit would otherwise reach every number mountcal writes (``rotate`` 9.8 times off).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from mountcal.core.errors import InputError
from mountcal.core.option_names import option
from mountcal.io.can.mapping import Plan
from mountcal.io.can.signals import G_N, UNITS
from mountcal.io.samples import GRAVITY_BAND_G, GRAVITY_FREE_MPS2, Samples


def noted(samples: Samples, plan: Plan) -> Samples:
    """The samples with what the plan left out and says (:attr:`Plan.notes`), and the units their signals
    were read in (the convention ``can_units``, stated by the DBC or the mapping)."""
    from mountcal.core.result import Convention

    said = (Convention("can_units", plan.units[0], "stated", plan.units[1]),) if plan.units[0] else ()
    return replace(samples, notes=(*samples.notes, *plan.notes), conventions=(*samples.conventions, *said))


def check_magnitude(samples: Samples, plan: Plan) -> Samples:
    """``samples`` after a look at the median magnitude of their acceleration, which gravity sets near 1 g.

    Below 0.5 m/s² the acceleration has no gravity in it (a "linear acceleration" signal): marked
    gravity-free (it reads and rotates, but does not calibrate) — unless it keeps a steady direction at a
    magnitude a unit explains (gravity in g read as mg), which is refused. Outside 0.5–1.5 g otherwise, the unit
    the signals were read in (the DBC's, or the mapping's ``[units] accel``) or their DBC factor is wrong:
    refused, naming what stated the unit and the unit the magnitudes fit, before any command uses a
    number (``rotate`` would write it 9.8 times off).
    """
    if not len(samples) or not plan.acc_units:
        return samples
    with np.errstate(over="ignore"):  # a decoded value near the float range (a float signal's bits): inf, quietly
        m = float(np.median(np.linalg.norm(samples.acc_s, axis=1)))  # m/s², as read
    lo, hi = GRAVITY_BAND_G
    if lo * G_N <= m <= hi * G_N:
        return samples
    read_scale = plan.acc_units[0][3]  # m/s² per unit of the signal as read
    true_scale = read_scale * G_N / m  # what the scale would be were the median magnitude 1 g
    fits = [u for u, (k, _) in UNITS["accel"].items() if abs(math.log(k / true_scale)) < math.log(1.25)]
    # gravity read 1000 times too small (g as mg) is as small as a gravity-free signal, but keeps its direction
    with np.errstate(over="ignore", invalid="ignore"):
        steady = float(np.linalg.norm(np.mean(samples.acc_s, axis=0))) >= 0.5 * m
    if m < GRAVITY_FREE_MPS2 and not (fits and steady):
        reason = f"the acceleration's median magnitude is {m:.3g} m/s²: no gravity in it, as in a 'linear acceleration'"
        return replace(samples, gravity_free=reason)
    by_unit: dict[str, list[str]] = {}
    for label, unit, by, _ in plan.acc_units:
        by_unit.setdefault(unit or "(no unit)", []).append(label if by.startswith("the DBC") else by)
    read_in = "; ".join(
        f"{unit} ({by[0] if by[0].startswith('the mapping') else 'the DBC unit of ' + ', '.join(by)})"
        for unit, by in by_unit.items()
    )
    mapped = any(by.startswith("the mapping") for _, _, by, _ in plan.acc_units)
    signals = ", ".join(label for label, *_ in plan.acc_units)
    if fits:
        state = (
            f'write accel = "{fits[0]}" in the CAN mapping\'s [units] table ({option("mapping")}) instead of '
            f'"{plan.acc_units[0][1]}"'
            if mapped
            else f'state it in the CAN mapping\'s [units] table, accel = "{fits[0]}" ({option("mapping")}), or '
            "correct their unit in the DBC"
        )
        todo = f"The magnitudes fit {fits[0]}: if the signals ({signals}) are in {fits[0]}, {state}."
    else:
        unit = plan.acc_units[0][1] or "(no unit)"
        todo = (
            f"No unit fits: the signals ({signals}) decode to a median magnitude of {m / read_scale:.4g} {unit}, "
            f"where 1 g is {G_N / read_scale:.4g} {unit}: check their factor and offset in the DBC "
            "(SG_ … (factor,offset)) against the sensor's datasheet, and the mapping's [units] accel."
        )
    raise InputError(
        plan.where,
        f"accelerations of magnitude near 1 g ({lo:g}–{hi:g} g) read in {read_in}",
        f"a median magnitude of {m:.4g} m/s² ({m / G_N:.4g} g) over {len(samples)} samples",
        todo,
    )


__all__ = ["check_magnitude", "noted"]
