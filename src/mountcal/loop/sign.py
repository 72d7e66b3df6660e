"""An acceleration sign only assumed (a Sensor Logger recording from iOS, :mod:`mountcal.io.sensor_logger`), turned
round once where a handedness check finds the data mirrored: the one rule for a log's samples
(:mod:`mountcal.calibration.pipeline`) and for a stop table made from one (:func:`mountcal.calibration.fit.calibrate`).

A sign reversed in all three axes is a reflection: the data of a right-handed sensor then turn the wrong way round.
Where the sign was stated or inferred, or is not a phone app's at all, a mirror is refused as found
(:class:`~mountcal.loop.crosscheck.Mirrored`), with what the sign rests on; where it was only the app's default,
the other sign is taken, inferred and said, and a mirror with that one too is refused.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import TypeVar

from mountcal.core.result import Calibration, Convention
from mountcal.io.sensor_logger import acceleration_sign, sign_hint, turned_sign
from mountcal.loop.crosscheck import Mirrored
from mountcal.stops.table import StopTable

Data = TypeVar("Data")
Out = TypeVar("Out")


def turned_once(
    run: Callable[[Data], Out],
    data: Data,
    turn: Callable[[Data, str], Data | None],
    conventions: Callable[[Data], Sequence[Convention]],
) -> Out:
    """``run(data)``; where it raises :class:`Mirrored` and ``turn`` gives the data with the other sign (the sign
    was only a default; ``turn`` gets what was found), ``run`` of those. A refusal names the sign's
    (``conventions`` of the data).

    Raises
    ------
    Mirrored
        The data are mirrored with either sign, or with a sign that was stated or inferred.
    """
    try:
        return run(data)
    except Mirrored as err:
        turned = turn(data, err.found)
        if turned is None:
            raise _with_hint(err, conventions(data)) from err
    try:
        return run(turned)
    except Mirrored as err:
        raise _with_hint(err, conventions(turned)) from err


def other_table_sign(table: StopTable, why: str) -> StopTable | None:
    """The stop table with the acceleration's other sign, where it was only the app's default (else None): the
    means turned round, their covariances unchanged (a negation keeps them), the sign inferred and said."""
    turned = turned_sign(table.conventions, why)
    if turned is None:
        return None
    return replace(table, acc_s=-table.acc_s, conventions=turned[0])


def with_turn_note(cal: Calibration, given: Sequence[Convention]) -> Calibration:
    """The calibration with a note where its sign is not the one ``given`` (the stops were turned round)."""
    before, after = acceleration_sign(given), acceleration_sign(cal.provenance.conventions)
    if before is None or after is None or before.value == after.value:
        return cal
    note = (
        f"acceleration_sign: {after.value}, inferred by the handedness checks (the app's default, {before.value}, "
        "mirrored the stops): the stops' means were turned round and fitted again"
    )
    return replace(cal, notes=(*cal.notes, note))


def _with_hint(err: Mirrored, conventions: Sequence[Convention]) -> Mirrored:
    hint = sign_hint(conventions)
    return Mirrored(err.where, err.expected, err.found, err.todo + hint) if hint else err
